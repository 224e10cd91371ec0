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

    /// The C struct; its strings point into this object.
    huddle_node_config c_config() const {
        huddle_node_config c = cfg_;
        c.group_address = group_ ? group_->c_str() : nullptr;
        c.interface_address = iface_ ? iface_->c_str() : nullptr;
        c.key_file = key_file_ ? key_file_->c_str() : nullptr;
        c.config_dir = config_dir_ ? config_dir_->c_str() : nullptr;
        return c;
    }

private:
    huddle_node_config cfg_;
    std::optional<std::string> group_, iface_, key_file_, config_dir_;
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
    /// The next datagram to send to the group, or nothing.
    std::optional<std::string> poll_transmit() {
        huddle_error err = detail::fresh_error();
        std::string buf(65536, '\0');
        std::size_t len = 0;
        int rc = huddle_replica_poll_transmit(
            replica_, reinterpret_cast<std::uint8_t *>(&buf[0]), buf.size(), &len, &err);
        if (detail::check(rc, err) == 0) return std::nullopt;
        buf.resize(len);
        return buf;
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
};

}  // namespace huddle

#endif  // HUDDLE_HPP
