#pragma once
// The capture-quality state an operator sees at a glance (STATUS, the log, the stats
// file, the control API): good, degraded or bad, from a window's telemetry against the
// [quality] thresholds. The worst criterion decides, and each criterion that is not good
// is named with its figure ("5.1 of 48 markers used (11%)"). Not real-time code.
#include <array>
#include <cstdint>
#include <string>
#include <vector>

#include "config/daemon_config.hpp"
#include "core/enum_table.hpp"

namespace facecap::daemon {

enum class CaptureQuality : uint8_t { kGood, kDegraded, kBad };
inline constexpr EnumTable kCaptureQualities{std::array{
    EnumEntry{CaptureQuality::kGood, "good", "every criterion within its degraded threshold"},
    EnumEntry{CaptureQuality::kDegraded, "degraded", "some criterion past its degraded threshold"},
    EnumEntry{CaptureQuality::kBad, "bad", "some criterion past its bad threshold, or no frame solved"},
}};

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

  double markers_used_fraction() const noexcept { return markers_expected > 0 ? markers_used / markers_expected : 0.0; }
};

struct QualityAssessment {
  CaptureQuality state = CaptureQuality::kGood;
  std::vector<std::string> reasons;  // one per criterion not good, worst first

  // "good", or "bad: 5.1 of 48 markers used (11%), head pose held in 100% of frames".
  std::string describe() const;
};

QualityAssessment assess_quality(const CaptureFigures& figures, const config::QualitySection& thresholds);

}  // namespace facecap::daemon
