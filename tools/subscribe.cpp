// facecap subscribe: a renderer's view of facecapd's output, through the client library.
#include <algorithm>
#include <atomic>
#include <csignal>
#include <ctime>
#include <vector>

#include <fmt/format.h>
#include <nlohmann/json.hpp>

#include "client/facecap_client.hpp"
#include "core/error.hpp"
#include "core/time.hpp"
#include "tools/commands.hpp"
#include "tools/subscription.hpp"

namespace facecap::tools {
namespace {

std::atomic<bool> interrupted{false};

int64_t latency_percentile(std::vector<int64_t>& values, double q) {
  if (values.empty()) return 0;
  const auto k = std::size_t(q * double(values.size() - 1) + 0.5);
  std::nth_element(values.begin(), values.begin() + std::ptrdiff_t(k), values.end());
  return values[k];
}

client::Subscriber open_with_retry(const SubscriptionOptions& options) {
  if (!options.udp_address.empty()) {
    try {
      return client::Subscriber::udp(options.udp_address, options.udp_interface);
    } catch (const std::runtime_error& e) {
      throw Error(e.what());
    }
  }
  const int64_t give_up = monotonic_now_ns() + int64_t(options.open_timeout_s * kNsPerSecond);
  for (;;) {
    try {
      return client::Subscriber(options.shm_name);
    } catch (const std::runtime_error& e) {
      if (monotonic_now_ns() >= give_up) throw Error(e.what());
    }
    timespec pause{0, 50'000'000};
    nanosleep(&pause, nullptr);
  }
}

// The shapes that moved most in the last second, for a glance at the face.
std::string busiest_shapes(const client::Subscriber& sub, const std::vector<float>& weights) {
  std::vector<uint32_t> order(weights.size());
  for (uint32_t i = 0; i < order.size(); ++i) order[i] = i;
  std::partial_sort(order.begin(), order.begin() + std::min<std::ptrdiff_t>(3, std::ptrdiff_t(order.size())),
                    order.end(), [&](uint32_t a, uint32_t b) { return weights[a] > weights[b]; });
  std::string text;
  for (std::size_t i = 0; i < std::min<std::size_t>(3, order.size()); ++i)
    text += fmt::format("  {} {:.2f}", sub.shape_name(order[i]), weights[order[i]]);
  return text;
}

}  // namespace

SubscriptionSummary run_subscription(const SubscriptionOptions& options) {
  client::Subscriber sub = open_with_retry(options);
  const bool udp = !options.udp_address.empty();
  auto describe_writer = [&] {
    if (options.json) return;
    if (udp)
      fmt::print("udp {}: rig {}, {} shapes, {} vertices, {:g} Hz\n", options.udp_address, sub.rig_name(), sub.shape_count(),
                 sub.vertex_count(), sub.nominal_rate_hz());
    else
      fmt::print("shm {}: rig {}, {} shapes, {} vertices, writer pid {}, {:g} Hz\n", options.shm_name, sub.rig_name(),
                 sub.shape_count(), sub.vertex_count(), sub.writer_pid(), sub.nominal_rate_hz());
  };
  if (!udp) describe_writer();  // over UDP the shapes come with the first schema
  SubscriptionSummary summary;
  std::vector<int64_t> window_latency, all_latency;
  std::vector<float> last_weights;
  uint64_t window_frames = 0, window_dropped = 0;
  const int64_t start = monotonic_now_ns();
  int64_t window_start = start;
  facecap_frame frame{};
  bool stalled = false;  // said once per stall
  for (;;) {
    const int status = sub.wait_next(frame, 50 * kNsPerMs);
    const int64_t now = monotonic_now_ns();
    if (status == FACECAP_WRITER_STALLED && !stalled && !options.json)
      fmt::print("writer pid {} stalled: alive but not beating (stopped or hung)\n", sub.writer_pid());
    stalled = status == FACECAP_WRITER_STALLED || (stalled && status == FACECAP_NO_FRAME);
    if (status == FACECAP_OK) {
      const int64_t latency = now - frame.publish_time_ns;
      window_latency.push_back(latency);
      all_latency.push_back(latency);
      ++window_frames;
      window_dropped += frame.dropped;
      summary.dropped += frame.dropped;
      ++summary.frames;
      last_weights.assign(frame.weights, frame.weights + frame.shape_count);
      if (options.on_frame) options.on_frame(frame);
    } else if (status == FACECAP_RESTARTED) {
      describe_writer();
    } else if (status == FACECAP_ERR_WRITER_GONE) {
      if (!options.json) fmt::print("writer stopped\n");
      break;
    } else if (status != FACECAP_NO_FRAME && status != FACECAP_WRITER_STALLED) {
      throw Error(fmt::format("reading {}: {}", udp ? options.udp_address : options.shm_name, facecap_status_string(status)));
    }
    if (now - window_start >= kNsPerSecond) {
      const double seconds = double(now - window_start) / kNsPerSecond;
      const double fps = double(window_frames) / seconds;
      const double p50 = double(latency_percentile(window_latency, 0.5)) / kNsPerMs;
      const double p99 = double(latency_percentile(window_latency, 0.99)) / kNsPerMs;
      if (options.json) {
        nlohmann::json j = {{"t", double(now - start) / kNsPerSecond}, {"fps", fps}, {"latency_p50_ms", p50},
                            {"latency_p99_ms", p99}, {"dropped", window_dropped}, {"frame_no", frame.frame_no},
                            {"incomplete", sub.incomplete_frames()}};
        fmt::print("{}\n", j.dump());
      } else {
        fmt::print("{:5.1f} s  {:6.1f} fps  publish->read p50 {:.3f} ms p99 {:.3f} ms  dropped {}  frame {}{}{}\n",
                   double(now - start) / kNsPerSecond, fps, p50, p99, window_dropped, frame.frame_no,
                   busiest_shapes(sub, last_weights), options.line_suffix ? options.line_suffix() : std::string());
      }
      std::fflush(stdout);
      window_latency.clear();
      window_frames = window_dropped = 0;
      window_start = now;
    }
    if (interrupted.load() || (options.seconds > 0 && now - start >= int64_t(options.seconds * kNsPerSecond))) break;
  }
  summary.seconds = double(monotonic_now_ns() - start) / kNsPerSecond;
  summary.latency_p50_ns = latency_percentile(all_latency, 0.5);
  summary.latency_p99_ns = latency_percentile(all_latency, 0.99);
  summary.incomplete = sub.incomplete_frames();
  return summary;
}

void add_subscribe_command(CLI::App& app, int& exit_code) {
  auto opts = std::make_shared<SubscriptionOptions>();
  auto* cmd = app.add_subcommand("subscribe", "Read facecapd's shared memory or UDP stream and print frame rate, latency and drops");
  auto* shm = cmd->add_option("--shm", opts->shm_name, "Shared-memory name (outputs.shm.name)");
  auto* udp = cmd->add_option("--udp", opts->udp_address,
                              "Receive the UDP stream on ADDRESS:PORT (outputs.udp: 127.0.0.1:39540, 0.0.0.0:PORT, or a "
                              "multicast group)");
  shm->excludes(udp);
  cmd->add_option("--interface", opts->udp_interface, "With --udp and a multicast group: the interface to join it on")->needs(udp);
  cmd->add_option("--seconds", opts->seconds, "Stop after this long (0: until the writer stops or Ctrl-C)");
  cmd->add_option("--open-timeout", opts->open_timeout_s, "Seconds to keep trying to open while facecapd starts");
  cmd->add_flag("--json", opts->json, "One JSON object per second");
  cmd->callback([opts, &exit_code] {
    if (opts->shm_name.empty() && opts->udp_address.empty()) throw CLI::RequiredError("--shm or --udp");
    std::signal(SIGINT, [](int) { interrupted.store(true); });
    const SubscriptionSummary s = run_subscription(*opts);
    if (!opts->json)
      fmt::print("{} frames in {:.1f} s ({:.1f} fps), publish->read p50 {:.3f} ms p99 {:.3f} ms, {} dropped{}\n", s.frames,
                 s.seconds, s.seconds > 0 ? double(s.frames) / s.seconds : 0.0, double(s.latency_p50_ns) / kNsPerMs,
                 double(s.latency_p99_ns) / kNsPerMs, s.dropped,
                 opts->udp_address.empty() ? "" : fmt::format(", {} incomplete", s.incomplete));
    exit_code = s.frames > 0 ? 0 : 1;
  });
}

}  // namespace facecap::tools
