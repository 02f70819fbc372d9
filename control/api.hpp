#pragma once
// The control API's request handling, apart from the sockets (control/server.hpp) so that
// it can be tested and fuzzed on bytes: authorisation, routing, JSON bodies and their
// fields, and the answers. Reads are answered at once from the StatusBoard; commands go
// to the supervisor through the CommandQueue and are answered later. Every malformed
// request gets a 4xx with {"error": "..."}; nothing here throws. Routes and messages:
// docs/control-api.md. Not real-time code (the I/O thread runs it).
#include <cstdint>
#include <functional>
#include <optional>
#include <string>
#include <string_view>
#include <variant>

#include <boost/beast/http/message.hpp>
#include <boost/beast/http/string_body.hpp>

#include "control/access.hpp"
#include "control/commands.hpp"
#include "control/status.hpp"

namespace facecap::control {

using HttpRequest = boost::beast::http::request<boost::beast::http::string_body>;
using HttpResponse = boost::beast::http::response<boost::beast::http::string_body>;

// Bounds on what a client may send (the server's parser enforces them).
inline constexpr std::size_t kMaxHeaderBytes = 8 * 1024;
inline constexpr std::size_t kMaxBodyBytes = 64 * 1024;
// The WebSocket stream's rates, frames per second.
inline constexpr double kDefaultStreamRateHz = 30.0;
inline constexpr double kMinStreamRateHz = 0.1;
inline constexpr double kMaxStreamRateHz = 120.0;

struct ApiContext {
  const StatusBoard& board;
  CommandQueue& commands;
  std::string version;  // for the Server header
  std::string dashboard_dir;  // the dashboard's files, served at "/" (docs/dashboard.md); "": none
  AccessOptions access;       // tokens, Host and Origin allow-lists, session lifetime
  SessionTable sessions;
  LoginThrottle throttle;
};

// The name of the session cookie: one per port, since browsers share cookies across ports.
std::string session_cookie_name(const AccessOptions& access);

// A JSON (or, for /metrics, text) response to `request` with its keep-alive.
HttpResponse make_response(const HttpRequest& request, const Reply& reply, std::string_view server);

// Whether the request carries the credentials handle_request asks for (a bearer token or a session
// cookie; always, with no token configured); the server keeps some connections for such clients.
bool request_authenticated(const HttpRequest& request, ApiContext& context);

// Handles one request from `peer` (the client's address, for the throttle on wrong
// tokens): returns the response when it is known at once, else nullopt after handing a
// command to the supervisor, whose answer comes through `respond` (from any thread,
// once). /stream is answered here only when it is refused.
std::optional<HttpResponse> handle_request(const HttpRequest& request, ApiContext& context,
                                           std::function<void(HttpResponse)> respond, const std::string& peer = {});

// What GET /stream asks for (query: rate=<Hz>, vertices=0|1).
struct StreamRequest {
  double rate_hz = kDefaultStreamRateHz;
  bool vertices = false;
};
// The stream's parameters, or the 4xx response refusing it (Host, Origin, token, query).
std::variant<StreamRequest, HttpResponse> accept_stream(const HttpRequest& request, ApiContext& context,
                                                        const std::string& peer = {});

// The path of a request target without its query ("/stream?rate=30" -> "/stream").
std::string_view target_path(std::string_view target) noexcept;

}  // namespace facecap::control
