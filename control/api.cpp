#include "control/api.hpp"

#include <algorithm>
#include <charconv>
#include <cmath>
#include <set>

#include <boost/beast/http/field.hpp>
#include <boost/beast/http/verb.hpp>
#include <fmt/format.h>

#include "control/recordings.hpp"
#include "control/static_files.hpp"
#include "core/time.hpp"

namespace facecap::control {
namespace http = boost::beast::http;
using nlohmann::json;

namespace {

constexpr std::size_t kMaxNameBytes = 200;
constexpr std::size_t kMaxNotesBytes = 4000;
constexpr double kMinCalibrationSeconds = 0.5;
constexpr double kMaxCalibrationSeconds = 30.0;

// Refused for a while after too many wrong tokens from one address.
HttpResponse too_many_failures(const HttpRequest& request, const ApiContext& context, int64_t wait_s) {
  HttpResponse response = make_response(
      request, error_reply(429, fmt::format("too many wrong tokens from this address: try again in {} s", wait_s)),
      context.version);
  response.set(http::field::retry_after, std::to_string(wait_s));
  return response;
}

std::string_view header_value(const HttpRequest& request, http::field field) {
  const auto it = request.find(field);
  return it == request.end() ? std::string_view() : std::string_view(it->value().data(), it->value().size());
}

// Who is asking, from a bearer token or a session cookie.
struct Caller {
  Role role = Role::kNone;
  bool presented_bearer = false;
};

// The session id in the request's cookie, "" when none.
std::string_view session_cookie(const HttpRequest& request, const std::string& name) {
  for (auto it = request.find(http::field::cookie); it != request.end() && it->name() == http::field::cookie; ++it) {
    std::string_view cookies(it->value().data(), it->value().size());
    while (!cookies.empty()) {
      std::string_view pair = cookies.substr(0, cookies.find(';'));
      cookies.remove_prefix(std::min(cookies.size(), pair.size() + 1));
      while (!pair.empty() && pair.front() == ' ') pair.remove_prefix(1);
      if (pair.size() > name.size() && pair.starts_with(name) && pair[name.size()] == '=') return pair.substr(name.size() + 1);
    }
  }
  return {};
}

// The token of an "Authorization: Bearer <token>" header (the scheme in any case).
std::optional<std::string_view> bearer_token(const HttpRequest& request) {
  const std::string_view given = header_value(request, http::field::authorization);
  constexpr std::string_view kScheme = "Bearer ";
  const bool has_bearer = given.size() > kScheme.size() && std::equal(kScheme.begin(), kScheme.end(), given.begin(),
      [](char a, char b) { return std::tolower((unsigned char)a) == std::tolower((unsigned char)b); });
  if (!has_bearer) return std::nullopt;
  return given.substr(kScheme.size());
}

// The role a token grants: kNone when it is neither the operator's nor the viewer's.
Role bearer_role(std::string_view token, const AccessOptions& access) {
  if (same_secret(token, access.operator_token)) return Role::kOperator;
  if (!access.viewer_token.empty() && same_secret(token, access.viewer_token)) return Role::kViewer;
  return Role::kNone;
}

// The caller's role, or the 401 (wrong bearer token, RFC 6750) or 429 (too many wrong
// ones from this address) refusing it. No token configured: everyone is the operator.
std::variant<Caller, HttpResponse> identify(const HttpRequest& request, ApiContext& context, const std::string& peer) {
  const AccessOptions& access = context.access;
  if (access.operator_token.empty()) return Caller{Role::kOperator, false};
  if (!header_value(request, http::field::authorization).empty()) {
    const int64_t now = monotonic_now_ns();
    if (const int64_t wait = context.throttle.wait_seconds(peer, now)) return too_many_failures(request, context, wait);
    const auto token = bearer_token(request);
    const Role role = token ? bearer_role(*token, access) : Role::kNone;
    if (role != Role::kNone) return Caller{role, true};
    context.throttle.failed(peer, now);
    HttpResponse response = make_response(
        request, error_reply(401, token ? "the bearer token is wrong" : "the Authorization header must be \"Bearer <token>\""),
        context.version);
    response.set(http::field::www_authenticate, "Bearer realm=\"facecap\", error=\"invalid_token\"");
    return response;
  }
  const std::string_view session = session_cookie(request, session_cookie_name(access));
  return Caller{session.empty() ? Role::kNone : context.sessions.find(session, monotonic_now_ns()), false};
}

// The 401 of a request with no (or an expired) credential.
HttpResponse unauthenticated(const HttpRequest& request, const ApiContext& context) {
  HttpResponse response = make_response(
      request, error_reply(401, "log in first (POST /login, or the dashboard's login page) or send Authorization: Bearer <token>"),
      context.version);
  response.set(http::field::www_authenticate, "Bearer realm=\"facecap\"");
  return response;
}

// The Host and Origin rules (docs/control-api.md#access): nullopt when the request may
// proceed. `from_page_matters`: a command or the WebSocket upgrade, where a page's Referer
// stands in for a missing Origin. A request with neither is not from a web page (browsers
// send Origin with every POST and WebSocket handshake), so tokens alone decide it.
std::optional<HttpResponse> check_source(const HttpRequest& request, const ApiContext& context, bool from_page_matters) {
  const std::string_view host = header_value(request, http::field::host);
  if (host.empty()) return make_response(request, error_reply(400, "a Host header is required"), context.version);
  if (!host_allowed(host, context.access))
    return make_response(request,
                         error_reply(421, fmt::format("Host \"{}\" is not this facecapd: use its address, or add the name to "
                                                      "control.http.allowed_hosts", host)),
                         context.version);
  std::string_view origin = header_value(request, http::field::origin);
  std::string_view header_name = "Origin";
  if (origin.empty() && from_page_matters) {
    const std::string_view referer = header_value(request, http::field::referer);
    if (referer.empty()) return std::nullopt;
    origin = url_origin(referer);
    if (origin.empty()) origin = referer;  // no URL: matches nothing
    header_name = "Referer";
  }
  if (origin.empty() || origin_allowed(origin, host, context.access)) return std::nullopt;
  return make_response(request,
                       error_reply(403, fmt::format("a page of {} ({}) may not use this facecapd: open the dashboard from it, "
                                                    "or add the origin to control.http.allowed_origins", origin, header_name)),
                       context.version);
}

// A request body's JSON object, its fields read by name; unknown fields are errors.
class Body {
 public:
  static std::variant<Body, Reply> parse(const std::string& text, std::set<std::string> allowed) {
    json object = json::object();
    if (!text.empty()) {
      try {
        object = json::parse(text);
      } catch (const json::parse_error& e) {
        return error_reply(400, fmt::format("the body is not valid JSON (at byte {})", e.byte));
      } catch (const json::out_of_range&) {  // a number beyond double's range (fuzz finding: 1e309)
        return error_reply(400, "the body holds a number too large for a double");
      }
    }
    if (!object.is_object()) return error_reply(400, "the body must be a JSON object");
    for (const auto& [key, value] : object.items())
      if (!allowed.count(key))
        return error_reply(400, fmt::format("unknown field \"{}\" (allowed: {})", key, fmt::join(allowed, ", ")));
    return Body(std::move(object));
  }

  // The string field `key` (empty when absent) into out; an error text otherwise.
  std::optional<std::string> text(const std::string& key, std::string& out, std::size_t max_bytes = kMaxNameBytes) const {
    const auto it = object_.find(key);
    if (it == object_.end() || it->is_null()) return std::nullopt;
    if (!it->is_string()) return fmt::format("\"{}\" must be a string", key);
    out = it->get<std::string>();
    if (out.size() > max_bytes) return fmt::format("\"{}\" is longer than {} bytes", key, max_bytes);
    return std::nullopt;
  }
  std::optional<std::string> number(const std::string& key, double& out, double min, double max) const {
    const auto it = object_.find(key);
    if (it == object_.end() || it->is_null()) return std::nullopt;
    if (!it->is_number() || !std::isfinite(it->get<double>()) || it->get<double>() < min || it->get<double>() > max)
      return fmt::format("\"{}\" must be a number from {:g} to {:g}", key, min, max);
    out = it->get<double>();
    return std::nullopt;
  }
  std::optional<std::string> flag(const std::string& key, bool& out) const {
    const auto it = object_.find(key);
    if (it == object_.end() || it->is_null()) return std::nullopt;
    if (!it->is_boolean()) return fmt::format("\"{}\" must be true or false", key);
    out = it->get<bool>();
    return std::nullopt;
  }

 private:
  explicit Body(json object) : object_(std::move(object)) {}
  json object_;
};

// Why the field `key` cannot name a file in the profiles directory, or nullopt ("" is
// checked elsewhere). Decided on the text alone: no answer tells what exists elsewhere.
std::optional<std::string> file_name_problem(std::string_view key, std::string_view name) {
  const bool bad = !name.empty() && (name.front() == '.' || std::any_of(name.begin(), name.end(), [](char c) {
                     return c == '/' || c == '\\' || (unsigned char)c < 0x20 || c == 0x7f;
                   }));
  if (!bad) return std::nullopt;
  return fmt::format("\"{}\" must be a file name in the profiles directory: no '/' or '\\', no control characters, "
                     "not starting with '.'", key);
}

// The command a POST body describes, or the 400 refusing it.
std::variant<Request, Reply> parse_command(std::string_view path, const std::string& body_text) {
  auto first_error = [](std::initializer_list<std::optional<std::string>> errors) -> std::optional<Reply> {
    for (const auto& e : errors)
      if (e) return error_reply(400, *e);
    return std::nullopt;
  };
  if (path == "/actor") {
    auto parsed = Body::parse(body_text, {"name", "file"});
    if (auto* reply = std::get_if<Reply>(&parsed)) return *reply;
    const Body& body = std::get<Body>(parsed);
    SelectActor actor;
    if (auto e = first_error({body.text("name", actor.name), body.text("file", actor.file, 4096)})) return *e;
    if (actor.name.empty() == actor.file.empty()) return error_reply(400, "give one of \"name\" (a profile) and \"file\"");
    if (auto e = first_error({file_name_problem("name", actor.name), file_name_problem("file", actor.file)})) return *e;
    return Request{actor};
  }
  if (path == "/calibrate") {
    auto parsed = Body::parse(body_text, {"seconds", "save", "replace"});
    if (auto* reply = std::get_if<Reply>(&parsed)) return *reply;
    const Body& body = std::get<Body>(parsed);
    Calibrate calibrate;
    if (auto e = first_error({body.number("seconds", calibrate.seconds, kMinCalibrationSeconds, kMaxCalibrationSeconds),
                              body.text("save", calibrate.save), body.flag("replace", calibrate.replace)}))
      return *e;
    if (calibrate.replace && calibrate.save.empty()) return error_reply(400, "\"replace\" needs \"save\": the profile to replace");
    if (auto e = first_error({file_name_problem("save", calibrate.save)})) return *e;
    return Request{calibrate};
  }
  if (path == "/record/start") {
    auto parsed = Body::parse(body_text, {"take", "actor", "scene", "shot", "notes", "markers_only"});
    if (auto* reply = std::get_if<Reply>(&parsed)) return *reply;
    const Body& body = std::get<Body>(parsed);
    StartRecording start;
    if (auto e = first_error({body.text("take", start.take), body.text("actor", start.actor), body.text("scene", start.scene),
                              body.text("shot", start.shot), body.text("notes", start.notes, kMaxNotesBytes),
                              body.flag("markers_only", start.markers_only)}))
      return *e;
    return Request{start};
  }
  auto parsed = Body::parse(body_text, {});  // /record/stop takes no fields
  if (auto* reply = std::get_if<Reply>(&parsed)) return *reply;
  return Request{StopRecording{}};
}

struct Route {
  std::string_view path;
  http::verb method;
};
constexpr Route kRoutes[] = {
    {"/status", http::verb::get},         {"/metrics", http::verb::get},    {"/config", http::verb::get},
    {"/actors", http::verb::get},         {"/actor", http::verb::post},     {"/calibrate", http::verb::post},
    {"/record/start", http::verb::post},  {"/record/stop", http::verb::post}, {"/stream", http::verb::get},
    {"/recordings", http::verb::get},     {"/recordings/frames", http::verb::get},
};

// The query's parameters as (key, value) pairs, in order.
std::vector<std::pair<std::string_view, std::string_view>> query_items(std::string_view target) {
  const std::size_t question = target.find('?');
  std::string_view query = question == std::string_view::npos ? std::string_view() : target.substr(question + 1);
  std::vector<std::pair<std::string_view, std::string_view>> items;
  while (!query.empty()) {
    const std::string_view item = query.substr(0, query.find('&'));
    query.remove_prefix(std::min(query.size(), item.size() + 1));
    const std::size_t eq = item.find('=');
    if (!item.empty()) items.emplace_back(item.substr(0, eq), eq == std::string_view::npos ? "" : item.substr(eq + 1));
  }
  return items;
}

// A whole unsigned number from min to max, or nullopt.
std::optional<uint64_t> bounded_count(std::string_view text, uint64_t min, uint64_t max) {
  uint64_t value = 0;
  const auto [end, ec] = std::from_chars(text.data(), text.data() + text.size(), value);
  if (ec != std::errc() || end != text.data() + text.size() || value < min || value > max) return std::nullopt;
  return value;
}

// GET /recordings/frames?name=N&first=F&count=C&step=S, or the 400 refusing it.
std::variant<Request, Reply> parse_recording_query(std::string_view target) {
  ReadRecording read;
  for (const auto& [key, value] : query_items(target)) {
    if (key == "name") {
      read.name = std::string(value);
      continue;
    }
    std::optional<uint64_t> number;
    if (key == "first") number = bounded_count(value, 0, uint64_t(1) << 40);
    else if (key == "count") number = bounded_count(value, 1, kMaxRecordingFramesPerRequest);
    else if (key == "step") number = bounded_count(value, 1, 1000000);
    else return error_reply(400, fmt::format("unknown query parameter \"{}\" (allowed: name, first, count, step)", key));
    if (!number)
      return error_reply(400, key == "count" ? fmt::format("count must be a whole number from 1 to {}", kMaxRecordingFramesPerRequest)
                                             : fmt::format("{} must be a whole number{}", key, key == "step" ? " from 1" : ""));
    (key == "first" ? read.first : key == "count" ? read.count : read.step) = *number;
  }
  if (read.name.empty() || read.name.size() > kMaxNameBytes || read.name.find('/') != std::string::npos ||
      read.name.front() == '.' || !read.name.ends_with(".fcrec"))
    return error_reply(400, "name must be a recording's file name (*.fcrec, no '/', not starting with '.')");
  return Request{read};
}

}  // namespace

std::string_view target_path(std::string_view target) noexcept { return target.substr(0, target.find('?')); }

HttpResponse make_response(const HttpRequest& request, const Reply& reply, std::string_view server) {
  HttpResponse response{static_cast<http::status>(reply.status), request.version()};
  response.set(http::field::server, std::string(server));
  if (reply.body.is_string() && reply.status == 200) {
    response.set(http::field::content_type, "text/plain; version=0.0.4; charset=utf-8");
    response.body() = reply.body.get<std::string>();
  } else {
    response.set(http::field::content_type, "application/json");
    response.body() = reply.body.dump(-1, ' ', false, json::error_handler_t::replace) + "\n";
  }
  if (reply.retry_after_s > 0) response.set(http::field::retry_after, std::to_string(reply.retry_after_s));
  response.keep_alive(request.keep_alive());
  response.prepare_payload();
  return response;
}

std::string session_cookie_name(const AccessOptions& access) {
  return access.port == 0 ? std::string("facecap_session") : fmt::format("facecap_session_{}", access.port);
}

namespace {

// POST /login {"token": "..."}: a session cookie for the token's role.
HttpResponse login(const HttpRequest& request, ApiContext& context, const std::string& peer) {
  auto answer = [&](const Reply& reply) { return make_response(request, reply, context.version); };
  const AccessOptions& access = context.access;
  if (access.operator_token.empty())
    return answer(error_reply(400, "this facecapd needs no login: control.http.token_file is not set"));
  auto parsed = Body::parse(request.body(), {"token"});
  if (auto* refused = std::get_if<Reply>(&parsed)) return answer(*refused);
  std::string token;
  if (auto e = std::get<Body>(parsed).text("token", token, 4096)) return answer(error_reply(400, *e));
  const int64_t now = monotonic_now_ns();
  if (const int64_t wait = context.throttle.wait_seconds(peer, now)) return too_many_failures(request, context, wait);
  const Role role = token.empty() ? Role::kNone : bearer_role(token, access);
  if (role == Role::kNone) {
    context.throttle.failed(peer, now);
    return answer(error_reply(401, "the token is wrong"));
  }
  context.throttle.succeeded(peer);
  const std::string id = context.sessions.open(role, now, access.session_max_age_s * kNsPerSecond);
  HttpResponse response = answer({200, {{"role", role_name(role)}, {"max_age_s", access.session_max_age_s}}});
  response.set(http::field::set_cookie, fmt::format("{}={}; Path=/; Max-Age={}; HttpOnly; SameSite=Strict{}",
                                                    session_cookie_name(access), id, access.session_max_age_s,
                                                    access.tls ? "; Secure" : ""));
  return response;
}

// POST /logout: the request's session ends and its cookie is cleared.
HttpResponse logout(const HttpRequest& request, ApiContext& context) {
  const std::string name = session_cookie_name(context.access);
  const bool ended = context.sessions.close(session_cookie(request, name));
  HttpResponse response = make_response(request, {200, {{"logged_out", ended}}}, context.version);
  response.set(http::field::set_cookie,
               fmt::format("{}=; Path=/; Max-Age=0; HttpOnly; SameSite=Strict{}", name, context.access.tls ? "; Secure" : ""));
  return response;
}

bool is_json_media_type(std::string_view content_type) {
  std::string_view type = content_type.substr(0, content_type.find(';'));
  while (!type.empty() && type.back() == ' ') type.remove_suffix(1);
  constexpr std::string_view kJson = "application/json";
  return type.size() == kJson.size() && std::equal(type.begin(), type.end(), kJson.begin(), [](char a, char b) {
           return std::tolower((unsigned char)a) == b;
         });
}

}  // namespace

bool request_authenticated(const HttpRequest& request, ApiContext& context) {
  if (context.access.operator_token.empty()) return true;
  if (auto token = bearer_token(request)) return bearer_role(*token, context.access) != Role::kNone;
  const std::string_view session = session_cookie(request, session_cookie_name(context.access));
  return !session.empty() && context.sessions.find(session, monotonic_now_ns()) != Role::kNone;
}

std::optional<HttpResponse> handle_request(const HttpRequest& request, ApiContext& context,
                                           std::function<void(HttpResponse)> respond, const std::string& peer) {
  auto answer = [&](const Reply& reply) { return make_response(request, reply, context.version); };
  const bool command = request.method() != http::verb::get && request.method() != http::verb::head;
  if (auto refused = check_source(request, context, command)) return refused;
  if (request.method() == http::verb::post && !is_json_media_type(header_value(request, http::field::content_type)))
    return answer(error_reply(415, "a POST's body must be JSON, sent with Content-Type: application/json"));
  const std::string_view target(request.target().data(), request.target().size());
  const std::string_view path = target_path(target);
  if (request.method() == http::verb::post && path == "/login") return login(request, context, peer);
  if (request.method() == http::verb::post && path == "/logout") return logout(request, context);
  const Route* route = std::find_if(std::begin(kRoutes), std::end(kRoutes), [&](const Route& r) { return r.path == path; });
  // The dashboard's files hold no secrets: its login page must load before a login.
  if (route == std::end(kRoutes) && request.method() == http::verb::get && path != "/session")
    return serve_static_file(request, path, context.dashboard_dir, context.version);
  auto identified = identify(request, context, peer);
  if (auto* refused = std::get_if<HttpResponse>(&identified)) return std::move(*refused);
  const Caller caller = std::get<Caller>(identified);
  if (caller.role == Role::kNone) return unauthenticated(request, context);
  if (path == "/session" && request.method() == http::verb::get)
    return answer({200, {{"role", role_name(caller.role)}, {"login", !context.access.operator_token.empty()}}});
  if (route == std::end(kRoutes)) return answer(error_reply(404, fmt::format("no route {}", path)));
  if (request.method() != route->method) {
    HttpResponse response = answer(error_reply(405, fmt::format("{} takes {}, not {}", path, std::string(http::to_string(route->method)),
                                                                std::string(request.method_string()))));
    response.set(http::field::allow, std::string(http::to_string(route->method)));
    return response;
  }
  if (route->method != http::verb::get && caller.role != Role::kOperator)
    return answer(error_reply(403, fmt::format("{} is a command, and this {} is a viewer's: log in with the operator's token",
                                               path, caller.presented_bearer ? "token" : "session")));
  if (path == "/stream") return answer(error_reply(400, "/stream is a WebSocket: send an Upgrade request"));
  const bool queued_read = path == "/actors" || path == "/recordings" || path == "/recordings/frames";
  if (route->method == http::verb::get && !queued_read) {
    const std::shared_ptr<const Published> published = context.board.latest();
    if (path == "/metrics") return answer({200, published->metrics_text});
    const std::string& text = path == "/status" ? published->status_json : published->config_json;
    HttpResponse response = answer({200, json::object()});
    response.body() = text;
    response.prepare_payload();
    return response;
  }
  Request queued = ListActors{};
  if (path == "/recordings") {
    queued = ListRecordings{};
  } else if (path == "/recordings/frames") {
    auto parsed = parse_recording_query(target);
    if (auto* refused = std::get_if<Reply>(&parsed)) return answer(*refused);
    queued = std::get<Request>(std::move(parsed));
  } else if (path != "/actors") {
    auto parsed = parse_command(path, request.body());
    if (auto* refused = std::get_if<Reply>(&parsed)) return answer(*refused);
    queued = std::get<Request>(std::move(parsed));
  }
  // The reply copies what it needs of the request: the request itself is gone by then.
  ReplyFn reply = [respond = std::move(respond), version = request.version(), keep_alive = request.keep_alive(),
                   server = context.version](Reply reply) {
    HttpRequest shape;
    shape.version(version);
    shape.keep_alive(keep_alive);
    respond(make_response(shape, reply, server));
  };
  if (!context.commands.push({std::move(queued), reply}))
    return answer(error_reply(503, "facecapd is busy with other commands; try again"));
  return std::nullopt;
}

std::variant<StreamRequest, HttpResponse> accept_stream(const HttpRequest& request, ApiContext& context,
                                                        const std::string& peer) {
  // WebSockets have no same-origin policy: the Origin check is all that keeps pages out.
  if (auto refused = check_source(request, context, true)) return *refused;
  auto identified = identify(request, context, peer);
  if (auto* refused = std::get_if<HttpResponse>(&identified)) return std::move(*refused);
  if (std::get<Caller>(identified).role == Role::kNone) return unauthenticated(request, context);
  StreamRequest stream;
  const std::string_view target(request.target().data(), request.target().size());
  for (const auto& [key, value] : query_items(target)) {
    auto bad = [&](std::string what) { return make_response(request, error_reply(400, std::move(what)), context.version); };
    if (key == "rate") {
      double hz = 0;
      const auto [end, ec] = std::from_chars(value.data(), value.data() + value.size(), hz);
      // Also what keeps 1e9 / rate an int64_t (1e-300 would overflow it).
      if (ec != std::errc() || end != value.data() + value.size() || !(hz >= kMinStreamRateHz) || !(hz <= kMaxStreamRateHz))
        return bad(fmt::format("rate must be a number from {:g} to {:g} (frames per second)", kMinStreamRateHz, kMaxStreamRateHz));
      stream.rate_hz = hz;
    } else if (key == "vertices") {
      if (value != "0" && value != "1") return bad("vertices must be 0 or 1");
      stream.vertices = value == "1";
    } else if (!key.empty()) {
      return bad(fmt::format("unknown query parameter \"{}\" (allowed: rate, vertices)", key));
    }
  }
  return stream;
}

}  // namespace facecap::control
