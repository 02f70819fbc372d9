// Who may use the control API (control/access.hpp), on bytes through handle_request: the
// Host check against DNS rebinding, the Origin and Content-Type checks against other web
// pages, login sessions and their cookie, the viewer role, the throttle on wrong tokens,
// and the lower findings of issue 35 (stream rate, profile names, token file modes).
#include <set>

#include <catch2/catch.hpp>
#include <nlohmann/json.hpp>

#include "config/config_file.hpp"
#include "control/api.hpp"
#include "core/text_list.hpp"
#include "core/time.hpp"
#include "tests/test_support.hpp"

using namespace facecap;
using Catch::Contains;
using nlohmann::json;
namespace fs = std::filesystem;
namespace http = boost::beast::http;

namespace {

struct Headers {
  std::string host = "127.0.0.1:8765";
  std::string origin, referer, content_type = "application/json", authorization, cookie, upgrade;
};

control::HttpRequest request(http::verb method, std::string target, const Headers& h = {}, std::string body = {}) {
  control::HttpRequest r{method, target, 11};
  if (!h.host.empty()) r.set(http::field::host, h.host);
  if (!h.origin.empty()) r.set(http::field::origin, h.origin);
  if (!h.referer.empty()) r.set(http::field::referer, h.referer);
  if (method == http::verb::post && !h.content_type.empty()) r.set(http::field::content_type, h.content_type);
  if (!h.authorization.empty()) r.set(http::field::authorization, h.authorization);
  if (!h.cookie.empty()) r.set(http::field::cookie, h.cookie);
  r.body() = std::move(body);
  r.prepare_payload();
  return r;
}

struct Api {
  explicit Api(std::string address = "127.0.0.1") {
    context.access.address = std::move(address);
    context.access.port = 8765;
  }
  control::StatusBoard board;
  control::CommandQueue queue{8};
  control::ApiContext context{board, queue, "test"};

  // The status of the answer: 0 when the request was queued for the supervisor.
  int status(const control::HttpRequest& r, const std::string& peer = "10.0.0.9") {
    last = control::handle_request(r, context, [](control::HttpResponse) {}, peer);
    return last ? int(last->result_int()) : 0;
  }
  std::string error() const { return last ? json::parse(last->body()).value("error", "") : ""; }
  std::size_t queued() {
    std::size_t n = 0;
    while (queue.pop()) ++n;
    return n;
  }
  int stream_status(const control::HttpRequest& r) {
    const auto accepted = control::accept_stream(r, context, "10.0.0.9");
    return std::holds_alternative<control::StreamRequest>(accepted) ? 0
                                                                    : int(std::get<control::HttpResponse>(accepted).result_int());
  }
  std::optional<control::HttpResponse> last;
};

// "name=value" of a Set-Cookie header, for sending it back.
std::string cookie_pair(const control::HttpResponse& response) {
  const std::string set_cookie(response[http::field::set_cookie]);
  return set_cookie.substr(0, set_cookie.find(';'));
}

}  // namespace

TEST_CASE("the Host must name this facecapd: DNS rebinding gets 421 on every route") {
  Api api;
  api.board.publish(std::make_shared<control::Published>(control::Published{"{}\n", "", "{}\n"}));
  for (const std::string host : {"127.0.0.1:8765", "127.0.0.1", "localhost:8765", "LOCALHOST"}) {
    INFO(host);
    CHECK(api.status(request(http::verb::get, "/status", {.host = host})) == 200);
  }
  for (const std::string host : {"attacker.example", "attacker.example:8765", "127.0.0.1:8766", "127.0.0.2:8765", "localhost.:8765",
                                 "127.0.0.1:8765@evil", "[::1]:8765", "::1", "127.0.0.1:", "", "[127.0.0.1]"}) {
    INFO(host);
    CHECK(api.status(request(http::verb::get, "/status", {.host = host})) == (host.empty() ? 400 : 421));
    CHECK(api.status(request(http::verb::get, "/", {.host = host})) == (host.empty() ? 400 : 421));  // the dashboard's files too
    CHECK(api.stream_status(request(http::verb::get, "/stream", {.host = host})) == (host.empty() ? 400 : 421));
    CHECK(api.status(request(http::verb::post, "/record/start", {.host = host}, "{}")) == (host.empty() ? 400 : 421));
  }
  CHECK(api.queued() == 0);
  api.status(request(http::verb::get, "/config", {.host = "evil.example:8765"}));
  CHECK(api.error() == "Host \"evil.example:8765\" is not this facecapd: use its address, or add the name to "
                       "control.http.allowed_hosts");

  api.context.access.allowed_hosts = {"stage-box.local"};
  CHECK(api.status(request(http::verb::get, "/status", {.host = "Stage-Box.local:8765"})) == 200);
  CHECK(api.status(request(http::verb::get, "/status", {.host = "stage-box.local.evil.example:8765"})) == 421);

  // Bound to every address: any IP literal is this box (a literal cannot be rebound); names are not.
  Api any("0.0.0.0");
  any.board.publish(std::make_shared<control::Published>(control::Published{"{}\n", "", "{}\n"}));
  CHECK(any.status(request(http::verb::get, "/status", {.host = "10.77.0.1:8765"})) == 200);
  CHECK(any.status(request(http::verb::get, "/status", {.host = "localhost:8765"})) == 200);
  CHECK(any.status(request(http::verb::get, "/status", {.host = "stage.example:8765"})) == 421);
  // Bound to one LAN address: localhost is not it.
  Api lan("10.77.0.1");
  CHECK(lan.status(request(http::verb::get, "/status", {.host = "localhost:8765"})) == 421);
  CHECK(lan.status(request(http::verb::get, "/status", {.host = "10.77.0.1:8765"})) != 421);
  Api v6("::1");
  v6.board.publish(std::make_shared<control::Published>(control::Published{"{}\n", "", "{}\n"}));
  CHECK(v6.status(request(http::verb::get, "/status", {.host = "[::1]:8765"})) == 200);
  CHECK(v6.status(request(http::verb::get, "/status", {.host = "[0:0:0:0:0:0:0:1]:8765"})) == 200);
}

TEST_CASE("pages of other origins cannot command nor open the stream, and POST needs JSON") {
  Api api;
  const std::string own = "http://127.0.0.1:8765";
  // The issue's attack: fetch(..., {mode: 'no-cors', headers: {'Content-Type': 'text/plain'}}) from another port.
  CHECK(api.status(request(http::verb::post, "/record/start", {.origin = "http://127.0.0.1:9999", .content_type = "text/plain"}, "{}")) == 403);
  CHECK(api.status(request(http::verb::post, "/record/start", {.origin = "http://127.0.0.1:9999"}, "{}")) == 403);
  CHECK(api.error() == "a page of http://127.0.0.1:9999 (Origin) may not use this facecapd: open the dashboard from it, or add "
                       "the origin to control.http.allowed_origins");
  CHECK(api.status(request(http::verb::post, "/record/stop", {.origin = "null"}, "{}")) == 403);
  CHECK(api.status(request(http::verb::post, "/record/stop", {.origin = "https://127.0.0.1:8765"}, "{}")) == 403);
  CHECK(api.status(request(http::verb::post, "/record/stop", {.referer = "http://evil.example/page.html"}, "{}")) == 403);
  CHECK(api.status(request(http::verb::post, "/record/stop", {.referer = "garbage"}, "{}")) == 403);
  CHECK(api.status(request(http::verb::post, "/login", {.origin = "http://evil.example"}, R"({"token": "x"})")) == 403);
  CHECK(api.status(request(http::verb::get, "/status", {.origin = "http://evil.example"})) == 403);  // a CORS read
  CHECK(api.stream_status(request(http::verb::get, "/stream", {.origin = "http://127.0.0.1:9999"})) == 403);
  CHECK(api.stream_status(request(http::verb::get, "/stream", {.referer = "http://127.0.0.1:9999/"})) == 403);
  // Simple (no-preflight) content types from the page itself, and none at all: 415.
  for (const std::string type : {"text/plain", "application/x-www-form-urlencoded", "multipart/form-data; boundary=x", ""}) {
    INFO(type);
    CHECK(api.status(request(http::verb::post, "/record/stop", {.origin = own, .content_type = type}, "{}")) == 415);
  }
  CHECK(api.queued() == 0);

  // The dashboard's own page, an allowed origin, and clients that are no page (no Origin).
  CHECK(api.status(request(http::verb::post, "/record/stop", {.origin = own}, "{}")) == 0);
  CHECK(api.status(request(http::verb::post, "/record/stop", {.referer = own + "/index.html"}, "{}")) == 0);
  CHECK(api.status(request(http::verb::post, "/record/stop", {.content_type = "Application/JSON; charset=utf-8"}, "{}")) == 0);
  CHECK(api.status(request(http::verb::post, "/record/stop", {}, "{}")) == 0);
  api.context.access.allowed_origins = {"http://tablet.lan:8080"};
  CHECK(api.status(request(http::verb::post, "/record/stop", {.origin = "http://tablet.lan:8080"}, "{}")) == 0);
  CHECK(api.stream_status(request(http::verb::get, "/stream", {.origin = own})) == 0);
  CHECK(api.stream_status(request(http::verb::get, "/stream")) == 0);
  CHECK(api.queued() == 5);
}

TEST_CASE("login: the token for an HttpOnly SameSite=Strict session cookie, logout ends it, viewers only read") {
  Api api;
  api.context.access.operator_token = "op-s3cret";
  api.context.access.viewer_token = "view-s3cret";
  api.context.access.session_max_age_s = 3600;
  api.board.publish(std::make_shared<control::Published>(control::Published{"{}\n", "", "{}\n"}));
  const std::string own = "http://127.0.0.1:8765";

  // Without a credential: the dashboard's files load (its login page), the API says 401.
  CHECK(api.status(request(http::verb::get, "/status")) == 401);
  CHECK(api.status(request(http::verb::get, "/session")) == 401);
  CHECK(api.stream_status(request(http::verb::get, "/stream")) == 401);
  CHECK(api.status(request(http::verb::post, "/record/start", {.origin = own}, "{}")) == 401);
  CHECK(api.status(request(http::verb::get, "/index.html")) == 404);  // served (no dashboard here), not 401

  CHECK(api.status(request(http::verb::post, "/login", {.origin = own}, R"({"token": "op-s3creT"})")) == 401);
  CHECK(api.error() == "the token is wrong");
  CHECK(api.status(request(http::verb::post, "/login", {.origin = own, .content_type = "text/plain"}, R"({"token": "op-s3cret"})")) == 415);
  REQUIRE(api.status(request(http::verb::post, "/login", {.origin = own}, R"({"token": "op-s3cret"})")) == 200);
  const std::string set_cookie((*api.last)[http::field::set_cookie]);
  CHECK_THAT(set_cookie, Catch::Matches("facecap_session_8765=[0-9a-f]{64}; Path=/; Max-Age=3600; HttpOnly; SameSite=Strict"));
  CHECK(json::parse(api.last->body()) == json{{"role", "operator"}, {"max_age_s", 3600}});
  const std::string operator_cookie = cookie_pair(*api.last);

  CHECK(api.status(request(http::verb::get, "/status", {.cookie = "theme=dark; " + operator_cookie})) == 200);
  CHECK(api.status(request(http::verb::get, "/session", {.cookie = operator_cookie})) == 200);
  CHECK(json::parse(api.last->body())["role"] == "operator");
  CHECK(api.stream_status(request(http::verb::get, "/stream", {.origin = own, .cookie = operator_cookie})) == 0);
  CHECK(api.status(request(http::verb::post, "/record/start", {.origin = own, .cookie = operator_cookie}, "{}")) == 0);
  // A session is not a pass for other pages: same-site is not same-origin (another port).
  CHECK(api.status(request(http::verb::post, "/record/stop", {.origin = "http://127.0.0.1:9999", .cookie = operator_cookie}, "{}")) == 403);
  // Another facecapd's cookie (another port) and a forged id do not pass.
  CHECK(api.status(request(http::verb::get, "/status", {.cookie = "facecap_session_8766" + operator_cookie.substr(20)})) == 401);
  CHECK(api.status(request(http::verb::get, "/status", {.cookie = "facecap_session_8765=" + std::string(64, '0')})) == 401);

  // The viewer reads but does not command, by session or by bearer token.
  REQUIRE(api.status(request(http::verb::post, "/login", {.origin = own}, R"({"token": "view-s3cret"})")) == 200);
  const std::string viewer_cookie = cookie_pair(*api.last);
  CHECK(viewer_cookie != operator_cookie);
  CHECK(api.status(request(http::verb::get, "/status", {.cookie = viewer_cookie})) == 200);
  CHECK(api.status(request(http::verb::get, "/recordings", {.cookie = viewer_cookie})) == 0);
  CHECK(api.stream_status(request(http::verb::get, "/stream", {.origin = own, .cookie = viewer_cookie})) == 0);
  for (const std::string route : {"/record/start", "/record/stop", "/actor", "/calibrate"}) {
    INFO(route);
    CHECK(api.status(request(http::verb::post, route, {.origin = own, .cookie = viewer_cookie}, "{}")) == 403);
    CHECK(api.status(request(http::verb::post, route, {.authorization = "Bearer view-s3cret"}, "{}")) == 403);
  }
  CHECK(api.error() == "/calibrate is a command, and this token is a viewer's: log in with the operator's token");
  CHECK(api.status(request(http::verb::post, "/record/stop", {.authorization = "Bearer op-s3cret"}, "{}")) == 0);
  CHECK(api.queued() == 3);  // record/start by the operator's session, /recordings, record/stop by its token

  // Logout ends the session and clears the cookie.
  REQUIRE(api.status(request(http::verb::post, "/logout", {.origin = own, .cookie = operator_cookie}, "{}")) == 200);
  CHECK(std::string((*api.last)[http::field::set_cookie]) == "facecap_session_8765=; Path=/; Max-Age=0; HttpOnly; SameSite=Strict");
  CHECK(api.status(request(http::verb::get, "/status", {.cookie = operator_cookie})) == 401);
  CHECK(api.context.sessions.size() == 1);
}

TEST_CASE("wrong tokens: 5 a minute per address, then 429 even for the right one, other addresses unaffected") {
  Api api;
  api.context.access.operator_token = "op-s3cret";
  const std::string own = "http://127.0.0.1:8765";
  for (int i = 0; i < control::LoginThrottle::kMaxFailures; ++i)
    CHECK(api.status(request(http::verb::post, "/login", {.origin = own}, R"({"token": "guess"})"), "10.0.0.66") == 401);
  CHECK(api.status(request(http::verb::post, "/login", {.origin = own}, R"({"token": "op-s3cret"})"), "10.0.0.66") == 429);
  CHECK_THAT(api.error(), Contains("too many wrong tokens from this address: try again in"));
  const int retry_after = std::stoi(std::string((*api.last)[http::field::retry_after]));
  CHECK(retry_after >= 59);
  CHECK(retry_after <= 60);
  CHECK(api.status(request(http::verb::get, "/status", {.authorization = "Bearer op-s3cret"}), "10.0.0.66") == 429);
  CHECK(api.status(request(http::verb::post, "/login", {.origin = own}, R"({"token": "op-s3cret"})"), "10.0.0.67") == 200);
  // Wrong bearer tokens count too.
  for (int i = 0; i < control::LoginThrottle::kMaxFailures; ++i)
    CHECK(api.status(request(http::verb::get, "/status", {.authorization = "Bearer nope"}), "10.0.0.68") == 401);
  CHECK(api.status(request(http::verb::get, "/status", {.authorization = "Bearer op-s3cret"}), "10.0.0.68") == 429);

  // The window ends; the table of addresses stays bounded.
  control::LoginThrottle throttle;
  for (int i = 0; i < control::LoginThrottle::kMaxFailures; ++i) throttle.failed("a", 0);
  CHECK(throttle.wait_seconds("a", 0) == 60);
  CHECK(throttle.wait_seconds("a", control::LoginThrottle::kWindowNs) == 0);
}

TEST_CASE("sessions: random 256-bit ids, bounded table, expiry") {
  control::SessionTable sessions;
  const int64_t hour = 3600 * kNsPerSecond;
  const std::string first = sessions.open(control::Role::kOperator, 0, hour);
  CHECK(first.size() == 64);
  CHECK(first.find_first_not_of("0123456789abcdef") == std::string::npos);
  CHECK(sessions.find(first, hour - 1) == control::Role::kOperator);
  CHECK(sessions.find(first, hour) == control::Role::kNone);  // expired, and forgotten
  CHECK(sessions.size() == 0);
  std::set<std::string> ids;
  for (int i = 0; i < 200; ++i) ids.insert(sessions.open(control::Role::kViewer, i, hour));
  CHECK(ids.size() == 200);
  CHECK(sessions.size() == control::SessionTable::kCapacity);
  // The oldest logins gave way; the newest hold.
  int live = 0;
  for (const std::string& id : ids) live += sessions.find(id, 300) == control::Role::kViewer;
  CHECK(live == int(control::SessionTable::kCapacity));
}

TEST_CASE("lower findings: stream rate bounds, profile names, no path for /actor") {
  Api api;
  for (const std::string rate : {"1e-300", "0", "-1", "0.05", "nan", "inf", "120.0001", "1e308", "0x10", ""}) {
    INFO(rate);
    CHECK(api.stream_status(request(http::verb::get, "/stream?rate=" + rate)) == 400);
  }
  for (const std::string rate : {"0.1", "120", "30"}) {
    INFO(rate);
    CHECK(api.stream_status(request(http::verb::get, "/stream?rate=" + rate)) == 0);
  }

  // /actor's file names a file of the profiles directory; a path gets one answer whether it exists or not.
  const fs::path dir = test::scratch_dir("control-security-actor");
  test::write_text(dir / "exists.toml", "x");
  std::set<std::string> errors;
  for (const std::string& file : {(dir / "exists.toml").string(), (dir / "missing.toml").string(), std::string("../exists.toml"),
                                 std::string("sub/x.toml"), std::string("..\\x.toml"), std::string(".hidden.toml")}) {
    INFO(file);
    CHECK(api.status(request(http::verb::post, "/actor", {}, json{{"file", file}}.dump())) == 400);
    errors.insert(api.error());
  }
  CHECK(errors == std::set<std::string>{"\"file\" must be a file name in the profiles directory: no '/' or '\\', no control "
                                        "characters, not starting with '.'"});
  CHECK(api.status(request(http::verb::post, "/actor", {}, R"({"file": "alice-cal.toml"})")) == 0);
  // /calibrate's save: no NUL (it wrote profiles/evil without .toml), control characters or separators.
  for (const std::string& save : {std::string("evil\\u0000"), std::string("a\\nb"), std::string("a\\u001b[31m"), std::string("a/b"),
                                 std::string("a\\\\b"), std::string("..")}) {
    INFO(save);
    CHECK(api.status(request(http::verb::post, "/calibrate", {}, "{\"save\": \"" + save + "\"}")) == 400);
    CHECK_THAT(api.error(), Contains("\"save\" must be a file name in the profiles directory"));
  }
  CHECK(api.status(request(http::verb::post, "/calibrate", {}, R"({"save": "alice 2"})")) == 0);
  CHECK(api.queued() == 2);
}

TEST_CASE("token files others may read are refused, like ssh keys, and the lists are checked") {
  const fs::path dir = test::scratch_dir("control-security-config");
  const fs::path token = dir / "token";
  test::write_text(token, "s3cret\n");
  fs::permissions(token, fs::perms::owner_read | fs::perms::owner_write | fs::perms::group_read | fs::perms::others_read);
  const std::vector<std::string> on{"control.http.enabled=true", "control.http.token_file=" + token.string()};
  CHECK_THROWS_WITH(config::load_config("", on),
                    Contains("[control.http.token_file]: \"" + token.string() +
                             "\" holds a token but group or others may access it (mode 0644): chmod 600 it"));
  fs::permissions(token, fs::perms::owner_read | fs::perms::owner_write | fs::perms::group_read);
  CHECK_THROWS_WITH(config::load_config("", on), Contains("(mode 0640)"));
  fs::permissions(token, fs::perms::owner_read | fs::perms::owner_write);
  CHECK_NOTHROW(config::load_config("", on));

  CHECK_THROWS_WITH(config::load_config("", {"control.http.enabled=true", "control.http.viewer_token_file=" + token.string()}),
                    Contains("a viewer's token needs the operator's"));
  CHECK_THROWS_WITH(config::load_config("", {"control.http.enabled=true", "control.http.allowed_origins=tablet.lan:8080"}),
                    Contains("\"tablet.lan:8080\" is not an origin"));
  CHECK_THROWS_WITH(config::load_config("", {"control.http.enabled=true", "control.http.allowed_hosts=http://box"}),
                    Contains("\"http://box\" is not a host name"));
  CHECK(split_list(" a.lan, b.lan  c.lan,,", config::kListSeparators) == std::vector<std::string>{"a.lan", "b.lan", "c.lan"});
}

TEST_CASE("over TLS the box's own origin is https:// and the session cookie is Secure") {
  Api api;
  api.context.access.tls = true;
  api.context.access.operator_token = "op-s3cret";
  api.board.publish(std::make_shared<control::Published>(control::Published{"{}\n", "", "{}\n"}));
  // The page the box serves over TLS may log in; the same host over plain http:// is another origin.
  CHECK(api.status(request(http::verb::post, "/login", {.origin = "http://127.0.0.1:8765"}, R"({"token": "op-s3cret"})")) == 403);
  REQUIRE(api.status(request(http::verb::post, "/login", {.origin = "https://127.0.0.1:8765"}, R"({"token": "op-s3cret"})")) == 200);
  CHECK_THAT(std::string((*api.last)[http::field::set_cookie]), Catch::EndsWith("; HttpOnly; SameSite=Strict; Secure"));
  const std::string cookie = cookie_pair(*api.last);
  CHECK(api.status(request(http::verb::post, "/record/start", {.origin = "https://127.0.0.1:8765", .cookie = cookie}, "{}")) == 0);
  CHECK(api.status(request(http::verb::post, "/record/start", {.origin = "http://127.0.0.1:8765", .cookie = cookie}, "{}")) == 403);
  REQUIRE(api.status(request(http::verb::post, "/logout", {.origin = "https://127.0.0.1:8765", .cookie = cookie}, "{}")) == 200);
  CHECK_THAT(std::string((*api.last)[http::field::set_cookie]), Catch::EndsWith("; Secure"));
}
