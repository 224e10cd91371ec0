// huddle.hpp: C++17 RAII wrappers over huddle.h (header-only; link libhuddle as for C).
//
//   huddle::Node robot(huddle::NodeConfig{}.robot(1).group("239.7.7.7", 2000));
//   robot.set("*.var.ball.dist", "1.5");
//   if (auto b = robot.get("2.var.ball.dist")) std::cout << b->value << " " << b->age_ms;
//
// Errors become huddle::Error (code + message). A Node stops when it goes out of scope;
// a Replica is freed. Both are movable, not copyable. Node methods may be called from
// any thread, as the C functions they wrap.
#ifndef HUDDLE_HPP
#define HUDDLE_HPP

#include <cstdint>
#include <cstring>
#include <optional>
#include <stdexcept>
#include <string>
#include <utility>
#include <vector>

#include "huddle.h"

namespace huddle {

/// A failed call: the huddle_error code (HUDDLE_E_*) and its message.
class Error : public std::runtime_error {
public:
    Error(int code, const std::string &message) : std::runtime_error(message), code_(code) {}
    int code() const noexcept { return code_; }

private:
    int code_;
};

namespace detail {
inline huddle_error fresh_error() {
    huddle_error err;
    std::memset(&err, 0, sizeof err);
    return err;
}
inline int check(int rc, const huddle_error &err) {
    if (rc < 0) throw Error(err.code, err.message);
    return rc;
}
/// A variable-length read: asks for the length, then reads exactly that much.
/// `call(buf, cap, &len, &err)` is one of the huddle_node_get_* calls bound to its key;
/// `extra` is room beyond the length (1 for a string's NUL).
template <typename T, typename Call>
std::optional<std::vector<T>> read_sized(Call call, std::size_t extra) {
    huddle_error err = fresh_error();
    std::size_t len = 0;
    if (check(call(static_cast<T *>(nullptr), 0, &len, &err), err) == 0) return std::nullopt;
    std::vector<T> out(len + extra);
    // The value may have grown in between: read again with the length it now has.
    while (call(out.data(), out.size(), &len, &err) < 0) {
        if (err.code != HUDDLE_E_BUFFER) throw Error(err.code, err.message);
        out.resize(len + extra);
    }
    out.resize(len);
    return out;
}
}  // namespace detail

/// A binding read from the blackboard.
struct Binding {
    std::string key, type, value;  // value: a literal, as huddle_node_set reads it
    std::uint8_t owner = 0;
    std::uint64_t age_ms = 0;
    bool truncated = false;  // the literal was longer than huddle_binding holds
};

/// An event, as huddle_event (kind: HUDDLE_EVENT_*).
struct Event {
    int kind = 0;
    std::uint8_t robot = 0;
    std::string name, type, value;
    std::uint64_t seq = 0, last = 0, incarnation = 0, count = 0;
};

inline Binding to_binding(const huddle_binding &b) {
    return Binding{b.key, b.type, b.value, b.owner, b.age_ms, b.value_len >= sizeof b.value};
}

inline Event to_event(const huddle_event &e) {
    return Event{e.kind, e.robot, e.name, e.type, e.value, e.seq, e.last, e.incarnation, e.count};
}

/// Settings of a Node, builder style; unset fields take huddle's defaults.
class NodeConfig {
public:
    NodeConfig() { std::memset(&cfg_, 0, sizeof cfg_); }
    NodeConfig &robot(std::uint8_t id) { cfg_.robot_id = id; return *this; }
    NodeConfig &team(std::uint8_t id) { cfg_.team_id = id; return *this; }
    NodeConfig &group(std::string address, std::uint16_t port) {
        group_ = std::move(address);
        cfg_.group_port = port;
        return *this;
    }
    NodeConfig &interface(std::string address) { iface_ = std::move(address); return *this; }
    NodeConfig &refresh_ms(std::uint32_t ms) { cfg_.refresh_ms = ms; return *this; }
    NodeConfig &key_file(std::string path) { key_file_ = std::move(path); return *this; }
    NodeConfig &config_dir(std::string path) { config_dir_ = std::move(path); return *this; }
    /// HUDDLE_TRANSPORT_MULTICAST (default), _BROADCAST (RoboCup SPL) or _UNICAST.
    NodeConfig &transport(int t) { cfg_.transport = t; return *this; }
    /// The team port for broadcast or unicast (default 10000 + team).
    NodeConfig &port(std::uint16_t port) { cfg_.group_port = port; return *this; }
    NodeConfig &broadcast(std::string address) { broadcast_ = std::move(address); return *this; }
    /// A teammate "ADDR:PORT" that also gets every frame by unicast (repeatable).
    NodeConfig &peer(std::string address) { peers_.push_back(std::move(address)); return *this; }
    /// "spl", "humanoid" or "N/DURATION", shared by team_size robots.
    NodeConfig &budget(std::string spec, std::uint8_t team_size = 5, bool pool = false) {
        budget_ = std::move(spec);
        cfg_.team_size = team_size;
        cfg_.budget_pool = pool ? 1 : 0;
        return *this;
    }
    /// Refuse to start if another robot sends with this id within ms.
    NodeConfig &id_check_ms(std::uint32_t ms) { cfg_.id_check_ms = ms; return *this; }

    /// The C struct; its strings point into this object.
    huddle_node_config c_config() const {
        huddle_node_config c = cfg_;
        c.group_address = group_ ? group_->c_str() : nullptr;
        c.interface_address = iface_ ? iface_->c_str() : nullptr;
        c.key_file = key_file_ ? key_file_->c_str() : nullptr;
        c.config_dir = config_dir_ ? config_dir_->c_str() : nullptr;
        c.broadcast_address = broadcast_ ? broadcast_->c_str() : nullptr;
        c.budget = budget_ ? budget_->c_str() : nullptr;
        peer_ptrs_.clear();
        for (const auto &p : peers_) peer_ptrs_.push_back(p.c_str());
        c.peers = peer_ptrs_.empty() ? nullptr : peer_ptrs_.data();
        c.peer_count = peer_ptrs_.size();
        return c;
    }

private:
    huddle_node_config cfg_;
    std::optional<std::string> group_, iface_, key_file_, config_dir_, broadcast_, budget_;
    std::vector<std::string> peers_;
    mutable std::vector<const char *> peer_ptrs_;
};

/// A running node (huddle_node): stopped when destroyed.
class Node {
public:
    explicit Node(const NodeConfig &config) {
        huddle_node_config c = config.c_config();
        huddle_error err = detail::fresh_error();
        node_ = huddle_node_start(&c, &err);
        if (node_ == nullptr) throw Error(err.code, err.message);
    }
    ~Node() { huddle_node_stop(node_); }
    Node(Node &&other) noexcept : node_(std::exchange(other.node_, nullptr)) {}
    Node &operator=(Node &&other) noexcept {
        if (this != &other) {
            huddle_node_stop(node_);
            node_ = std::exchange(other.node_, nullptr);
        }
        return *this;
    }
    Node(const Node &) = delete;
    Node &operator=(const Node &) = delete;

private:
    // Helpers of the typed calls (defined before them: their return types are deduced).
    template <typename F, typename... A>
    int call(F f, const std::string &key, A... args) {
        huddle_error err = detail::fresh_error();
        return detail::check(f(node_, key.c_str(), args..., &err), err);
    }
    template <typename T, typename F>
    std::optional<T> get_one(F f, const std::string &key) {
        T v{};
        if (call(f, key, &v) == 0) return std::nullopt;
        return v;
    }
    template <typename F>
    auto bound(F f, const std::string &key) {
        return [this, f, &key](auto *buf, std::size_t cap, std::size_t *len, huddle_error *err) {
            return f(node_, key.c_str(), buf, cap, len, err);
        };
    }
    static std::optional<std::string> as_string(const std::optional<std::vector<char>> &v) {
        if (!v) return std::nullopt;
        return std::string(v->begin(), v->end());
    }

public:

    /// Sets key to the value the literal spells ("1.5", "\"text\"", "[1, 2]").
    void set(const std::string &key, const std::string &literal) {
        huddle_error err = detail::fresh_error();
        detail::check(huddle_node_set(node_, key.c_str(), literal.c_str(), &err), err);
    }
    /// The binding, or nothing when the key is unknown.
    std::optional<Binding> get(const std::string &key) {
        huddle_error err = detail::fresh_error();
        huddle_binding b;
        if (detail::check(huddle_node_get(node_, key.c_str(), &b, &err), err) == 0) {
            return std::nullopt;
        }
        return to_binding(b);
    }
    /// Posts to this robot's talk queue; returns the message's sequence number.
    std::uint64_t post(const std::string &key, const std::string &literal) {
        huddle_error err = detail::fresh_error();
        std::uint64_t seq = 0;
        detail::check(huddle_node_post(node_, key.c_str(), literal.c_str(), &seq, &err), err);
        return seq;
    }
    /// The next event, waiting up to timeout_ms; nothing if none came.
    std::optional<Event> next_event(std::uint32_t timeout_ms = 0) {
        huddle_error err = detail::fresh_error();
        huddle_event e;
        if (detail::check(huddle_node_next_event(node_, timeout_ms, &e, &err), err) == 0) {
            return std::nullopt;
        }
        return to_event(e);
    }

    // Typed set and get: no text in between. A get gives nothing when the key is
    // unknown and throws Error (HUDDLE_E_TYPE) when it holds another type.
    void set_int(const std::string &key, std::int64_t v) { call(huddle_node_set_int, key, v); }
    void set_float(const std::string &key, double v) { call(huddle_node_set_float, key, v); }
    void set_bool(const std::string &key, bool v) { call(huddle_node_set_bool, key, v ? 1 : 0); }
    void set_string(const std::string &key, const std::string &v) {
        call(huddle_node_set_string, key, v.c_str());
    }
    void set_floats(const std::string &key, const std::vector<double> &v) {
        call(huddle_node_set_floats, key, v.data(), v.size());
    }
    void set_bytes(const std::string &key, const std::vector<std::uint8_t> &v) {
        call(huddle_node_set_bytes, key, v.data(), v.size());
    }
    /// Sets on the priority path: under a budget it goes at once, from the reserve.
    void set_priority(const std::string &key, const std::string &literal) {
        call(huddle_node_set_priority, key, literal.c_str());
    }
    std::optional<std::int64_t> get_int(const std::string &key) { return get_one<std::int64_t>(huddle_node_get_int, key); }
    std::optional<double> get_float(const std::string &key) { return get_one<double>(huddle_node_get_float, key); }
    std::optional<bool> get_bool(const std::string &key) {
        auto v = get_one<int>(huddle_node_get_bool, key);
        return v ? std::optional<bool>(*v != 0) : std::nullopt;
    }
    std::optional<std::string> get_string(const std::string &key) {
        return as_string(detail::read_sized<char>(bound(huddle_node_get_string, key), 1));
    }
    /// The value of any type as its literal, however long.
    std::optional<std::string> get_literal(const std::string &key) {
        return as_string(detail::read_sized<char>(bound(huddle_node_get_literal, key), 1));
    }
    std::optional<std::vector<double>> get_floats(const std::string &key) {
        return detail::read_sized<double>(bound(huddle_node_get_floats, key), 0);
    }
    std::optional<std::vector<std::uint8_t>> get_bytes(const std::string &key) {
        return detail::read_sized<std::uint8_t>(bound(huddle_node_get_bytes, key), 0);
    }
    /// Value changes of keys matching pattern arrive as HUDDLE_EVENT_VALUE_CHANGED.
    void watch(const std::string &pattern) { call(huddle_node_watch, pattern); }
    void unwatch(const std::string &pattern) { call(huddle_node_unwatch, pattern); }
    /// The stored keys matching pattern, in key order.
    std::vector<std::string> keys(const std::string &pattern = "#") {
        auto text = as_string(detail::read_sized<char>(bound(huddle_node_keys, pattern), 1));
        std::vector<std::string> out;
        std::size_t at = 0;
        while (text && at < text->size()) {
            std::size_t nl = text->find('\n', at);
            out.push_back(text->substr(at, nl - at));
            at = nl + 1;
        }
        return out;
    }
    huddle_stats stats() {
        huddle_error err = detail::fresh_error();
        huddle_stats s;
        detail::check(huddle_node_stats(node_, &s, &err), err);
        return s;
    }
    /// The budget now (headroom, sent, left), or nothing without a budget.
    std::optional<huddle_budget> budget() {
        huddle_error err = detail::fresh_error();
        huddle_budget b;
        if (detail::check(huddle_node_budget(node_, &b, &err), err) == 0) return std::nullopt;
        return b;
    }
    void set_game_clock(std::uint64_t remaining_ms) {
        huddle_error err = detail::fresh_error();
        detail::check(huddle_node_set_game_clock(node_, remaining_ms, &err), err);
    }
    bool is_pending(const std::string &key) { return call(huddle_node_is_pending, key) == 1; }
    /// The team layer's ball (local.var.team.ball), or nothing yet.
    std::optional<huddle_team_ball> team_ball() {
        huddle_error err = detail::fresh_error();
        huddle_team_ball b;
        if (detail::check(huddle_node_get_team_ball(node_, &b, &err), err) == 0) return std::nullopt;
        return b;
    }

    huddle_node *c_node() const noexcept { return node_; }

private:
    huddle_node *node_ = nullptr;
};

/// A sans-IO replica (huddle_replica): freed when destroyed. Time is an argument.
class Replica {
public:
    Replica(const huddle_replica_config &config, std::uint64_t incarnation, std::uint64_t now_us) {
        huddle_error err = detail::fresh_error();
        replica_ = huddle_replica_new(&config, incarnation, now_us, &err);
        if (replica_ == nullptr) throw Error(err.code, err.message);
    }
    ~Replica() { huddle_replica_free(replica_); }
    Replica(Replica &&other) noexcept : replica_(std::exchange(other.replica_, nullptr)) {}
    Replica &operator=(Replica &&other) noexcept {
        if (this != &other) {
            huddle_replica_free(replica_);
            replica_ = std::exchange(other.replica_, nullptr);
        }
        return *this;
    }
    Replica(const Replica &) = delete;
    Replica &operator=(const Replica &) = delete;

    void set(std::uint64_t now_us, const std::string &key, const std::string &literal) {
        huddle_error err = detail::fresh_error();
        detail::check(huddle_replica_set(replica_, now_us, key.c_str(), literal.c_str(), &err), err);
    }
    std::uint64_t post(std::uint64_t now_us, const std::string &key, const std::string &literal) {
        huddle_error err = detail::fresh_error();
        std::uint64_t seq = 0;
        detail::check(
            huddle_replica_post(replica_, now_us, key.c_str(), literal.c_str(), &seq, &err), err);
        return seq;
    }
    std::optional<Binding> get(std::uint64_t now_us, const std::string &key) {
        huddle_error err = detail::fresh_error();
        huddle_binding b;
        if (detail::check(huddle_replica_get(replica_, now_us, key.c_str(), &b, &err), err) == 0) {
            return std::nullopt;
        }
        return to_binding(b);
    }
    // Typed set and get (as Node's; a get gives nothing for an unknown key and throws
    // Error HUDDLE_E_TYPE for another type).
    void set_int(std::uint64_t now_us, const std::string &key, std::int64_t v) {
        huddle_error err = detail::fresh_error();
        detail::check(huddle_replica_set_int(replica_, now_us, key.c_str(), v, &err), err);
    }
    void set_float(std::uint64_t now_us, const std::string &key, double v) {
        huddle_error err = detail::fresh_error();
        detail::check(huddle_replica_set_float(replica_, now_us, key.c_str(), v, &err), err);
    }
    void set_floats(std::uint64_t now_us, const std::string &key, const std::vector<double> &v) {
        huddle_error err = detail::fresh_error();
        detail::check(huddle_replica_set_floats(replica_, now_us, key.c_str(), v.data(), v.size(), &err), err);
    }
    void set_string(std::uint64_t now_us, const std::string &key, const std::string &v) {
        huddle_error err = detail::fresh_error();
        detail::check(huddle_replica_set_string(replica_, now_us, key.c_str(), v.c_str(), &err), err);
    }
    std::optional<double> get_float(const std::string &key) {
        huddle_error err = detail::fresh_error();
        double v = 0;
        if (detail::check(huddle_replica_get_float(replica_, key.c_str(), &v, &err), err) == 0) return std::nullopt;
        return v;
    }
    std::optional<std::int64_t> get_int(const std::string &key) {
        huddle_error err = detail::fresh_error();
        std::int64_t v = 0;
        if (detail::check(huddle_replica_get_int(replica_, key.c_str(), &v, &err), err) == 0) return std::nullopt;
        return v;
    }
    std::optional<std::vector<double>> get_floats(const std::string &key) {
        return detail::read_sized<double>(
            [this, &key](double *buf, std::size_t cap, std::size_t *len, huddle_error *err) {
                return huddle_replica_get_floats(replica_, key.c_str(), buf, cap, len, err);
            },
            0);
    }
    /// The value of any type as its literal, however long.
    std::optional<std::string> get_literal(const std::string &key) {
        auto v = detail::read_sized<char>(
            [this, &key](char *buf, std::size_t cap, std::size_t *len, huddle_error *err) {
                return huddle_replica_get_literal(replica_, key.c_str(), buf, cap, len, err);
            },
            1);
        if (!v) return std::nullopt;
        return std::string(v->begin(), v->end());
    }
    void handle_datagram(std::uint64_t now_us, const std::string &bytes) {
        huddle_error err = detail::fresh_error();
        detail::check(huddle_replica_handle_datagram(
                          replica_, now_us, reinterpret_cast<const std::uint8_t *>(bytes.data()),
                          bytes.size(), &err),
                      err);
    }
    void handle_timeout(std::uint64_t now_us) {
        huddle_error err = detail::fresh_error();
        detail::check(huddle_replica_handle_timeout(replica_, now_us, &err), err);
    }
    /// The next datagram to send to the group, or nothing. Reads into a buffer the
    /// replica keeps (grown to the largest datagram seen, the MTU at most), so the
    /// only allocation per datagram is the returned string's own.
    std::optional<std::string> poll_transmit() {
        std::size_t len = 0;
        if (!poll_transmit_into(scratch_, len)) return std::nullopt;
        return std::string(reinterpret_cast<const char *>(scratch_.data()), len);
    }
    /// poll_transmit into the caller's buffer (grown when a datagram does not fit):
    /// true with the datagram's first len bytes in buf; no allocation once buf is
    /// large enough.
    bool poll_transmit_into(std::vector<std::uint8_t> &buf, std::size_t &len) {
        huddle_error err = detail::fresh_error();
        if (buf.empty()) buf.resize(2048);
        for (;;) {
            int rc = huddle_replica_poll_transmit(replica_, buf.data(), buf.size(), &len, &err);
            if (rc >= 0) return rc == 1;
            if (err.code != HUDDLE_E_BUFFER) throw Error(err.code, err.message);
            buf.resize(len);  // the datagram waits for the next call
        }
    }
    std::optional<std::uint64_t> poll_timeout() {
        huddle_error err = detail::fresh_error();
        std::uint64_t at = 0;
        if (detail::check(huddle_replica_poll_timeout(replica_, &at, &err), err) == 0) {
            return std::nullopt;
        }
        return at;
    }
    std::optional<Event> poll_event() {
        huddle_error err = detail::fresh_error();
        huddle_event e;
        if (detail::check(huddle_replica_poll_event(replica_, &e, &err), err) == 0) {
            return std::nullopt;
        }
        return to_event(e);
    }

private:
    huddle_replica *replica_ = nullptr;
    std::vector<std::uint8_t> scratch_;
};

}  // namespace huddle

#endif  // HUDDLE_HPP
