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

namespace facecap::control {
namespace http = boost::beast::http;
using nlohmann::json;

namespace {

constexpr std::size_t kMaxNameBytes = 200;
constexpr std::size_t kMaxNotesBytes = 4000;
constexpr double kMinCalibrationSeconds = 0.5;
constexpr double kMaxCalibrationSeconds = 30.0;

// Equal in time independent of where the first difference is.
bool same_secret(std::string_view a, std::string_view b) noexcept {
  unsigned char diff = a.size() == b.size() ? 0 : 1;
  for (std::size_t i = 0; i < a.size(); ++i) diff |= (unsigned char)(a[i] ^ (i < b.size() ? b[i] : 0));
  return diff == 0;
}

// nullopt when the request may proceed, else the 401 (RFC 6750: missing or invalid token).
std::optional<HttpResponse> check_token(const HttpRequest& request, const ApiContext& context) {
  if (context.token.empty()) return std::nullopt;
  const auto header = request.find(http::field::authorization);
  std::string_view given;
  if (header != request.end()) given = std::string_view(header->value().data(), header->value().size());
  constexpr std::string_view kScheme = "Bearer ";
  const bool has_bearer = given.size() > kScheme.size() && std::equal(kScheme.begin(), kScheme.end(), given.begin(),
      [](char a, char b) { return std::tolower((unsigned char)a) == std::tolower((unsigned char)b); });
  if (has_bearer && same_secret(given.substr(kScheme.size()), context.token)) return std::nullopt;
  HttpResponse response = make_response(
      request, error_reply(401, has_bearer ? "the bearer token is wrong" : "a bearer token is required (Authorization: Bearer <token>)"),
      context.version);
  response.set(http::field::www_authenticate,
               has_bearer ? "Bearer realm=\"facecap\", error=\"invalid_token\"" : "Bearer realm=\"facecap\"");
  return response;
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
    if (!actor.name.empty() && (actor.name.find('/') != std::string::npos || actor.name.front() == '.'))
      return error_reply(400, fmt::format("\"{}\" is not a profile name (no '/', not starting with '.')", actor.name));
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
    if (!calibrate.save.empty() && (calibrate.save.find('/') != std::string::npos || calibrate.save.front() == '.'))
      return error_reply(400, fmt::format("\"{}\" is not a profile name (no '/', not starting with '.')", calibrate.save));
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

bool request_authenticated(const HttpRequest& request, const ApiContext& context) {
  return !check_token(request, context).has_value();
}

std::optional<HttpResponse> handle_request(const HttpRequest& request, ApiContext& context,
                                           std::function<void(HttpResponse)> respond) {
  if (auto refused = check_token(request, context)) return refused;
  const std::string_view target(request.target().data(), request.target().size());
  const std::string_view path = target_path(target);
  const Route* route = std::find_if(std::begin(kRoutes), std::end(kRoutes), [&](const Route& r) { return r.path == path; });
  if (route == std::end(kRoutes)) {
    if (request.method() == http::verb::get) return serve_static_file(request, path, context.dashboard_dir, context.version);
    return make_response(request, error_reply(404, fmt::format("no route {}", path)), context.version);
  }
  if (request.method() != route->method) {
    HttpResponse response = make_response(
        request,
        error_reply(405, fmt::format("{} takes {}, not {}", path, std::string(http::to_string(route->method)),
                                     std::string(request.method_string()))),
        context.version);
    response.set(http::field::allow, std::string(http::to_string(route->method)));
    return response;
  }
  auto answer = [&](const Reply& reply) { return make_response(request, reply, context.version); };
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
  Request command = ListActors{};
  if (path == "/recordings") {
    command = ListRecordings{};
  } else if (path == "/recordings/frames") {
    auto parsed = parse_recording_query(target);
    if (auto* refused = std::get_if<Reply>(&parsed)) return answer(*refused);
    command = std::get<Request>(std::move(parsed));
  } else if (path != "/actors") {
    auto parsed = parse_command(path, request.body());
    if (auto* refused = std::get_if<Reply>(&parsed)) return answer(*refused);
    command = std::get<Request>(std::move(parsed));
  }
  // The reply copies what it needs of the request: the request itself is gone by then.
  ReplyFn reply = [respond = std::move(respond), version = request.version(), keep_alive = request.keep_alive(),
                   server = context.version](Reply reply) {
    HttpRequest shape;
    shape.version(version);
    shape.keep_alive(keep_alive);
    respond(make_response(shape, reply, server));
  };
  if (!context.commands.push({std::move(command), reply}))
    return answer(error_reply(503, "facecapd is busy with other commands; try again"));
  return std::nullopt;
}

std::variant<StreamRequest, HttpResponse> accept_stream(const HttpRequest& request, const ApiContext& context) {
  if (auto refused = check_token(request, context)) return *refused;
  StreamRequest stream;
  const std::string_view target(request.target().data(), request.target().size());
  for (const auto& [key, value] : query_items(target)) {
    auto bad = [&](std::string what) { return make_response(request, error_reply(400, std::move(what)), context.version); };
    if (key == "rate") {
      double hz = 0;
      const auto [end, ec] = std::from_chars(value.data(), value.data() + value.size(), hz);
      if (ec != std::errc() || end != value.data() + value.size() || !(hz > 0) || hz > kMaxStreamRateHz)
        return bad(fmt::format("rate must be a number above 0 and at most {:g} (frames per second)", kMaxStreamRateHz));
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
