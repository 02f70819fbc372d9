#pragma once
// Who may use the control API, and from which page (docs/control-api.md#access): the Host
// and Origin rules that keep other web pages and DNS rebinding out, the two roles
// (operator, viewer) their tokens grant, the login sessions the dashboard's cookie names,
// and the throttle on wrong tokens. Runs on the I/O thread only (no locks). Not real-time.
#include <array>
#include <cstdint>
#include <string>
#include <string_view>
#include <unordered_map>
#include <vector>

namespace facecap::control {

enum class Role : uint8_t {
  kNone,      // not authenticated
  kViewer,    // reads: status, metrics, config, actors, recordings, the stream
  kOperator,  // reads and commands
};
std::string_view role_name(Role role) noexcept;  // "none", "viewer", "operator"

struct AccessOptions {
  std::string operator_token;  // empty: no token anywhere, every client is the operator (loopback only)
  std::string viewer_token;    // empty: no viewer role
  std::string address = "127.0.0.1";  // the address listened on, for the Host check
  uint16_t port = 0;                  // the port listened on; 0: a Host's port is not checked
  std::vector<std::string> allowed_hosts;    // further names the box is reached by ("stage-box.local")
  std::vector<std::string> allowed_origins;  // further pages that may command ("http://tablet.lan:8080")
  int64_t session_max_age_s = 12 * 3600;
  bool tls = false;  // served over TLS: the box's own origin is https://, the session cookie Secure
};

// Whether the Host header names this box: the address listened on (any IP literal when
// it is 0.0.0.0 or ::), "localhost" when that is loopback or any, or an allowed host;
// a port, when given, must be the one listened on. Compared without case.
bool host_allowed(std::string_view host, const AccessOptions& options);

// The origin ("http://name:port") of a URL (a Referer), or "" when it has none.
std::string_view url_origin(std::string_view url) noexcept;

// Whether a page of `origin` may use the API: the box's own origin (http://, or https://
// with TLS, and the Host the request came with) or an allowed origin. "null" never is.
bool origin_allowed(std::string_view origin, std::string_view host, const AccessOptions& options);

// Equal in time independent of where the first difference is.
bool same_secret(std::string_view a, std::string_view b) noexcept;

// Login sessions: random ids (256 bits from getrandom, as 64 hex digits), each with its
// role and expiry. Bounded: a login beyond kCapacity ends the session closest to expiry.
class SessionTable {
 public:
  static constexpr std::size_t kCapacity = 64;
  static constexpr std::size_t kIdHexDigits = 64;

  // The new session's id. Throws Error when the kernel gives no random bytes.
  std::string open(Role role, int64_t now_ns, int64_t max_age_ns);
  // The role of session `id`; kNone when unknown or expired (then forgotten). Compares
  // with every live id in constant time.
  Role find(std::string_view id, int64_t now_ns) noexcept;
  // Ends session `id` (logout); false when there was none.
  bool close(std::string_view id) noexcept;
  std::size_t size() const noexcept;

 private:
  struct Entry {
    std::string id;  // "": free
    Role role = Role::kNone;
    int64_t expires_ns = 0;
  };
  std::array<Entry, kCapacity> entries_;
};

// Wrong tokens per client address: after kMaxFailures within kWindowNs the address is
// refused (429) until the window ends. Bounded: beyond kMaxAddresses the oldest window
// is forgotten.
class LoginThrottle {
 public:
  static constexpr int kMaxFailures = 5;
  static constexpr int64_t kWindowNs = 60'000'000'000;
  static constexpr std::size_t kMaxAddresses = 4096;

  // 0 when `address` may try a token now, else the seconds until it may.
  int64_t wait_seconds(const std::string& address, int64_t now_ns) const;
  void failed(const std::string& address, int64_t now_ns);
  void succeeded(const std::string& address) { failures_.erase(address); }

 private:
  struct Window {
    int64_t start_ns = 0;
    int failures = 0;
  };
  std::unordered_map<std::string, Window> failures_;
};

}  // namespace facecap::control
