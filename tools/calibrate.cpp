// facecap calibrate: an actor's calibration profile from one neutral frame of a take
// (paper Algorithm 1 plus stable markers for head stabilisation). See docs/alignment.md.
#include <algorithm>
#include <cmath>
#include <cstdio>
#include <filesystem>

#include <fmt/format.h>
#include <nlohmann/json.hpp>

#include "core/error.hpp"
#include "core/text_list.hpp"
#include "core/units.hpp"
#include "formats/take.hpp"
#include "solver/align/neutral.hpp"
#include "pipeline/capture_calibration.hpp"
#include "pipeline/marker_mapper.hpp"
#include "solver/align/calibrate_take.hpp"
#include "solver/align/profile.hpp"
#include "solver/align/stabilise.hpp"
#include "tools/align_support.hpp"
#include "tools/commands.hpp"

namespace facecap::tools {
namespace {

struct CalibrateOptions {
  std::string rig, take, output, markers, stable, head, units, rig_units;
  int64_t frame = 0;
  bool auto_neutral = false;
  int stable_count = 6;
  int average = 0;
  double observable_mm = align::kObservableShapeMm;
  bool json = false;
  bool force = false;
  double min_presence = align::NeutralSearchOptions{}.min_presence;
};

// Keeps only the named markers (in the take's order). Throws on an unknown name.
formats::MarkerTake select_markers(formats::MarkerTake take, const std::vector<std::string>& names, const std::string& take_name) {
  if (names.empty()) return take;
  std::vector<std::size_t> keep;
  for (const auto& n : names) {
    const auto it = std::find(take.labels.begin(), take.labels.end(), n);
    if (it == take.labels.end()) throw file_error(take_name, fmt::format("--markers names '{}', which the take does not have", n));
    keep.push_back(std::size_t(it - take.labels.begin()));
  }
  std::sort(keep.begin(), keep.end());
  keep.erase(std::unique(keep.begin(), keep.end()), keep.end());
  formats::MarkerTake out = std::move(take);
  std::vector<std::string> labels;
  for (auto k : keep) labels.push_back(out.labels[k]);
  for (auto& f : out.frames) {
    std::vector<Marker> m;
    for (auto k : keep) m.push_back(f.markers[k]);
    f.markers = std::move(m);
  }
  out.labels = std::move(labels);
  return out;
}

void run_calibrate(const CalibrateOptions& o, bool frame_given) {
  const Rig rig = load_rig(o.rig);
  const double rig_mm = rig_mm_per_unit(rig, o.rig_units);
  // --stable and --head markers stay in the take when --markers leaves them out: a stable
  // marker that is not calibrated is a head marker (head pose only, not bound).
  std::vector<std::string> kept = split_list(o.markers);
  const std::vector<std::string> stable_names = split_list(o.stable), head_names = split_list(o.head);
  std::vector<std::string> unbound = head_names;
  if (!kept.empty())
    for (const auto& n : stable_names)
      if (std::find(kept.begin(), kept.end(), n) == kept.end()) unbound.push_back(n);
  if (!kept.empty()) kept.insert(kept.end(), unbound.begin(), unbound.end());
  formats::MarkerTake take = select_markers(formats::read_take(o.take), kept, o.take);
  for (const auto& w : take.warnings) fmt::print(stderr, "facecap: warning: {}: {}\n", o.take, w);
  pipeline::check_calibration_take(take, o.take);

  std::optional<double> given_units;
  if (!o.units.empty()) {
    given_units = millimetres_per_unit(o.units);
    if (!given_units) throw Error(fmt::format("--units '{}': use mm, cm or m", o.units));
  }
  const auto file_units = millimetres_per_unit(take.units);

  align::TakeCalibrationOptions topts;
  topts.calibration.take_mm_per_unit = given_units;
  topts.calibration.rig_mm_per_unit = rig_mm;
  topts.neutral.rate_hz = take.rate_hz > 0 ? take.rate_hz : 60.0;
  topts.neutral.take_mm_per_unit = pipeline::neutral_search_mm_per_unit(take, given_units);
  topts.neutral.min_presence = o.min_presence;
  topts.average = o.average;
  topts.stable_count = o.stable_count;
  // Stable markers: named, or found (mutual distances vary least over this take, among
  // the markers the rig moves least).
  auto slot_of = [&](const std::string& option, const std::string& n) {
    const auto it = std::find(take.labels.begin(), take.labels.end(), n);
    if (it == take.labels.end()) throw file_error(o.take, fmt::format("{} names '{}', which the take does not have", option, n));
    return int(it - take.labels.begin());
  };
  for (const auto& n : stable_names) topts.stable_slots.push_back(slot_of("--stable", n));
  if (!stable_names.empty() && topts.stable_slots.size() < 3) throw Error("--stable: name at least 3 markers");
  for (const auto& n : unbound)
    if (const int slot = slot_of(std::find(head_names.begin(), head_names.end(), n) != head_names.end() ? "--head" : "--stable", n);
        std::find(topts.head_slots.begin(), topts.head_slots.end(), slot) == topts.head_slots.end())
      topts.head_slots.push_back(slot);
  if (frame_given) topts.frame = frame_index(take, o.frame, o.take);
  const align::TakeCalibration result = align::calibrate_take(rig, take.labels, take.frames, topts);
  align::Calibration cal = result.calibration;
  const bool auto_neutral = result.neutral.has_value();
  const align::NeutralFrame neutral = result.neutral.value_or(align::NeutralFrame{});
  pipeline::describe_calibration_source(cal, result, take, std::filesystem::path(o.take).filename().string());
  if (cal.units_detected && file_units && *file_units != cal.take_mm_per_unit)
    cal.notes.push_back(fmt::format("the take states '{}' but its size says '{}'; used '{}' (override with --units)", take.units,
                                    unit_name(cal.take_mm_per_unit), unit_name(cal.take_mm_per_unit)));

  // How well the stable markers hold still once the head motion is removed, over the take
  // (in the calibration's units, which came from this take's own size).
  pipeline::MarkerMapper mapper(cal, take.labels, "");
  if (!mapper.stabilising())
    throw Error(fmt::format("head stabilisation needs 3 stable markers; {} are in the take", mapper.stable_markers_found()));
  auto mapped = mapper.make_output();
  std::vector<double> stable_residuals;
  std::size_t held = 0;
  for (const auto& f : take.frames) {
    mapper.process(f, mapped);
    held += mapped.head_held;
    for (std::size_t i = 0; i < mapper.stable_residual_count(); ++i)
      if (const double r = mapper.stable_residual_mm(i); !std::isnan(r)) stable_residuals.push_back(r);
  }
  const double stable_median = pipeline::median_of(stable_residuals);

  cal.observable_shape_mm = o.observable_mm;
  align::find_unobserved_shapes(cal, rig);
  std::vector<std::string> unobserved;
  for (const auto& u : cal.unobserved_shapes)
    unobserved.push_back(u.same_as.empty() ? fmt::format("{} ({:.2f} mm)", u.name, u.max_displacement_mm)
                                           : fmt::format("{} (as {}, {:.2f} mm apart)", u.name, u.same_as, u.distinct_mm));

  if (cal.scale_at_band_limit)
    fmt::print(stderr, "facecap: warning: {}: the scale ended at the end of its search band ({:.4f}; the face would be {:.2f}x "
                       "the rig's): check the units (--units) and the markers (--markers, --head)\n",
               o.take, cal.take_to_rig.scale, cal.face_size_ratio());
  const std::vector<std::string> warnings = pipeline::residual_outliers(result, take.labels, take.frames);
  for (const auto& w : warnings) fmt::print(stderr, "facecap: warning: {}: {}\n", o.take, w);
  const std::optional<std::filesystem::path> backup = pipeline::save_profile(o.output, cal, o.force);

  std::vector<double> residuals;
  for (const auto& m : cal.markers) residuals.push_back(m.residual_mm);
  if (o.json) {
    nlohmann::json j;
    j["profile"] = o.output;
    j["rig"] = {{"name", cal.rig_name}, {"content_hash", fmt::format("{:016x}", cal.rig_hash)}};
    j["take"] = o.take;
    j["frame"] = cal.source_frame;
    j["auto_neutral"] = auto_neutral;
    if (auto_neutral) j["neutral"] = {{"distance_mm", neutral.distance_mm}, {"speed_mm_s", neutral.speed_mm_s}};
    j["units"] = unit_name(cal.take_mm_per_unit);
    j["units_detected"] = cal.units_detected;
    j["scale"] = cal.take_to_rig.scale;
    j["scale_at_band_limit"] = cal.scale_at_band_limit;
    j["face_size_ratio"] = cal.face_size_ratio();
    std::vector<std::string> heads, ignored;
    for (const auto& h : cal.head_markers) heads.push_back(h.label);
    for (int s : result.ignored_slots) ignored.push_back(take.labels[std::size_t(s)]);
    j["head_markers"] = heads;
    j["ignored_markers"] = ignored;
    j["hull_rms_mm"] = cal.hull_rms_mm;
    j["trimmed_rms_mm"] = cal.trimmed_rms_mm;
    j["residual_mm"] = {{"median", pipeline::median_of(residuals)}, {"max", *std::max_element(residuals.begin(), residuals.end())}};
    nlohmann::json per = nlohmann::json::object();
    for (const auto& m : cal.markers) per[m.label] = m.residual_mm;
    j["markers"] = per;
    j["stable_markers"] = cal.stable_markers;
    j["stable_residual_median_mm"] = stable_median;
    j["head_pose_held_frames"] = held;
    j["observable_shape_mm"] = cal.observable_shape_mm;
    nlohmann::json shapes = nlohmann::json::object();
    for (const auto& u : cal.unobserved_shapes) shapes[u.name] = u.max_displacement_mm;
    j["unobserved_shapes"] = shapes;
    nlohmann::json same = nlohmann::json::object();
    for (const auto& u : cal.unobserved_shapes)
      if (!u.same_as.empty()) same[u.name] = {{"same_as", u.same_as}, {"distinct_mm", u.distinct_mm}};
    j["indistinct_shapes"] = same;
    j["notes"] = cal.notes;
    j["warnings"] = warnings;
    j["backup"] = backup ? nlohmann::json(backup->string()) : nlohmann::json(nullptr);
    std::puts(j.dump(2).c_str());
    return;
  }
  fmt::print("calibrated {} on {} frame {}{}\n", o.take, rig.name, cal.source_frame,
             !auto_neutral ? "" : fmt::format(" (auto-neutral: {:.2f} mm from the median shape, {:.1f} mm/s)",
                                            neutral.distance_mm, neutral.speed_mm_s));
  fmt::print("units {} ({}), scale {:.4f} rig units per take unit (the face is {:.3f}x the rig's), hull ICP {:.2f} mm, "
             "surface ICP {:.2f} mm (trimmed RMS)\n",
             unit_name(cal.take_mm_per_unit), cal.units_detected ? "detected" : "given", cal.take_to_rig.scale,
             cal.face_size_ratio(), cal.hull_rms_mm, cal.trimmed_rms_mm);
  fmt::print("\n{:<24} {:>10}  {}\n", "marker", "residual", "bound to (triangle vertices, barycentric)");
  for (const auto& m : cal.markers) {
    const bool stable = std::find(cal.stable_markers.begin(), cal.stable_markers.end(), m.label) != cal.stable_markers.end();
    fmt::print("{:<24} {:>7.2f} mm  {} {} {}  ({:.2f} {:.2f} {:.2f}){}\n", m.label, m.residual_mm, m.binding.vertices[0],
               m.binding.vertices[1], m.binding.vertices[2], m.binding.barycentric[0], m.binding.barycentric[1],
               m.binding.barycentric[2], stable ? "  stable" : "");
  }
  fmt::print("\nresidual median {:.2f} mm, max {:.2f} mm over {} markers\n", pipeline::median_of(residuals),
             *std::max_element(residuals.begin(), residuals.end()), residuals.size());
  if (!cal.head_markers.empty()) {
    std::vector<std::string> heads;
    for (const auto& h : cal.head_markers) heads.push_back(h.label);
    fmt::print("head markers (head pose only, not bound): {}\n", fmt::join(heads, ", "));
  }
  fmt::print("stable markers: {}; after stabilisation their residual median is {:.3f} mm over {} frames ({} held)\n",
             fmt::join(cal.stable_markers, ", "), stable_median, take.frames.size(), held);
  if (!unobserved.empty())
    fmt::print("{} of {} shapes move no marker by {} mm at full weight, or move them within {} mm of a larger shape: the "
               "markers cannot observe them, the weight fit leaves them at 0: {}\n",
               unobserved.size(), rig.shape_count(), cal.observable_shape_mm, cal.distinct_shape_mm, fmt::join(unobserved, ", "));
  for (const auto& n : cal.notes) fmt::print("note: {}\n", n);
  fmt::print("wrote {}{}\n", o.output, backup ? fmt::format(" (the old profile kept as {})", backup->string()) : "");
}

}  // namespace

void add_calibrate_command(CLI::App& app, int& exit_code) {
  auto opts = std::make_shared<CalibrateOptions>();
  auto* cmd = app.add_subcommand("calibrate", "Calibrate an actor's markers to a rig from a neutral frame of a take");
  cmd->add_option("--rig", opts->rig, "builtin, an OBJ directory, a rig.toml manifest, a .gltf/.glb or an .fbx file")->required();
  cmd->add_option("--take", opts->take, "Marker take (.trc, .c3d, .fcrec)")->required()->check(CLI::ExistingFile);
  auto* frame = cmd->add_option("--frame", opts->frame, "Calibrate on this frame number (as numbered in the file)");
  auto* autoneutral = cmd->add_flag("--auto-neutral", opts->auto_neutral,
                                    "Find the most neutral stretch of the take (the default without --frame)");
  frame->excludes(autoneutral);
  cmd->add_option("--average", opts->average,
                  "Average this many frames around the calibration frame (default: the auto-neutral stretch, or 1 with --frame)");
  cmd->add_option("--markers", opts->markers, "Comma-separated markers to calibrate (default: all)");
  cmd->add_option("--stable", opts->stable,
                  "Comma-separated stable markers for head stabilisation (default: found); those --markers leaves out are head markers");
  cmd->add_option("--head", opts->head,
                  "Comma-separated head-rig markers: head pose only, never bound (default: found, >20 mm off the face and rigid)");
  cmd->add_option("--stable-count", opts->stable_count, "How many stable markers to find")->capture_default_str()->check(CLI::Range(3, 64));
  cmd->add_option("--observable-mm", opts->observable_mm,
                  "Shapes moving no bound marker by this many rig mm at full weight are left out of the weight fit")
      ->capture_default_str()
      ->check(CLI::NonNegativeNumber);
  cmd->add_option("--units", opts->units, "Take units mm|cm|m (default: detected from the face's size)");
  cmd->add_option("--rig-units", opts->rig_units, "Rig units mm|cm|m (default: guessed from the face's size)");
  cmd->add_option("-o,--output", opts->output, "Calibration profile to write (.toml)")->required();
  cmd->add_flag("--force", opts->force, "Replace the output profile if it exists, keeping the old one as NAME.toml.bak");
  cmd->add_option("--min-presence", opts->min_presence,
                  "Auto-neutral: each marker must be present in this fraction of the neutral stretch's frames")
      ->capture_default_str()
      ->check(CLI::Range(0.01, 1.0));
  cmd->add_flag("--json", opts->json, "Print JSON instead of text");
  cmd->callback([opts, frame, &exit_code] {
    run_calibrate(*opts, frame->count() > 0);
    exit_code = 0;
  });
}

}  // namespace facecap::tools
