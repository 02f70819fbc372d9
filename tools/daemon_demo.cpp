// facecap daemon-demo: starts facecapd on its built-in default (simulated capture of the built-in
// face, shared-memory output), waits for its READY=1 the way systemd would, subscribes
// for a few seconds printing live figures (and how close they are to the simulated
// performance), then stops it with SIGTERM.
#include <cerrno>
#include <csignal>
#include <cstring>
#include <filesystem>
#include <optional>
#include <vector>

#include <fmt/format.h>
#include <spawn.h>
#include <sys/wait.h>
#include <unistd.h>

#include "config/config_file.hpp"
#include "core/error.hpp"
#include "core/time.hpp"
#include "daemon/notify_listener.hpp"
#include "solver/builtin_face.hpp"
#include "tools/commands.hpp"
#include "tools/subscription.hpp"

extern char** environ;

namespace facecap::tools {
namespace {

namespace fs = std::filesystem;

// facecapd beside this binary (installed), in the build tree, or on PATH.
std::string find_facecapd() {
  std::error_code ec;
  const fs::path self = fs::read_symlink("/proc/self/exe", ec).parent_path();
  for (const fs::path& candidate : {self / "facecapd", self / ".." / "daemon" / "facecapd", self / ".." / "sbin" / "facecapd"})
    if (fs::exists(candidate, ec)) return candidate.lexically_normal().string();
  return "facecapd";
}

std::string value_of(const std::string& message, const std::string& key) {
  for (std::size_t at = 0; at < message.size();) {
    const std::size_t end = std::min(message.find('\n', at), message.size());
    if (message.compare(at, key.size() + 1, key + "=") == 0) return message.substr(at + key.size() + 1, end - at - key.size() - 1);
    at = end + 1;
  }
  return {};
}

struct DemoOptions {
  std::string facecapd;
  std::string config;
  std::vector<std::string> overrides;
  double seconds = 5.0;
  std::optional<double> noise_mm;
};

// How far the solved stream is from the sim's performance, when facecapd runs the sim on
// the built-in face with the built-in motion (the truth is then known from frame numbers).
class GroundTruth {
 public:
  static std::optional<GroundTruth> for_config(const config::DaemonConfig& c) {
    if (c.source.driver != drivers::DriverId::kSim || c.rig.path != "builtin" || c.source.sim.motion != "builtin") return std::nullopt;
    return GroundTruth(c.source.sim.rate_hz);
  }
  // Every 12th frame: the articulated pose costs a fraction of a millisecond.
  void observe(const facecap_frame& f) {
    if (f.frame_no % 12 != 0 || f.vertex_count == 0) return;
    const BuiltinFace& face = BuiltinFace::instance();
    const Eigen::VectorXd truth = face.motion_weights(double(f.frame_no) / rate_hz_);
    if (Eigen::Index(f.shape_count) != truth.size()) return;
    const Eigen::Map<const Eigen::VectorXf> weights(f.weights, f.shape_count);
    const Eigen::Map<const Eigen::Matrix3Xf> vertices(f.vertices, 3, f.vertex_count);
    window_weights_ += (weights.cast<double>() - truth).cwiseAbs().mean();
    window_vertices_cm_ += (vertices.cast<double>() - face.articulated_pose(truth)).colwise().norm().mean();
    ++window_count_;
  }
  std::string line_suffix() {
    if (window_count_ == 0) return {};
    const std::string text = fmt::format("  | vs truth: weights {:.3f}, vertices {:.2f} mm", window_weights_ / window_count_,
                                         10.0 * window_vertices_cm_ / window_count_);
    total_weights_ += window_weights_;
    total_vertices_cm_ += window_vertices_cm_;
    total_count_ += window_count_;
    window_weights_ = window_vertices_cm_ = 0.0;
    window_count_ = 0;
    return text;
  }
  std::string summary() const {
    if (total_count_ == 0) return "no frames compared with the truth";
    return fmt::format("mean |weight - true weight| {:.3f}, mean vertex error {:.2f} mm ({} frames compared)",
                       total_weights_ / total_count_, 10.0 * total_vertices_cm_ / total_count_, total_count_);
  }

 private:
  explicit GroundTruth(double rate_hz) : rate_hz_(rate_hz) {}
  double rate_hz_;
  double window_weights_ = 0, window_vertices_cm_ = 0, total_weights_ = 0, total_vertices_cm_ = 0;
  int window_count_ = 0, total_count_ = 0;
};

int run_demo(DemoOptions options) {
  if (options.noise_mm) options.overrides.push_back(fmt::format("source.sim.noise_mm={}", *options.noise_mm));
  // Validated here too, so that a bad option fails before anything starts.
  const config::LoadedConfig effective = config::load_config(options.config, options.overrides);
  std::optional<GroundTruth> truth = GroundTruth::for_config(effective.values);
  daemon::NotifyListener notify;
  const std::string shm_name = fmt::format("facecap-demo-{}", ::getpid());
  const std::string binary = options.facecapd.empty() ? find_facecapd() : options.facecapd;
  std::vector<std::string> args = {binary, "--set", "outputs.shm.name=" + shm_name, "--set", "logging.level=warn"};
  if (!options.config.empty()) args.insert(args.end(), {"--config", options.config});
  if (::geteuid() == 0) {  // a demo in a root shell or container: facecapd refuses root otherwise
    fmt::print("facecap daemon-demo: running facecapd as root for this demo; on a capture box run it as the facecap "
               "user (docs/daemon.md)\n");
    args.emplace_back("--allow-root");
  }
  for (const auto& o : options.overrides) args.insert(args.end(), {"--set", o});
  std::vector<char*> argv;
  for (auto& a : args) argv.push_back(a.data());
  argv.push_back(nullptr);
  std::vector<std::string> env_storage = {"NOTIFY_SOCKET=" + notify.address()};
  for (char** e = environ; *e; ++e)
    if (std::strncmp(*e, "NOTIFY_SOCKET=", 14) != 0) env_storage.emplace_back(*e);
  std::vector<char*> envp;
  for (auto& e : env_storage) envp.push_back(e.data());
  envp.push_back(nullptr);

  fmt::print("starting {} (sim source on the built-in face, shared memory {})\n", binary, shm_name);
  std::fflush(stdout);
  pid_t pid = 0;
  const int64_t launched = monotonic_now_ns();
  if (const int rc = posix_spawnp(&pid, binary.c_str(), nullptr, nullptr, argv.data(), envp.data()); rc != 0)
    throw Error(fmt::format("cannot start {}: {}", binary, std::strerror(rc)));

  auto child_exited = [&](int* status) { return ::waitpid(pid, status, WNOHANG) == pid; };
  std::string last_status;
  for (bool ready = false; !ready;) {
    int status = 0;
    if (child_exited(&status))
      throw Error(fmt::format("facecapd exited before it was ready (status {})", WIFEXITED(status) ? WEXITSTATUS(status) : -1));
    if (monotonic_now_ns() - launched > 120 * kNsPerSecond) {
      ::kill(pid, SIGKILL);
      throw Error("facecapd was not ready within 120 s");
    }
    if (auto message = notify.receive(100 * kNsPerMs)) {
      ready = message->find("READY=1") != std::string::npos;
      if (const auto s = value_of(*message, "STATUS"); !s.empty()) last_status = s;
    }
  }
  fmt::print("facecapd pid {} is READY after {:.2f} s ({}); subscribing for {:g} s:\n", pid,
             double(monotonic_now_ns() - launched) / kNsPerSecond, last_status, options.seconds);
  std::fflush(stdout);

  SubscriptionSummary summary;
  try {
    SubscriptionOptions subscription{.shm_name = shm_name, .seconds = options.seconds};
    if (truth) {
      subscription.on_frame = [&](const facecap_frame& f) { truth->observe(f); };
      subscription.line_suffix = [&] { return truth->line_suffix(); };
    }
    summary = run_subscription(subscription);
  } catch (...) {
    ::kill(pid, SIGTERM);
    ::waitpid(pid, nullptr, 0);
    throw;
  }
  while (auto message = notify.receive(0))
    if (const auto s = value_of(*message, "STATUS"); !s.empty()) last_status = s;
  fmt::print("facecapd STATUS: {}\n", last_status);

  const int64_t stop_sent = monotonic_now_ns();
  ::kill(pid, SIGTERM);
  int status = 0;
  while (!child_exited(&status)) {
    if (monotonic_now_ns() - stop_sent > 10 * kNsPerSecond) {
      ::kill(pid, SIGKILL);
      ::waitpid(pid, &status, 0);
      throw Error("facecapd did not stop within 10 s of SIGTERM");
    }
    timespec pause{0, 2'000'000};
    nanosleep(&pause, nullptr);
  }
  const bool clean = WIFEXITED(status) && WEXITSTATUS(status) == 0;
  fmt::print("SIGTERM: facecapd stopped in {:.0f} ms, {}\n", double(monotonic_now_ns() - stop_sent) / kNsPerMs,
             clean ? "exit status 0" : fmt::format("exit status {}", WIFEXITED(status) ? WEXITSTATUS(status) : -1));
  fmt::print("received {} frames in {:.1f} s ({:.1f} fps), publish->read p50 {:.3f} ms p99 {:.3f} ms, {} dropped\n",
             summary.frames, summary.seconds, summary.seconds > 0 ? double(summary.frames) / summary.seconds : 0.0,
             double(summary.latency_p50_ns) / kNsPerMs, double(summary.latency_p99_ns) / kNsPerMs, summary.dropped);
  if (truth) fmt::print("accuracy against the simulated performance: {}\n", truth->summary());
  return clean && summary.frames > 0 ? 0 : 1;
}

}  // namespace

void add_daemon_demo_command(CLI::App& app, int& exit_code) {
  auto opts = std::make_shared<DemoOptions>();
  auto* cmd = app.add_subcommand("daemon-demo", "Run facecapd on its built-in default as systemd would, watch its live output, stop it");
  cmd->add_option("--seconds", opts->seconds, "How long to watch")->capture_default_str();
  cmd->add_option("--facecapd", opts->facecapd, "The facecapd binary (default: beside facecap, or on PATH)");
  cmd->add_option("--config", opts->config, "A facecapd configuration file instead of the defaults");
  cmd->add_option("--set", opts->overrides, "Pass a key=value override to facecapd (repeatable)");
  cmd->add_option("--noise", opts->noise_mm, "Marker noise of the simulated capture, mm (source.sim.noise_mm)");
  cmd->callback([opts, &exit_code] { exit_code = run_demo(*opts); });
}

}  // namespace facecap::tools
