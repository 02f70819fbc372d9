#include "pipeline/marker_consistency.hpp"

#include <algorithm>
#include <limits>

#include "solver/solver_model.hpp"

namespace facecap::pipeline {
namespace {

// Median of the first n values (n <= kNeighbours), by insertion sort on a copy.
double median(std::array<double, MarkerConsistency::kNeighbours> v, int n) noexcept {
  for (int i = 1; i < n; ++i)
    for (int j = i; j > 0 && v[std::size_t(j)] < v[std::size_t(j - 1)]; --j) std::swap(v[std::size_t(j)], v[std::size_t(j - 1)]);
  return n % 2 ? v[std::size_t(n / 2)] : 0.5 * (v[std::size_t(n / 2 - 1)] + v[std::size_t(n / 2)]);
}

}  // namespace

MarkerConsistency::MarkerConsistency(const SolverModel& model, double gate_rig) : model_(model), gate_rig_(gate_rig) {
  const Eigen::Index K = model.marker_count();
  const Eigen::VectorXd& rest = model.weights.marker_neutral;  // 3K
  neighbours_.resize(std::size_t(K));
  for (Eigen::Index k = 0; k < K; ++k) {
    std::vector<std::pair<double, int>> by_distance;
    for (Eigen::Index j = 0; j < K; ++j)
      if (j != k) by_distance.push_back({(rest.segment<3>(3 * j) - rest.segment<3>(3 * k)).squaredNorm(), int(j)});
    std::sort(by_distance.begin(), by_distance.end());
    auto& n = neighbours_[std::size_t(k)];
    n.fill(-1);
    for (std::size_t i = 0; i < n.size() && i < by_distance.size(); ++i) n[i] = by_distance[i].second;
  }
  predicted_.resize(3, K);
  residual_.resize(3, K);
  verdict_.assign(std::size_t(K), 0);
  inconsistent_.reserve(std::size_t(K));
}

bool MarkerConsistency::consistent(int k, const Eigen::Vector3d& r, std::span<const uint8_t> present) const noexcept {
  std::array<std::array<double, kNeighbours>, 3> components{};
  int n = 0;
  for (const int j : neighbours_[std::size_t(k)]) {
    if (j < 0 || !present[std::size_t(j)] || verdict_[std::size_t(j)] == 1) continue;
    for (int c = 0; c < 3; ++c) components[std::size_t(c)][std::size_t(n)] = residual_(c, j);
    ++n;
  }
  if (n < 3) return true;
  const Eigen::Vector3d neighbours(median(components[0], n), median(components[1], n), median(components[2], n));
  return (r - neighbours).norm() <= gate_rig_;
}

MarkerConsistency::Result MarkerConsistency::check(Eigen::Matrix3Xd& targets, std::span<uint8_t> present,
                                                   const Eigen::VectorXd& previous_weights) noexcept {
  const WeightsData& w = model_.weights;
  const Eigen::Index K = model_.marker_count();
  Result result;
  std::fill(verdict_.begin(), verdict_.end(), 0);
  // x0~ + B~ w_prev, marker by marker (3 x M rows each: no temporary).
  for (Eigen::Index k = 0; k < K; ++k) {
    predicted_.col(k) = w.marker_neutral.segment<3>(3 * k) + w.marker_basis.middleRows<3>(3 * k) * previous_weights;
    residual_.col(k) = present[std::size_t(k)] ? Eigen::Vector3d(targets.col(k) - predicted_.col(k)) : Eigen::Vector3d::Zero();
  }
  inconsistent_.clear();
  for (Eigen::Index k = 0; k < K; ++k)
    if (present[std::size_t(k)] && !consistent(int(k), residual_.col(k), present)) inconsistent_.push_back(int(k));
  // A pair each consistent with the other's target: swapped labels, swapped back.
  for (std::size_t i = 0; i < inconsistent_.size(); ++i)
    for (std::size_t j = i + 1; j < inconsistent_.size(); ++j) {
      const int a = inconsistent_[i], b = inconsistent_[j];
      if (verdict_[std::size_t(a)] || verdict_[std::size_t(b)]) continue;
      if (!consistent(a, targets.col(b) - predicted_.col(a), present) || !consistent(b, targets.col(a) - predicted_.col(b), present))
        continue;
      const Eigen::Vector3d t = targets.col(a);
      targets.col(a) = targets.col(b);
      targets.col(b) = t;
      residual_.col(a) = targets.col(a) - predicted_.col(a);
      residual_.col(b) = targets.col(b) - predicted_.col(b);
      verdict_[std::size_t(a)] = verdict_[std::size_t(b)] = 2;
      ++result.unswapped;
    }
  for (const int k : inconsistent_) {
    if (verdict_[std::size_t(k)]) continue;
    verdict_[std::size_t(k)] = 1;
    present[std::size_t(k)] = 0;
    targets.col(k).setConstant(std::numeric_limits<double>::quiet_NaN());
    ++result.dropped;
  }
  return result;
}

}  // namespace facecap::pipeline
