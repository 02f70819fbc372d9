// The one solve path on a real take: JawMoCap from AnimFace (41 markers, cm, 60 Hz) with the
// ICT FaceKit face, calibrated as `facecap calibrate --auto-neutral` does
// (pipeline::calibrate_capture). Units and labelling that recovers. Skipped with a
// message when ../shared/data is absent.
#include <algorithm>

#include <catch2/catch.hpp>
#include <fmt/format.h>

#include "formats/take.hpp"
#include "pipeline/calibration.hpp"
#include "pipeline/capture_calibration.hpp"
#include "pipeline/solve_pipeline.hpp"
#include "pipeline/source_units.hpp"
#include "solver/rig.hpp"
#include "tests/labelling_test_support.hpp"
#include "tools/label_swap.hpp"
#include "tests/test_support.hpp"

using namespace facecap;
using Catch::Contains;

namespace {

struct JawTake {
  Rig rig;
  formats::MarkerTake take;
  pipeline::Calibration calibration;
};

// The rig, the take and its calibration (auto-neutral, from the whole take).
const JawTake& jaw_take(const std::filesystem::path& ict, const std::filesystem::path& jaw) {
  static const JawTake scene = [&] {
    JawTake s{load_rig(ict.string()), formats::read_take(jaw), {}};
    s.calibration = pipeline::calibrate_capture(s.rig, s.take, "JawMoCap.trc", 0.8).result.calibration;  // calibration.neutral_min_presence
    return s;
  }();
  return scene;
}

// The take's slot of a label.
std::size_t slot_of(const formats::MarkerTake& take, const std::string& label) {
  return std::size_t(std::find(take.labels.begin(), take.labels.end(), label) - take.labels.begin());
}

// The first `frames` frames with every value times `scale`, stating `units`.
formats::MarkerTake converted(const formats::MarkerTake& take, std::size_t frames, double scale, const std::string& units) {
  formats::MarkerTake out = take;
  out.frames.resize(std::min(frames, out.frames.size()));
  out.units = units;
  for (MarkerFrame& f : out.frames)
    for (Marker& m : f.markers) m.position *= scale;
  return out;
}

}  // namespace

TEST_CASE("JawMoCap converted to mm solves with its cm profile as the cm take within 0.01; stating cm for mm is refused",
          "[data]") {
  FACECAP_REQUIRE_SHARED_DATA(ict, "ict-face");
  FACECAP_REQUIRE_SHARED_DATA(jaw, "markers/animface/JawMoCap.trc");
  const JawTake& s = jaw_take(ict, jaw);
  REQUIRE(s.take.units == "cm");
  REQUIRE(s.calibration.take_mm_per_unit == 10.0);
  const std::size_t frames = 300;
  const formats::MarkerTake cm = converted(s.take, frames, 1.0, "cm"), mm = converted(s.take, frames, 10.0, "mm");
  CHECK_NOTHROW(pipeline::require_plausible_units(cm, "", s.calibration, "cm.trc"));
  CHECK_NOTHROW(pipeline::require_plausible_units(mm, "", s.calibration, "mm.trc"));
  pipeline::SolvePipeline from_cm(s.rig, s.calibration, {cm.labels, cm.units}, {});
  pipeline::SolvePipeline from_mm(s.rig, s.calibration, {mm.labels, mm.units}, {});
  SolvedFrame a = from_cm.make_solved_frame(false), b = from_mm.make_solved_frame(false);
  double worst = 0.0, head_mm = 0.0;
  for (std::size_t i = 0; i < frames; ++i) {
    from_cm.process(cm.frames[i], a);
    from_mm.process(mm.frames[i], b);
    worst = std::max(worst, double((a.weights - b.weights).cwiseAbs().maxCoeff()));
    head_mm = std::max(head_mm, double((a.head_translation - b.head_translation).norm()) * s.calibration.rig_mm_per_unit);
  }
  WARN("JawMoCap in mm vs cm, " << frames << " frames: largest weight difference " << worst << ", head " << head_mm << " mm");
  CHECK(worst < 0.01);
  CHECK(head_mm < 0.01);

  formats::MarkerTake mislabelled = mm;
  mislabelled.units = "cm";
  const pipeline::UnitsCheck check = pipeline::check_take_units(mislabelled, "", s.calibration);
  CHECK(check.size_ratio == Approx(10.0).epsilon(0.1));
  CHECK_THROWS_WITH(pipeline::require_plausible_units(mislabelled, "", s.calibration, "mislabelled.trc"),
                    Contains("mislabelled.trc") && Contains("look like mm") && Contains("--units mm"));
}

TEST_CASE("JawMoCap labelling recovers within a few frames of a label swap, an occlusion while the head moves and a ghost",
          "[data]") {
  FACECAP_REQUIRE_SHARED_DATA(ict, "ict-face");
  FACECAP_REQUIRE_SHARED_DATA(jaw, "markers/animface/JawMoCap.trc");
  const JawTake& s = jaw_take(ict, jaw);
  const std::vector<MarkerFrame> frames(s.take.frames.begin(), s.take.frames.begin() + 420);
  const auto slot = [&](const char* label) { return slot_of(s.take, label); };
  test::LabelEvents e;
  // Neighbouring lip markers swapped for good (the source's labels are wrong from then on),
  // the chin hidden for a second while the head moves 3 cm, a ghost 4 mm from the upper lip.
  e.swap_a = slot("Mouth_DownL"), e.swap_b = slot("Mouth_Down"), e.swap_from = 100;
  e.occluded = slot("Chin"), e.occluded_from = 200, e.occluded_to = 260, e.head_move = Eigen::Vector3d(3.0, 1.0, 0.0);
  e.ghosted = slot("Mouth_Up"), e.ghost_offset = Eigen::Vector3d(0.4, 0.0, 0.0), e.ghost_from = 320, e.ghost_to = 350;
  for (const bool cloud : {false, true}) {
    INFO((cloud ? "labelling an unlabelled cloud" : "checking the labels"));
    const std::vector<bool> right = test::labelled_frames_right(s.rig, s.calibration, s.take.labels, frames, s.take.units, e, cloud);
    const auto right_in = [&](std::size_t from, std::size_t to) {
      return std::size_t(std::count(right.begin() + std::ptrdiff_t(from), right.begin() + std::ptrdiff_t(to), true));
    };
    const std::size_t after_occlusion = test::frames_to_recover(right, e.occluded_to);
    const std::size_t after_ghost = test::frames_to_recover(right, e.ghost_to);
    WARN("JawMoCap, " << (cloud ? "cloud" : "check") << ": right in " << right_in(0, e.swap_from) << " of " << e.swap_from
         << " frames before the events and " << right_in(e.swap_from, e.occluded_from) << " of " << e.occluded_from - e.swap_from
         << " after the swap; frames to recover after the occlusion " << after_occlusion << ", the ghost " << after_ghost);
    CHECK(right_in(0, e.swap_from) == e.swap_from);
    CHECK(right_in(e.swap_from, e.occluded_from) == e.occluded_from - e.swap_from);  // every swapped frame corrected
    CHECK(after_occlusion <= 3);
    CHECK(after_ghost <= 3);
  }
}

TEST_CASE("JawMoCap starting with two lip labels swapped is corrected by the label check from the first frame", "[data]") {
  FACECAP_REQUIRE_SHARED_DATA(ict, "ict-face");
  FACECAP_REQUIRE_SHARED_DATA(jaw, "markers/animface/JawMoCap.trc");
  const JawTake& s = jaw_take(ict, jaw);
  const std::vector<MarkerFrame> frames(s.take.frames.begin(), s.take.frames.begin() + 300);
  const auto slot = [&](const char* label) { return slot_of(s.take, label); };
  test::LabelEvents e;
  e.swap_a = slot("Mouth_DownL"), e.swap_b = slot("Mouth_Down"), e.swap_from = 0;
  const std::vector<bool> right = test::labelled_frames_right(s.rig, s.calibration, s.take.labels, frames, s.take.units, e, false);
  CHECK(std::count(right.begin(), right.end(), true) == 300);
}

namespace {

// Frames of `take` the nonlinear pipeline (facecapd's defaults, marker_consistency_mm as
// given) solves torn: a triangle folded against the linear blend of the same weights, or an
// edge stretched by more than 20 mm against it (the torn brow: 68 mm).
struct TornCount {
  int torn = 0, flagged_inconsistent = 0;
  double worst_stretch_mm = 0;
};
TornCount torn_frames(const JawTake& s, const formats::MarkerTake& take, double consistency_mm) {
  pipeline::SolveSettings settings;
  settings.marker_consistency_mm = consistency_mm;
  pipeline::SolvePipeline solve(s.rig, s.calibration, {take.labels, take.units}, settings);
  SolvedFrame out = solve.make_solved_frame(false);
  TornCount count;
  for (const MarkerFrame& frame : take.frames) {
    solve.process(frame, out);
    count.torn += out.folded_triangles > 0 || out.max_edge_stretch_mm > 20.0f;
    count.flagged_inconsistent += (out.flags & kSolvedInconsistentMarker) != 0;
    count.worst_stretch_mm = std::max(count.worst_stretch_mm, double(out.max_edge_stretch_mm));
  }
  return count;
}

}  // namespace

TEST_CASE("JawMoCap with label swaps injected (slow and fast, neighbours and not) solves without torn frames", "[data]") {
  FACECAP_REQUIRE_SHARED_DATA(ict, "ict-face");
  FACECAP_REQUIRE_SHARED_DATA(jaw, "markers/animface/JawMoCap.trc");
  const JawTake& s = jaw_take(ict, jaw);
  formats::MarkerTake take = s.take;
  take.frames.resize(900);
  const double on = config::kSuggestedMarkerConsistencyMm;
  REQUIRE(on > 0.0);  // the check is on by default
  const TornCount clean = torn_frames(s, take, on);
  for (const std::string spec : {"Leyebrow_M:Leyebrow_Inside:200:40:6", "Mouth_DownL:Mouth_Down:400:30:0",
                                 "Leye_Up:Rcheek_up:600:20:3", "Reyebrow_M:Reyebrow_Outside:750:60:0"})
    tools::inject_label_swap(take, tools::parse_label_swap(spec));
  const TornCount before = torn_frames(s, take, 0.0), after = torn_frames(s, take, on);
  WARN(fmt::format("JawMoCap, 900 frames, four swaps injected: torn frames without the consistency check {} (worst "
                   "stretch {:.1f} mm), with it {} ({:.1f} mm; {} frames flagged inconsistent_marker); the clean take {} "
                   "({} flagged)", before.torn, before.worst_stretch_mm, after.torn, after.worst_stretch_mm,
                   after.flagged_inconsistent, clean.torn, clean.flagged_inconsistent));
  CHECK(before.torn > 0);
  CHECK(after.torn == 0);
  CHECK(clean.torn == 0);
}
