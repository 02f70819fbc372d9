// facecapd's NatNet source end to end on loopback, as on a stage: `facecap natnet-serve`
// streaming real AnimFace takes (../shared/data/markers) and facecapd processes solving
// them with their `facecap calibrate` profiles, compared frame by frame with `facecap
// solve` of the same takes. Every handshake style at bitstreams 3.1 and 4.1; two actors
// on one multicast stream; an unlabelled point cloud labelled by the pipeline; a server
// that falls silent and returns, and one that restarts; the latency chain in STATUS and
// the stats file; a spoofed sender on 127.0.0.9 that changes nothing; and a real Motive
// capture replayed at its recorded timing. Skipped
// without ../shared/data; the multicast cases skip with a message where loopback
// multicast does not work.
#include <algorithm>
#include <atomic>
#include <csignal>
#include <fstream>
#include <set>
#include <sstream>
#include <thread>

#include <catch2/catch.hpp>
#include <fmt/format.h>
#include <nlohmann/json.hpp>

#include "drivers/natnet/udp_socket.hpp"
#include "formats/natnet.hpp"
#include "formats/recording.hpp"
#include "formats/take.hpp"
#include "tests/process_test_support.hpp"
#include "tools/natnet_server.hpp"

using namespace facecap;
using namespace facecap::test;
using Catch::Contains;
namespace fs = std::filesystem;

namespace {

constexpr int64_t kSecond = kNsPerSecond;

// Ports of this process's servers: apart from those of other test processes.
uint16_t stage_port(int stage) { return uint16_t(30000 + (::getpid() % 1000) * 20 + stage * 2); }

// Whether a datagram sent to a multicast group out of the loopback interface comes back to
// a socket that joined the group there (lo lacks the MULTICAST flag on some machines).
std::string loopback_multicast_problem() {
  using drivers::natnet::UdpSocket;
  try {
    const auto lo = drivers::natnet::resolve_interface("127.0.0.1");
    UdpSocket receiver(0, 0, true, "multicast probe");
    receiver.join_multicast(0xefff2a63, lo);
    UdpSocket sender(0x7f000001, 0, false, "multicast probe");
    sender.set_multicast_sender(lo, 1);
    const std::vector<char> hello{'h', 'i'};
    sender.send_to(hello, {0xefff2a63, receiver.local().port});
    std::vector<char> buffer(16);
    if (drivers::natnet::wait_readable(receiver, nullptr, 500 * kNsPerMs) && receiver.receive(buffer)) return {};
    return "a datagram sent to 239.255.42.99 out of 127.0.0.1 did not come back";
  } catch (const std::exception& e) {
    return e.what();
  }
}

#define REQUIRE_LOOPBACK_MULTICAST()                                                                  \
  if (const std::string problem = loopback_multicast_problem(); !problem.empty()) {                   \
    WARN("SKIPPED: multicast on the loopback interface does not work here (" << problem << ")");     \
    return;                                                                                          \
  }

nlohmann::json read_json(const fs::path& path) { return nlohmann::json::parse(slurp(path)); }

// A take and its profile, made by `facecap calibrate` for the built-in face.
struct Actor {
  fs::path take, profile;
};

Actor calibrated_actor(const fs::path& dir, const fs::path& take, const std::string& name) {
  Actor a{take, dir / (name + ".toml")};
  const Run calibrate = run_facecap(dir, {"calibrate", "--rig", "builtin", "--take", take.string(), "-o", a.profile.string()});
  INFO(calibrate.err);
  REQUIRE(calibrate.exit_code == 0);
  return a;
}

// facecapd's recording against the actor's take, frame by frame: frame number N is the
// take's frame (N - 1) mod its length (natnet-serve numbers from 1, looping).
//   - the markers received must be the take's (in metres, to float precision);
//   - the frames solved must be what `facecap solve` makes of the same take frames, read
//     from the take's own file (a TRC of exactly the frames facecapd solved, in order).
struct Comparison {
  std::size_t frames = 0;
  std::size_t markers_exact = 0;  // frames whose every marker is the take's
  double worst_weight = 0;        // largest |w - w_offline| over frames and shapes
};

// `offset_cm`: where the stream moved the actor's take (its markers are solved there).
Comparison compare_with_take(const fs::path& recording, const Actor& actor, const fs::path& dir, const std::string& name,
                             const Eigen::Vector3d& offset_cm = Eigen::Vector3d::Zero()) {
  const formats::MarkerTake take = formats::read_take(actor.take);
  formats::RecordingReader live(recording);
  Comparison c;
  MarkerFrame received;
  formats::MarkerTake solved = take;
  solved.frames.clear();
  for (std::size_t i = 0; i < live.marker_frame_count(); ++i) {
    live.read_marker_frame(i, received);
    const MarkerFrame& sent = take.frames[std::size_t(received.frame_no - 1) % take.frames.size()];
    bool same = received.markers.size() == sent.markers.size();
    for (std::size_t k = 0; same && k < sent.markers.size(); ++k) {
      same = received.markers[k].label.view() == take.labels[k] && sent.markers[k].present() == received.markers[k].present() &&
             (!sent.markers[k].present() ||
              (received.markers[k].position - (sent.markers[k].position + offset_cm) * 0.01).norm() < 1e-6);
    }
    c.markers_exact += same;
    MarkerFrame& moved = solved.frames.emplace_back(sent);
    moved.frame_no = received.frame_no;
    for (Marker& m : moved.markers)
      if (m.present()) m.position += offset_cm;
  }
  c.frames = live.marker_frame_count();
  const fs::path frames_file = dir / (name + "-solved-frames.trc"), offline = dir / (name + "-offline.fcrec");
  formats::write_take(frames_file, solved);
  const Run solve = run_facecap(dir, {"solve", "--rig", "builtin", "--calib", actor.profile.string(), "--take",
                                      frames_file.string(), "-o", offline.string(), "--quiet"});
  INFO(solve.err);
  REQUIRE(solve.exit_code == 0);
  formats::RecordingReader reference(offline);
  REQUIRE(reference.solved_frame_count() == live.solved_frame_count());
  SolvedFrame a, b;
  for (std::size_t i = 0; i < live.solved_frame_count(); ++i) {
    live.read_solved_frame(i, a);
    reference.read_solved_frame(i, b);
    c.worst_weight = std::max(c.worst_weight, double((a.weights - b.weights).cwiseAbs().maxCoeff()));
  }
  return c;
}

fs::path only_recording(const fs::path& dir) {
  std::vector<fs::path> files;
  for (const auto& entry : fs::directory_iterator(dir)) files.push_back(entry.path());
  REQUIRE(files.size() == 1);
  return files.front();
}

// facecapd on the NatNet source of a server on loopback, recording, with a stats file.
std::vector<std::string> facecapd_args(const fs::path& dir, uint16_t port, const std::string& name,
                                       const fs::path& profile, double seconds, std::vector<std::string> extra = {}) {
  std::vector<std::string> args = {
      "--set", "source.driver=natnet",
      "--set", "source.natnet.server_address=127.0.0.1",
      "--set", "source.natnet.local_interface=127.0.0.1",
      "--set", fmt::format("source.natnet.command_port={}", port),
      "--set", fmt::format("source.natnet.data_port={}", port + 1),
      "--set", "calibration.file=" + profile.string(),
      "--set", fmt::format("outputs.shm.name=facecap-natnet-{}-{}", ::getpid(), name),
      "--set", "outputs.recording.enabled=true",
      "--set", "outputs.recording.directory=" + (dir / (name + "-recordings")).string(),
      "--set", fmt::format("control.run_seconds={}", seconds),
      "--set", "control.status_interval_s=0.25",
      "--set", "logging.stats_file=" + (dir / (name + "-stats.json")).string(),
      "--set", "loop.rate_hz=120",
      // Compared frame by frame with facecap solve, which does not filter in time.
      "--set", "filter.mode=off"};
  args.insert(args.end(), extra.begin(), extra.end());
  return args;
}

std::vector<std::string> serve_args(const fs::path& take, uint16_t port, std::vector<std::string> extra) {
  std::vector<std::string> args = {"natnet-serve", take.string(), "--loop", "--rate", "60", "--address", "127.0.0.1",
                                   "--interface", "127.0.0.1", "--command-port", std::to_string(port), "--data-port",
                                   std::to_string(port + 1)};
  args.insert(args.end(), extra.begin(), extra.end());
  return args;
}

// The local UDP ports of `pid`'s sockets (/proc: its socket inodes, found in the
// namespace's UDP table).
std::vector<uint16_t> udp_ports_of(pid_t pid) {
  std::set<std::string> inodes;
  for (const auto& fd : fs::directory_iterator(fmt::format("/proc/{}/fd", pid))) {
    std::error_code error;
    const std::string target = fs::read_symlink(fd.path(), error).string();
    if (!error && target.starts_with("socket:[")) inodes.insert(target.substr(8, target.size() - 9));
  }
  std::vector<uint16_t> ports;
  std::istringstream table(slurp(fmt::format("/proc/{}/net/udp", pid)));
  std::string line;
  std::getline(table, line);  // the header
  while (std::getline(table, line)) {
    std::istringstream fields(line);
    std::string slot, local, remote, state, queues, timer, retransmits, uid, timeout, inode;
    fields >> slot >> local >> remote >> state >> queues >> timer >> retransmits >> uid >> timeout >> inode;
    if (inodes.count(inode)) ports.push_back(uint16_t(std::stoul(local.substr(local.find(':') + 1), nullptr, 16)));
  }
  return ports;
}

}  // namespace

TEST_CASE("facecapd solves a real take from natnet-serve in each handshake style at bitstreams 3.1 and 4.1",
          "[natnet][stage][realtime]") {
  FACECAP_REQUIRE_SHARED_DATA(animface, "markers/animface");
  const fs::path dir = scratch_dir("natnet-styles");
  const Actor jaw = calibrated_actor(dir, animface / "JawMoCap.trc", "jaw");
  const bool multicast = loopback_multicast_problem().empty();
  if (!multicast) WARN("SKIPPED multicast: " << loopback_multicast_problem());
  int stage = 0;
  for (const char* mode : {"multicast", "unicast", "unicast-data-port"}) {
    if (std::string(mode) == "multicast" && !multicast) continue;
    for (const char* bitstream : {"3.1", "4.1"}) {
      const std::string name = fmt::format("{}-{}", mode, bitstream);
      DYNAMIC_SECTION(name) {
        const uint16_t port = stage_port(stage++);
        ChildProcess serve("tools/facecap",
                           serve_args(jaw.take, port, {"--seconds", "8", "--mode", mode, "--bitstream", bitstream,
                                                       "--marker-set", "Anna", "--exposure-latency-ms", "4"}),
                           {}, dir / (name + "-serve.log"));
        REQUIRE(serve.wait_for_log("commands on", 10 * kSecond));
        NotifyRecorder notify;
        DaemonProcess d(facecapd_args(dir, port, name, jaw.profile, 2.5, {"--set", "source.natnet.marker_set=Anna"}),
                        {"NOTIFY_SOCKET=" + notify.listener.address()}, dir / (name + ".log"));
        INFO(d.log() << serve.log());
        REQUIRE(notify.wait_for("READY=1", 60 * kSecond));
        REQUIRE(notify.wait_for("exposure->receive p50", 10 * kSecond));
        CHECK(notify.wait_exit(d, 30 * kSecond) == 0);
        CHECK_THAT(d.log(), Contains(fmt::format("bitstream {}", bitstream)) &&
                                Contains(std::string(mode) == "multicast" ? "multicast 239.255.42.99" : "unicast to port"));

        const nlohmann::json stats = read_json(dir / (name + "-stats.json"));
        INFO(stats.dump(2));
        CHECK(stats["solved_fps"].get<double>() > 57.0);  // the stream's 60 Hz
        CHECK(stats["source"]["errors"] == 0);
        const auto& exposure = stats["latency_stages_ms"]["exposure_to_receive"];
        CHECK(exposure["frames"].get<uint64_t>() > 100);
        CHECK(exposure["p50"].get<double>() >= 4.0);  // natnet-serve stamps exposures 4 ms before the frame is due
        CHECK(exposure["p50"].get<double>() < 30.0);
        CHECK(stats["latency_stages_ms"]["receive_to_solved"]["frames"].get<uint64_t>() > 100);

        const Comparison c = compare_with_take(only_recording(dir / (name + "-recordings")), jaw, dir, name);
        WARN(name << ": " << c.frames << " frames received and solved; markers as in the take in " << c.markers_exact
                  << "; largest weight difference from facecap solve of those take frames " << c.worst_weight);
        CHECK(c.frames > 100);
        CHECK(c.markers_exact == c.frames);
        CHECK(c.worst_weight < 1e-4);
      }
    }
  }
}

TEST_CASE("two facecapd on one multicast stream each solve their own actor at the stream's rate", "[natnet][stage][realtime]") {
  FACECAP_REQUIRE_SHARED_DATA(animface, "markers/animface");
  REQUIRE_LOOPBACK_MULTICAST();
  const fs::path dir = scratch_dir("natnet-two-actors");
  const Actor anna = calibrated_actor(dir, animface / "JawMoCap.trc", "anna");
  const Actor ben = calibrated_actor(dir, animface / "CheeksMoCap.trc", "ben");
  // One take of both faces: Anna's markers "A:...", Ben's "B:..." 30 cm to her right.
  const formats::MarkerTake a = formats::read_take(anna.take), b = formats::read_take(ben.take);
  formats::MarkerTake stage;
  stage.format = formats::TakeFormat::kTrc;
  stage.rate_hz = 60;
  stage.units = "cm";
  for (const auto& l : a.labels) stage.labels.push_back("A:" + l);
  for (const auto& l : b.labels) stage.labels.push_back("B:" + l);
  for (std::size_t i = 0; i < std::min(a.frames.size(), b.frames.size()); ++i) {
    MarkerFrame& f = formats::append_empty_frame(stage, int64_t(i) + 1, int64_t(i) * kSecond / 60);
    for (std::size_t k = 0; k < a.labels.size(); ++k) f.markers[k] = a.frames[i].markers[k];
    for (std::size_t k = 0; k < b.labels.size(); ++k) {
      Marker& m = f.markers[a.labels.size() + k];
      m = b.frames[i].markers[k];
      m.position.x() += 30.0;
    }
    for (std::size_t k = 0; k < stage.labels.size(); ++k) f.markers[k].label.assign(stage.labels[k]);
  }
  formats::write_take(dir / "stage.trc", stage);

  const uint16_t port = stage_port(10);
  ChildProcess serve("tools/facecap",
                     serve_args(dir / "stage.trc", port, {"--seconds", "9", "--marker-set", "Anna=A:", "--marker-set", "Ben=B:"}),
                     {}, dir / "serve.log");
  REQUIRE(serve.wait_for_log("commands on", 10 * kSecond));
  DaemonProcess first(facecapd_args(dir, port, "anna", anna.profile, 3, {"--set", "source.natnet.marker_set=Anna"}), {},
                      dir / "anna.log");
  DaemonProcess second(facecapd_args(dir, port, "ben", ben.profile, 3, {"--set", "source.natnet.marker_set=Ben"}), {},
                       dir / "ben.log");
  INFO(first.log() << second.log() << serve.log());
  CHECK(first.wait_exit(60 * kSecond) == 0);
  CHECK(second.wait_exit(60 * kSecond) == 0);
  CHECK_THAT(first.log(), Contains("marker set 'Anna' (41 markers)"));
  CHECK_THAT(second.log(), Contains("marker set 'Ben' (41 markers)"));
  for (const char* name : {"anna", "ben"}) {
    const nlohmann::json stats = read_json(dir / (std::string(name) + "-stats.json"));
    INFO(name << ": " << stats.dump(2));
    CHECK(stats["solved_fps"].get<double>() > 57.0);
    CHECK(stats["solved_fps"].get<double>() < 61.0);
  }
  const Comparison anna_own = compare_with_take(only_recording(dir / "anna-recordings"), anna, dir, "anna");
  const Comparison ben_own =
      compare_with_take(only_recording(dir / "ben-recordings"), ben, dir, "ben", Eigen::Vector3d(30, 0, 0));
  const Comparison ben_as_anna = compare_with_take(only_recording(dir / "ben-recordings"), anna, dir, "ben-as-anna");
  WARN("Anna: " << anna_own.frames << " frames, markers as her take in " << anna_own.markers_exact
       << ", largest weight difference from the offline solve " << anna_own.worst_weight << "; Ben: " << ben_own.frames
       << ", " << ben_own.markers_exact << ", " << ben_own.worst_weight << "; Ben's frames against Anna's take: markers as "
       << "hers in " << ben_as_anna.markers_exact);
  CHECK(anna_own.markers_exact == anna_own.frames);
  CHECK(ben_own.markers_exact == ben_own.frames);
  CHECK(anna_own.worst_weight < 1e-4);
  CHECK(ben_own.worst_weight < 1e-4);
  CHECK(ben_as_anna.markers_exact == 0);  // the check tells the actors apart
}

TEST_CASE("facecapd labels an unlabelled point cloud from natnet-serve and solves it as the labelled take",
          "[natnet][stage][realtime]") {
  FACECAP_REQUIRE_SHARED_DATA(animface, "markers/animface");
  const fs::path dir = scratch_dir("natnet-cloud");
  const Actor jaw = calibrated_actor(dir, animface / "JawMoCap.trc", "jaw");
  const uint16_t port = stage_port(11);
  ChildProcess serve("tools/facecap", serve_args(jaw.take, port, {"--seconds", "8", "--mode", "unicast", "--unlabelled"}),
                     {}, dir / "serve.log");
  REQUIRE(serve.wait_for_log("commands on", 10 * kSecond));
  DaemonProcess d(facecapd_args(dir, port, "cloud", jaw.profile, 2.5,
                                {"--set", "source.natnet.unlabelled_markers=48"}),
                  {}, dir / "cloud.log");
  INFO(d.log() << serve.log());
  CHECK(d.wait_exit(60 * kSecond) == 0);
  CHECK_THAT(d.log(), Contains("48 unlabelled slots"));
  CHECK_THAT(d.log(), Contains("calibration.label_markers turned on"));
  // The recording holds the unlabelled points as they came; the offline solve of the
  // labelled take frames is what labelling them must give.
  const Comparison c = compare_with_take(only_recording(dir / "cloud-recordings"), jaw, dir, "cloud");
  WARN("unlabelled cloud: " << c.frames << " frames, largest weight difference from facecap solve of the labelled take "
                            << "frames " << c.worst_weight);
  CHECK(c.frames > 100);
  CHECK(c.markers_exact == 0);  // the points came unlabelled, in shuffled order
  CHECK(c.worst_weight < 1e-4);
}

TEST_CASE("a NatNet server that falls silent is reported in STATUS and followed when it returns", "[natnet][stage][realtime]") {
  FACECAP_REQUIRE_SHARED_DATA(animface, "markers/animface");
  const fs::path dir = scratch_dir("natnet-silence");
  const Actor jaw = calibrated_actor(dir, animface / "JawMoCap.trc", "jaw");
  const uint16_t port = stage_port(12);
  ChildProcess serve("tools/facecap",
                     serve_args(jaw.take, port, {"--seconds", "20", "--mode", "unicast", "--marker-set", "Anna",
                                                 "--silence-for", "2.5"}),
                     {}, dir / "serve.log");
  REQUIRE(serve.wait_for_log("commands on", 10 * kSecond));
  NotifyRecorder notify;
  DaemonProcess d(facecapd_args(dir, port, "silence", jaw.profile, 6.5, {"--set", "source.natnet.marker_set=Anna"}),
                  {"NOTIFY_SOCKET=" + notify.listener.address()}, dir / "silence.log");
  INFO(d.log() << serve.log());
  REQUIRE(notify.wait_for("READY=1", 60 * kSecond));
  notify.wait_for("no such message", kSecond);  // a second of frames, then 2.5 s of silence
  REQUIRE(::kill(serve.pid(), SIGUSR2) == 0);
  REQUIRE(notify.wait_for("no frames from 127.0.0.1 for", 10 * kSecond));
  const std::size_t silent_at = notify.index_of("no frames from 127.0.0.1 for");
  // Back: a STATUS with frames and without the complaint, after the one with it.
  bool resumed = false;
  const int64_t give_up = monotonic_now_ns() + 10 * kSecond;
  while (!resumed && monotonic_now_ns() < give_up) {
    notify.wait_for("STATUS=", 100 * kNsPerMs, notify.messages.size());
    for (std::size_t i = silent_at + 1; i < notify.messages.size(); ++i)
      resumed |= notify.messages[i].find("STATUS=") != std::string::npos &&
                 notify.messages[i].find("no frames") == std::string::npos &&
                 notify.messages[i].find("STATUS=0.0 fps") == std::string::npos;
  }
  CHECK(resumed);
  CHECK(notify.wait_exit(d, 30 * kSecond) == 0);
  CHECK_THAT(d.log(), Contains("natnet: no frames from 127.0.0.1 for 1.0 s: connecting again every second") &&
                          Contains("natnet: frames from 127.0.0.1 again after"));
  const nlohmann::json stats = read_json(dir / "silence-stats.json");
  CHECK(stats["frames_solved"].get<uint64_t>() > 60 * 3);  // 6.5 s run, 2.5 s of it silent
}

TEST_CASE("a NatNet server that restarts is followed: frame numbers from 1, the client connected again",
          "[natnet][stage][realtime]") {
  FACECAP_REQUIRE_SHARED_DATA(animface, "markers/animface");
  const fs::path dir = scratch_dir("natnet-restart");
  const Actor jaw = calibrated_actor(dir, animface / "JawMoCap.trc", "jaw");
  const uint16_t port = stage_port(13);
  // Unicast: the restarted server has forgotten its clients, so the driver must connect again.
  ChildProcess serve("tools/facecap",
                     serve_args(jaw.take, port, {"--seconds", "20", "--mode", "unicast", "--marker-set", "Anna",
                                                 "--first-frame", "5000"}),
                     {}, dir / "serve.log");
  REQUIRE(serve.wait_for_log("commands on", 10 * kSecond));
  NotifyRecorder notify;
  DaemonProcess d(facecapd_args(dir, port, "restart", jaw.profile, 5, {"--set", "source.natnet.marker_set=Anna"}),
                  {"NOTIFY_SOCKET=" + notify.listener.address()}, dir / "restart.log");
  INFO(d.log() << serve.log());
  REQUIRE(notify.wait_for("READY=1", 60 * kSecond));
  notify.wait_for("no such message", kSecond);  // a second of frames before the restart
  REQUIRE(::kill(serve.pid(), SIGUSR1) == 0);
  CHECK(notify.wait_exit(d, 60 * kSecond) == 0);
  CHECK_THAT(d.log(), Contains("natnet: 127.0.0.1 restarted (frame numbers went back from"));
  CHECK_THAT(d.log(), Contains("natnet: new model definitions from 127.0.0.1 followed"));
  formats::RecordingReader reader(only_recording(dir / "restart-recordings"));
  SolvedFrame f;
  std::size_t before = 0, after = 0;
  for (std::size_t i = 0; i < reader.solved_frame_count(); ++i) {
    reader.read_solved_frame(i, f);
    (f.frame_no >= 5000 ? before : after) += 1;
  }
  INFO(before << " frames solved before the restart, " << after << " after");
  CHECK(before > 30);
  CHECK(after > 60);
}

TEST_CASE("a real Motive capture replayed through facecapd at its recorded timing delivers every frame to the loop",
          "[natnet][stage][realtime]") {
  FACECAP_REQUIRE_SHARED_DATA(natnet, "natnet");
  const fs::path dir = scratch_dir("natnet-pcap");
  // The capture's rigid body (five markers of a quadcopter, in metres) pinned to five
  // vertices of the built-in face: a calibration for counting frames, not for a face.
  write_text(dir / "quad.toml", "version = 1\nmarker_units = \"m\"\ntranslation = [-17, -145, 73]\n"
                                "[[face]]\nlabel = \"Marker1\"\nvertex = 100\n[[face]]\nlabel = \"Marker2\"\nvertex = 900\n"
                                "[[face]]\nlabel = \"Marker3\"\nvertex = 1700\n[[face]]\nlabel = \"Marker4\"\nvertex = 2500\n"
                                "[[face]]\nlabel = \"Marker5\"\nvertex = 3300\n");
  DaemonProcess d({"--set", "source.driver=replay", "--set", "source.replay.file=" + (natnet / "traffic.pcapng").string(),
                   "--set", "source.natnet.marker_set=RaceQuad", "--set", "calibration.file=" + (dir / "quad.toml").string(),
                   "--set", "calibration.stabilise_head=false", "--set", "solver.method=linear", "--set",
                   "solver.collisions=none", "--set", "loop.rate_hz=1000", "--set",
                   fmt::format("outputs.shm.name=facecap-natnet-{}-pcap", ::getpid()), "--set",
                   "logging.stats_file=" + (dir / "stats.json").string()},
                  {}, dir / "facecapd.log");
  INFO(d.log());
  CHECK(d.wait_exit(60 * kSecond) == 0);
  CHECK_THAT(d.log(), Contains("traffic.pcapng (pcap, 5 markers, 518 frames at 120 Hz)") &&
                          Contains("stopping: the source ended"));
  const nlohmann::json stats = read_json(dir / "stats.json");
  const uint64_t solved = stats["frames_solved"], late = stats["source"]["late"];
  WARN("traffic.pcapng replayed at its recorded timing: " << solved << " frames solved, " << late
       << " passed over (late), in " << stats["seconds"].get<double>() << " s, " << stats["missed_deadlines"]
       << " missed deadlines");
  CHECK(solved + late == 518);
  CHECK(solved >= 512);  // a deadline missed by more than a frame's 3.8 to 12.8 ms passes one over
  CHECK(stats["seconds"].get<double>() >= 4.3);  // the capture's 4.309 s
}

TEST_CASE("a spoofed NatNet sender changes no solved frame: its frames and SERVERINFO are dropped unread and counted",
          "[natnet][stage][realtime]") {
  FACECAP_REQUIRE_SHARED_DATA(animface, "markers/animface");
  namespace nn = formats::natnet;
  using drivers::natnet::Endpoint;
  using drivers::natnet::UdpSocket;
  const fs::path dir = scratch_dir("natnet-spoof");
  const Actor jaw = calibrated_actor(dir, animface / "JawMoCap.trc", "jaw");
  const uint16_t port = stage_port(14);
  ChildProcess serve("tools/facecap",
                     serve_args(jaw.take, port, {"--seconds", "20", "--mode", "unicast", "--marker-set", "Anna"}), {},
                     dir / "serve.log");
  REQUIRE(serve.wait_for_log("commands on", 10 * kSecond));
  NotifyRecorder notify;
  DaemonProcess d(facecapd_args(dir, port, "spoof", jaw.profile, 4, {"--set", "source.natnet.marker_set=Anna"}),
                  {"NOTIFY_SOCKET=" + notify.listener.address()}, dir / "spoof.log");
  INFO(d.log() << serve.log());
  REQUIRE(notify.wait_for("READY=1", 60 * kSecond));

  // The attacker: another take (the cheeks) as the same marker set, each frame numbered one
  // ahead of the real stream's (read as one more unicast client of the server), sent to
  // facecapd's command socket and data port from 127.0.0.9; and once a second a SERVERINFO
  // announcing NatNet 3.1, which would make facecapd misread the real 4.1 frames.
  const Endpoint server{0x7f000001, port};
  std::vector<Endpoint> targets;
  for (const uint16_t p : udp_ports_of(d.pid())) targets.push_back({0x7f000001, p});
  REQUIRE(targets.size() >= 2);  // the command and data sockets
  tools::ServeOptions spoof_options;
  spoof_options.mode = tools::ServeMode::kMulticast;
  spoof_options.loop = true;
  spoof_options.rate_hz = 60;
  spoof_options.marker_sets = {{"Anna", ""}};
  std::optional<tools::NatNetServer> spoof;
  const formats::MarkerTake cheeks = formats::read_take(animface / "CheeksMoCap.trc");
  nn::ServerInfo spoofed_info = tools::NatNetServer(spoof_options, cheeks).server_info();
  spoofed_info.sender.natnet_version = {3, 1, 0, 0};
  const std::vector<char> info_packet = nn::encode_message({nn::MessageId::kServerInfo, spoofed_info}, nn::kBitstream31);

  UdpSocket watcher(0x7f000001, 0, false, "watcher"), attacker(0x7f000009, 0, false, "attacker");
  std::atomic<bool> stop{false};
  std::atomic<uint64_t> sent{0}, frames_spoofed{0};
  std::thread attack([&] {
    std::vector<char> buffer(nn::kHeaderBytes + nn::kMaxPayloadBytes);
    int64_t next_hello_ns = 0;
    while (!stop.load()) {
      const int64_t now = monotonic_now_ns();
      if (now >= next_hello_ns) {  // stay a client of the real server; spoof its SERVERINFO
        nn::Connect connect;
        connect.sender.natnet_version = {4, 1, 0, 0};
        watcher.send_to(nn::encode_message({nn::MessageId::kConnect, connect}, nn::kBitstream41), server);
        for (const Endpoint& to : targets) sent += attacker.send_to(info_packet, to);
        next_hello_ns = now + kSecond;
      }
      if (!drivers::natnet::wait_readable(watcher, nullptr, 20 * kNsPerMs)) continue;
      const auto got = watcher.receive(buffer);
      if (!got) continue;
      nn::Message real;
      try {
        real = nn::parse_message(std::span<const char>(buffer.data(), got->size), nn::kBitstream41, "real stream");
      } catch (const std::exception&) {
        continue;
      }
      if (real.id != nn::MessageId::kFrameOfData) continue;
      const int32_t real_number = std::get<nn::FrameOfData>(real.body).frame_number;
      if (!spoof) {
        spoof_options.first_frame = real_number + 1;
        spoof.emplace(spoof_options, cheeks);
      }
      const int64_t t = monotonic_now_ns();
      for (const tools::Outgoing& o : spoof->next_frame(t, t))
        for (const Endpoint& to : targets) sent += attacker.send_to(o.bytes, to);
      ++frames_spoofed;
    }
  });
  const int status = notify.wait_exit(d, 30 * kSecond);
  stop = true;
  attack.join();
  CHECK(status == 0);
  CHECK(frames_spoofed.load() > 120);

  const nlohmann::json stats = read_json(dir / "spoof-stats.json");
  INFO(stats.dump(2));
  const uint64_t foreign = stats["source"]["foreign"];
  WARN("spoofed sender: " << frames_spoofed.load() << " frames and " << sent.load() << " datagrams sent from 127.0.0.9, " << foreign
                          << " counted as foreign by facecapd");
  CHECK(foreign > 2 * 120);
  CHECK(foreign <= sent.load());
  CHECK(stats["source"]["errors"] == 0);
  CHECK(stats["solved_fps"].get<double>() > 50.0);  // the stream's 60 Hz (55.7 on a host at load 16)
  CHECK_THAT(d.log(), Contains("natnet: dropped a datagram from 127.0.0.9:") && Contains("which is not the server 127.0.0.1:"));
  const Comparison c = compare_with_take(only_recording(dir / "spoof-recordings"), jaw, dir, "spoof");
  WARN("with the spoofed sender: " << c.frames << " frames solved; markers as in the real take in " << c.markers_exact
                                   << "; largest weight difference from facecap solve of those frames " << c.worst_weight);
  CHECK(c.frames > 120);
  CHECK(c.markers_exact == c.frames);
  CHECK(c.worst_weight < 1e-4);
}
