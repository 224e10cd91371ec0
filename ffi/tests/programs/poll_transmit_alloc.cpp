// Counts the bytes huddle.hpp's Replica::poll_transmit allocates per datagram: a
// replacement operator new records the largest single allocation while it runs.
// Exits 0 and prints "largest allocation N bytes over M datagrams".
#include <cstdio>
#include <cstdlib>
#include <new>

#include "huddle.hpp"

static bool counting = false;
static std::size_t largest = 0;

void *operator new(std::size_t n) {
    if (counting && n > largest) largest = n;
    void *p = std::malloc(n == 0 ? 1 : n);
    if (p == nullptr) throw std::bad_alloc();
    return p;
}
void operator delete(void *p) noexcept { std::free(p); }
void operator delete(void *p, std::size_t) noexcept { std::free(p); }

int main() {
    huddle_replica_config cfg{};
    cfg.robot_id = 1;
    huddle::Replica replica(cfg, 42, 0);
    std::uint64_t now = 0;
    int datagrams = 0;
    for (int i = 0; i < 50; ++i) {
        now += 10000;
        replica.set(now, "*.var.x", std::to_string(i) + ".5");
        replica.handle_timeout(now);
        counting = true;
        while (auto d = replica.poll_transmit()) {
            if (d->empty()) return 2;
            ++datagrams;
        }
        counting = false;
    }
    std::printf("largest allocation %zu bytes over %d datagrams\n", largest, datagrams);
    return datagrams > 0 ? 0 : 1;
}
