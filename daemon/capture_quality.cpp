#include "daemon/capture_quality.hpp"

#include <algorithm>
#include <array>
#include <cctype>
#include <cmath>
#include <map>

#include <fmt/format.h>

namespace facecap::daemon {
namespace {

// Words in a marker's or a shape's name and the region they mean, first match wins
// ("eyebrow" is brows, "lipcorner" mouth).
constexpr std::array<std::pair<std::string_view, std::string_view>, 12> kRegionWords{{
    {"brow", "brows"}, {"lid", "eyes"}, {"blink", "eyes"}, {"eye", "eyes"}, {"squint", "eyes"},
    {"lip", "mouth"}, {"mouth", "mouth"}, {"jaw", "jaw"}, {"chin", "jaw"}, {"cheek", "cheeks"},
    {"nose", "nose"}, {"sneer", "nose"},
}};

std::string_view region_of_name(const std::string& name) {
  std::string lower(name);
  std::transform(lower.begin(), lower.end(), lower.begin(), [](unsigned char c) { return char(std::tolower(c)); });
  for (const auto& [word, region] : kRegionWords)
    if (lower.find(word) != std::string::npos) return region;
  return {};
}

// "Mouth_L, Mouth_R, LipLower" (at most `most`, then "and N more").
std::string list_labels(const std::vector<std::string>& labels, std::size_t most = 6) {
  std::string out;
  for (std::size_t i = 0; i < labels.size() && i < most; ++i) out += (i ? ", " : "") + labels[i];
  if (labels.size() > most) out += fmt::format(" and {} more", labels.size() - most);
  return out;
}

}  // namespace

std::string marker_region(const std::string& label, const MarkerBinding& binding, const Rig& rig) {
  if (const std::string_view region = region_of_name(label); !region.empty()) return std::string(region);
  double largest = 0.0;
  Eigen::Index moving = -1;
  for (Eigen::Index s = 0; s < rig.shape_count(); ++s) {
    Eigen::Vector3d d = Eigen::Vector3d::Zero();
    for (int i = 0; i < 3; ++i) d += binding.barycentric[i] * rig.deltas.block<3, 1>(3 * Eigen::Index(binding.vertices[std::size_t(i)]), s);
    if (d.norm() > largest) largest = d.norm(), moving = s;
  }
  if (moving >= 0)
    if (const std::string_view region = region_of_name(rig.shape_names[std::size_t(moving)]); !region.empty())
      return std::string(region);
  return "face";
}

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
  // Coverage per region: a region that lost half of its markers (two or more) is bad, any
  // marker missing is degraded; the missing ones are named.
  std::map<std::string, std::pair<std::size_t, std::vector<std::string>>> regions;  // region -> markers, missing
  for (const MarkerQuality& m : f.markers) {
    auto& [count, missing] = regions[m.region];
    ++count;
    if (m.missing()) missing.push_back(m.label);
  }
  for (const auto& [region, tally] : regions) {
    const auto& [count, missing] = tally;
    if (missing.empty()) continue;
    judge(count >= 2 && 2 * missing.size() >= count, true,
          fmt::format("{} of {} {} marker{} missing: {}", missing.size(), count, region, count == 1 ? "" : "s",
                      list_labels(missing)));
  }
  // Noise from the data: the median marker's, and the markers noisier than the threshold.
  if (f.noise_measured) {
    std::vector<double> noise;
    for (const MarkerQuality& m : f.markers)
      if (std::isfinite(m.noise_mm)) noise.push_back(m.noise_mm);
    if (!noise.empty()) {
      std::nth_element(noise.begin(), noise.begin() + std::ptrdiff_t(noise.size() / 2), noise.end());
      const double median = noise[noise.size() / 2];
      const bool overall = median > t.noise_degraded_mm;
      judge(median > t.noise_bad_mm, overall, fmt::format("marker noise {:.2f} mm (the median of {} markers)", median, noise.size()));
      if (!overall) {  // a few noisy markers on a quiet capture: named, noisiest first
        std::vector<const MarkerQuality*> noisy;
        for (const MarkerQuality& m : f.markers)
          if (std::isfinite(m.noise_mm) && m.noise_mm > t.noise_degraded_mm) noisy.push_back(&m);
        std::sort(noisy.begin(), noisy.end(), [](const auto* a, const auto* b) { return a->noise_mm > b->noise_mm; });
        std::vector<std::string> named;
        for (const MarkerQuality* m : noisy) named.push_back(fmt::format("{} {:.2f} mm", m->label, m->noise_mm));
        if (!named.empty()) judge(false, true, fmt::format("noisy: {}", list_labels(named, 4)));
      }
    }
  }
  std::stable_sort(findings.begin(), findings.end(), [](const Finding& a, const Finding& b) { return a.level > b.level; });
  for (Finding& finding : findings) {
    out.state = std::max(out.state, finding.level);
    out.reasons.push_back(std::move(finding.text));
  }
  return out;
}

const QualityAssessment& QualityHold::update(const QualityAssessment& latest, int hold_windows) {
  if (!started_ || latest.state == shown_.state) {
    started_ = true;
    shown_ = latest;
    pending_windows_ = 0;
    return shown_;
  }
  pending_windows_ = latest.state == pending_ ? pending_windows_ + 1 : 1;
  pending_ = latest.state;
  if (pending_windows_ >= std::max(hold_windows, 1)) {
    shown_ = latest;
    pending_windows_ = 0;
    ++changes_;
  }
  return shown_;
}

}  // namespace facecap::daemon
