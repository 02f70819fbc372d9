#pragma once
// The capture-quality state an operator sees at a glance (STATUS, the log, the stats
// file, the control API): good, degraded or bad, from a window's telemetry against the
// [quality] thresholds. The worst criterion decides, and each criterion that is not good
// is named with its figure and the markers concerned ("3 of 6 mouth markers missing:
// Mouth_L, ...", "marker noise 1.02 mm"). Per marker, the data say how often it was there,
// how much it jitters (MarkerTelemetry) and how far it sits from the solved surface; a
// marker's region (mouth, jaw, eyes, brows, ...) comes from its name or else from the rig
// shape that moves its bound point most. QualityHold keeps the state from flapping.
// Not real-time code.
#include <array>
#include <cstdint>
#include <limits>
#include <string>
#include <vector>

#include "config/daemon_config.hpp"
#include "core/enum_table.hpp"
#include "solver/face_solver.hpp"
#include "solver/rig.hpp"

namespace facecap::daemon {

enum class CaptureQuality : uint8_t { kGood, kDegraded, kBad };
inline constexpr EnumTable kCaptureQualities{std::array{
    EnumEntry{CaptureQuality::kGood, "good", "every criterion within its degraded threshold"},
    EnumEntry{CaptureQuality::kDegraded, "degraded", "some criterion past its degraded threshold"},
    EnumEntry{CaptureQuality::kBad, "bad", "some criterion past its bad threshold, or no frame solved"},
}};

// A marker below this presence over a window counts as missing.
inline constexpr double kMissingBelowPresence = 0.5;

// One face marker the calibration binds, over a window.
struct MarkerQuality {
  std::string label;
  std::string region;              // marker_region()
  double present_fraction = 0.0;   // of the window's solved frames (0: the source lacks it)
  double noise_mm = std::numeric_limits<double>::quiet_NaN();     // per coordinate; NaN: not measured
  double residual_mm = std::numeric_limits<double>::quiet_NaN();  // mean fit residual; NaN: not measured
  bool missing() const noexcept { return present_fraction < kMissingBelowPresence; }
};

// "mouth", "jaw", "eyes", "brows", "cheeks", "nose" from the label's words (Mouth_L,
// LBrowOuter, Chin_1, ...), else from the name of the rig shape that moves the bound point
// most at full weight (jawOpen, mouthSmile_L, eyeBlink_R, browInnerUp, ...), else "face".
std::string marker_region(const std::string& label, const MarkerBinding& binding, const Rig& rig);

// A window's solve telemetry.
struct CaptureFigures {
  uint64_t frames = 0;            // solved in the window
  double markers_used = 0.0;      // mean face markers used per frame
  double markers_expected = 0.0;  // mean face markers the calibration binds
  double head_held_fraction = 0.0;  // of the frames, with the head pose held
  double face_held_fraction = 0.0;  // of the frames, with the face held (too few markers)
  uint64_t residuals = 0;         // fit residuals measured
  double residual_p50_mm = 0.0;   // of the fit residuals (0 when none)
  double residual_p95_mm = 0.0;
  double residual_max_mm = 0.0;
  std::vector<MarkerQuality> markers;  // the calibration's face markers, in its order
  bool noise_measured = false;         // markers are identities (not relabelled per frame): noise is theirs

  double markers_used_fraction() const noexcept { return markers_expected > 0 ? markers_used / markers_expected : 0.0; }
};

struct QualityAssessment {
  CaptureQuality state = CaptureQuality::kGood;
  std::vector<std::string> reasons;  // one per criterion not good, worst first

  // "good", or "bad: 5.1 of 48 markers used (11%), head pose held in 100% of frames".
  std::string describe() const;
};

QualityAssessment assess_quality(const CaptureFigures& figures, const config::QualitySection& thresholds);

// Hysteresis: the state shown changes only once hold_windows assessments in a row agree on
// a new state, so a capture at the edge of a threshold does not flap. The reasons shown are
// the latest assessment's that agreed with the state shown.
class QualityHold {
 public:
  // Returns the state to show after this window's assessment.
  const QualityAssessment& update(const QualityAssessment& latest, int hold_windows);
  const QualityAssessment& shown() const noexcept { return shown_; }
  // Changes of the state shown after the first window's.
  uint64_t changes() const noexcept { return changes_; }

 private:
  QualityAssessment shown_;
  bool started_ = false;
  CaptureQuality pending_ = CaptureQuality::kGood;
  int pending_windows_ = 0;
  uint64_t changes_ = 0;
};

}  // namespace facecap::daemon
