// The network outputs end to end over loopback, on a real I/O thread: the UDP stream into
// the client library (whole frames, schema, restarts, lost datagrams), send errors counted
// and survived, the rate limit, and our VMC and Live Link packets decoded by real peers:
// oscdump (liblo-tools), the npm `osc` package, and an independent Live Link decoder.
#include <cmath>
#include <csignal>
#include <cstring>
#include <fstream>
#include <map>
#include <thread>

#include <arpa/inet.h>
#include <fcntl.h>
#include <netinet/in.h>
#include <poll.h>
#include <spawn.h>
#include <sys/socket.h>
#include <sys/wait.h>
#include <unistd.h>

#include <catch2/catch.hpp>
#include <fmt/format.h>
#include <nlohmann/json.hpp>

#include "client/facecap_client.hpp"
#include "config/schema.hpp"
#include "core/time.hpp"
#include "daemon/io_thread.hpp"
#include "formats/arkit.hpp"
#include "outputs/udp/udp_stream_encoding.hpp"
#include "outputs/livelink/livelink_protocol.hpp"
#include "outputs/net/net_sink.hpp"
#include "outputs/udp/udp_stream_protocol.hpp"
#include "outputs/vmc/vmc_protocol.hpp"
#include "pipeline/calibration.hpp"
#include "pipeline/settings.hpp"
#include "pipeline/solve_pipeline.hpp"
#include "drivers/sim/sim_source.hpp"
#include "solver/builtin_face.hpp"

extern char** environ;

using namespace facecap;
using namespace facecap::outputs;
namespace fs = std::filesystem;

namespace {

const fs::path kPeers = fs::path(FACECAP_SOURCE_DIR) / "tests" / "peers";

// A port nobody listens on right now (bound, read, released).
uint16_t free_udp_port() {
  const int fd = socket(AF_INET, SOCK_DGRAM, 0);
  sockaddr_in a{};
  a.sin_family = AF_INET;
  a.sin_addr.s_addr = htonl(INADDR_LOOPBACK);
  bind(fd, reinterpret_cast<sockaddr*>(&a), sizeof a);
  socklen_t n = sizeof a;
  getsockname(fd, reinterpret_cast<sockaddr*>(&a), &n);
  close(fd);
  return ntohs(a.sin_port);
}

NetSinkSpec loopback(uint16_t port, Eigen::Index shapes, Eigen::Index vertices = 0) {
  NetSinkSpec spec;
  spec.destination.address = "127.0.0.1";
  spec.destination.port = port;
  spec.shape_count = shapes;
  spec.vertex_count = vertices;
  spec.periodic_interval_ns = kNsPerSecond;
  return spec;
}

SolvedFrame numbered_frame(int64_t n, Eigen::Index shapes, Eigen::Index vertices) {
  SolvedFrame f;
  f.resize(shapes, vertices);
  f.frame_no = n;
  f.source_time_ns = n * 4'166'667;
  f.receive_time_ns = monotonic_now_ns();
  f.timecode = {10, 20, 30, uint8_t(n % 30), 0.25f, 30};
  f.head_rotation = Eigen::Quaterniond(Eigen::AngleAxisd(0.01 * double(n), Eigen::Vector3d::UnitY()));
  f.head_translation = {0.5 * double(n), 1.0, -2.0};
  f.flags = uint32_t(n % 3);
  f.markers_used = uint32_t(40 + n);
  for (Eigen::Index i = 0; i < shapes; ++i) f.weights[i] = float(n) * 0.01f + float(i) * 0.001f;
  for (Eigen::Index i = 0; i < f.vertices.size(); ++i) f.vertices.data()[i] = float(n) + float(i) * 0.125f;
  return f;
}

udp_stream::StreamSchema test_schema(std::vector<std::string> names, uint32_t vertices) {
  udp_stream::StreamSchema s;
  s.rig_hash = 0xfeedface12345678ull;
  s.rig_name = "testrig";
  s.shape_names = std::move(names);
  s.arkit_names = formats::arkit_names_of(s.shape_names);
  s.vertex_count = vertices;
  s.frame_rate_hz = 240.0;
  return s;
}

// Waits for the client's first schema (FACECAP_RESTARTED).
void expect_schema(client::Subscriber& sub, facecap_frame& frame) {
  int status = FACECAP_NO_FRAME;
  const int64_t give_up = monotonic_now_ns() + 3 * kNsPerSecond;
  while (status == FACECAP_NO_FRAME && monotonic_now_ns() < give_up) status = sub.wait_next(frame, 100 * kNsPerMs);
  REQUIRE(status == FACECAP_RESTARTED);
}

// A frame solved from the sim on the built-in face: real weights for the decoders.
SolvedFrame solved_frame(int64_t n) {
  const config::DaemonConfig c = config::default_config();
  const auto rig = std::shared_ptr<const Rig>(std::shared_ptr<const Rig>(), &BuiltinFace::instance().rig());
  const pipeline::Calibration calibration = pipeline::load_calibration(pipeline::calibration_spec(c), *rig);
  drivers::SimSource sim(c.source.sim, rig, pipeline::rest_marker_set(calibration));
  sim.open();
  pipeline::SolvePipeline solve(*rig, calibration, {sim.info().labels, sim.info().units}, pipeline::solve_settings(c, pipeline::SolveContext::kLive));
  SolvedFrame solved = solve.make_solved_frame(false);
  MarkerFrame markers = make_marker_frame(sim.info().labels);
  for (int64_t i = 0; i <= n; ++i) {
    sim.render_frame(i, markers);
    solve.process(markers, solved);
  }
  solved.timecode = {1, 2, 3, 4, 0.5f, 60};
  return solved;
}

const std::vector<std::string>& builtin_shapes() { return BuiltinFace::instance().rig().shape_names; }

// A decoder peer as a child process, its standard output read line by line.
class Peer {
 public:
  explicit Peer(std::vector<std::string> args) {
    int fds[2];
    REQUIRE(pipe2(fds, O_CLOEXEC) == 0);
    posix_spawn_file_actions_t actions;
    posix_spawn_file_actions_init(&actions);
    posix_spawn_file_actions_adddup2(&actions, fds[1], 1);
    std::vector<char*> argv;
    for (auto& a : args) argv.push_back(a.data());
    argv.push_back(nullptr);
    REQUIRE(posix_spawnp(&pid_, argv[0], &actions, nullptr, argv.data(), environ) == 0);
    posix_spawn_file_actions_destroy(&actions);
    close(fds[1]);
    fd_ = fds[0];
  }
  ~Peer() {
    kill(pid_, SIGTERM);
    waitpid(pid_, nullptr, 0);
    close(fd_);
  }
  // The next whole line, or nullopt when none came within timeout_ns.
  std::optional<std::string> line(int64_t timeout_ns) {
    const int64_t give_up = monotonic_now_ns() + timeout_ns;
    for (;;) {
      if (const auto end = buffer_.find('\n'); end != std::string::npos) {
        std::string l = buffer_.substr(0, end);
        buffer_.erase(0, end + 1);
        return l;
      }
      const int64_t left = give_up - monotonic_now_ns();
      pollfd p{fd_, POLLIN, 0};
      if (left <= 0 || poll(&p, 1, int(left / kNsPerMs) + 1) <= 0) return std::nullopt;
      char chunk[4096];
      const ssize_t n = read(fd_, chunk, sizeof chunk);
      if (n <= 0) return std::nullopt;
      buffer_.append(chunk, std::size_t(n));
    }
  }

 private:
  pid_t pid_ = 0;
  int fd_ = -1;
  std::string buffer_;
};

// Offers `frame` every 20 ms until the peer prints a line that `done` accepts.
std::optional<std::string> offer_until(NetSink& sink, const SolvedFrame& frame, Peer& peer,
                                       const std::function<bool(const std::string&)>& done) {
  const MarkerFrame markers;
  const int64_t give_up = monotonic_now_ns() + 10 * kNsPerSecond;
  while (monotonic_now_ns() < give_up) {
    sink.offer(markers, frame);
    while (auto l = peer.line(20 * kNsPerMs))
      if (done(*l)) return l;
  }
  return std::nullopt;
}

bool have_program(const std::string& name) {
  return std::system(fmt::format("command -v {} >/dev/null 2>&1", name).c_str()) == 0;
}

}  // namespace

TEST_CASE("the UDP stream reaches the client library whole: schema, weights, vertices, pose, timecode, then its stop") {
  daemon::IoThread io;
  io.start();
  const uint16_t port = free_udp_port();
  client::Subscriber sub = client::Subscriber::udp(fmt::format("127.0.0.1:{}", port));
  const std::vector<std::string> names = {"jawOpen", "eyeBlink_L", "browInnerUp_L", "custom"};
  constexpr Eigen::Index kVertices = 700;  // 8.5 KB: 7 datagrams a frame
  NetSink sink(io.context(), loopback(port, 4, kVertices), std::make_unique<UdpStreamProtocol>(test_schema(names, kVertices), true));
  CHECK(sink.wants_vertices());

  facecap_frame frame{};
  expect_schema(sub, frame);
  REQUIRE(sub.shape_count() == 4);
  CHECK(sub.shape_name(0) == "jawOpen");
  CHECK(sub.arkit_name(0) == "JawOpen");
  CHECK(sub.arkit_name(1) == "EyeBlinkLeft");
  CHECK(sub.arkit_name(2).empty());
  CHECK(sub.shape_name(4).empty());
  CHECK(sub.vertex_count() == kVertices);
  CHECK(sub.rig_name() == "testrig");
  CHECK(sub.rig_hash() == 0xfeedface12345678ull);
  CHECK(sub.nominal_rate_hz() == 240.0);
  CHECK(sub.writer_pid() == 0);

  const MarkerFrame markers;
  for (int64_t n = 0; n < 30; ++n) {
    const SolvedFrame sent = numbered_frame(n, 4, kVertices);
    sink.offer(markers, sent);
    REQUIRE(sub.wait_next(frame, 2 * kNsPerSecond) == FACECAP_OK);
    CHECK(frame.frame_no == n);
    CHECK(frame.sequence == uint64_t(n + 1));
    CHECK(frame.dropped == 0);
    CHECK(frame.source_time_ns == sent.source_time_ns);
    CHECK(frame.receive_time_ns == sent.receive_time_ns);
    CHECK(frame.publish_time_ns >= sent.receive_time_ns);
    CHECK(frame.rig_hash == 0xfeedface12345678ull);
    CHECK(frame.flags == sent.flags);
    CHECK(frame.markers_used == sent.markers_used);
    CHECK(frame.timecode_hours == 10);
    CHECK(frame.timecode_frames == n % 30);
    CHECK(frame.timecode_rate_hz == 30);
    CHECK(frame.timecode_subframe == 0.25f);
    CHECK(frame.head_rotation_wxyz[0] == float(sent.head_rotation.w()));
    CHECK(frame.head_rotation_wxyz[2] == float(sent.head_rotation.y()));
    CHECK(frame.head_translation[0] == float(sent.head_translation.x()));
    REQUIRE(frame.shape_count == 4);
    REQUIRE(frame.vertex_count == kVertices);
    CHECK(std::equal(frame.weights, frame.weights + 4, sent.weights.data()));
    CHECK(std::equal(frame.vertices, frame.vertices + kVertices * 3, sent.vertices.data()));
  }
  sink.stop();
  CHECK(sub.wait_next(frame, 2 * kNsPerSecond) == FACECAP_ERR_WRITER_GONE);
  CHECK(sub.incomplete_frames() == 0);
  const SinkHealth h = sink.health();
  CHECK(h.offered == 30);
  CHECK(h.delivered == 30);
  CHECK(h.dropped == 0);
  CHECK(h.errors == 0);
  CHECK(sink.delivery_latency()->snapshot().total() == 30);
}

TEST_CASE("a UDP subscriber follows a restarted sender and its new shapes") {
  daemon::IoThread io;
  io.start();
  const uint16_t port = free_udp_port();
  client::Subscriber sub = client::Subscriber::udp(fmt::format("127.0.0.1:{}", port));
  facecap_frame frame{};
  const MarkerFrame markers;
  {
    NetSink first(io.context(), loopback(port, 2), std::make_unique<UdpStreamProtocol>(test_schema({"a", "b"}, 0), false));
    expect_schema(sub, frame);
    first.offer(markers, numbered_frame(1, 2, 0));
    REQUIRE(sub.wait_next(frame, 2 * kNsPerSecond) == FACECAP_OK);
  }
  CHECK(sub.wait_next(frame, 2 * kNsPerSecond) == FACECAP_ERR_WRITER_GONE);
  NetSink second(io.context(), loopback(port, 3), std::make_unique<UdpStreamProtocol>(test_schema({"x", "y", "z"}, 0), false));
  expect_schema(sub, frame);
  CHECK(sub.shape_count() == 3);
  CHECK(sub.shape_name(2) == "z");
  second.offer(markers, numbered_frame(5, 3, 0));
  REQUIRE(sub.wait_next(frame, 2 * kNsPerSecond) == FACECAP_OK);
  CHECK(frame.frame_no == 5);
  CHECK(frame.sequence == 1);
  CHECK(frame.dropped == 0);
}

TEST_CASE("the UDP client drops a frame that lost a datagram, counts it, and reports the gap") {
  const uint16_t port = free_udp_port();
  client::Subscriber sub = client::Subscriber::udp(fmt::format("127.0.0.1:{}", port));
  const int fd = socket(AF_INET, SOCK_DGRAM, 0);
  sockaddr_in to{};
  to.sin_family = AF_INET;
  to.sin_port = htons(port);
  to.sin_addr.s_addr = htonl(INADDR_LOOPBACK);
  auto send_all = [&](const std::vector<std::vector<char>>& grams, std::optional<std::size_t> skip = {}) {
    for (std::size_t i = 0; i < grams.size(); ++i)
      if (i != skip) sendto(fd, grams[i].data(), grams[i].size(), 0, reinterpret_cast<sockaddr*>(&to), sizeof to);
  };
  std::vector<char> message;
  const uint32_t schema_id = udp_stream::encode_schema(test_schema({"a", "b", "c"}, 400), 0, message);
  send_all(udp_stream::datagrams(udp::kSchemaMessage, 11, 1, message));
  for (int64_t n = 1; n <= 3; ++n) {
    udp_stream::encode_frame(numbered_frame(n, 3, 400), {schema_id, 1, 0}, true, message);
    const auto grams = udp_stream::datagrams(udp::kFrameMessage, 11, uint64_t(n), message);
    REQUIRE(grams.size() == 4);
    send_all(grams, n == 2 ? std::optional<std::size_t>(1) : std::nullopt);  // frame 2 loses a datagram
  }
  close(fd);
  facecap_frame frame{};
  REQUIRE(sub.read_next(frame) == FACECAP_RESTARTED);
  REQUIRE(sub.read_next(frame) == FACECAP_OK);
  CHECK(frame.frame_no == 1);
  REQUIRE(sub.read_next(frame) == FACECAP_OK);
  CHECK(frame.frame_no == 3);
  CHECK(frame.dropped == 1);
  CHECK(sub.read_next(frame) == FACECAP_NO_FRAME);
  CHECK(sub.incomplete_frames() == 1);
}

TEST_CASE("UDP client addresses are checked") {
  facecap_client* c = nullptr;
  CHECK(facecap_client_open_udp("no-port", nullptr, &c) == FACECAP_ERR_ARGUMENT);
  CHECK(facecap_client_open_udp("example.org:1", nullptr, &c) == FACECAP_ERR_ARGUMENT);  // numeric only
  CHECK(facecap_client_open_udp("127.0.0.1:1", "no-such-interface0", &c) == FACECAP_ERR_ADDRESS);
  CHECK(facecap_client_open_udp("192.0.2.1:40000", nullptr, &c) == FACECAP_ERR_ADDRESS);  // not this machine's
  CHECK(c == nullptr);
  REQUIRE(facecap_client_open_udp("[::1]:0", nullptr, &c) == FACECAP_OK);
  facecap_client_close(c);
}

TEST_CASE("sending to a closed port counts errors in the sink's health and goes on") {
  daemon::IoThread io;
  io.start();
  NetSink sink(io.context(), loopback(free_udp_port(), 45),
               std::make_unique<VmcProtocol>(arkit_vmc_shapes(builtin_shapes()), VmcRootPose{}));
  const MarkerFrame markers;
  const SolvedFrame frame = numbered_frame(1, 45, 0);
  for (int i = 0; i < 20; ++i) {
    sink.offer(markers, frame);
    sleep_until(monotonic_now_ns() + 2 * kNsPerMs);
  }
  sink.stop();
  const SinkHealth h = sink.health();
  CHECK(h.offered == 20);
  CHECK(h.delivered + h.dropped == 20);
  CHECK(h.errors >= 5);  // ECONNREFUSED from loopback, reported on every other send
  CHECK(h.dropped == h.errors);
  CHECK_FALSE(h.failed);
}

TEST_CASE("the rate limit sends every n-th frame") {
  CHECK(send_every_for(240, 60) == 4);
  CHECK(send_every_for(120, 50) == 3);
  CHECK(send_every_for(120, 0) == 1);
  CHECK(send_every_for(120, 240) == 1);
  daemon::IoThread io;
  io.start();
  const uint16_t port = free_udp_port();
  client::Subscriber sub = client::Subscriber::udp(fmt::format("127.0.0.1:{}", port));
  NetSinkSpec spec = loopback(port, 2);
  spec.send_every = 3;
  NetSink sink(io.context(), spec, std::make_unique<UdpStreamProtocol>(test_schema({"a", "b"}, 0), false));
  facecap_frame frame{};
  expect_schema(sub, frame);
  const MarkerFrame markers;
  for (int64_t n = 0; n < 9; ++n) sink.offer(markers, numbered_frame(n, 2, 0));
  for (const int64_t expected : {0, 3, 6}) {
    REQUIRE(sub.wait_next(frame, 2 * kNsPerSecond) == FACECAP_OK);
    CHECK(frame.frame_no == expected);
  }
  sink.stop();
  CHECK(sink.health().offered == 9);
  CHECK(sink.health().delivered == 3);
}

TEST_CASE("a VMC map file names the shapes it lists, and its mistakes are errors at file:line") {
  const std::vector<std::string> rig = {"jawOpen", "eyeBlink_L", "eyeBlink_R"};
  const fs::path dir = fs::temp_directory_path() / fmt::format("facecap-vmc-map-{}", ::getpid());
  fs::create_directories(dir);
  const auto write_map = [&](const std::string& text) {
    std::ofstream(dir / "map.toml", std::ios::trunc) << text;
    return dir / "map.toml";
  };
  const std::vector<VmcShape> shapes = mapped_vmc_shapes(rig, write_map("[names]\neyeBlink_R = \"Blink_R\"\njawOpen = \"A\"\n"));
  REQUIRE(shapes.size() == 2);  // eyeBlink_L is left out, so not sent
  std::map<std::string, std::vector<std::size_t>> by_name;
  for (const VmcShape& shape : shapes) by_name[shape.name] = shape.rig_shapes;
  CHECK(by_name["A"] == std::vector<std::size_t>{0});
  CHECK(by_name["Blink_R"] == std::vector<std::size_t>{2});

  const std::string file = (dir / "map.toml").string();
  CHECK_THROWS_WITH(mapped_vmc_shapes(rig, write_map("[names]\njawOpen = \"A\"\nmouthClose = \"B\"\n")),
                    Catch::Contains(file + ":3") && Catch::Contains("names.mouthClose") &&
                        Catch::Contains("the rig has no shape of that name"));
  CHECK_THROWS_WITH(mapped_vmc_shapes(rig, write_map("[names]\neyeBlink_L = \"A\"\njawOpen = \"A\"\n")),
                    Catch::Contains(file + ":3") && Catch::Contains("names.jawOpen: \"A\" is given to two shapes"));
  CHECK_THROWS_WITH(mapped_vmc_shapes(rig, write_map("jawOpen = \"A\"\n")), Catch::Contains("no [names] table"));
  // The shared TOML reader's errors: where the text stops being TOML.
  CHECK_THROWS_WITH(mapped_vmc_shapes(rig, write_map("[names]\njawOpen = \n")), Catch::Contains(file + ":2:"));
  fs::remove_all(dir);
}

TEST_CASE("oscdump (liblo) decodes our VMC bundle: every ARKit name in order, values the solved weights") {
  if (!have_program("oscdump")) {
    WARN("oscdump is not installed (Debian liblo-tools; scripts/quickstart.sh test installs it): not checked");
    return;
  }
  daemon::IoThread io;
  io.start();
  const uint16_t port = free_udp_port();
  Peer oscdump({"oscdump", "-L", std::to_string(port)});
  NetSink sink(io.context(), loopback(port, 45), std::make_unique<VmcProtocol>(arkit_vmc_shapes(builtin_shapes()), VmcRootPose{}));
  const SolvedFrame solved = solved_frame(40);
  const formats::ArkitWeights arkit(builtin_shapes());
  std::array<float, formats::kArkitShapeCount> expected{};
  arkit.map(std::span<const float>(solved.weights.data(), std::size_t(solved.weights.size())), expected);

  // oscdump prints one line per message: "<time tag> /VMC/Ext/Blend/Val sf "JawOpen" 0.123457".
  std::vector<std::pair<std::string, double>> values;
  const auto apply = offer_until(sink, solved, oscdump, [&](const std::string& line) {
    char name[64] = {};
    double value = 0;
    if (std::sscanf(line.c_str(), "%*s /VMC/Ext/Blend/Val sf \"%63[^\"]\" %lf", name, &value) == 2) values.emplace_back(name, value);
    if (line.find("/VMC/Ext/Blend/Apply") == std::string::npos) return false;
    if (values.size() == formats::kArkitShapeCount) return true;
    values.clear();  // a bundle whose start we missed
    return false;
  });
  REQUIRE(apply);
  REQUIRE(values.size() == formats::kArkitShapeCount);
  std::size_t moving = 0;
  for (std::size_t a = 0; a < formats::kArkitShapeCount; ++a) {
    INFO(formats::kArkitShapes[a].arkit);
    CHECK(values[a].first == formats::kArkitShapes[a].arkit);
    CHECK(std::abs(values[a].second - double(expected[a])) <= 5e-7);  // oscdump prints 6 decimals
    moving += expected[a] > 0.01f;
  }
  CHECK(moving >= 3);  // a real expression, not a neutral face
}

TEST_CASE("the npm osc package decodes our VMC bundle exactly: names, float32 values, the root pose") {
  if (!fs::exists(kPeers / "node_modules" / "osc")) {
    WARN("the npm osc package is not installed in tests/peers (scripts/quickstart.sh test runs npm ci): not checked");
    return;
  }
  daemon::IoThread io;
  io.start();
  const uint16_t port = free_udp_port();
  Peer node({"node", (kPeers / "vmc_decode.js").string(), std::to_string(port)});
  REQUIRE(node.line(10 * kNsPerSecond) == std::optional<std::string>("listening"));
  NetSink sink(io.context(), loopback(port, 45),
               std::make_unique<VmcProtocol>(rig_vmc_shapes(builtin_shapes()), VmcRootPose{true, 0.01}));
  SolvedFrame solved = solved_frame(60);
  solved.head_translation = {10.0, -20.0, 30.0};
  const auto line = offer_until(sink, solved, node, [](const std::string& l) { return l.starts_with("{"); });
  REQUIRE(line);
  const nlohmann::json j = nlohmann::json::parse(*line);
  CHECK(j["bundle"] == true);
  const auto& messages = j["messages"];
  const std::size_t shapes = builtin_shapes().size();
  REQUIRE(messages.size() == shapes + 2);
  for (std::size_t s = 0; s < shapes; ++s) {
    INFO(builtin_shapes()[s]);
    CHECK(messages[s]["address"] == "/VMC/Ext/Blend/Val");
    CHECK(messages[s]["args"][0]["type"] == "s");
    CHECK(messages[s]["args"][0]["value"] == builtin_shapes()[s]);
    CHECK(messages[s]["args"][1]["type"] == "f");
    CHECK(float(messages[s]["args"][1]["value"].get<double>()) == solved.weights[Eigen::Index(s)]);
  }
  CHECK(messages[shapes]["address"] == "/VMC/Ext/Blend/Apply");
  CHECK(messages[shapes]["args"].empty());
  const auto& root = messages[shapes + 1];
  CHECK(root["address"] == "/VMC/Ext/Root/Pos");
  CHECK(root["args"][0]["value"] == "root");
  const Eigen::Quaterniond& q = solved.head_rotation;
  const float pose[7] = {-0.1f, -0.2f, 0.3f, float(q.x()), float(-q.y()), float(-q.z()), float(q.w())};
  for (int i = 0; i < 7; ++i) CHECK(float(root["args"][i + 1]["value"].get<double>()) == pose[i]);
}

TEST_CASE("an independent decoder reads every field of our Live Link Face packets back") {
  if (!have_program("python3")) {
    WARN("python3 is not installed: the Live Link decoder cannot run");
    return;
  }
  daemon::IoThread io;
  io.start();
  const uint16_t port = free_udp_port();
  Peer python({"python3", (kPeers / "livelink_decode.py").string(), std::to_string(port)});
  REQUIRE(python.line(10 * kNsPerSecond) == std::optional<std::string>("listening"));
  auto protocol = std::make_unique<LiveLinkProtocol>(LiveLinkSpec{"", "actor1", builtin_shapes(), 60.0});
  const std::string device_id = protocol->device_id();
  NetSink sink(io.context(), loopback(port, 45), std::move(protocol));
  SolvedFrame solved = solved_frame(50);
  solved.head_rotation = Eigen::AngleAxisd(0.2, Eigen::Vector3d::UnitY()) * Eigen::AngleAxisd(-0.1, Eigen::Vector3d::UnitX()) *
                         Eigen::AngleAxisd(0.05, Eigen::Vector3d::UnitZ());
  const auto line = offer_until(sink, solved, python, [](const std::string& l) { return l.starts_with("{"); });
  REQUIRE(line);
  const nlohmann::json j = nlohmann::json::parse(*line);
  CHECK(j["version"] == 6);
  CHECK(j["device_id"] == device_id);
  CHECK(device_id.size() == 36);
  CHECK(device_id == device_id_for("actor1"));  // the same at every start
  CHECK(j["subject"] == "actor1");
  CHECK(j["frame_number"] == (3600 + 2 * 60 + 3) * 60 + 4);
  CHECK(j["subframe"] == 0.5);
  CHECK(j["fps_numerator"] == 60);
  CHECK(j["fps_denominator"] == 1);
  CHECK(j["count"] == 61);
  CHECK(j["left_over"] == 0);
  CHECK(j["size"] == 270 + 36 + 6);
  const formats::ArkitWeights arkit(builtin_shapes());
  const std::span<const float> weights(solved.weights.data(), std::size_t(solved.weights.size()));
  const auto& values = j["values"];
  REQUIRE(values.size() == 61);
  for (std::size_t a = 0; a < formats::kArkitShapeCount; ++a) {
    INFO(formats::kArkitShapes[a].arkit);
    CHECK(float(values[a].get<double>()) == arkit.weight(a, weights));
  }
  CHECK(float(values[52].get<double>()) == Approx(0.2f).margin(1e-6));   // HeadYaw
  CHECK(float(values[53].get<double>()) == Approx(-0.1f).margin(1e-6));  // HeadPitch
  CHECK(float(values[54].get<double>()) == Approx(0.05f).margin(1e-6));  // HeadRoll
  for (std::size_t i = 55; i < 61; ++i) CHECK(values[i] == 0.0);        // the eyes: not tracked
}
