#include "control/access.hpp"

#include <sys/random.h>

#include <algorithm>
#include <cerrno>
#include <charconv>
#include <cstring>
#include <optional>

#include <boost/asio/ip/address.hpp>
#include <fmt/format.h>

#include "core/error.hpp"

namespace facecap::control {

namespace {

bool same_text_ignoring_case(std::string_view a, std::string_view b) noexcept {
  return a.size() == b.size() && std::equal(a.begin(), a.end(), b.begin(), [](char x, char y) {
           return std::tolower((unsigned char)x) == std::tolower((unsigned char)y);
         });
}

struct HostParts {
  std::string_view name;  // without brackets for IPv6
  std::string_view port;  // "" when absent
  bool bracketed = false;
};

// "name", "name:port", "[v6]" or "[v6]:port"; nullopt for anything else.
std::optional<HostParts> split_host(std::string_view host) noexcept {
  HostParts parts;
  std::string_view rest;
  if (host.starts_with('[')) {
    const std::size_t close = host.find(']');
    if (close == std::string_view::npos) return std::nullopt;
    parts.name = host.substr(1, close - 1);
    parts.bracketed = true;
    rest = host.substr(close + 1);
  } else {
    const std::size_t colon = host.find(':');
    parts.name = host.substr(0, colon);
    rest = colon == std::string_view::npos ? std::string_view() : host.substr(colon);
  }
  if (!rest.empty()) {
    if (rest.front() != ':' || rest.size() < 2) return std::nullopt;
    parts.port = rest.substr(1);
    if (!std::all_of(parts.port.begin(), parts.port.end(), [](char c) { return c >= '0' && c <= '9'; })) return std::nullopt;
  }
  if (parts.name.empty()) return std::nullopt;
  return parts;
}

}  // namespace

std::string_view role_name(Role role) noexcept {
  switch (role) {
    case Role::kViewer: return "viewer";
    case Role::kOperator: return "operator";
    case Role::kNone: break;
  }
  return "none";
}

bool host_allowed(std::string_view host, const AccessOptions& options) {
  const std::optional<HostParts> parts = split_host(host);
  if (!parts) return false;
  if (!parts->port.empty() && options.port != 0) {
    unsigned port = 0;
    const auto [end, ec] = std::from_chars(parts->port.data(), parts->port.data() + parts->port.size(), port);
    if (ec != std::errc() || end != parts->port.data() + parts->port.size() || port != options.port) return false;
  }
  boost::system::error_code ec;
  const auto bound = boost::asio::ip::make_address(options.address, ec);
  if (ec) return false;
  // An IP literal cannot be rebound by DNS: one naming the address listened on is the box.
  const auto literal = boost::asio::ip::make_address(std::string(parts->name), ec);
  if (!ec) {
    if (literal.is_v6() != parts->bracketed) return false;  // "::1" unbracketed is no Host
    return bound.is_unspecified() || literal == bound;
  }
  if (same_text_ignoring_case(parts->name, "localhost")) return bound.is_loopback() || bound.is_unspecified();
  return std::any_of(options.allowed_hosts.begin(), options.allowed_hosts.end(),
                     [&](const std::string& allowed) { return same_text_ignoring_case(parts->name, allowed); });
}

std::string_view url_origin(std::string_view url) noexcept {
  const std::size_t scheme_end = url.find("://");
  if (scheme_end == std::string_view::npos) return {};
  const std::size_t path = url.find_first_of("/?#", scheme_end + 3);
  return url.substr(0, path);
}

bool origin_allowed(std::string_view origin, std::string_view host, const AccessOptions& options) {
  const std::string_view kScheme = options.tls ? "https://" : "http://";
  if (origin.size() == kScheme.size() + host.size() && same_text_ignoring_case(origin.substr(0, kScheme.size()), kScheme) &&
      same_text_ignoring_case(origin.substr(kScheme.size()), host))
    return true;
  return std::any_of(options.allowed_origins.begin(), options.allowed_origins.end(),
                     [&](const std::string& allowed) { return same_text_ignoring_case(origin, allowed); });
}

bool same_secret(std::string_view a, std::string_view b) noexcept {
  unsigned char diff = a.size() == b.size() ? 0 : 1;
  for (std::size_t i = 0; i < a.size(); ++i) diff |= (unsigned char)(a[i] ^ (i < b.size() ? b[i] : 0));
  return diff == 0;
}

std::string SessionTable::open(Role role, int64_t now_ns, int64_t max_age_ns) {
  std::array<unsigned char, kIdHexDigits / 2> random{};
  std::size_t got = 0;
  while (got < random.size()) {
    const ssize_t n = getrandom(random.data() + got, random.size() - got, 0);
    if (n < 0 && errno == EINTR) continue;
    if (n <= 0) throw Error(fmt::format("control API: no random bytes for a session id: {}", std::strerror(errno)));
    got += std::size_t(n);
  }
  std::string id;
  id.reserve(kIdHexDigits);
  for (const unsigned char byte : random) id += fmt::format("{:02x}", byte);
  // A free or expired entry, else the one closest to expiry.
  Entry* slot = &entries_[0];
  for (Entry& entry : entries_) {
    if (entry.id.empty() || entry.expires_ns <= now_ns) {
      slot = &entry;
      break;
    }
    if (entry.expires_ns < slot->expires_ns) slot = &entry;
  }
  *slot = Entry{id, role, now_ns + max_age_ns};
  return id;
}

Role SessionTable::find(std::string_view id, int64_t now_ns) noexcept {
  if (id.size() != kIdHexDigits) return Role::kNone;
  Entry* found = nullptr;
  for (Entry& entry : entries_)  // no early exit: the time does not tell which entry matched
    if (!entry.id.empty() && same_secret(id, entry.id)) found = &entry;
  if (!found) return Role::kNone;
  if (found->expires_ns <= now_ns) {
    *found = Entry{};
    return Role::kNone;
  }
  return found->role;
}

bool SessionTable::close(std::string_view id) noexcept {
  if (id.size() != kIdHexDigits) return false;
  bool closed = false;
  for (Entry& entry : entries_)
    if (!entry.id.empty() && same_secret(id, entry.id)) {
      entry = Entry{};
      closed = true;
    }
  return closed;
}

std::size_t SessionTable::size() const noexcept {
  return std::size_t(std::count_if(entries_.begin(), entries_.end(), [](const Entry& e) { return !e.id.empty(); }));
}

int64_t LoginThrottle::wait_seconds(const std::string& address, int64_t now_ns) const {
  const auto it = failures_.find(address);
  if (it == failures_.end() || it->second.failures < kMaxFailures || now_ns >= it->second.start_ns + kWindowNs) return 0;
  return (it->second.start_ns + kWindowNs - now_ns + 999'999'999) / 1'000'000'000;
}

void LoginThrottle::failed(const std::string& address, int64_t now_ns) {
  auto it = failures_.find(address);
  if (it == failures_.end()) {
    if (failures_.size() >= kMaxAddresses) {
      std::erase_if(failures_, [&](const auto& item) { return now_ns >= item.second.start_ns + kWindowNs; });
      if (failures_.size() >= kMaxAddresses)
        failures_.erase(std::min_element(failures_.begin(), failures_.end(), [](const auto& a, const auto& b) {
          return a.second.start_ns < b.second.start_ns;
        }));
    }
    it = failures_.emplace(address, Window{now_ns, 0}).first;
  }
  if (now_ns >= it->second.start_ns + kWindowNs) it->second = Window{now_ns, 0};
  ++it->second.failures;
}

}  // namespace facecap::control
