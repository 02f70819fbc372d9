// The control API: request handling on bytes (routes, JSON bodies, tokens, a full queue),
// then facecapd in-process on the sim with the API on: status, Prometheus metrics checked
// by promtool, takes, markers-only takes, calibration on the box, actor swaps, the
// WebSocket stream, and all of it over TLS; the capture-quality state of the issue's
// motivating failure; --version.
#include <algorithm>
#include <cstdio>
#include <future>
#include <regex>
#include <thread>

#include <boost/asio/connect.hpp>
#include <boost/asio/ip/tcp.hpp>
#include <boost/beast/core.hpp>
#include <boost/asio/ssl.hpp>
#include <boost/beast/ssl.hpp>
#include <boost/beast/websocket.hpp>
#include <boost/beast/websocket/ssl.hpp>
#include <catch2/catch.hpp>
#include <fmt/format.h>
#include <nlohmann/json.hpp>
#include <spdlog/sinks/ostream_sink.h>
#include <spdlog/spdlog.h>

#include "config/config_file.hpp"
#include "control/api.hpp"
#include "control/bounded_workers.hpp"
#include "control/connection_limits.hpp"
#include "control/http_client.hpp"
#include "control/static_files.hpp"
#include "control/tls.hpp"
#include "core/error.hpp"
#include "core/time.hpp"
#include "daemon/daemon.hpp"
#include "formats/recording.hpp"
#include "pipeline/calibration.hpp"
#include "pipeline/recording_header.hpp"
#include "solver/align/profile.hpp"
#include "solver/builtin_face.hpp"
#include "tests/test_support.hpp"

using namespace facecap;
using Catch::Contains;
using nlohmann::json;
namespace fs = std::filesystem;
namespace http = boost::beast::http;

namespace {

// A request as facecap ctl sends it: Host the address, a POST's body JSON.
control::HttpRequest request(http::verb method, std::string target, std::string body = {}, std::string token = {}) {
  control::HttpRequest r{method, target, 11};
  r.set(http::field::host, "127.0.0.1");
  if (method == http::verb::post) r.set(http::field::content_type, "application/json");
  if (!token.empty()) r.set(http::field::authorization, "Bearer " + token);
  r.body() = std::move(body);
  r.prepare_payload();
  return r;
}

struct Api {
  control::StatusBoard board;
  control::CommandQueue queue{2};
  control::ApiContext context{board, queue, "test"};
  std::optional<control::HttpResponse> later;

  std::optional<control::HttpResponse> handle(const control::HttpRequest& r) {
    return control::handle_request(r, context, [this](control::HttpResponse response) { later = std::move(response); });
  }
  // The status and the JSON error of an immediate answer.
  std::pair<int, std::string> refusal(const control::HttpRequest& r) {
    const auto response = handle(r);
    REQUIRE(response);
    const json body = json::parse(response->body());
    return {int(response->result_int()), body.value("error", "")};
  }
};

// facecapd in-process on the sim, its supervisor on a thread of the test.
class RunningDaemon {
 public:
  explicit RunningDaemon(std::vector<std::string> overrides)
      : daemon_({.handle_signals = false, .version = "facecapd test"}, config::load_config("", overrides)) {
    daemon_.start();
    thread_ = std::thread([this] { status_ = daemon_.run(); });
  }
  ~RunningDaemon() { stop(); }
  int stop() {
    if (thread_.joinable()) {
      daemon_.request_stop();
      thread_.join();
    }
    return status_;
  }
  daemon::Daemon& operator*() { return daemon_; }
  daemon::Daemon* operator->() { return &daemon_; }

 private:
  daemon::Daemon daemon_;
  std::thread thread_;
  int status_ = -1;
};

std::string unique_shm(const std::string& what) { return fmt::format("facecap-test-{}-{}", ::getpid(), what); }

json get_json(control::HttpClient& client, const std::string& target) {
  const control::HttpResult r = client.request("GET", target);
  INFO(target << ": " << r.body);
  REQUIRE(r.status == 200);
  return json::parse(r.body);
}

json post(control::HttpClient& client, const std::string& target, const json& body, int want_status = 200) {
  const control::HttpResult r = client.request("POST", target, body.dump());
  INFO("POST " << target << " " << body.dump() << ": " << r.body);
  REQUIRE(r.status == want_status);
  return json::parse(r.body);
}

// Bytes sent as they are on a new connection; what comes back until the server closes.
std::string raw_exchange(uint16_t port, const std::string& bytes) {
  boost::asio::io_context io;
  boost::asio::ip::tcp::socket socket(io);
  socket.connect({boost::asio::ip::make_address("127.0.0.1"), port});
  boost::asio::write(socket, boost::asio::buffer(bytes));
  std::string answer;
  boost::system::error_code ec;
  char buffer[4096];
  while (std::size_t n = socket.read_some(boost::asio::buffer(buffer), ec)) answer.append(buffer, n);
  return answer;
}

// `promtool check metrics` of text: its exit status and what it said.
std::pair<int, std::string> promtool_check(const std::string& text, const fs::path& dir) {
  test::write_text(dir / "metrics.txt", text);
  int status = 0;
  const std::string said = test::run_and_capture(fmt::format("promtool check metrics < '{}' 2>&1", (dir / "metrics.txt").string()), &status);
  return {WEXITSTATUS(status), said};
}

bool have_promtool() { return std::system("command -v promtool > /dev/null 2>&1") == 0; }

}  // namespace

TEST_CASE("the API answers malformed requests with the right 4xx and a JSON error") {
  Api api;
  CHECK(api.refusal(request(http::verb::post, "/nope")) == std::pair{404, std::string("no route /nope")});
  {
    const auto response = api.handle(request(http::verb::delete_, "/status"));
    REQUIRE(response);
    CHECK(response->result_int() == 405);
    CHECK((*response)[http::field::allow] == "GET");
  }
  CHECK(api.refusal(request(http::verb::post, "/actor", "{\"name\": ")) ==
        std::pair{400, std::string("the body is not valid JSON (at byte 10)")});
  CHECK(api.refusal(request(http::verb::post, "/calibrate", R"({"seconds": 1e309})")) ==
        std::pair{400, std::string("the body holds a number too large for a double")});  // fuzz finding: threw
  CHECK(api.refusal(request(http::verb::post, "/actor", "[1, 2]")) == std::pair{400, std::string("the body must be a JSON object")});
  CHECK(api.refusal(request(http::verb::post, "/actor", R"({"nmae": "alice"})")) ==
        std::pair{400, std::string("unknown field \"nmae\" (allowed: file, name)")});
  CHECK(api.refusal(request(http::verb::post, "/actor", R"({"name": "../etc/passwd"})")).first == 400);
  CHECK(api.refusal(request(http::verb::post, "/actor", R"({"name": "a", "file": "b"})")).first == 400);
  CHECK(api.refusal(request(http::verb::post, "/calibrate", R"({"seconds": 100})")) ==
        std::pair{400, std::string("\"seconds\" must be a number from 0.5 to 30")});
  CHECK(api.refusal(request(http::verb::post, "/calibrate", R"({"replace": true})")).second ==
        "\"replace\" needs \"save\": the profile to replace");
  CHECK(api.refusal(request(http::verb::post, "/record/start", R"({"take": 7})")).second == "\"take\" must be a string");
  CHECK(api.refusal(request(http::verb::post, "/record/stop", R"({"now": true})")).first == 400);
  CHECK(api.refusal(request(http::verb::get, "/stream")).first == 400);  // not an upgrade
  CHECK(api.queue.pop() == std::nullopt);  // nothing malformed reached the supervisor

  // Commands go to the queue; its replies come later; a full queue refuses with 503.
  CHECK_FALSE(api.handle(request(http::verb::post, "/record/start", R"({"take": "t1", "markers_only": true})")));
  CHECK_FALSE(api.handle(request(http::verb::get, "/actors")));
  CHECK(api.refusal(request(http::verb::post, "/record/stop")).first == 503);
  std::optional<control::Command> command = api.queue.pop();
  REQUIRE(command);
  const auto* start = std::get_if<control::StartRecording>(&command->request);
  REQUIRE(start);
  CHECK(start->take == "t1");
  CHECK(start->markers_only);
  command->reply({200, {{"file", "t1.fcrec"}}});
  REQUIRE(api.later);
  CHECK(api.later->result_int() == 200);
  CHECK(json::parse(api.later->body())["file"] == "t1.fcrec");

  // Reads come from the board.
  api.board.publish(std::make_shared<control::Published>(control::Published{"{\"x\":1}\n", "m 1\n", "{}\n"}));
  const auto status = api.handle(request(http::verb::get, "/status?pretty"));
  REQUIRE(status);
  CHECK(status->result_int() == 200);
  CHECK(status->body() == "{\"x\":1}\n");
  CHECK((*status)[http::field::content_type] == "application/json");
  const auto metrics = api.handle(request(http::verb::get, "/metrics"));
  REQUIRE(metrics);
  CHECK(metrics->body() == "m 1\n");
  CHECK((*metrics)[http::field::content_type].starts_with("text/plain; version=0.0.4"));
}

TEST_CASE("connections: the oldest anonymous one makes way, authenticated ones keep their slots, one address is capped") {
  control::ConnectionTable table({.max_connections = 20, .kept_for_authenticated = 4, .max_per_address = 6,
                                  .max_stream_clients = 100});
  // One address: 6, then each new one evicts that address's oldest.
  std::vector<control::ConnectionTable::Id> from_a;
  for (int i = 0; i < 6; ++i) {
    const auto admission = table.admit("10.0.0.1");
    REQUIRE(admission.admitted);
    CHECK_FALSE(admission.evicted);
    from_a.push_back(*admission.admitted);
  }
  auto admission = table.admit("10.0.0.1");
  CHECK(admission.admitted);
  CHECK(admission.evicted == from_a[0]);
  CHECK(table.connections() == 6);
  // Authenticated connections do not count against their address: a 7th comes in freely.
  for (int i = 1; i < 6; ++i) table.authenticated(from_a[std::size_t(i)]);
  table.authenticated(*admission.admitted);
  CHECK(table.anonymous() == 0);
  admission = table.admit("10.0.0.1");
  CHECK(admission.admitted);
  CHECK_FALSE(admission.evicted);
  table.remove(*admission.admitted);

  // Anonymous ones from many addresses fill 20 - 4 slots less the 6 authenticated: 14 more
  // would reach the 20; anonymous may hold only 16 of them, and the total is 20.
  std::vector<control::ConnectionTable::Id> others;
  for (int i = 0; i < 14; ++i) {
    admission = table.admit(fmt::format("10.0.1.{}", i));
    REQUIRE(admission.admitted);
    CHECK_FALSE(admission.evicted);
    others.push_back(*admission.admitted);
  }
  CHECK(table.connections() == 20);
  admission = table.admit("10.0.2.1");  // full: the oldest anonymous goes
  CHECK(admission.admitted);
  CHECK(admission.evicted == others[0]);
  CHECK(table.connections() == 20);
  // Every slot authenticated: a new one is refused.
  for (std::size_t i = 1; i < others.size(); ++i) table.authenticated(others[i]);
  table.authenticated(*admission.admitted);
  admission = table.admit("10.0.2.2");
  CHECK_FALSE(admission.admitted);
  CHECK_FALSE(admission.evicted);
  // Leaving frees a slot.
  table.remove(others[1]);
  CHECK(table.admit("10.0.2.3").admitted);

  // Anonymous connections alone stop at max - kept, leaving the kept slots to authenticated ones.
  control::ConnectionTable anonymous({.max_connections = 20, .kept_for_authenticated = 4, .max_per_address = 100});
  std::vector<control::ConnectionTable::Id> idle;
  for (int i = 0; i < 16; ++i) idle.push_back(*anonymous.admit("127.0.0.1").admitted);
  admission = anonymous.admit("127.0.0.1");
  CHECK(admission.evicted == idle[0]);
  CHECK(anonymous.connections() == 16);
}

TEST_CASE("stream clients are capped, and leave the kept slots to HTTP") {
  control::ConnectionTable table({.max_connections = 20, .kept_for_authenticated = 4, .max_per_address = 100,
                                  .max_stream_clients = 3});
  std::vector<control::ConnectionTable::Id> ids;
  for (int i = 0; i < 5; ++i) ids.push_back(*table.admit("127.0.0.1").admitted);
  for (int i = 0; i < 3; ++i) CHECK(table.become_stream_client(ids[std::size_t(i)]));
  CHECK_FALSE(table.become_stream_client(ids[3]));
  table.remove(ids[0]);
  CHECK(table.become_stream_client(ids[3]));
  CHECK(table.stream_clients() == 3);

  control::ConnectionTable wide({.max_connections = 20, .kept_for_authenticated = 4, .max_per_address = 100,
                                 .max_stream_clients = 100});
  int streams = 0;
  for (int i = 0; i < 20; ++i) {
    const auto id = wide.admit(fmt::format("10.0.0.{}", i)).admitted;
    REQUIRE(id);
    wide.authenticated(*id);
    streams += wide.become_stream_client(*id);
  }
  CHECK(streams == 16);
}

TEST_CASE("a failing accept() backs off from 50 ms to 1 s and warns once per 10 s with the count") {
  control::AcceptBackoff backoff;
  std::vector<int64_t> delays_ms;
  std::vector<uint64_t> warnings;
  int64_t now = 1'000'000'000;
  // 10,000 failures, each followed by its wait: the waits and the warnings they cost.
  for (int i = 0; i < 10'000; ++i) {
    const control::AcceptBackoff::Step step = backoff.failed(now);
    if (delays_ms.size() < 8) delays_ms.push_back(step.delay_ns / kNsPerMs);
    if (step.warn_with_count > 0) warnings.push_back(step.warn_with_count);
    now += step.delay_ns;
  }
  CHECK(delays_ms == std::vector<int64_t>{50, 100, 200, 400, 800, 1000, 1000, 1000});
  // 10,000 failures take about 10,000 s at 1 s each: one warning per 10 s, counting all.
  CHECK(warnings.size() == Approx(1000).margin(2));
  uint64_t counted = 0;
  for (const uint64_t w : warnings) counted += w;
  // All but the last few (at most 10 s of them, waiting for the next warning) were counted.
  CHECK(counted <= 10'000);
  CHECK(counted > 10'000 - 11);
  CHECK(warnings.front() == 1);
  backoff.succeeded();
  CHECK(backoff.failed(now).delay_ns == 50 * kNsPerMs);
}

TEST_CASE("bounded workers: at most threads + queue jobs taken, the rest refused; queued ones dropped at the end") {
  std::promise<void> open;
  const std::shared_future<void> gate = open.get_future().share();
  std::atomic<int> ran{0}, dropped{0};
  int taken = 0, refused = 0;
  {
    control::BoundedWorkers workers(2, 3);
    auto blocked = [&] {
      gate.wait();
      ++ran;
    };
    // The two workers take a job each (and block), three wait, the rest are refused.
    for (int i = 0; i < 2; ++i) taken += workers.try_submit(blocked, [&] { ++dropped; });
    while (workers.queued() > 0) std::this_thread::yield();
    for (int i = 0; i < 8; ++i) (workers.try_submit(blocked, [&] { ++dropped; }) ? taken : refused)++;
    CHECK(workers.queued() == 3);
    open.set_value();
  }
  CHECK(taken == 5);
  CHECK(refused == 5);
  // Stopping let the running two finish and dropped the three waiting, or ran some of them.
  CHECK(ran + dropped == 5);
  CHECK(ran >= 2);
}

TEST_CASE("the command queue keeps room for commands and hands them out before reads of recordings") {
  control::CommandQueue queue(10);
  std::vector<int> answered;
  int reads = 0;
  while (queue.push({control::ReadRecording{}, nullptr})) ++reads;
  CHECK(reads == 10 - int(control::CommandQueue::kSlotsKeptForCommands));
  CHECK(queue.push({control::StopRecording{}, nullptr}));
  CHECK(queue.push({control::StartRecording{}, nullptr}));
  const auto first = queue.pop();
  REQUIRE(first);
  CHECK(std::holds_alternative<control::StopRecording>(first->request));
  CHECK(std::holds_alternative<control::StartRecording>(queue.pop()->request));
  CHECK(std::holds_alternative<control::ReadRecording>(queue.pop()->request));
}

TEST_CASE("the dashboard's files are served from its directory and never from outside it") {
  const fs::path dir = test::scratch_dir("dashboard-files");
  const fs::path root = dir / "dashboard";
  test::write_text(root / "index.html", "<!doctype html><title>live</title>");
  test::write_text(root / "assets" / "live-1a2b.js", "console.log(1);");
  test::write_text(dir / "secret.txt", "SECRET");
  fs::create_directories(dir / "outside");
  test::write_text(dir / "outside" / "secret.txt", "SECRET");
  fs::create_symlink(dir / "secret.txt", root / "escape.txt");
  fs::create_directory_symlink(dir / "outside", root / "linked");
  Api api;
  api.context.dashboard_dir = root.string();
  auto get = [&](const std::string& target) {
    const auto response = api.handle(request(http::verb::get, target));
    REQUIRE(response);
    return *response;
  };

  const control::HttpResponse index = get("/");
  CHECK(index.result_int() == 200);
  CHECK(index.body() == "<!doctype html><title>live</title>");
  CHECK(index[http::field::content_type] == "text/html; charset=utf-8");
  CHECK(get("/index.html?x=1").body() == index.body());
  const control::HttpResponse script = get("/assets/live-1a2b.js");
  CHECK(script.result_int() == 200);
  CHECK(script.body() == "console.log(1);");
  CHECK(script[http::field::content_type] == "text/javascript; charset=utf-8");
  CHECK(script[http::field::cache_control] == "max-age=31536000, immutable");
  // The API's routes stay the API's.
  CHECK(get("/status").result_int() == 200);
  CHECK(get("/status")[http::field::content_type] == "application/json");

  for (const std::string target : {"/../secret.txt", "/assets/../../secret.txt", "/%2e%2e/secret.txt", "/%2E%2E%2Fsecret.txt",
                                   "/assets/%2e%2e/%2e%2e/secret.txt", "/..%2fsecret.txt", "/./index.html", "/assets//live-1a2b.js",
                                   "/..\\secret.txt", "/%5c..%5csecret.txt", "/escape.txt", "/linked/secret.txt",
                                   "/index.html%00.js", "/%zz", "/%2", "/missing.js"}) {
    INFO(target);
    const control::HttpResponse refused = get(target);
    CHECK(refused.result_int() == 404);
    CHECK_THAT(refused.body(), !Contains("SECRET") && Contains("<h1>Not found</h1>"));
    CHECK(refused[http::field::content_type] == "text/html; charset=utf-8");
  }
  CHECK(control::resolve_static_path("/assets/live-1a2b.js", root.string()) ==
        fs::canonical(root / "assets" / "live-1a2b.js").string());
  CHECK(control::resolve_static_path("/escape.txt", root.string()).empty());

  // No dashboard: a page that says so and what to do.
  api.context.dashboard_dir = (dir / "not-built").string();
  const control::HttpResponse absent = get("/");
  CHECK(absent.result_int() == 404);
  CHECK_THAT(absent.body(), Contains("The dashboard is not installed") && Contains((dir / "not-built").string()) &&
                                Contains("control.http.dashboard_dir"));
}

TEST_CASE("a bearer token is required when one is set: missing and wrong give 401, right passes") {
  Api api;
  api.context.access.operator_token = "s3cret";
  auto missing = api.handle(request(http::verb::get, "/status"));
  REQUIRE(missing);
  CHECK(missing->result_int() == 401);
  CHECK((*missing)[http::field::www_authenticate] == "Bearer realm=\"facecap\"");
  auto wrong = api.handle(request(http::verb::get, "/status", "", "s3cree"));
  REQUIRE(wrong);
  CHECK(wrong->result_int() == 401);
  CHECK((*wrong)[http::field::www_authenticate] == "Bearer realm=\"facecap\", error=\"invalid_token\"");
  CHECK(api.refusal(request(http::verb::post, "/nope", "", "s3cret")).first == 404);  // past the token: routed
  auto right = api.handle(request(http::verb::get, "/status", "", "s3cret"));
  REQUIRE(right);
  CHECK(right->result_int() == 200);
  CHECK(std::holds_alternative<control::HttpResponse>(control::accept_stream(request(http::verb::get, "/stream"), api.context)));
}

TEST_CASE("the stream's query: rate and vertices, bounded") {
  Api api;
  const auto ok = control::accept_stream(request(http::verb::get, "/stream?rate=12.5&vertices=1"), api.context);
  REQUIRE(std::holds_alternative<control::StreamRequest>(ok));
  CHECK(std::get<control::StreamRequest>(ok).rate_hz == 12.5);
  CHECK(std::get<control::StreamRequest>(ok).vertices);
  for (const char* bad : {"/stream?rate=0", "/stream?rate=500", "/stream?rate=x", "/stream?vertices=yes", "/stream?fps=3"}) {
    INFO(bad);
    const auto refused = control::accept_stream(request(http::verb::get, bad), api.context);
    REQUIRE(std::holds_alternative<control::HttpResponse>(refused));
    CHECK(std::get<control::HttpResponse>(refused).result_int() == 400);
  }
}

TEST_CASE("facecapd refuses a control API on a non-loopback address without a token") {
  CHECK_THROWS_WITH(config::load_config("", {"control.http.enabled=true", "control.http.address=0.0.0.0"}),
                    Contains("[control.http.token_file]: the control API listens on 0.0.0.0, which is not loopback: a "
                             "bearer token is required"));
  CHECK_THROWS_WITH(config::load_config("", {"control.http.enabled=true", "control.http.address=localhost"}),
                    Contains("\"localhost\" is not an IPv4 or IPv6 address"));
  CHECK_NOTHROW(config::load_config("", {"control.http.enabled=true", "control.http.address=::1"}));
  CHECK_NOTHROW(config::load_config("", {"control.http.enabled=true", "control.http.address=127.0.0.2"}));
}

TEST_CASE("a recording's rate is the source's: 60 Hz under a 120 Hz loop records 60 Hz") {
  CHECK(pipeline::recorded_rate_hz(60, 120, false) == 60);
  CHECK(pipeline::recorded_rate_hz(240, 120, false) == 120);  // every other frame
  CHECK(pipeline::recorded_rate_hz(240, 120, true) == 240);   // lockstep: every frame
  CHECK(pipeline::recorded_rate_hz(0, 120, false) == 0);      // unknown: readers use the frames' times
}

TEST_CASE("metrics text passes promtool check metrics") {
  if (!have_promtool()) {
    WARN("SKIPPED: promtool (Debian package prometheus) is not installed");
    return;
  }
  control::StatusReport r;
  r.version = "facecapd \"quoted\" \\ 1";
  r.rig_name = "builtin";
  r.quality = "degraded";
  r.flagged_frames = {{"head_pose_held", 3}, {"too_few_markers", 0}};
  r.outputs = {{.name = "shm", .offered = 10, .delivered = 10}, {.name = "recording", .offered = 10, .delivered = 9, .dropped = 1}};
  const auto [status, said] = promtool_check(control::metrics_text(r), test::scratch_dir("promtool-unit"));
  INFO(said);
  CHECK(status == 0);
  CHECK(said.empty());
}

TEST_CASE("control API end to end on the sim: status, metrics, takes, calibration, actor swap, stream, tokens", "[realtime]") {
  const fs::path dir = test::scratch_dir("control-e2e");
  test::write_text(dir / "token", "s3cret\n");
  fs::permissions(dir / "token", fs::perms::owner_read | fs::perms::owner_write);
  // A 60 Hz source under a 120 Hz loop, with the sim's default dropouts (0.5% per marker:
  // hardly a 0.25 s stretch has every marker in every frame).
  RunningDaemon d({"outputs.shm.name=" + unique_shm("control"), "control.http.enabled=true", "control.http.port=0",
                   "control.http.token_file=" + (dir / "token").string(), "control.status_interval_s=0.25",
                   "source.sim.rate_hz=60",
                   "outputs.recording.directory=" + (dir / "takes").string(),
                   "calibration.profiles_directory=" + (dir / "profiles").string()});
  const uint16_t port = d->control_port();
  REQUIRE(port != 0);
  control::HttpClient client("127.0.0.1", port, "s3cret");
  std::this_thread::sleep_for(std::chrono::milliseconds(600));

  // Tokens, routes and bodies as the server sees them.
  CHECK(control::HttpClient("127.0.0.1", port).request("GET", "/status").status == 401);
  CHECK(control::HttpClient("127.0.0.1", port, "wrong").request("GET", "/status").status == 401);
  CHECK(client.request("GET", "/no/such/route").status == 404);
  CHECK(client.request("POST", "/record/start", "{\"take\": ").status == 400);
  CHECK_THAT(raw_exchange(port, "GARBAGE\r\n\r\n"), Contains("HTTP/1.1 400 Bad Request") && Contains("malformed HTTP request"));
  CHECK_THAT(raw_exchange(port, fmt::format("POST /actor HTTP/1.1\r\nContent-Length: {}\r\n\r\n", 1 << 20)),
             Contains("HTTP/1.1 413"));
  // Issue 35 through the server: a rebound name (421), a page's text/plain POST (415), another origin (403).
  const std::string bearer = "Authorization: Bearer s3cret\r\nConnection: close\r\n";
  CHECK_THAT(raw_exchange(port, fmt::format("GET /status HTTP/1.1\r\nHost: attacker.example:{}\r\n{}\r\n", port, bearer)),
             Contains("HTTP/1.1 421") && !Contains("\"version\""));
  CHECK_THAT(raw_exchange(port, "POST /record/start HTTP/1.1\r\nHost: 127.0.0.1\r\nContent-Type: text/plain\r\n"
                                "Content-Length: 2\r\n" + bearer + "\r\n{}"),
             Contains("HTTP/1.1 415"));
  CHECK_THAT(raw_exchange(port, "POST /record/start HTTP/1.1\r\nHost: 127.0.0.1\r\nOrigin: http://127.0.0.1:1\r\n"
                                "Content-Type: application/json\r\nContent-Length: 2\r\n" + bearer + "\r\n{}"),
             Contains("HTTP/1.1 403"));
  CHECK_FALSE(get_json(client, "/status")["recording"]["active"].get<bool>());

  json status = get_json(client, "/status");
  CHECK(status["version"] == "facecapd test");
  CHECK(status["source"]["driver"] == "sim");
  CHECK(status["source"]["rate_hz"] == 60.0);
  CHECK(status["rig"]["name"] == "builtin");
  CHECK(status["calibration"]["markers"] == 48);
  CHECK(status["window"]["quality"] == "good");
  CHECK(status["window"]["markers_expected"] == 48.0);
  CHECK(status["window"]["solved_fps"].get<double>() == Approx(60).epsilon(0.1));
  CHECK(status["outputs"].size() == 3);  // shm, recording, stream
  CHECK(status["recording"]["active"] == false);
  CHECK(get_json(client, "/config")["values"]["control.http.port"] == 0);

  const control::HttpResult metrics = client.request("GET", "/metrics");
  REQUIRE(metrics.status == 200);
  CHECK_THAT(metrics.body, Contains("facecap_frames_solved_total ") && Contains("facecap_capture_quality{state=\"good\"} 1"));
  if (have_promtool()) {
    const auto [checked, said] = promtool_check(metrics.body, dir);
    INFO(said);
    CHECK(checked == 0);
    CHECK(said.empty());
  } else {
    WARN("promtool (Debian package prometheus) is not installed: metrics not checked by it");
  }

  // A take with its slate: the file is named from it, the HEAD holds it, the rate is the source's.
  const json started = post(client, "/record/start", {{"take", "t/1"}, {"scene", "s 1"}, {"shot", "2"}, {"notes", "first"}});
  CHECK(started["file"] == (dir / "takes" / "s-1_2_t-1.fcrec").string());
  CHECK(post(client, "/record/start", {{"take", "again"}}, 409)["error"] == "a take is being recorded: stop it first");
  std::this_thread::sleep_for(std::chrono::milliseconds(700));
  CHECK(get_json(client, "/status")["recording"]["active"] == true);
  const json stopped = post(client, "/record/stop", json::object());
  CHECK(stopped["marker_frames"].get<uint64_t>() > 20);
  CHECK(post(client, "/record/stop", json::object(), 409)["error"] == "no take is being recorded");
  {
    formats::RecordingReader take(stopped["file"].get<std::string>());
    CHECK_FALSE(take.truncated());
    CHECK(take.header().format_version == formats::kRecordingFormatVersion);
    CHECK(take.header().take == "t/1");
    CHECK(take.header().scene == "s 1");
    CHECK(take.header().shot == "2");
    CHECK(take.header().notes == "first");
    CHECK(take.header().rate_hz == 60.0);
    CHECK(take.solved_frame_count() == take.marker_frame_count());
    CHECK(take.marker_frame_count() == stopped["marker_frames"].get<uint64_t>());
    // Recorded frames 1/60 s apart on the source's clock.
    MarkerFrame a, b;
    take.read_marker_frame(0, a);
    take.read_marker_frame(take.marker_frame_count() - 1, b);
    CHECK(double(b.source_time_ns - a.source_time_ns) / double(b.frame_no - a.frame_no) == Approx(1e9 / 60).epsilon(0.001));
  }

  // The same slate again is refused, naming the file and the next number; without a take
  // the scene and shot's next number is used; no take shares a file or a number.
  CHECK_THAT(post(client, "/record/start", {{"take", "t/1"}, {"scene", "s 1"}, {"shot", "2"}}, 409)["error"].get<std::string>(),
             Contains("is already recorded in " + (dir / "takes" / "s-1_2_t-1.fcrec").string()));
  for (const std::string expected : {"1", "2"}) {
    const json numbered = post(client, "/record/start", {{"scene", "s 1"}, {"shot", "2"}});
    CHECK(numbered["take"] == expected);
    CHECK(numbered["file"] == (dir / "takes" / ("s-1_2_" + expected + ".fcrec")).string());
    std::this_thread::sleep_for(std::chrono::milliseconds(100));
    // As the README writes it: ctl's own options after the subcommand.
    const test::Run stop = test::run_facecap(dir, {"ctl", "--port", std::to_string(port), "--token-file", (dir / "token").string(),
                                                  "record", "stop", "--json"});
    INFO(stop.out);
    CHECK(stop.exit_code == 0);
    CHECK(json::parse(stop.out)["take"] == expected);
  }
  CHECK_THAT(post(client, "/record/start", {{"take", "2"}, {"scene", "s 1"}, {"shot", "2"}}, 409)["error"].get<std::string>(),
             Contains("give another take, or none for the next number (3)"));
  CHECK(fs::exists(dir / "takes" / "s-1_2_t-1.fcrec"));
  CHECK_FALSE(fs::exists(dir / "takes" / "s-1_2_t-1-2.fcrec"));

  // A new actor with no profile: markers only.
  post(client, "/record/start", {{"take", "newface"}, {"actor", "bob"}, {"markers_only", true}});
  std::this_thread::sleep_for(std::chrono::milliseconds(300));
  const json markers_only = post(client, "/record/stop", json::object());
  {
    formats::RecordingReader take(markers_only["file"].get<std::string>());
    CHECK(take.header().actor == "bob");
    CHECK(take.header().rig_name.empty());
    CHECK(take.header().calibration.empty());
    CHECK(take.solved_frame_count() == 0);
    CHECK(take.marker_frame_count() > 5);
  }

  // Calibration on the box, saved as a profile, then swapped for the default and back.
  const json calibrated = post(client, "/calibrate", {{"seconds", 2.0}, {"save", "alice"}});
  CHECK(calibrated["actor"] == "alice");
  CHECK(calibrated["frames"].get<uint64_t>() >= 100);
  CHECK(calibrated["residual_mm"]["median"].get<double>() < 1.0);
  // The sim's 48 face markers and 2 of its 4 headband markers are bound: the two above the
  // brow (58-62 mm off the face) are found as head markers, the two at temple height sit
  // within 10 mm of the built-in face, where a skin marker could be. H1's residual (about
  // 10 mm) stands out, and the answer warns that it moves with the head; H3 sits within
  // about 1 mm of the face, as a skin marker could. (A capture whose stillest stretch is
  // not at rest has face markers warned about too.)
  CHECK(calibrated["markers_in_source"] == 50);
  INFO(calibrated.dump(1));
  const std::vector<std::string> warnings = calibrated["warnings"];
  CHECK(std::count_if(warnings.begin(), warnings.end(), [](const std::string& w) {
          return w.starts_with("marker 'H1'") && w.find("likely on a head rig") != std::string::npos;
        }) == 1);
  CHECK(std::none_of(warnings.begin(), warnings.end(), [](const std::string& w) { return w.starts_with("marker 'H3'"); }));
  CHECK(fs::exists(dir / "profiles" / "alice.toml"));
  CHECK(calibrated["backup"].is_null());
  CHECK_THAT(post(client, "/calibrate", {{"seconds", 1.0}, {"save", "alice"}}, 409)["error"].get<std::string>(),
             Catch::StartsWith("profile \"alice\" exists") && Contains("\"replace\": true"));
  // Refreshed: the new profile in place, the old one kept beside it.
  const std::string first_profile = test::slurp(dir / "profiles" / "alice.toml");
  const json replaced = post(client, "/calibrate", {{"seconds", 1.0}, {"save", "alice"}, {"replace", true}});
  CHECK(replaced["backup"] == (dir / "profiles" / "alice.toml.bak").string());
  CHECK(test::slurp(dir / "profiles" / "alice.toml.bak") == first_profile);
  CHECK(test::slurp(dir / "profiles" / "alice.toml") != first_profile);
  const json actors = get_json(client, "/actors");
  REQUIRE(actors["actors"].size() == 1);
  CHECK(actors["actors"][0]["name"] == "alice");
  CHECK(actors["actors"][0]["usable"] == true);
  CHECK(post(client, "/actor", {{"name", "carol"}}, 404)["error"].get<std::string>().starts_with("no profile \"carol\""));
  const json swapped = post(client, "/actor", {{"name", "alice"}});
  CHECK(swapped["markers"] == 50);
  CHECK(swapped["head_stabilised"] == true);
  std::this_thread::sleep_for(std::chrono::milliseconds(600));
  status = get_json(client, "/status");
  CHECK(status["actor"] == "alice");
  CHECK(status["window"]["markers_expected"] == 50.0);
  CHECK(status["window"]["quality"] == "good");
  CHECK(status["totals"]["pipeline_swaps"] == 3);  // calibrated, replaced, selected
  INFO("missed deadlines over the run: " << status["totals"]["missed_deadlines"]);
  CHECK(status["totals"]["swap_misses"] == 0);  // no swap cost a deadline

  // The WebSocket stream at 20 frames a second, with vertices.
  {
    namespace websocket = boost::beast::websocket;
    boost::asio::io_context io;
    boost::asio::ip::tcp::socket socket(io);
    socket.connect({boost::asio::ip::make_address("127.0.0.1"), port});
    websocket::stream<boost::asio::ip::tcp::socket> ws(std::move(socket));
    ws.set_option(websocket::stream_base::decorator(
        [](websocket::request_type& r) { r.set(http::field::authorization, "Bearer s3cret"); }));
    ws.handshake("127.0.0.1", "/stream?rate=20&vertices=1");
    boost::beast::flat_buffer buffer;
    ws.read(buffer);
    const json schema = json::parse(boost::beast::buffers_to_string(buffer.data()));
    CHECK(schema["type"] == "schema");
    CHECK(schema["shapes"].size() == 45);
    CHECK(schema["markers"].size() == 52);
    CHECK(schema["vertex_count"] == 6174);
    CHECK(schema["triangles"].size() % 3 == 0);
    int frames = 0, statuses = 0;
    int64_t first_ns = 0, last_ns = 0;
    const int64_t until = monotonic_now_ns() + 1500 * kNsPerMs;
    while (monotonic_now_ns() < until) {
      buffer.clear();
      ws.read(buffer);
      const json message = json::parse(boost::beast::buffers_to_string(buffer.data()));
      if (message["type"] == "status") {
        ++statuses;
        CHECK(message["status"]["actor"] == "alice");
        continue;
      }
      REQUIRE(message["type"] == "frame");
      CHECK(message["weights"].size() == 45);
      CHECK(message["vertices"].size() == 3 * 6174);
      CHECK(message["markers"]["residual_mm"].size() == 52);
      CHECK(message["telemetry"]["markers_expected"] == 50);
      (frames == 0 ? first_ns : last_ns) = message["receive_time_ns"].get<int64_t>();
      ++frames;
    }
    ws.close(websocket::close_code::normal);
    REQUIRE(frames > 2);
    const double rate = double(frames - 1) / (double(last_ns - first_ns) / 1e9);
    INFO(frames << " frames at " << rate << " per second");
    CHECK(rate == Approx(20).epsilon(0.25));
    CHECK(statuses >= 1);
  }
  CHECK(d.stop() == 0);
}

TEST_CASE("the replay page's routes: takes listed, and a take's solved frames read back as the stream's frames") {
  const fs::path dir = test::scratch_dir("control-replay");
  test::write_text(dir / "dashboard" / "index.html", "<title>live</title>");
  test::write_text(dir / "secret.txt", "SECRET");
  RunningDaemon d({"outputs.shm.name=" + unique_shm("replay"), "control.http.enabled=true", "control.http.port=0",
                   "source.sim.rate_hz=60", "outputs.recording.directory=" + (dir / "takes").string(),
                   "control.http.dashboard_dir=" + (dir / "dashboard").string()});
  const uint16_t port = d->control_port();
  REQUIRE(port != 0);
  control::HttpClient client("127.0.0.1", port);

  // The dashboard through the real server; a ".." target as a client sends it, unnormalised.
  const control::HttpResult page = client.request("GET", "/");
  CHECK(page.status == 200);
  CHECK(page.body == "<title>live</title>");
  const std::string escaped = raw_exchange(port, "GET /../secret.txt HTTP/1.1\r\nHost: 127.0.0.1\r\nConnection: close\r\n\r\n");
  CHECK_THAT(escaped, Contains("HTTP/1.1 404") && !Contains("SECRET"));

  CHECK(get_json(client, "/recordings")["recordings"].empty());
  post(client, "/record/start", {{"take", "r1"}, {"actor", "ann"}});
  std::this_thread::sleep_for(std::chrono::milliseconds(500));
  const json stopped = post(client, "/record/stop", json::object());
  test::write_text(dir / "takes" / "junk.fcrec", "not a recording");
  const std::string name = fs::path(stopped["file"].get<std::string>()).filename().string();
  const formats::RecordingReader take(stopped["file"].get<std::string>());
  REQUIRE(take.solved_frame_count() >= 12);

  const json listed = get_json(client, "/recordings");
  CHECK(listed["directory"] == (dir / "takes").string());
  REQUIRE(listed["recordings"].size() == 2);
  const json* r1 = nullptr;
  for (const json& r : listed["recordings"]) {
    if (r["name"] == "junk.fcrec") CHECK_THAT(r["error"].get<std::string>(), Contains("junk.fcrec"));
    if (r["name"] == name) r1 = &r;
  }
  REQUIRE(r1);
  CHECK((*r1)["take"] == "r1");
  CHECK((*r1)["actor"] == "ann");
  CHECK((*r1)["rig"] == "builtin");
  CHECK((*r1)["rate_hz"] == 60.0);
  CHECK((*r1)["solved_frames"] == take.solved_frame_count());
  CHECK((*r1)["vertices"] == false);  // outputs.recording.vertices is off by default
  CHECK((*r1)["seconds"].get<double>() == Approx(double(take.solved_frame_count() - 1) / 60).margin(0.02));

  // Frames 1, 4, 7: the recorded weights, and the rig's blend of them as the mesh.
  const json read = get_json(client, fmt::format("/recordings/frames?name={}&first=1&count=3&step=3", name));
  CHECK(read["solved_frames"] == take.solved_frame_count());
  CHECK(read["vertices_from"] == "blend");
  CHECK(read["schema"]["vertex_count"] == 6174);
  CHECK(read["schema"]["triangles"].size() == 3 * std::size_t(BuiltinFace::instance().rig().triangle_count()));
  REQUIRE(read["frames"].size() == 3);
  const Rig& rig = BuiltinFace::instance().rig();
  for (std::size_t k = 0; k < 3; ++k) {
    SolvedFrame recorded;
    take.read_solved_frame(1 + 3 * k, recorded);
    const json& frame = read["frames"][k];
    CHECK(frame["type"] == "frame");
    CHECK(frame["frame_no"] == recorded.frame_no);
    REQUIRE(frame["weights"].size() == std::size_t(recorded.weights.size()));
    for (Eigen::Index i = 0; i < recorded.weights.size(); ++i) CHECK(frame["weights"][std::size_t(i)] == recorded.weights[i]);
    const Eigen::Matrix3Xd blended = rig.linear_blend(recorded.weights.cast<double>());
    REQUIRE(frame["vertices"].size() == 3 * 6174);
    for (const Eigen::Index v : {Eigen::Index(0), Eigen::Index(3000), Eigen::Index(6173)})
      for (int c = 0; c < 3; ++c)
        CHECK(frame["vertices"][std::size_t(3 * v + c)].get<double>() == Approx(blended(c, v)).margin(1e-4));
  }

  // Refusals: what is wrong, and whose fault.
  auto refused = [&](const std::string& target) {
    const control::HttpResult r = client.request("GET", target);
    INFO(target << ": " << r.body);
    return std::pair{r.status, json::parse(r.body).value("error", "")};
  };
  CHECK(refused("/recordings/frames?first=0").first == 400);
  CHECK(refused("/recordings/frames?name=../takes/" + name).first == 400);
  CHECK(refused("/recordings/frames?name=.hidden.fcrec").first == 400);
  CHECK(refused("/recordings/frames?name=" + name + "&count=61") ==
        std::pair{400, std::string("count must be a whole number from 1 to 60")});
  CHECK(refused("/recordings/frames?name=" + name + "&step=0").first == 400);
  CHECK(refused("/recordings/frames?name=" + name + "&speed=2").second ==
        "unknown query parameter \"speed\" (allowed: name, first, count, step)");
  CHECK(refused("/recordings/frames?name=nope.fcrec").first == 404);
  CHECK(refused(fmt::format("/recordings/frames?name={}&first={}", name, take.solved_frame_count())).first == 416);
  const auto junk = refused("/recordings/frames?name=junk.fcrec");
  CHECK(junk.first == 422);
  CHECK_THAT(junk.second, Contains("junk.fcrec"));
  CHECK(d.stop() == 0);
}

namespace {

// A connection that sends half a request header and then nothing (slowloris).
boost::asio::ip::tcp::socket idle_connection(boost::asio::io_context& io, uint16_t port) {
  boost::asio::ip::tcp::socket socket(io);
  socket.connect({boost::asio::ip::make_address("127.0.0.1"), port});
  boost::asio::write(socket, boost::asio::buffer(std::string_view("GET /status HTTP/1.1\r\nHost: 127.0.0.1\r\n")));
  return socket;
}

// Whether the server closed `socket` (EOF or reset) within `seconds`.
bool closed_by_server_within(boost::asio::ip::tcp::socket& socket, int seconds) {
  const timeval timeout{seconds, 0};
  ::setsockopt(socket.native_handle(), SOL_SOCKET, SO_RCVTIMEO, &timeout, sizeof timeout);
  char byte;
  const ssize_t n = ::recv(socket.native_handle(), &byte, 1, 0);
  return n == 0 || (n < 0 && errno == ECONNRESET);
}

}  // namespace

TEST_CASE("the API holds against idle connections, a WebSocket flood and a doubtful Transfer-Encoding") {
  RunningDaemon d({"outputs.shm.name=" + unique_shm("bounded"), "control.http.enabled=true", "control.http.port=0",
                   "control.http.max_stream_clients=10"});
  const uint16_t port = d->control_port();
  REQUIRE(port != 0);
  boost::asio::io_context io;

  // 64 slowloris connections, the API's whole default cap.
  std::vector<boost::asio::ip::tcp::socket> idle;
  for (int i = 0; i < 64; ++i) idle.push_back(idle_connection(io, port));

  // 30 WebSocket clients that read nothing: 10 let in, the others answered 503.
  namespace websocket = boost::beast::websocket;
  std::vector<std::unique_ptr<websocket::stream<boost::asio::ip::tcp::socket>>> streams;
  int declined = 0;
  for (int i = 0; i < 30; ++i) {
    boost::asio::ip::tcp::socket socket(io);
    socket.connect({boost::asio::ip::make_address("127.0.0.1"), port});
    auto ws = std::make_unique<websocket::stream<boost::asio::ip::tcp::socket>>(std::move(socket));
    boost::system::error_code ec;
    ws->handshake("127.0.0.1", "/stream", ec);
    if (ec == websocket::error::upgrade_declined) ++declined;
    else if (!ec) streams.push_back(std::move(ws));
    else FAIL("stream handshake: " << ec.message());
  }
  CHECK(streams.size() == 10);
  CHECK(declined == 20);

  // Every /status probe on a new connection is answered.
  int answered = 0;
  for (int i = 0; i < 20; ++i) answered += control::HttpClient("127.0.0.1", port, "", 5.0).request("GET", "/status").status == 200;
  CHECK(answered == 20);

  CHECK_THAT(raw_exchange(port, "POST /record/stop HTTP/1.1\r\nTransfer-Encoding: chunked, identity\r\n\r\n0\r\n\r\n"),
             Contains("HTTP/1.1 400") && Contains("Transfer-Encoding must be absent or exactly"));
  CHECK_THAT(raw_exchange(port, "POST /record/stop HTTP/1.1\r\nTransfer-Encoding: gzip\r\n\r\n"), Contains("HTTP/1.1 400"));

  // A new connection that sends half a header is closed after the 5 s header timeout.
  const int64_t opened_ns = monotonic_now_ns();
  boost::asio::ip::tcp::socket late = idle_connection(io, port);
  CHECK(closed_by_server_within(late, 8));
  const double closed_after_s = double(monotonic_now_ns() - opened_ns) / kNsPerSecond;
  CHECK(closed_after_s > 4.5);
  CHECK(closed_after_s < 7.0);
  CHECK(d.stop() == 0);
}

TEST_CASE("with 90% of markers missing, the capture reads bad and STATUS says why (the issue's motivating failure)", "[realtime]") {
  for (const double dropout : {0.005, 0.9}) {
    RunningDaemon d({"outputs.shm.name=" + unique_shm(fmt::format("quality{}", dropout)),
                     fmt::format("source.sim.dropout_probability={}", dropout), "control.status_interval_s=0.25"});
    std::this_thread::sleep_for(std::chrono::milliseconds(1500));
    const daemon::Figures f = d->figures_since_start();
    const std::string status = d->status_line(f);
    INFO(status);
    // The loop keeps its rate either way: its ticks and the slots it gave up fill the time.
    // (Frames a busy host's scheduler made the sim miss show as idle ticks, not as a slower loop.)
    INFO(f.ticks << " ticks, " << f.skipped_ticks << " skipped, " << f.idle_ticks << " idle in " << f.seconds << " s");
    CHECK(double(f.ticks + f.skipped_ticks) / f.seconds == Approx(120).epsilon(0.02));
    CHECK(double(f.frames_solved) >= 0.9 * double(f.ticks));
    if (dropout < 0.5) {
      CHECK(d->quality(f).state == daemon::CaptureQuality::kGood);
      CHECK_THAT(status, Contains("capture good"));
      CHECK(f.capture.markers_used > 47.0);
    } else {
      CHECK(d->quality(f).state == daemon::CaptureQuality::kBad);
      CHECK(f.capture.markers_used < 8.0);  // 4.8 of 48 expected
      CHECK(f.capture.head_held_fraction > 0.95);
      CHECK_THAT(status, Contains("capture bad: ") && Contains(" of 48 markers used (") &&
                             Contains("head pose held in 100% of frames"));
    }
    CHECK(d.stop() == 0);
  }
}

TEST_CASE("a live source 10 times off its calibration's units: /status, STATUS and the log say which units it looks like, "
          "and of a right one nothing") {
  // The sim streams the built-in face in cm. A profile of the same face whose positions are
  // stated in mm is a face 10 times smaller: the sim's values look like mm against it.
  const fs::path dir = test::scratch_dir("control-units");
  const Rig& rig = BuiltinFace::instance().rig();
  pipeline::Calibration calibration = pipeline::default_calibration(rig, 48, 4);
  REQUIRE(calibration.take_mm_per_unit == 10.0);
  calibration.take_mm_per_unit = 1.0;
  align::save_calibration_profile(dir / "mm.toml", calibration);

  std::ostringstream log;
  const auto sink = std::make_shared<spdlog::sinks::ostream_sink_mt>(log);
  spdlog::default_logger()->sinks().push_back(sink);
  for (const bool wrong : {true, false}) {
    std::vector<std::string> overrides{"outputs.shm.name=" + unique_shm(fmt::format("units{}", wrong)), "control.http.enabled=true",
                                       "control.http.port=0", "control.status_interval_s=0.25"};
    if (wrong) overrides.push_back("calibration.file=" + (dir / "mm.toml").string());
    log.str("");
    RunningDaemon d(overrides);
    control::HttpClient client("127.0.0.1", d->control_port());
    json status = get_json(client, "/status");
    CHECK(status["source"]["units"]["stated"] == "cm");
    // Decided after 2 s of frames with 3 calibrated markers, published every 100 ms.
    for (int i = 0; i < 100 && status["source"]["units"]["check"] == "checking"; ++i) {
      std::this_thread::sleep_for(std::chrono::milliseconds(100));
      status = get_json(client, "/status");
    }
    INFO(status.dump(2));
    std::this_thread::sleep_for(std::chrono::milliseconds(600));  // a STATUS window after the verdict
    status = get_json(client, "/status");
    const std::string status_line = d->status_line(d->figures_since_start());
    INFO(status_line);
    const json& units = status["source"]["units"];
    if (wrong) {
      CHECK(units["check"] == "implausible");
      CHECK(units["look_like"] == "mm");
      CHECK(units["size_ratio"].get<double>() == Approx(10.0).epsilon(0.05));
      CHECK_THAT(units["problem"].get<std::string>(),
                 Contains("read in cm as it states, its face is 10") && Contains("times the size of the calibrated one: its values look like mm"));
      CHECK(status["window"]["quality"] == "bad");
      REQUIRE(!status["window"]["quality_reasons"].empty());
      CHECK_THAT(status["window"]["quality_reasons"][0].get<std::string>(), Catch::StartsWith("source units: ") && Contains("look like mm"));
      CHECK_THAT(status_line, Contains("capture bad: source units: read in cm") && Contains("look like mm"));
    } else {
      CHECK(units["check"] == "plausible");
      CHECK(units["size_ratio"].get<double>() == Approx(1.0).epsilon(0.1));
      CHECK(units["problem"] == "");
      CHECK_THAT(status_line, !Contains("source units"));
    }
    CHECK(d.stop() == 0);
    const std::string logged = log.str();
    INFO(logged);
    std::size_t warnings = 0;
    for (std::size_t at = logged.find("source units implausible"); at != std::string::npos;
         at = logged.find("source units implausible", at + 1))
      ++warnings;
    CHECK(warnings == (wrong ? 1u : 0u));
    if (wrong) CHECK_THAT(logged, Contains("source units implausible: read in cm as it states") && Contains("look like mm"));
    else CHECK_THAT(logged, Contains("source units cm: its face is ") && Contains(" times the size of the calibrated one"));
  }
  auto& sinks = spdlog::default_logger()->sinks();
  sinks.erase(std::find(sinks.begin(), sinks.end(), sink));
}

TEST_CASE("facecapd --version and facecap --version give the version and, in a checkout, the commit") {
  const fs::path dir = test::scratch_dir("version");
  const test::Run daemon = test::run_built("daemon/facecapd", dir, {"--version"});
  const test::Run tool = test::run_facecap(dir, {"--version"});
  CHECK(daemon.exit_code == 0);
  CHECK(tool.exit_code == 0);
  CHECK_THAT(daemon.out, Catch::StartsWith("facecapd 0.1.0"));
  CHECK_THAT(tool.out, Catch::StartsWith("facecap 0.1.0"));
  int status = 0;
  test::run_and_capture(fmt::format("git -C '{}' rev-parse --git-dir > /dev/null 2>&1", FACECAP_SOURCE_DIR), &status);
  if (WEXITSTATUS(status) != 0) {
    WARN("not a git checkout: only the version is checked");
    return;
  }
  // The commit the binaries were built from (HEAD may have moved since): 12 hex digits,
  // "-dirty" with uncommitted changes, and a commit of this repository.
  for (const std::string& out : {daemon.out, tool.out}) {
    std::smatch commit;
    REQUIRE(std::regex_search(out, commit, std::regex(R"(\(git ([0-9a-f]{12})(-dirty)?\))")));
    test::run_and_capture(fmt::format("git -C '{}' cat-file -e '{}^{{commit}}' 2>&1", FACECAP_SOURCE_DIR, commit[1].str()), &status);
    CHECK(WEXITSTATUS(status) == 0);
  }
}

namespace {

// `facecap diff` of two recordings as JSON; weights to 1e-6.
json diff_weights(const fs::path& dir, const fs::path& a, const fs::path& b, int expected_exit) {
  const test::Run r = test::run_facecap(dir, {"diff", a.string(), b.string(), "--tolerance-weight", "1e-6", "--json"});
  INFO(r.err);
  REQUIRE(r.exit_code == expected_exit);
  return json::parse(r.out);
}

// A copy of a recording without its start state (STAT), as recordings were before it.
void copy_without_start_state(const fs::path& from, const fs::path& to) {
  const formats::RecordingReader reader(from);
  formats::RecordingWriter writer(to, reader.header());
  MarkerFrame markers;
  SolvedFrame solved;
  for (std::size_t i = 0; i < reader.marker_frame_count(); ++i) {
    reader.read_marker_frame(i, markers);
    reader.read_solved_frame(i, solved);
    writer.append_marker_frame(markers);
    writer.append_solved_frame(solved);
  }
  writer.close();
}

}  // namespace

TEST_CASE("a take started mid-run re-solves to itself from its first frame: the recording stores the solve's start state") {
  const fs::path dir = test::scratch_dir("control-midrun");
  test::write_text(dir / "token", "s3cret\n");
  fs::permissions(dir / "token", fs::perms::owner_read | fs::perms::owner_write);
  // facecapd's defaults: the temporal filter on, a 120 Hz source under a 120 Hz fixed-rate loop.
  RunningDaemon d({"outputs.shm.name=" + unique_shm("midrun"), "control.http.enabled=true", "control.http.port=0",
                   "control.http.token_file=" + (dir / "token").string(),
                   "outputs.recording.directory=" + (dir / "takes").string()});
  REQUIRE(d->control_port() != 0);
  control::HttpClient client("127.0.0.1", d->control_port(), "s3cret");
  // 1.5 s in, the filter, the warm start and the speed gate have state.
  std::this_thread::sleep_for(std::chrono::milliseconds(1500));
  post(client, "/record/start", {{"take", "midrun"}});
  std::this_thread::sleep_for(std::chrono::milliseconds(2000));
  const fs::path live = post(client, "/record/stop", json::object())["file"].get<std::string>();
  {
    const formats::RecordingReader take(live);
    CHECK(take.start_state().size() > 0);
    CHECK(take.start_state_damage().empty());
    REQUIRE(take.solved_frame_count() > 120);
    SolvedFrame first;
    take.read_solved_frame(0, first);
    CHECK(first.frame_no > 120);  // a frame of the running loop's, not its first
  }

  // Solved again from what it stores, from its first frame on.
  const fs::path again = dir / "again.fcrec";
  test::Run r = test::run_facecap(dir, {"solve", "--rig", "builtin", "--take", live.string(), "-o", again.string(), "-q"});
  INFO(r.out << r.err);
  REQUIRE(r.exit_code == 0);
  CHECK_THAT(r.out, Contains("from the recording's start state"));
  const json same = diff_weights(dir, live, again, 0);
  INFO(same.dump(2));
  CHECK(same["frames"]["compared"].get<std::size_t>() == formats::RecordingReader(live).solved_frame_count());
  CHECK(same["weights"]["max"].get<double>() <= 1e-6);
  CHECK(same["flags"]["frames_differ"] == 0);
  WARN("a take started mid-run, re-solved from its start state: largest weight difference " << same["weights"]["max"]);

  // A state that does not fit the solve asked for (the filter off) is named and left out.
  r = test::run_facecap(dir, {"solve", "--rig", "builtin", "--take", live.string(), "-o", (dir / "unfiltered.fcrec").string(),
                              "--set", "filter.mode=off", "-q"});
  INFO(r.out << r.err);
  REQUIRE(r.exit_code == 0);
  CHECK_THAT(r.err, Contains(live.string() + ": the pipeline state's target filter does not fit this solve: this solve has "
                             "none; solving from a cold start"));
  CHECK_THAT(r.out, Contains("from a cold start: the recording's start state does not fit this solve"));

  // Without the start state (a recording from before it), the re-solve starts cold, says
  // so, and its first frames differ: the comparison above can fail.
  const fs::path stateless = dir / "stateless.fcrec";
  copy_without_start_state(live, stateless);
  const fs::path cold = dir / "cold.fcrec";
  r = test::run_facecap(dir, {"solve", "--rig", "builtin", "--take", stateless.string(), "-o", cold.string(), "-q"});
  INFO(r.out << r.err);
  REQUIRE(r.exit_code == 0);
  CHECK_THAT(r.out, Contains("from a cold start: the recording carries no start state"));
  const json differs = diff_weights(dir, live, cold, 1);
  INFO(differs.dump(2));
  CHECK(differs["weights"]["max"].get<double>() > 1e-3);
  SolvedFrame first;
  formats::RecordingReader(live).read_solved_frame(0, first);
  // The worst frame is among the first seconds (the filter and warm start settling).
  CHECK(differs["weights"]["largest"]["frame"].get<int64_t>() - first.frame_no < 360);
  WARN("the same take re-solved from a cold start: largest weight difference " << differs["weights"]["max"] << " at frame "
       << differs["weights"]["largest"]["frame"].get<int64_t>() - first.frame_no << " of the take");
}

TEST_CASE("TLS: a certificate made on first start and kept after, trusted by curl, openssl and facecap ctl's client; "
          "login cookie Secure, WSS stream, plain HTTP told to use HTTPS", "[tls]") {
  const fs::path dir = test::scratch_dir("control-tls");
  const fs::path certificate = dir / "tls" / "facecapd.crt", key = dir / "tls" / "facecapd.key";
  test::write_text(dir / "token", "tls-operator-token\n");
  fs::permissions(dir / "token", fs::perms::owner_read | fs::perms::owner_write);
  const std::vector<std::string> settings = {
      "outputs.shm.name=" + unique_shm("tls"), "control.http.enabled=true", "control.http.port=0", "control.http.tls=true",
      "control.http.tls_certificate=" + certificate.string(), "control.http.tls_key=" + key.string(),
      "control.http.token_file=" + (dir / "token").string(), "control.http.allowed_hosts=stage-box.local"};
  auto sh = [](const std::string& command, int* status = nullptr) {
    int ignored = 0;
    return test::run_and_capture(command + " 2>&1", status ? status : &ignored);
  };
  std::string fingerprint;
  {
    std::ostringstream log;
    struct LogCapture {  // removed after the daemon below has stopped
      explicit LogCapture(std::ostringstream& out) {
        spdlog::default_logger()->sinks().push_back(std::make_shared<spdlog::sinks::ostream_sink_mt>(out));
      }
      ~LogCapture() { spdlog::default_logger()->sinks().pop_back(); }
    } capture(log);
    RunningDaemon d(settings);
    const uint16_t port = d->control_port();
    REQUIRE(port != 0);
    INFO(log.str());
    CHECK_THAT(log.str(), Contains(fmt::format("control API on https://127.0.0.1:{}", port)) && Contains("made now, self-signed"));
    // The key is the owner's only, from the moment it exists; the certificate names the box.
    CHECK((fs::status(key).permissions() & (fs::perms::group_all | fs::perms::others_all)) == fs::perms::none);
    CHECK((fs::status(certificate.parent_path()).permissions() & (fs::perms::group_all | fs::perms::others_all)) == fs::perms::none);
    const std::string text = sh(fmt::format("openssl x509 -in '{}' -noout -text", certificate.string()));
    CHECK_THAT(text, Contains("IP Address:127.0.0.1") && Contains("DNS:localhost") && Contains("DNS:stage-box.local") &&
                         Contains("ASN1 OID: prime256v1") && Contains("TLS Web Server Authentication") && Contains("CA:FALSE"));
    fingerprint = sh(fmt::format("openssl x509 -in '{}' -noout -fingerprint -sha256", certificate.string()));
    CHECK_THAT(log.str(), Contains(fingerprint.substr(fingerprint.find('=') + 1, 95)));

    // curl trusting only this certificate (which also checks that it names 127.0.0.1).
    const std::string url = fmt::format("https://127.0.0.1:{}", port);
    int status = 0;
    CHECK(sh(fmt::format("curl -sS --cacert '{}' -o /dev/null -w '%{{http_code}}' -H 'Authorization: Bearer tls-operator-token' {}/status",
                         certificate.string(), url), &status) == "200");
    CHECK(WEXITSTATUS(status) == 0);
    // Without trusting it curl refuses the connection (exit 60: certificate not trusted).
    sh(fmt::format("curl -sS -o /dev/null {}/status", url), &status);
    CHECK(WEXITSTATUS(status) == 60);
    // TLS 1.1 is refused; plain HTTP on the TLS port is told, in words, to use HTTPS.
    sh(fmt::format("openssl s_client -connect 127.0.0.1:{} -tls1_1 < /dev/null", port), &status);
    CHECK(WEXITSTATUS(status) != 0);
    CHECK_THAT(sh(fmt::format("curl -sS -i http://127.0.0.1:{}/status", port)),
               Contains("400 Bad Request") && Contains(fmt::format("speaks HTTPS only: https://127.0.0.1:{}/", port)));
    // The login's cookie is Secure over TLS.
    CHECK_THAT(sh(fmt::format("curl -sS -i --cacert '{}' -H 'Content-Type: application/json' -H 'Origin: {}' "
                              "--data '{{\"token\": \"tls-operator-token\"}}' {}/login", certificate.string(), url, url)),
               Contains("HttpOnly; SameSite=Strict; Secure"));

    // facecap ctl's client: the certificate as its trust, and another certificate refused.
    control::HttpClient client("127.0.0.1", port, "tls-operator-token", 10.0, certificate.string());
    CHECK(get_json(client, "/status").contains("loop"));
    sh(fmt::format("openssl req -x509 -newkey ec -pkeyopt ec_paramgen_curve:P-256 -nodes -subj /CN=other -days 1 "
                   "-keyout '{}' -out '{}'", (dir / "other.key").string(), (dir / "other.crt").string()));
    control::HttpClient stranger("127.0.0.1", port, "tls-operator-token", 10.0, (dir / "other.crt").string());
    CHECK_THROWS_WITH(stranger.request("GET", "/status"), Contains("TLS with https://127.0.0.1:") && Contains("certificate verify failed"));

    // The stream over WSS: the schema first, then frames.
    namespace ssl = boost::asio::ssl;
    namespace websocket = boost::beast::websocket;
    boost::asio::io_context io;
    ssl::context trust(ssl::context::tls_client);
    trust.load_verify_file(certificate.string());
    websocket::stream<boost::beast::ssl_stream<boost::asio::ip::tcp::socket>> ws(io, trust);
    boost::beast::get_lowest_layer(ws).connect({boost::asio::ip::make_address("127.0.0.1"), port});
    ws.next_layer().set_verify_mode(ssl::verify_peer);
    ws.next_layer().handshake(ssl::stream_base::client);
    ws.set_option(websocket::stream_base::decorator(
        [](websocket::request_type& r) { r.set(http::field::authorization, "Bearer tls-operator-token"); }));
    ws.handshake(fmt::format("127.0.0.1:{}", port), "/stream?rate=30");
    std::vector<std::string> types;
    for (int i = 0; i < 3; ++i) {
      boost::beast::flat_buffer buffer;
      ws.read(buffer);
      types.push_back(json::parse(boost::beast::buffers_to_string(buffer.data()))["type"]);
    }
    CHECK(types[0] == "schema");
    CHECK(std::count(types.begin(), types.end(), "frame") >= 1);
    boost::system::error_code ignored;
    ws.close(websocket::close_code::normal, ignored);
    CHECK(d.stop() == 0);
  }
  // The next start keeps the pair: the same certificate.
  {
    RunningDaemon d(settings);
    REQUIRE(d->control_port() != 0);
    CHECK(sh(fmt::format("openssl x509 -in '{}' -noout -fingerprint -sha256", certificate.string())) == fingerprint);
    CHECK(d.stop() == 0);
  }
}

TEST_CASE("TLS files that cannot be used are refused at start, naming the file and what is wrong", "[tls]") {
  const fs::path dir = test::scratch_dir("control-tls-refused");
  const control::TlsFiles files{(dir / "a.crt").string(), (dir / "a.key").string()};
  const control::TlsIdentity made = control::ensure_tls_identity(files, {"10.1.2.3", "box.lan"});
  CHECK(made.generated);
  CHECK(made.names == std::vector<std::string>{"DNS:localhost", "IP:10.1.2.3", "DNS:box.lan"});
  const control::TlsIdentity loaded = control::ensure_tls_identity(files, {"10.1.2.3"});
  CHECK_FALSE(loaded.generated);
  CHECK(loaded.sha256_fingerprint == made.sha256_fingerprint);
  CHECK(loaded.warnings.empty());
  // A name the certificate does not cover is a warning (browsers would refuse it there).
  const control::TlsIdentity moved = control::ensure_tls_identity(files, {"10.9.9.9", "box.lan"});
  REQUIRE(moved.warnings.size() == 1);
  CHECK_THAT(moved.warnings[0], Contains("does not name 10.9.9.9"));

  // One file without the other.
  const control::TlsFiles lone{(dir / "a.crt").string(), (dir / "missing.key").string()};
  CHECK_THROWS_WITH(control::ensure_tls_identity(lone, {}), Contains("missing.key") && Contains("does not exist but") &&
                                                                 Contains("a.crt"));
  // A key others may read.
  fs::permissions(files.key, fs::perms::others_read, fs::perm_options::add);
  CHECK_THROWS_WITH(control::ensure_tls_identity(files, {}), Contains("a.key") && Contains("chmod 600"));
  CHECK_THROWS_WITH(control::make_tls_server_context(files), Contains("a.key") && Contains("chmod 600"));
  fs::permissions(files.key, fs::perms::others_read, fs::perm_options::remove);
  // Not a certificate; another certificate's key.
  test::write_text(dir / "b.crt", "-----BEGIN CERTIFICATE-----\nnot base64 at all\n-----END CERTIFICATE-----\n");
  fs::copy_file(files.key, dir / "b.key");
  CHECK_THROWS_WITH(control::ensure_tls_identity({(dir / "b.crt").string(), (dir / "b.key").string()}, {}),
                    Contains("b.crt") && Contains("not a PEM certificate"));
  const control::TlsFiles other{(dir / "c.crt").string(), (dir / "c.key").string()};
  control::ensure_tls_identity(other, {});
  CHECK_THROWS_WITH(control::ensure_tls_identity({other.certificate, files.key}, {}),
                    Contains("a.key") && Contains("is not the key of the certificate") && Contains("c.crt"));

  // --check-config says the same before anything starts.
  CHECK_THROWS_WITH(config::load_config("", {"control.http.enabled=true", "control.http.tls=true",
                                             "control.http.tls_certificate=" + files.certificate,
                                             "control.http.tls_key=" + (dir / "missing.key").string()}),
                    Contains("control.http.tls_certificate") || Contains("control.http.tls_key"));
}
