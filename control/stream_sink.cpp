#include "control/stream_sink.hpp"

#include <algorithm>
#include <cmath>

#include <fmt/format.h>

namespace facecap::control {
using nlohmann::json;

StreamSink::StreamSink(StreamSchema schema, std::size_t slots)
    : schema_(std::move(schema)), queue_(slots, [&] {
        Entry prototype{make_marker_frame(schema_.marker_labels), {}};
        prototype.solved.resize(Eigen::Index(schema_.shape_names.size()), schema_.vertex_count,
                                Eigen::Index(schema_.marker_labels.size()));
        return prototype;
      }()) {}

std::string StreamSink::description() const {
  return fmt::format("control API stream (/stream), {} slots", queue_.capacity());
}

void StreamSink::offer(const MarkerFrame& markers, const SolvedFrame& solved) noexcept {
  const int64_t interval_ns = interval_ns_.load(std::memory_order_relaxed);
  if (interval_ns <= 0) return;
  offered_.fetch_add(1, std::memory_order_relaxed);
  // A little under the interval, so that a client asking for the loop's rate gets every frame.
  if (solved.receive_time_ns - last_copied_ns_ < interval_ns - interval_ns / 8) return;
  Entry* slot = queue_.begin_push();
  if (!slot) {
    dropped_.fetch_add(1, std::memory_order_relaxed);
    return;
  }
  // Sized like these frames: the copies reuse the slot's storage.
  if (slot->markers.markers.size() != markers.markers.size() || slot->solved.weights.size() != solved.weights.size() ||
      slot->solved.vertices.cols() != solved.vertices.cols() ||
      slot->solved.marker_residual_mm.size() != solved.marker_residual_mm.size()) {
    dropped_.fetch_add(1, std::memory_order_relaxed);
    return;
  }
  slot->markers = markers;
  slot->solved = solved;
  queue_.commit_push();
  last_copied_ns_ = solved.receive_time_ns;
  copied_.fetch_add(1, std::memory_order_relaxed);
}

void StreamSink::pop() noexcept {
  queue_.pop();
  delivered_.fetch_add(1, std::memory_order_relaxed);
}

void StreamSink::set_rate(double hz) noexcept {
  interval_ns_.store(hz > 0 ? int64_t(std::llround(1e9 / hz)) : 0, std::memory_order_relaxed);
}

outputs::SinkHealth StreamSink::health() const noexcept {
  outputs::SinkHealth h;
  h.offered = copied_.load(std::memory_order_relaxed) + dropped_.load(std::memory_order_relaxed);
  h.delivered = delivered_.load(std::memory_order_relaxed);
  h.dropped = dropped_.load(std::memory_order_relaxed);
  return h;
}

json schema_message(const StreamSchema& s, double rate_hz, bool vertices) {
  json message = {{"type", "schema"},          {"rate_hz", rate_hz},
                  {"rig", s.rig_name},         {"rig_units", s.rig_units},
                  {"shapes", s.shape_names},   {"markers", s.marker_labels},
                  {"vertex_count", vertices ? s.vertex_count : 0}};
  if (vertices) message["triangles"] = s.triangles;
  return message;
}

namespace {

json finite_or_null(float value) { return std::isfinite(value) ? json(value) : json(nullptr); }

}  // namespace

json frame_message(const StreamSink::Entry& entry, const StreamSchema& schema, bool vertices) {
  const SolvedFrame& f = entry.solved;
  json flags = json::array();
  for (std::size_t bit = 0; bit < kSolvedFlagCount; ++bit)
    if (f.flags & (1u << bit)) flags.push_back(solved_flag_name(bit));
  json targets = json::array(), residuals = json::array(), present = json::array();
  std::vector<float> measured;
  for (Eigen::Index k = 0; k < f.marker_residual_mm.size(); ++k) {
    const float r = f.marker_residual_mm[k];
    residuals.push_back(finite_or_null(r));
    if (std::isfinite(r)) measured.push_back(r);
    if (std::isfinite(f.marker_targets(0, k)))
      targets.push_back({f.marker_targets(0, k), f.marker_targets(1, k), f.marker_targets(2, k)});
    else
      targets.push_back(nullptr);
    present.push_back(std::size_t(k) < entry.markers.markers.size() && entry.markers.markers[std::size_t(k)].present());
  }
  float p95 = 0, max = 0;
  if (!measured.empty()) {
    const auto at = measured.begin() + std::ptrdiff_t(std::ceil(0.95 * double(measured.size())) - 1);
    std::nth_element(measured.begin(), at, measured.end());
    p95 = *at;
    max = *std::max_element(measured.begin(), measured.end());
  }
  json stage_us = json::object();
  for (std::size_t stage = 0; stage < kSolveStageCount; ++stage)
    stage_us[std::string(solve_stage_name(SolveStage(stage)))] = double(f.stage_ns[stage]) * 1e-3;
  const Timecode& tc = f.timecode;
  json message = {
      {"type", "frame"},
      {"frame_no", f.frame_no},
      {"source_time_ns", f.source_time_ns},
      {"receive_time_ns", f.receive_time_ns},
      {"timecode", tc.valid() ? json(fmt::format("{:02}:{:02}:{:02}:{:02}", tc.hours, tc.minutes, tc.seconds, tc.frames))
                              : json(nullptr)},
      {"flags", flags},
      {"head",
       {{"rotation_wxyz", {f.head_rotation.w(), f.head_rotation.x(), f.head_rotation.y(), f.head_rotation.z()}},
        {"translation", {f.head_translation.x(), f.head_translation.y(), f.head_translation.z()}}}},
      {"weights", std::vector<float>(f.weights.data(), f.weights.data() + f.weights.size())},
      {"markers", {{"present", present}, {"targets", targets}, {"residual_mm", residuals}}},
      {"telemetry",
       {{"markers_used", f.markers_used},
        {"markers_expected", f.markers_expected},
        {"head_held", (f.flags & kSolvedHeadPoseHeld) != 0},
        {"face_held", (f.flags & kSolvedTooFewMarkers) != 0},
        {"residual_p95_mm", p95},
        {"residual_max_mm", max},
        {"folded_triangles", f.folded_triangles},
        {"max_edge_stretch_mm", f.max_edge_stretch_mm}}},
      {"solve_us", double(f.solve_end_ns - f.solve_start_ns) * 1e-3},
      {"stage_us", std::move(stage_us)},
  };
  if (vertices && f.vertices.cols() == Eigen::Index(schema.vertex_count))
    message["vertices"] = std::vector<float>(f.vertices.data(), f.vertices.data() + f.vertices.size());
  return message;
}

}  // namespace facecap::control
