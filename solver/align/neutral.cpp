#include "solver/align/neutral.hpp"

#include <algorithm>
#include <cmath>
#include <limits>
#include <vector>

#include <fmt/format.h>
#include <fmt/ranges.h>

#include "core/error.hpp"
#include "solver/align/stabilise.hpp"

namespace facecap::align {

namespace {

bool usable(const Marker& m) { return m.present() && m.position.allFinite(); }

// A frame of K markers where every stable marker is usable: one that can anchor a head fit.
bool has_every_stable(const MarkerFrame& frame, std::size_t K, std::span<const int> stable_slots) {
  return frame.markers.size() == K &&
         std::all_of(stable_slots.begin(), stable_slots.end(), [&](int s) { return usable(frame.markers[std::size_t(s)]); });
}

// The frames with each gap of up to `longest` frames in a required marker bridged by linear
// interpolation of its raw positions. A stable marker's dropout then changes neither the
// head fit (five markers fit a slightly different pose than six on a face whose forehead
// skin slides) nor the speed and distance of a frame: with and without dropouts the same
// stretch wins.
std::vector<MarkerFrame> bridge_gaps(std::span<const MarkerFrame> frames, const std::vector<uint8_t>& required,
                                     std::size_t longest) {
  std::vector<MarkerFrame> out(frames.begin(), frames.end());
  const std::size_t K = required.size(), F = out.size();
  for (std::size_t k = 0; k < K; ++k) {
    if (!required[k]) continue;
    std::size_t seen = F;  // the last frame where marker k is present
    for (std::size_t f = 0; f < F; ++f) {
      if (out[f].markers.size() != K || !usable(out[f].markers[k])) continue;
      if (seen != F && f - seen > 1 && f - seen - 1 <= longest)
        for (std::size_t g = seen + 1; g < f; ++g) {
          if (out[g].markers.size() != K) continue;
          const double t = double(g - seen) / double(f - seen);
          Marker& m = out[g].markers[k];
          m.position = (1.0 - t) * out[seen].markers[k].position + t * out[f].markers[k].position;
          m.flags &= ~kMarkerMissing;
        }
      seen = f;
    }
  }
  return out;
}

}  // namespace

NeutralFrame find_neutral_frame(std::span<const MarkerFrame> frames, std::span<const int> stable_slots,
                                const NeutralSearchOptions& o) {
  if (frames.empty()) throw Error("auto-neutral: the take has no frames");
  const std::size_t K = frames.front().markers.size(), F = frames.size();
  if (K < 3) throw Error(fmt::format("auto-neutral: {} markers, at least 3 needed", K));
  if (stable_slots.size() < 3) throw Error("auto-neutral: at least 3 stable markers are needed to remove head motion");
  if (!(o.rate_hz > 0.0)) throw Error("auto-neutral: the take's frame rate is unknown");
  if (!(o.min_presence > 0.0 && o.min_presence <= 1.0))
    throw Error(fmt::format("auto-neutral: the presence fraction {} is outside (0, 1]", o.min_presence));
  for (int s : stable_slots)
    if (s < 0 || std::size_t(s) >= K) throw Error("auto-neutral: stable marker index out of range");
  const std::vector<uint8_t> required = mostly_present_slots(frames);
  const std::size_t W = std::max<std::size_t>(1, std::size_t(std::lround(o.window_seconds * o.rate_hz)));
  if (F < W) throw Error(fmt::format("auto-neutral: the take has {} frames, shorter than the {}-frame window", F, W));

  // Head motion is removed relative to the first frame with every stable marker.
  std::size_t first = F;
  for (std::size_t f = 0; f < F && first == F; ++f)
    if (has_every_stable(frames[f], K, stable_slots)) first = f;
  if (first == F) throw Error("auto-neutral: no frame has every stable marker present (name a frame with --frame)");
  Eigen::Matrix3Xd reference(3, Eigen::Index(stable_slots.size()));
  for (std::size_t i = 0; i < stable_slots.size(); ++i)
    reference.col(Eigen::Index(i)) = frames[first].markers[std::size_t(stable_slots[i])].position;
  HeadStabiliser stabiliser(std::vector<int>(stable_slots.begin(), stable_slots.end()), reference);
  const std::vector<MarkerFrame> bridged = bridge_gaps(frames, required, W);

  // Each frame whose head pose fits, stabilised, gaps bridged; a missing marker is NaN.
  // present_before[k][f]: frames before f where marker k is present in the take (windowed
  // presence by difference: a bridged gap still counts as missing).
  const double nan = std::numeric_limits<double>::quiet_NaN();
  std::vector<uint8_t> ok(F, 0);
  std::vector<Eigen::Matrix3Xd> shape(F);
  std::vector<std::vector<uint32_t>> present_before(K, std::vector<uint32_t>(F + 1, 0));
  std::size_t candidates = 0;
  for (std::size_t f = 0; f < F; ++f) {
    const bool same_slots = frames[f].markers.size() == K;
    for (std::size_t k = 0; k < K; ++k)
      present_before[k][f + 1] = present_before[k][f] + (same_slots && usable(frames[f].markers[k]) ? 1 : 0);
    if (!same_slots) continue;
    HeadPoseResult pose;
    if (stabiliser.process(bridged[f].markers, pose)) continue;  // held: too few stable markers
    ok[f] = 1;
    ++candidates;
    shape[f].resize(3, Eigen::Index(K));
    const Eigen::Matrix3d Rt = pose.pose.rotation.transpose();
    for (std::size_t k = 0; k < K; ++k) {
      const Marker& m = bridged[f].markers[k];
      shape[f].col(Eigen::Index(k)) =
          required[k] && usable(m) ? Eigen::Vector3d(Rt * (m.position - pose.pose.translation)) : Eigen::Vector3d::Constant(nan);
    }
  }
  if (candidates == 0) throw Error("auto-neutral: no frame has enough stable markers to remove head motion (name a frame with --frame)");
  const double mm = o.take_mm_per_unit;
  const double inf = std::numeric_limits<double>::infinity();
  // RMS speed of the markers present at both ends of a 50 ms baseline (3 frames at 60 Hz),
  // so marker noise reads as little motion; half of the markers must be seen at both ends.
  const std::size_t h = std::max<std::size_t>(1, std::size_t(std::lround(0.05 * o.rate_hz)));
  std::vector<double> distance(F, inf), speed(F, inf);
  for (std::size_t f = 0; f < F; ++f) {
    if (!ok[f]) continue;
    const std::size_t a = f >= h && ok[f - h] ? f - h : f, b = f + h < F && ok[f + h] ? f + h : f;
    if (a == b) continue;
    double sum = 0.0;
    std::size_t n = 0;
    for (Eigen::Index k = 0; k < Eigen::Index(K); ++k) {
      const double d2 = (shape[b].col(k) - shape[a].col(k)).squaredNorm();
      if (std::isfinite(d2)) sum += d2, ++n;
    }
    if (2 * n >= K) speed[f] = std::sqrt(sum / double(n)) * mm * o.rate_hz / double(b - a);
  }
  // The typical resting shape: per marker, the coordinate-wise median over the stillest 30%
  // of the frames where it is present (the face returns to rest between expressions;
  // motion frames would drag a median of all frames towards the expressions).
  std::vector<double> values;
  for (std::size_t f = 0; f < F; ++f)
    if (std::isfinite(speed[f])) values.push_back(speed[f]);
  if (values.empty()) throw Error("auto-neutral: too few consecutive frames with the head pose fitted to measure motion");
  std::nth_element(values.begin(), values.begin() + std::ptrdiff_t(values.size() * 3 / 10), values.end());
  const double still = values[values.size() * 3 / 10];
  Eigen::Matrix3Xd median = Eigen::Matrix3Xd::Constant(3, Eigen::Index(K), nan);
  for (Eigen::Index k = 0; k < Eigen::Index(K); ++k)
    for (int c = 0; c < 3; ++c) {
      values.clear();
      for (std::size_t f = 0; f < F; ++f)
        if (std::isfinite(speed[f]) && speed[f] <= still && std::isfinite(shape[f](c, k))) values.push_back(shape[f](c, k));
      if (values.empty()) continue;
      std::nth_element(values.begin(), values.begin() + std::ptrdiff_t(values.size() / 2), values.end());
      median(c, k) = values[values.size() / 2];
    }
  // Any marker off rest counts. A marker missing in a frame counts with its distance where
  // it was last seen, so that a dropout does not make a frame look more neutral.
  std::vector<double> last_distance(K, 0.0);
  for (std::size_t f = 0; f < F; ++f) {
    if (!ok[f]) continue;
    double largest = 0.0;
    for (Eigen::Index k = 0; k < Eigen::Index(K); ++k) {
      if (const double d = (shape[f].col(k) - median.col(k)).norm(); std::isfinite(d)) last_distance[std::size_t(k)] = d;
      largest = std::max(largest, last_distance[std::size_t(k)]);
    }
    distance[f] = largest * mm;
  }
  // A stretch qualifies when every frame's head pose fits and each (mostly present) marker is
  // present in min_presence of its frames; best_presence remembers, per marker, its best
  // fraction over the stretches that were still enough to measure, to name the culprits.
  const std::size_t needed = std::size_t(std::ceil(o.min_presence * double(W) - 1e-9));
  std::vector<std::size_t> best_presence(K, 0);
  NeutralFrame best;
  best.window_score = inf;
  best.candidate_frames = candidates;
  for (std::size_t start = 0; start + W <= F; ++start) {
    double dsum = 0, vsum = 0;
    bool still_measured = true;
    for (std::size_t f = start; f < start + W && still_measured; ++f) {
      still_measured = std::isfinite(distance[f]) && std::isfinite(speed[f]);
      dsum += distance[f], vsum += speed[f];
    }
    if (!still_measured) continue;
    bool covered = true;
    for (std::size_t k = 0; k < K; ++k) {
      if (!required[k]) continue;
      const std::size_t seen = present_before[k][start + W] - present_before[k][start];
      best_presence[k] = std::max(best_presence[k], seen);
      covered &= seen >= needed;
    }
    if (!covered) continue;
    // The returned frame anchors the average: every stable marker present, closest to rest.
    std::size_t anchor = F;
    for (std::size_t f = start; f < start + W; ++f)
      if (has_every_stable(frames[f], K, stable_slots) && (anchor == F || distance[f] < distance[anchor])) anchor = f;
    const double score = (dsum + o.speed_weight_s * vsum) / double(W);
    if (anchor != F && score < best.window_score) {
      best.window_score = score;
      best.speed_mm_s = vsum / double(W);
      best.frame_index = anchor;
      best.window_start = start;
      best.window_frames = W;
      best.distance_mm = distance[anchor];
    }
  }
  if (!std::isfinite(best.window_score)) {
    std::string missing;
    for (std::size_t k = 0; k < K; ++k)
      if (required[k] && best_presence[k] < needed)
        missing += fmt::format("{}{} (at best {:.0f}%)", missing.empty() ? "" : ", ",
                               frames[first].markers[k].label.view().empty() ? fmt::format("slot {}", k)
                                                                             : std::string(frames[first].markers[k].label.view()),
                               100.0 * double(best_presence[k]) / double(W));
    throw Error(fmt::format("auto-neutral: no {:.2f} s stretch has each marker present in {:.0f}% of its frames{}",
                            o.window_seconds, 100.0 * o.min_presence,
                            missing.empty() ? std::string(" with the head pose fitted in every frame")
                                            : "; too often missing: " + missing));
  }
  if (best.distance_mm > o.max_distance_mm || best.speed_mm_s > o.max_speed_mm_s)
    throw Error(fmt::format("auto-neutral: no neutral-looking stretch: the best ({} frames from index {}) is {:.2f} mm from "
                            "the take's median shape (limit {:.1f}) and moves {:.1f} mm/s (limit {:.1f}); "
                            "name a frame with --frame",
                            W, best.frame_index, best.distance_mm, o.max_distance_mm, best.speed_mm_s, o.max_speed_mm_s));
  return best;
}

Eigen::Matrix3Xd average_positions(std::span<const MarkerFrame> frames, std::size_t first, std::size_t count,
                                   std::size_t anchor, std::span<const int> stable_slots, double min_presence,
                                   std::vector<uint8_t>& present) {
  if (count == 0 || first + count > frames.size() || anchor >= frames.size())
    throw Error(fmt::format("average: frames {}..{} (anchor {}) outside the take's {}", first, first + count, anchor, frames.size()));
  const std::size_t K = frames[anchor].markers.size();
  for (const int s : stable_slots)
    if (s < 0 || std::size_t(s) >= K) throw Error("average: stable marker index out of range");
  // A dropout in the requested anchor must not fail the calibration: the head frame is taken
  // from the frame nearest to it, within the averaged frames, that has every stable marker.
  std::size_t reference_frame = frames.size();
  auto gap = [&](std::size_t f) { return f > anchor ? f - anchor : anchor - f; };
  for (std::size_t f = first; f < first + count; ++f)
    if (has_every_stable(frames[f], K, stable_slots) && (reference_frame == frames.size() || gap(f) < gap(reference_frame)))
      reference_frame = f;
  if (reference_frame == frames.size())
    throw Error(fmt::format("average: no frame in {}..{} has every stable marker ({}) present", first, first + count,
                            fmt::join(stable_slots, ", ")));
  Eigen::Matrix3Xd reference(3, Eigen::Index(stable_slots.size()));
  for (std::size_t i = 0; i < stable_slots.size(); ++i)
    reference.col(Eigen::Index(i)) = frames[reference_frame].markers[std::size_t(stable_slots[i])].position;
  HeadStabiliser stabiliser(std::vector<int>(stable_slots.begin(), stable_slots.end()), reference);
  std::vector<std::vector<Eigen::Vector3d>> samples(K);
  for (std::size_t f = first; f < first + count; ++f) {
    if (frames[f].markers.size() != K) throw Error("average: frames have different marker counts");
    HeadPoseResult pose;
    if (stabiliser.process(frames[f].markers, pose)) continue;  // held: no fit this frame
    const Eigen::Matrix3d Rt = pose.pose.rotation.transpose();
    for (std::size_t k = 0; k < K; ++k)
      if (usable(frames[f].markers[k])) samples[k].push_back(Rt * (frames[f].markers[k].position - pose.pose.translation));
  }
  present.assign(K, 0);
  Eigen::Matrix3Xd mean = Eigen::Matrix3Xd::Constant(3, Eigen::Index(K), std::numeric_limits<double>::quiet_NaN());
  const std::size_t needed = std::max<std::size_t>(1, std::size_t(std::ceil(min_presence * double(count) - 1e-9)));
  std::vector<double> values;
  for (std::size_t k = 0; k < K; ++k) {
    const std::vector<Eigen::Vector3d>& p = samples[k];
    if (p.size() < needed) continue;
    // Robust: the mean of the samples within 3 robust standard deviations (1.4826 MAD of
    // the distances) of the coordinate-wise median, so a swapped or jumping sample is ignored.
    Eigen::Vector3d median;
    for (int c = 0; c < 3; ++c) {
      values.clear();
      for (const auto& x : p) values.push_back(x[c]);
      std::nth_element(values.begin(), values.begin() + std::ptrdiff_t(values.size() / 2), values.end());
      median[c] = values[values.size() / 2];
    }
    values.clear();
    for (const auto& x : p) values.push_back((x - median).norm());
    std::vector<double> distances = values;
    std::nth_element(values.begin(), values.begin() + std::ptrdiff_t(values.size() / 2), values.end());
    const double limit = 3.0 * 1.4826 * values[values.size() / 2];
    Eigen::Vector3d sum = Eigen::Vector3d::Zero();
    std::size_t kept = 0;
    for (std::size_t i = 0; i < p.size(); ++i)
      if (distances[i] <= limit) sum += p[i], ++kept;
    present[k] = 1;
    mean.col(Eigen::Index(k)) = kept > 0 ? Eigen::Vector3d(sum / double(kept)) : median;
  }
  return mean;
}

}  // namespace facecap::align
