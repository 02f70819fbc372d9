#pragma once
// The control server's admission rules, apart from its sockets so that they can be tested
// on their own: how many connections (HTTP and WebSocket) it holds, how many one address
// may hold, how many WebSocket clients, and which connection goes when a new one arrives
// at a limit. Connections that have not yet shown credentials ("anonymous": nothing read
// from them yet, or only requests without the token) may fill all but a few slots kept
// for authenticated ones, and the oldest anonymous connection makes way for a new one, so
// idle or trickling connections (slowloris) cannot lock the API out. One address may hold
// only so many anonymous connections, so that its new ones evict its own, not others'. Also the back-off of
// failing accept() calls. docs/control-api.md, "Limits". Not real-time code.
#include <cstddef>
#include <cstdint>
#include <list>
#include <map>
#include <optional>
#include <string>
#include <unordered_map>

namespace facecap::control {

struct ConnectionLimits {
  std::size_t max_connections = 64;     // HTTP and WebSocket together
  std::size_t kept_for_authenticated = 8;  // of max_connections, never given to anonymous ones
  std::size_t max_per_address = 16;     // anonymous connections of one address
  std::size_t max_stream_clients = 16;  // WebSocket /stream clients (at most max_connections - kept_for_authenticated)
};

class ConnectionTable {
 public:
  using Id = uint64_t;
  // A new connection: admitted (with its id), and the one to close to make room, if any.
  struct Admission {
    std::optional<Id> admitted;
    std::optional<Id> evicted;
  };

  explicit ConnectionTable(ConnectionLimits limits) : limits_(limits) {}

  // From `address` (any text naming the peer's address). Admits it when there is room;
  // else makes room by evicting the oldest anonymous connection (of the same address when
  // that address has max_per_address anonymous ones); else (every connection
  // authenticated) refuses it (no id).
  Admission admit(const std::string& address);
  // The connection sent an authenticated request: it is no longer evicted for new ones.
  void authenticated(Id id);
  // The connection asks to become a WebSocket client: false when max_stream_clients are.
  bool become_stream_client(Id id);
  void remove(Id id);

  std::size_t connections() const noexcept { return connections_.size(); }
  std::size_t anonymous() const noexcept { return anonymous_order_.size(); }
  std::size_t stream_clients() const noexcept { return stream_clients_; }
  const ConnectionLimits& limits() const noexcept { return limits_; }

 private:
  struct Connection {
    std::string address;
    bool stream_client = false;
    std::list<Id>::iterator anonymous_at;  // into anonymous_order_ while anonymous
    bool anonymous = true;
  };
  std::optional<Id> oldest_anonymous(const std::string* address) const;
  void no_longer_anonymous(Connection& connection);

  ConnectionLimits limits_;
  Id next_id_ = 1;
  std::unordered_map<Id, Connection> connections_;
  std::list<Id> anonymous_order_;  // oldest first
  std::map<std::string, std::size_t> anonymous_per_address_;
  std::size_t stream_clients_ = 0;
};

// accept() failing (EMFILE, ENFILE, ENOBUFS: out of descriptors or memory) would fail again
// at once: the next try waits 50 ms, doubling to 1 s while it keeps failing, and one warning
// is logged per warning interval with the count of failures since the last one.
class AcceptBackoff {
 public:
  static constexpr int64_t kFirstDelayNs = 50'000'000;
  static constexpr int64_t kMaxDelayNs = 1'000'000'000;
  static constexpr int64_t kWarningIntervalNs = 10'000'000'000;

  struct Step {
    int64_t delay_ns = 0;
    uint64_t warn_with_count = 0;  // > 0: log a warning now, counting this many failures
  };
  // A failure at now_ns: how long to wait before the next accept, and whether to warn.
  Step failed(int64_t now_ns) noexcept;
  // An accept succeeded: the next failure starts the back-off afresh.
  void succeeded() noexcept { delay_ns_ = 0; }

 private:
  int64_t delay_ns_ = 0;
  int64_t last_warning_ns_ = 0;
  bool warned_ = false;
  uint64_t unreported_ = 0;
};

}  // namespace facecap::control
