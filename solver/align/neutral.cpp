#include "solver/align/neutral.hpp"

#include <algorithm>
#include <cmath>
#include <limits>
#include <vector>

#include <fmt/format.h>

#include "core/error.hpp"
#include "solver/align/stabilise.hpp"

namespace facecap::align {

NeutralFrame find_neutral_frame(std::span<const MarkerFrame> frames, std::span<const int> stable_slots,
                                const NeutralSearchOptions& o) {
  if (frames.empty()) throw Error("auto-neutral: the take has no frames");
  const std::size_t K = frames.front().markers.size(), F = frames.size();
  if (K < 3) throw Error(fmt::format("auto-neutral: {} markers, at least 3 needed", K));
  if (stable_slots.size() < 3) throw Error("auto-neutral: at least 3 stable markers are needed to remove head motion");
  if (!(o.rate_hz > 0.0)) throw Error("auto-neutral: the take's frame rate is unknown");
  const std::vector<uint8_t> required = mostly_present_slots(frames);
  auto complete = [&](const MarkerFrame& f) {
    if (f.markers.size() != K) return false;
    for (std::size_t k = 0; k < K; ++k)
      if (required[k] && (!f.markers[k].present() || !f.markers[k].position.allFinite())) return false;
    return true;
  };
  std::vector<uint8_t> ok(F);
  std::size_t first = F, candidates = 0;
  for (std::size_t f = 0; f < F; ++f) {
    ok[f] = complete(frames[f]);
    candidates += ok[f];
    if (ok[f] && first == F) first = f;
  }
  if (candidates == 0)
    throw Error("auto-neutral: no frame has every marker present that is present in most frames (name a frame with --frame)");
  const std::size_t W = std::max<std::size_t>(1, std::size_t(std::lround(o.window_seconds * o.rate_hz)));
  if (F < W) throw Error(fmt::format("auto-neutral: the take has {} frames, shorter than the {}-frame window", F, W));

  // Stabilise every complete frame onto the first one.
  Eigen::Matrix3Xd reference(3, Eigen::Index(stable_slots.size()));
  for (std::size_t i = 0; i < stable_slots.size(); ++i) {
    if (stable_slots[i] < 0 || std::size_t(stable_slots[i]) >= K) throw Error("auto-neutral: stable marker index out of range");
    reference.col(Eigen::Index(i)) = frames[first].markers[std::size_t(stable_slots[i])].position;
  }
  HeadStabiliser stabiliser(std::vector<int>(stable_slots.begin(), stable_slots.end()), reference);
  std::vector<Eigen::Matrix3Xd> shape(F);
  for (std::size_t f = 0; f < F; ++f) {
    if (!ok[f]) continue;
    HeadPoseResult pose;
    stabiliser.process(frames[f].markers, pose);
    if (pose.held) {
      ok[f] = 0;
      continue;
    }
    shape[f].resize(3, Eigen::Index(K));
    const Eigen::Matrix3d Rt = pose.pose.rotation.transpose();
    for (std::size_t k = 0; k < K; ++k)
      shape[f].col(Eigen::Index(k)) =
          required[k] ? Eigen::Vector3d(Rt * (frames[f].markers[k].position - pose.pose.translation)) : Eigen::Vector3d::Zero();
  }
  const double mm = o.take_mm_per_unit;
  const double inf = std::numeric_limits<double>::infinity();
  // Speed over a 50 ms baseline (3 frames at 60 Hz), so marker noise reads as little motion.
  const std::size_t h = std::max<std::size_t>(1, std::size_t(std::lround(0.05 * o.rate_hz)));
  std::vector<double> distance(F, inf), speed(F, inf);
  for (std::size_t f = 0; f < F; ++f) {
    if (!ok[f]) continue;
    const std::size_t a = f >= h && ok[f - h] ? f - h : f, b = f + h < F && ok[f + h] ? f + h : f;
    if (a != b) speed[f] = std::sqrt((shape[b] - shape[a]).colwise().squaredNorm().mean()) * mm * o.rate_hz / double(b - a);
  }
  // The typical resting shape: coordinate-wise median over the stillest 30% of the frames
  // (the face returns to rest between expressions; motion frames would drag a median of
  // all frames towards the expressions).
  std::vector<double> values;
  for (std::size_t f = 0; f < F; ++f)
    if (std::isfinite(speed[f])) values.push_back(speed[f]);
  if (values.empty()) throw Error("auto-neutral: too few consecutive complete frames to measure motion");
  std::nth_element(values.begin(), values.begin() + std::ptrdiff_t(values.size() * 3 / 10), values.end());
  const double still = values[values.size() * 3 / 10];
  Eigen::Matrix3Xd median(3, Eigen::Index(K));
  for (Eigen::Index k = 0; k < Eigen::Index(K); ++k)
    for (int c = 0; c < 3; ++c) {
      values.clear();
      for (std::size_t f = 0; f < F; ++f)
        if (std::isfinite(speed[f]) && speed[f] <= still) values.push_back(shape[f](c, k));
      std::nth_element(values.begin(), values.begin() + std::ptrdiff_t(values.size() / 2), values.end());
      median(c, k) = values[values.size() / 2];
    }
  for (std::size_t f = 0; f < F; ++f)
    if (ok[f]) distance[f] = (shape[f] - median).colwise().norm().maxCoeff() * mm;  // any marker off rest counts
  NeutralFrame best;
  best.window_score = inf;
  best.candidate_frames = candidates;
  for (std::size_t start = 0; start + W <= F; ++start) {
    double dsum = 0, vsum = 0;
    bool usable = true;
    for (std::size_t f = start; f < start + W && usable; ++f) {
      usable = std::isfinite(distance[f]) && std::isfinite(speed[f]);
      dsum += distance[f], vsum += speed[f];
    }
    if (!usable) continue;
    const double score = (dsum + o.speed_weight_s * vsum) / double(W);
    if (score < best.window_score) {
      best.window_score = score;
      best.speed_mm_s = vsum / double(W);
      best.frame_index = start;
      best.window_start = start;
      best.window_frames = W;
      for (std::size_t f = start; f < start + W; ++f)
        if (distance[f] < distance[best.frame_index]) best.frame_index = f;
      best.distance_mm = distance[best.frame_index];
    }
  }
  if (!std::isfinite(best.window_score))
    throw Error(fmt::format("auto-neutral: no {:.2f} s stretch has every marker present in every frame", o.window_seconds));
  if (best.distance_mm > o.max_distance_mm || best.speed_mm_s > o.max_speed_mm_s)
    throw Error(fmt::format("auto-neutral: no neutral-looking stretch: the best ({} frames from index {}) is {:.2f} mm from "
                            "the take's median shape (limit {:.1f}) and moves {:.1f} mm/s (limit {:.1f}); "
                            "name a frame with --frame",
                            W, best.frame_index, best.distance_mm, o.max_distance_mm, best.speed_mm_s, o.max_speed_mm_s));
  return best;
}

Eigen::Matrix3Xd average_positions(std::span<const MarkerFrame> frames, std::size_t first, std::size_t count,
                                   std::size_t anchor, std::span<const int> stable_slots, std::vector<uint8_t>& present) {
  if (count == 0 || first + count > frames.size() || anchor >= frames.size())
    throw Error(fmt::format("average: frames {}..{} (anchor {}) outside the take's {}", first, first + count, anchor, frames.size()));
  const std::size_t K = frames[anchor].markers.size();
  Eigen::Matrix3Xd reference(3, Eigen::Index(stable_slots.size()));
  for (std::size_t i = 0; i < stable_slots.size(); ++i) {
    const int s = stable_slots[i];
    if (s < 0 || std::size_t(s) >= K) throw Error("average: stable marker index out of range");
    const Marker& m = frames[anchor].markers[std::size_t(s)];
    if (!m.present() || !m.position.allFinite())
      throw Error(fmt::format("average: stable marker {} is missing in the anchor frame", s));
    reference.col(Eigen::Index(i)) = m.position;
  }
  HeadStabiliser stabiliser(std::vector<int>(stable_slots.begin(), stable_slots.end()), reference);
  Eigen::Matrix3Xd sum = Eigen::Matrix3Xd::Zero(3, Eigen::Index(K));
  std::vector<int> n(K, 0);
  for (std::size_t f = first; f < first + count; ++f) {
    if (frames[f].markers.size() != K) throw Error("average: frames have different marker counts");
    HeadPoseResult pose;
    if (stabiliser.process(frames[f].markers, pose)) continue;  // held: no fit this frame
    const Eigen::Matrix3d Rt = pose.pose.rotation.transpose();
    for (std::size_t k = 0; k < K; ++k) {
      const Marker& m = frames[f].markers[k];
      if (!m.present() || !m.position.allFinite()) continue;
      sum.col(Eigen::Index(k)) += Rt * (m.position - pose.pose.translation);
      ++n[k];
    }
  }
  present.assign(K, 0);
  Eigen::Matrix3Xd mean = Eigen::Matrix3Xd::Constant(3, Eigen::Index(K), std::numeric_limits<double>::quiet_NaN());
  for (std::size_t k = 0; k < K; ++k) {
    if (2 * std::size_t(n[k]) < count || n[k] == 0) continue;
    present[k] = 1;
    mean.col(Eigen::Index(k)) = sum.col(Eigen::Index(k)) / double(n[k]);
  }
  return mean;
}

}  // namespace facecap::align
