// two_robots.cpp: the C example in C++17 with huddle.hpp's RAII wrappers, plus two
// sans-IO replicas joined by a loop in virtual time.
//
//   c++ -std=c++17 -I ffi/include ffi/examples/two_robots.cpp -L target/debug -lhuddle
//       -Wl,-rpath,target/debug -o two_robots_cpp && ./two_robots_cpp 239.255.7.7 47000
//
// Sends only on loopback (interface 127.0.0.1).
#include <chrono>
#include <cstdlib>
#include <iostream>
#include <string>

#include "huddle.hpp"

using Clock = std::chrono::steady_clock;

static double ms_since(Clock::time_point t0) {
    return std::chrono::duration<double, std::milli>(Clock::now() - t0).count();
}

static int fail(const std::string &why) {
    std::cerr << "two_robots_cpp: " << why << "\n";
    return 1;
}

int main(int argc, char **argv) {
    const std::string group = argc > 1 ? argv[1] : "239.255.7.7";
    const auto port = static_cast<std::uint16_t>(argc > 2 ? std::atoi(argv[2]) : 47000);
    try {
        auto t0 = Clock::now();
        huddle::Node robot1(huddle::NodeConfig{}.robot(1).team(7).group(group, port).interface("127.0.0.1"));
        huddle::Node robot2(huddle::NodeConfig{}.robot(2).team(7).group(group, port).interface("127.0.0.1"));

        robot1.set("*.var.ball.dist", "2.25");
        std::optional<huddle::Binding> seen;
        while (!seen && ms_since(t0) < 1000.0) seen = robot2.get("1.var.ball.dist");
        if (!seen) return fail("robot 2 never saw 1.var.ball.dist");
        std::cout << "robot 2 read " << seen->key << " = " << seen->value << " (" << seen->type
                  << ", age " << seen->age_ms << " ms), " << ms_since(t0) << " ms after start\n";

        try {
            robot1.set("*.var.x", "\"unterminated");
            return fail("a bad literal was accepted");
        } catch (const huddle::Error &e) {
            if (e.code() != HUDDLE_E_LITERAL) return fail("wrong error code");
            std::cout << "refused: " << e.what() << "\n";
        }

        // Typed: no text in between; a long string read whole.
        robot2.watch("1.var.pose");
        robot1.set_floats("*.var.pose", {1.0, -0.5, 0.25});
        robot1.set_int("*.var.mode", 3);
        robot1.set_bool("*.var.ready", true);
        robot1.set_string("*.var.note", std::string(900, 'n'));
        robot1.set_bytes("*.var.raw", {1, 2, 255});
        std::optional<std::vector<std::uint8_t>> raw;  // set last: the others came before it
        while (!raw && ms_since(t0) < 3000.0) raw = robot2.get_bytes("1.var.raw");
        auto note = robot2.get_string("1.var.note");
        auto pose = robot2.get_floats("1.var.pose");
        if (!note || note->size() != 900 || !pose || pose->size() != 3 || !raw || raw->size() != 3 ||
            robot2.get_int("1.var.mode").value_or(0) != 3 || !robot2.get_bool("1.var.ready").value_or(false) ||
            robot2.get_float("1.var.mode").value_or(0) != 3.0 || robot2.get_literal("1.var.note")->size() != 902) {
            return fail("typed values did not arrive whole");
        }
        try {
            robot2.get_int("1.var.note");
            return fail("a string read as an int");
        } catch (const huddle::Error &e) {
            if (e.code() != HUDDLE_E_TYPE) return fail("wrong error code for a type mismatch");
        }
        auto keys = robot2.keys("1.var.#");
        std::cout << "typed: pose[2] " << (*pose)[2] << ", a string of " << note->size() << " bytes, "
                  << keys.size() << " keys of robot 1 (first " << keys.front() << "), "
                  << robot2.stats().peers_present << " peer present, budget "
                  << (robot2.budget() ? "set" : "none") << "\n";
        bool changed = false;
        while (!changed && ms_since(t0) < 4000.0) {
            auto ev = robot2.next_event(50);
            changed = ev && ev->kind == HUDDLE_EVENT_VALUE_CHANGED && ev->name == "1.var.pose";
        }
        if (!changed) return fail("no value-changed event for the watched key");
        robot2.unwatch("1.var.pose");

        for (int i = 1; i <= 100; i++) robot1.post("*.talk.plan", "\"msg " + std::to_string(i) + "\"");
        int delivered = 0;
        auto deadline = Clock::now() + std::chrono::seconds(5);
        while (delivered < 100 && Clock::now() < deadline) {
            auto ev = robot2.next_event(100);
            if (!ev) continue;
            if (ev->kind == HUDDLE_EVENT_TALK_DELIVERED) {
                delivered++;
                std::string want = "\"msg " + std::to_string(delivered) + "\"";
                if (ev->seq != static_cast<std::uint64_t>(delivered) || ev->value != want) {
                    return fail("out of order: seq " + std::to_string(ev->seq) + " " + ev->value);
                }
            } else if (ev->kind == HUDDLE_EVENT_TALK_GIVEN_UP || ev->kind == HUDDLE_EVENT_LAGGED) {
                return fail("talk lost");
            }
        }
        if (delivered != 100) return fail("only " + std::to_string(delivered) + " messages arrived");
        std::cout << "robot 2 got 100 talk messages from robot 1, in order\n";

        // The sans-IO level: two replicas, frames handed over by hand, 3 ms apart.
        huddle_replica_config c1{}, c2{};
        c1.robot_id = 1;
        c2.robot_id = 2;
        huddle::Replica r1(c1, 0x1111, 0), r2(c2, 0x2222, 0);
        r1.set(0, "*.var.machine.heuristic", "2.5");
        r1.set_floats(0, "*.var.pose", {1.0, 2.0, 0.5});
        r1.set_int(0, "*.var.mode", 2);
        while (auto frame = r1.poll_transmit()) r2.handle_datagram(3000, *frame);
        auto h = r2.get(3000, "1.var.machine.heuristic");
        if (!h || h->value != "2.5") return fail("the replica did not replicate");
        auto rp = r2.get_floats("1.var.pose");
        if (!rp || rp->size() != 3 || (*rp)[2] != 0.5 || r2.get_int("1.var.mode").value_or(0) != 2 ||
            r2.get_float("1.var.machine.heuristic").value_or(0) != 2.5 ||
            r2.get_literal("1.var.pose").value_or("") != "[1.0, 2.0, 0.5]") {
            return fail("the replica's typed values did not replicate");
        }
        std::cout << "replica 2 read " << h->key << " = " << h->value << " age " << h->age_ms
                  << " ms; next deadline at " << r1.poll_timeout().value_or(0) << " us\n";
    } catch (const huddle::Error &e) {
        return fail(std::string("error ") + std::to_string(e.code()) + ": " + e.what());
    }
    std::cout << "two_robots_cpp: OK\n";
    return 0;
}
