// The one solve path on a real take: JawMoCap from AnimFace (41 markers, cm, 60 Hz) with the
// ICT FaceKit face, calibrated as `facecap calibrate --auto-neutral` does
// (pipeline::calibrate_capture). Units and labelling that recovers. Skipped with a
// message when ../shared/data is absent.
#include <algorithm>

#include <catch2/catch.hpp>

#include "formats/take.hpp"
#include "pipeline/calibration.hpp"
#include "pipeline/capture_calibration.hpp"
#include "pipeline/solve_pipeline.hpp"
#include "pipeline/source_units.hpp"
#include "solver/rig.hpp"
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
    s.calibration = pipeline::calibrate_capture(s.rig, s.take, "JawMoCap.trc").result.calibration;
    return s;
  }();
  return scene;
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
