#include "solver/align/stabilise.hpp"

#include <algorithm>
#include <cmath>
#include <limits>

#include <fmt/format.h>

#include "core/error.hpp"

namespace facecap::align {

namespace {
bool usable(const Marker& m) { return m.present() && m.position.allFinite(); }
}  // namespace

std::vector<uint8_t> mostly_present_slots(std::span<const MarkerFrame> frames) {
  const std::size_t K = frames.empty() ? 0 : frames.front().markers.size();
  std::vector<std::size_t> count(K, 0);
  for (const auto& f : frames)
    for (std::size_t k = 0; k < std::min(K, f.markers.size()); ++k) count[k] += usable(f.markers[k]);
  std::vector<uint8_t> out(K, 0);
  for (std::size_t k = 0; k < K; ++k) out[k] = 2 * count[k] >= frames.size();
  return out;
}

double distance_deviation(std::span<const MarkerFrame> frames, int a, int b) {
  double sum = 0, sum2 = 0;
  std::size_t n = 0;
  for (const auto& f : frames) {
    if (std::size_t(std::max(a, b)) >= f.markers.size()) continue;
    const Marker& p = f.markers[std::size_t(a)];
    const Marker& q = f.markers[std::size_t(b)];
    if (!usable(p) || !usable(q)) continue;
    const double d = (p.position - q.position).norm();
    sum += d, sum2 += d * d, ++n;
  }
  return n >= 2 ? std::sqrt(std::max(0.0, sum2 / double(n) - (sum / double(n)) * (sum / double(n))))
                : std::numeric_limits<double>::infinity();
}

std::vector<int> find_stable_markers(std::span<const MarkerFrame> frames, int count, double* mean_deviation,
                                     std::span<const double> mobility) {
  if (frames.size() < 2) throw Error(fmt::format("stable markers: {} frames, at least 2 needed", frames.size()));
  const std::size_t K = frames.front().markers.size();
  for (const auto& f : frames)
    if (f.markers.size() != K) throw Error("stable markers: frames have different marker counts");
  std::vector<int> candidates;
  const std::vector<uint8_t> frequent = mostly_present_slots(frames);
  for (std::size_t k = 0; k < K; ++k)
    if (frequent[k]) candidates.push_back(int(k));
  if (!mobility.empty()) {
    if (mobility.size() != K) throw Error("stable markers: one mobility per marker needed");
    std::vector<int> by_mobility = candidates;
    std::stable_sort(by_mobility.begin(), by_mobility.end(),
                     [&](int a, int b) { return mobility[std::size_t(a)] < mobility[std::size_t(b)]; });
    by_mobility.resize(std::max<std::size_t>(std::min<std::size_t>(3, by_mobility.size()), (by_mobility.size() + 1) / 2));
    std::sort(by_mobility.begin(), by_mobility.end());
    candidates = by_mobility;
  }
  const std::size_t C = candidates.size();
  if (C < 3) throw Error(fmt::format("stable markers: {} markers are present in at least half of the frames, 3 needed", C));
  // Standard deviation of each candidate pair's distance.
  Eigen::MatrixXd deviation = Eigen::MatrixXd::Constant(Eigen::Index(C), Eigen::Index(C), 0.0);
  for (std::size_t a = 0; a < C; ++a)
    for (std::size_t b = a + 1; b < C; ++b)
      deviation(Eigen::Index(a), Eigen::Index(b)) = deviation(Eigen::Index(b), Eigen::Index(a)) =
          distance_deviation(frames, candidates[a], candidates[b]);
  // Mean position of each candidate (for spread), over the frames where it is present.
  std::vector<Eigen::Vector3d> mean(C, Eigen::Vector3d::Zero());
  for (std::size_t c = 0; c < C; ++c) {
    std::size_t n = 0;
    for (const auto& f : frames)
      if (usable(f.markers[std::size_t(candidates[c])])) mean[c] += f.markers[std::size_t(candidates[c])].position, ++n;
    mean[c] /= double(std::max<std::size_t>(n, 1));
  }
  const std::size_t want = std::min<std::size_t>(std::size_t(std::max(count, 3)), C);
  std::vector<std::size_t> best_set;
  double best_cost = std::numeric_limits<double>::infinity();
  for (std::size_t seed = 0; seed < C; ++seed) {
    std::vector<std::size_t> set{seed};
    std::vector<double> worst(C, 0.0);  // largest deviation of each candidate to the set
    for (std::size_t c = 0; c < C; ++c) worst[c] = deviation(Eigen::Index(c), Eigen::Index(seed));
    while (set.size() < want) {
      // Among the candidates nearly as steady as the steadiest (within 1.5x), the one
      // farthest from the set: a spread-out set pins the head's rotation; a tight cluster
      // turns marker noise into large rotations at the chin.
      double steadiest = std::numeric_limits<double>::infinity();
      for (std::size_t c = 0; c < C; ++c)
        if (std::find(set.begin(), set.end(), c) == set.end()) steadiest = std::min(steadiest, worst[c]);
      std::size_t pick = C;
      double pick_distance = -1.0;
      for (std::size_t c = 0; c < C; ++c) {
        if (std::find(set.begin(), set.end(), c) != set.end() || worst[c] > 1.5 * steadiest) continue;
        double nearest = std::numeric_limits<double>::infinity();
        for (std::size_t m : set) nearest = std::min(nearest, (mean[c] - mean[m]).norm());
        if (nearest > pick_distance) pick = c, pick_distance = nearest;
      }
      set.push_back(pick);
      for (std::size_t c = 0; c < C; ++c) worst[c] = std::max(worst[c], deviation(Eigen::Index(c), Eigen::Index(pick)));
    }
    double cost = 0;
    int pairs = 0;
    for (std::size_t i = 0; i < set.size(); ++i)
      for (std::size_t j = i + 1; j < set.size(); ++j) cost += deviation(Eigen::Index(set[i]), Eigen::Index(set[j])), ++pairs;
    cost /= std::max(pairs, 1);
    if (cost < best_cost) best_cost = cost, best_set = set;
  }
  std::vector<int> out;
  for (std::size_t c : best_set) out.push_back(candidates[c]);
  std::sort(out.begin(), out.end());
  if (mean_deviation) *mean_deviation = best_cost;
  return out;
}

HeadStabiliser::HeadStabiliser(std::vector<int> slots, Eigen::Matrix3Xd reference, StabiliserParams params)
    : slots_(std::move(slots)), reference_(std::move(reference)), params_(params) {
  const std::size_t S = slots_.size();
  if (S < 3) throw Error(fmt::format("head stabilisation: {} stable markers, at least 3 needed", S));
  if (reference_.cols() != Eigen::Index(S)) throw Error("head stabilisation: reference and marker slots disagree");
  if (!reference_.allFinite()) throw Error("head stabilisation: reference positions are not finite");
  params_.minimum_markers = std::max(params_.minimum_markers, 3);
  current_.resize(3, Eigen::Index(S));
  weight_.assign(S, 0.0);
  residual_.assign(S, std::numeric_limits<double>::quiet_NaN());
  scratch_.assign(S, 0.0);
  inlier_.assign(S, 0);
  present_.assign(S, 0);
}

void HeadStabiliser::reset() noexcept { last_ = Similarity{}; }

bool HeadStabiliser::process(std::span<const Marker> markers, HeadPoseResult& out, std::span<uint32_t> marker_flags) noexcept {
  const std::size_t S = slots_.size();
  int present = 0;
  for (std::size_t i = 0; i < S; ++i) {
    const int slot = slots_[i];
    const bool ok = slot >= 0 && std::size_t(slot) < markers.size() && markers[std::size_t(slot)].present() &&
                    markers[std::size_t(slot)].position.allFinite();
    present_[i] = ok;
    weight_[i] = ok ? 1.0 : 0.0;
    inlier_[i] = 0;
    residual_[i] = std::numeric_limits<double>::quiet_NaN();
    if (ok) current_.col(Eigen::Index(i)) = markers[std::size_t(slot)].position, ++present;
    else current_.col(Eigen::Index(i)).setZero();
  }
  auto update_residuals = [&](const Similarity& pose) {
    std::size_t n = 0;
    for (std::size_t i = 0; i < S; ++i) {
      if (!present_[i]) continue;
      residual_[i] = (pose.apply(Eigen::Vector3d(reference_.col(Eigen::Index(i)))) - current_.col(Eigen::Index(i))).norm();
      if (weight_[i] > 0.0) scratch_[n++] = residual_[i];
    }
    return n;
  };
  Similarity pose;
  bool fitted = present >= params_.minimum_markers && fit_similarity(reference_, current_, weight_, false, pose);
  int kept = present;
  // Robust rigid fit, one rejection at a time: the worst inlier is refitted without; if it
  // lies beyond max(factor x median of the others' residuals, floor) from that fit, it is
  // an outlier (a bumped or mislabelled marker). Leaving it out of its own test keeps a
  // large error from hiding itself by pulling the fit, which matters with few markers.
  for (int it = 0; fitted && it < params_.iterations && kept > params_.minimum_markers; ++it) {
    update_residuals(pose);
    std::size_t worst = S;
    for (std::size_t i = 0; i < S; ++i)
      if (weight_[i] > 0.0 && (worst == S || residual_[i] > residual_[worst])) worst = i;
    weight_[worst] = 0.0;
    Similarity without;
    if (!fit_similarity(reference_, current_, weight_, false, without)) {
      weight_[worst] = 1.0;
      break;
    }
    const std::size_t n = update_residuals(without);
    std::nth_element(scratch_.begin(), scratch_.begin() + std::ptrdiff_t(n / 2), scratch_.begin() + std::ptrdiff_t(n));
    const double gate = std::max(params_.outlier_factor * scratch_[n / 2], params_.outlier_floor);
    if (residual_[worst] <= gate) {
      weight_[worst] = 1.0;
      break;
    }
    pose = without;
    --kept;
  }
  if (fitted) update_residuals(pose);
  out.inliers = 0;
  out.rms = 0.0;
  if (fitted) {
    double sum = 0;
    for (std::size_t i = 0; i < S; ++i) {
      inlier_[i] = weight_[i] > 0.0;
      if (inlier_[i]) sum += residual_[i] * residual_[i], ++out.inliers;
    }
    out.rms = std::sqrt(sum / double(std::max(out.inliers, 1)));
    last_ = pose;
  } else {
    // Held: residuals against the pose still in use.
    for (std::size_t i = 0; i < S; ++i) weight_[i] = 0.0;
    update_residuals(last_);
  }
  out.held = !fitted;
  out.pose = last_;
  if (!marker_flags.empty() && fitted) {
    for (std::size_t i = 0; i < S; ++i) {
      const int slot = slots_[i];
      if (present_[i] && !inlier_[i] && slot >= 0 && std::size_t(slot) < marker_flags.size())
        marker_flags[std::size_t(slot)] |= kMarkerOutlier;
    }
  }
  return out.held;
}

}  // namespace facecap::align
