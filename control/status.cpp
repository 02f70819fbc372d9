#include "control/status.hpp"

#include <cmath>

#include <fmt/format.h>

namespace facecap::control {

nlohmann::json status_json(const StatusReport& r) {
  using nlohmann::json;
  json flagged = json::object();
  for (const auto& [name, count] : r.flagged_frames) flagged[name] = count;
  json outputs = json::array();
  for (const OutputReport& o : r.outputs)
    outputs.push_back({{"name", o.name}, {"description", o.description}, {"offered", o.offered},
                       {"delivered", o.delivered}, {"dropped", o.dropped}, {"errors", o.errors}, {"failed", o.failed},
                       {"offer_us", {{"p50", o.offer_p50_us}, {"p99", o.offer_p99_us}, {"max", o.offer_max_us}}}});
  // NaN (not measured) is null.
  auto number = [](double x) { return std::isfinite(x) ? json(x) : json(nullptr); };
  json markers = json::array(), missing = json::array();
  for (const MarkerReport& m : r.markers) {
    markers.push_back({{"label", m.label}, {"region", m.region}, {"present_fraction", m.present_fraction},
                       {"noise_mm", number(m.noise_mm)}, {"residual_mm", number(m.residual_mm)}, {"missing", m.missing},
                       {"rest", m.rest}});
    if (m.missing) missing.push_back(m.label);
  }
  const TakeReport& t = r.recording;
  return {
      {"version", r.version},
      {"pid", r.pid},
      {"uptime_s", r.uptime_s},
      {"busy", r.busy},
      {"source",
       {{"driver", r.source_driver}, {"description", r.source_description}, {"rate_hz", r.source_rate_hz},
        {"frames_delivered", r.source_delivered}, {"frames_overwritten", r.source_overwritten},
        {"frames_late", r.source_late}, {"errors", r.source_errors}, {"foreign", r.source_foreign}, {"finished", r.source_finished},
        {"units",
         {{"stated", r.source_units}, {"check", r.source_units_check}, {"size_ratio", r.source_size_ratio},
          {"look_like", r.source_units_look_like}, {"problem", r.source_units_problem}}}}},
      {"rig",
       {{"name", r.rig_name}, {"hash", fmt::format("{:016x}", r.rig_hash)}, {"vertices", r.rig_vertices},
        {"shapes", r.rig_shapes}}},
      {"solver", r.solver},
      {"kernels", {{"path", r.kernels}, {"cpu", r.cpu_features}}},
      {"actor", r.actor},
      {"calibration",
       {{"source", r.calibration}, {"markers", r.calibration_markers}, {"markers_in_source", r.calibration_markers_found},
        {"head_stabilised", r.head_stabilised}, {"unobserved_shapes", r.unobserved_shapes}}},
      {"loop", {{"mode", r.mode}, {"rate_hz", r.rate_hz}}},
      {"window",
       {{"seconds", r.window_s},
        {"solved_fps", r.solved_fps},
        {"latency_ms", {{"p50", r.latency_p50_ms}, {"p99", r.latency_p99_ms}, {"max", r.latency_max_ms}}},
        {"missed_deadlines", r.window_missed_deadlines},
        {"cpu_percent", r.cpu_percent},
        {"markers_used", r.markers_used},
        {"markers_expected", r.markers_expected},
        {"head_held_fraction", r.head_held_fraction},
        {"face_held_fraction", r.face_held_fraction},
        {"residual_mm", {{"p50", r.residual_p50_mm}, {"p95", r.residual_p95_mm}, {"max", r.residual_max_mm}}},
        {"quality", r.quality},
        {"quality_reasons", r.quality_reasons},
        {"markers", markers},
        {"missing_markers", missing}}},
      {"totals",
       {{"ticks", r.ticks}, {"frames_solved", r.frames_solved}, {"idle_ticks", r.idle_ticks},
        {"missed_deadlines", r.missed_deadlines}, {"late_start_misses", r.late_start_misses},
        {"skipped_ticks", r.skipped_ticks}, {"fold_deadline_stops", r.fold_deadline_stops},
        {"pipeline_swaps", r.pipeline_swaps}, {"swap_misses", r.swap_misses},
        {"reloads_accepted", r.reloads_accepted}, {"reloads_rejected", r.reloads_rejected},
        {"quality_changes", r.quality_changes}, {"flagged_frames", flagged}}},
      {"outputs", outputs},
      {"recording",
       {{"active", t.active}, {"file", t.file}, {"take", t.take}, {"actor", t.actor}, {"scene", t.scene},
        {"shot", t.shot}, {"notes", t.notes}, {"markers_only", t.markers_only}, {"seconds", t.seconds},
        {"frames_written", t.frames_written}, {"frames_dropped", t.frames_dropped}, {"failed", t.failed}}},
  };
}

namespace {

// A label value with \, " and newline escaped, as the exposition format wants.
std::string label_value(std::string_view text) {
  std::string out;
  for (const char c : text) {
    if (c == '\\' || c == '"') out += '\\';
    if (c == '\n') {
      out += "\\n";
      continue;
    }
    out += c;
  }
  return out;
}

class Exposition {
 public:
  // One metric family: HELP and TYPE, then its samples.
  Exposition& family(std::string_view name, std::string_view type, std::string_view help) {
    out_ += fmt::format("# HELP {} {}\n# TYPE {} {}\n", name, help, name, type);
    name_ = name;
    return *this;
  }
  Exposition& sample(double value, std::string_view labels = {}) {
    if (labels.empty()) out_ += fmt::format("{} {}\n", name_, value);
    else out_ += fmt::format("{}{{{}}} {}\n", name_, labels, value);
    return *this;
  }
  Exposition& gauge(std::string_view name, std::string_view help, double value) {
    return family(name, "gauge", help).sample(value);
  }
  Exposition& counter(std::string_view name, std::string_view help, double value) {
    return family(name, "counter", help).sample(value);
  }
  std::string text() && { return std::move(out_); }

 private:
  std::string out_;
  std::string_view name_;
};

}  // namespace

std::string metrics_text(const StatusReport& r) {
  Exposition e;
  e.family("facecap_info", "gauge", "facecapd's version, rig, solver and actor (always 1).")
      .sample(1, fmt::format("version=\"{}\",rig=\"{}\",solver=\"{}\",actor=\"{}\"", label_value(r.version),
                             label_value(r.rig_name), label_value(r.solver), label_value(r.actor)));
  e.gauge("facecap_uptime_seconds", "Seconds since the solve loop started.", r.uptime_s);
  e.gauge("facecap_loop_rate_hertz", "Ticks per second the solve loop is set to.", r.rate_hz);
  e.counter("facecap_ticks_total", "Solve loop ticks.", double(r.ticks));
  e.counter("facecap_frames_solved_total", "Frames solved.", double(r.frames_solved));
  e.counter("facecap_idle_ticks_total", "Ticks with no new frame from the source.", double(r.idle_ticks));
  e.counter("facecap_missed_deadlines_total", "Ticks whose work ran past the next deadline.", double(r.missed_deadlines));
  e.counter("facecap_late_start_misses_total", "Missed deadlines of ticks that started late.",
            double(r.late_start_misses));
  e.counter("facecap_skipped_ticks_total", "Ticks given up to get back on the deadline grid.", double(r.skipped_ticks));
  e.counter("facecap_fold_deadline_stops_total", "Solved frames whose fold stage stopped at the tick's deadline.",
            double(r.fold_deadline_stops));
  e.counter("facecap_pipeline_swaps_total", "Solve pipelines swapped in (reloads, actors, calibrations).",
            double(r.pipeline_swaps));
  e.counter("facecap_swap_misses_total", "Missed deadlines of the ticks that swapped in a pipeline and the tick after.",
            double(r.swap_misses));
  e.family("facecap_reloads_total", "counter", "Configuration reloads by outcome.")
      .sample(double(r.reloads_accepted), "result=\"accepted\"")
      .sample(double(r.reloads_rejected), "result=\"rejected\"");
  e.family("facecap_flagged_frames_total", "counter", "Solved frames with each status bit set.");
  for (const auto& [name, count] : r.flagged_frames) e.sample(double(count), fmt::format("flag=\"{}\"", label_value(name)));
  e.family("facecap_source_frames_total", "counter", "Source frames by what became of them.")
      .sample(double(r.source_delivered), "outcome=\"delivered\"")
      .sample(double(r.source_overwritten), "outcome=\"overwritten\"")
      .sample(double(r.source_late), "outcome=\"late\"");
  e.counter("facecap_source_errors_total", "Malformed input or device errors of the source.", double(r.source_errors));
  e.counter("facecap_source_foreign_total", "Datagrams from senders other than the source's server, dropped.",
            double(r.source_foreign));
  e.gauge("facecap_solved_frames_per_second", "Frames solved per second over the last status window.", r.solved_fps);
  e.gauge("facecap_latency_p50_seconds", "Median latency, frame received to published, over the last window.",
          r.latency_p50_ms / 1e3);
  e.gauge("facecap_latency_p99_seconds", "99th percentile latency over the last window.", r.latency_p99_ms / 1e3);
  e.gauge("facecap_latency_max_seconds", "Largest latency over the last window.", r.latency_max_ms / 1e3);
  e.gauge("facecap_window_missed_deadlines", "Missed deadlines in the last status window.",
          double(r.window_missed_deadlines));
  e.gauge("facecap_process_cpu_ratio", "CPU time of facecapd over the last window, in CPUs.", r.cpu_percent / 100.0);
  e.gauge("facecap_markers_used", "Face markers the solve used, mean per frame over the last window.", r.markers_used);
  e.gauge("facecap_markers_expected", "Face markers the calibration binds.", r.markers_expected);
  e.gauge("facecap_head_pose_held_ratio", "Fraction of the last window's frames that held the head pose.",
          r.head_held_fraction);
  e.gauge("facecap_face_held_ratio", "Fraction of the last window's frames that held the face (too few markers).",
          r.face_held_fraction);
  e.gauge("facecap_fit_residual_p50_meters", "Median marker fit residual over the last window.", r.residual_p50_mm / 1e3);
  e.gauge("facecap_fit_residual_p95_meters", "95th percentile marker fit residual over the last window.",
          r.residual_p95_mm / 1e3);
  e.gauge("facecap_fit_residual_max_meters", "Largest marker fit residual over the last window.", r.residual_max_mm / 1e3);
  e.family("facecap_capture_quality", "gauge", "The capture-quality state of the last window: 1 for the current state.");
  for (const char* state : {"good", "degraded", "bad"})
    e.sample(r.quality == state ? 1 : 0, fmt::format("state=\"{}\"", state));
  struct OutputCounter {
    const char* name;
    const char* help;
    uint64_t OutputReport::*field;
  };
  for (const OutputCounter& c :
       {OutputCounter{"facecap_output_frames_offered_total", "Frames offered to each output.", &OutputReport::offered},
        OutputCounter{"facecap_output_frames_delivered_total", "Frames each output delivered.", &OutputReport::delivered},
        OutputCounter{"facecap_output_frames_dropped_total", "Frames each output dropped.", &OutputReport::dropped},
        OutputCounter{"facecap_output_errors_total", "Destination failures of each output.", &OutputReport::errors}}) {
    e.family(c.name, "counter", c.help);
    for (const OutputReport& o : r.outputs) e.sample(double(o.*c.field), fmt::format("output=\"{}\"", label_value(o.name)));
  }
  e.family("facecap_output_offer_p99_seconds", "gauge", "99th percentile of what each output's offer costs the solve thread.");
  for (const OutputReport& o : r.outputs) e.sample(o.offer_p99_us / 1e6, fmt::format("output=\"{}\"", label_value(o.name)));
  e.gauge("facecap_recording_active", "1 while a take is being recorded.", r.recording.active ? 1 : 0);
  e.gauge("facecap_recording_frames_written", "Frames written to the current take.", double(r.recording.frames_written));
  return std::move(e).text();
}

}  // namespace facecap::control
