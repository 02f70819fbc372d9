#include "daemon/capture_quality.hpp"

#include <algorithm>

#include <fmt/format.h>

namespace facecap::daemon {

std::string QualityAssessment::describe() const {
  const std::string name(kCaptureQualities.name(state));
  return reasons.empty() ? name : fmt::format("{}: {}", name, fmt::join(reasons, ", "));
}

QualityAssessment assess_quality(const CaptureFigures& f, const config::QualitySection& t) {
  QualityAssessment out;
  if (f.frames == 0) {
    out.state = CaptureQuality::kBad;
    out.reasons.push_back("no frame solved");
    return out;
  }
  struct Finding {
    CaptureQuality level;
    std::string text;
  };
  std::vector<Finding> findings;
  auto judge = [&](bool bad, bool degraded, std::string text) {
    if (bad || degraded) findings.push_back({bad ? CaptureQuality::kBad : CaptureQuality::kDegraded, std::move(text)});
  };
  const double used = f.markers_used_fraction();
  judge(used < t.markers_used_bad, used < t.markers_used_degraded,
        fmt::format("{:.1f} of {:.0f} markers used ({:.0f}%)", f.markers_used, f.markers_expected, 100.0 * used));
  judge(f.head_held_fraction > t.head_held_bad, f.head_held_fraction > t.head_held_degraded,
        fmt::format("head pose held in {:.0f}% of frames", 100.0 * f.head_held_fraction));
  if (f.residuals > 0)
    judge(f.residual_p95_mm > t.residual_p95_bad_mm, f.residual_p95_mm > t.residual_p95_degraded_mm,
          fmt::format("fit residual p95 {:.2f} mm", f.residual_p95_mm));
  std::stable_sort(findings.begin(), findings.end(), [](const Finding& a, const Finding& b) { return a.level > b.level; });
  for (Finding& finding : findings) {
    out.state = std::max(out.state, finding.level);
    out.reasons.push_back(std::move(finding.text));
  }
  return out;
}

}  // namespace facecap::daemon
