#include "solver/align/label.hpp"

#include <algorithm>
#include <cmath>
#include <limits>

#include <fmt/format.h>

#include "core/error.hpp"
#include "solver/align/geometry.hpp"

namespace facecap::align {

AssignmentSolver::AssignmentSolver(int max_rows, int max_cols)
    : max_rows_(max_rows), max_cols_(max_cols), u_(std::size_t(max_rows) + 1), v_(std::size_t(max_cols) + 1),
      minv_(std::size_t(max_cols) + 1), p_(std::size_t(max_cols) + 1), way_(std::size_t(max_cols) + 1),
      used_(std::size_t(max_cols) + 1) {}

double AssignmentSolver::solve(int n, int m, std::span<const double> cost, std::span<int> row_to_col) noexcept {
  if (n > m || n > max_rows_ || m > max_cols_ || cost.size() < std::size_t(n) * std::size_t(m) ||
      row_to_col.size() < std::size_t(n))
    return std::numeric_limits<double>::quiet_NaN();
  if (n == 0) return 0.0;
  const double inf = std::numeric_limits<double>::infinity();
  // 1-based potentials u (rows), v (columns); p[j] = row matched to column j.
  std::fill(u_.begin(), u_.begin() + n + 1, 0.0);
  std::fill(v_.begin(), v_.begin() + m + 1, 0.0);
  std::fill(p_.begin(), p_.begin() + m + 1, 0);
  std::fill(way_.begin(), way_.begin() + m + 1, 0);
  for (int i = 1; i <= n; ++i) {
    p_[0] = i;
    int j0 = 0;
    std::fill(minv_.begin(), minv_.begin() + m + 1, inf);
    std::fill(used_.begin(), used_.begin() + m + 1, uint8_t(0));
    do {
      used_[std::size_t(j0)] = 1;
      const int i0 = p_[std::size_t(j0)];
      double delta = inf;
      int j1 = 0;
      for (int j = 1; j <= m; ++j) {
        if (used_[std::size_t(j)]) continue;
        const double cur = cost[std::size_t(i0 - 1) * std::size_t(m) + std::size_t(j - 1)] - u_[std::size_t(i0)] - v_[std::size_t(j)];
        if (cur < minv_[std::size_t(j)]) minv_[std::size_t(j)] = cur, way_[std::size_t(j)] = j0;
        if (minv_[std::size_t(j)] < delta) delta = minv_[std::size_t(j)], j1 = j;
      }
      if (j1 == 0) return std::numeric_limits<double>::quiet_NaN();  // non-finite costs only
      for (int j = 0; j <= m; ++j) {
        if (used_[std::size_t(j)]) {
          u_[std::size_t(p_[std::size_t(j)])] += delta;
          v_[std::size_t(j)] -= delta;
        } else {
          minv_[std::size_t(j)] -= delta;
        }
      }
      j0 = j1;
    } while (p_[std::size_t(j0)] != 0);
    do {
      const int j1 = way_[std::size_t(j0)];
      p_[std::size_t(j0)] = p_[std::size_t(j1)];
      j0 = j1;
    } while (j0 != 0);
  }
  double total = 0.0;
  for (int j = 1; j <= m; ++j)
    if (p_[std::size_t(j)] != 0) {
      row_to_col[std::size_t(p_[std::size_t(j)] - 1)] = j - 1;
      total += cost[std::size_t(p_[std::size_t(j)] - 1) * std::size_t(m) + std::size_t(j - 1)];
    }
  return total;
}

MarkerLabeller::MarkerLabeller(std::vector<std::string> labels, Eigen::Matrix3Xd reference, LabellerParams params)
    : labels_(std::move(labels)), reference_(std::move(reference)), params_(params),
      solver_(int(labels_.size()), params.max_points + int(labels_.size())) {
  const Eigen::Index K = Eigen::Index(labels_.size());
  if (K < 3) throw Error(fmt::format("labeller: {} markers, at least 3 needed", K));
  if (reference_.cols() != K) throw Error("labeller: labels and reference positions disagree");
  if (!reference_.allFinite()) throw Error("labeller: reference positions are not finite");
  if (params_.max_points < 1) throw Error("labeller: max_points must be positive");
  const std::size_t Ks = std::size_t(K), P = std::size_t(params_.max_points);
  points_.resize(3, params_.max_points);
  state_.last = reference_;
  state_.velocity.setZero(3, K);
  predicted_ = reference_;
  aligned_reference_ = reference_;
  state_.last_in_reference = reference_;
  state_.lost_frames.assign(Ks, 0);
  state_.ever_seen.assign(Ks, 0);
  cost_.assign(Ks * (P + Ks), 0.0);
  row_to_col_.assign(Ks, -1);
  assigned_point_.assign(Ks, -1);
  own_label_.assign(P, -1);
  no_label_.assign(P, -1);
  claimed_.assign(P, 0);
  fit_weight_.assign(Ks, 0.0);
  fit_src_.resize(3, K);
  fit_dst_.resize(3, K);
}

void MarkerLabeller::reset() noexcept {
  state_.tracking = false;
  std::fill(state_.lost_frames.begin(), state_.lost_frames.end(), 0);
  std::fill(state_.ever_seen.begin(), state_.ever_seen.end(), uint8_t(0));
  state_.velocity.setZero();
  state_.set_pose_known = false;
}

MarkerLabeller::State MarkerLabeller::make_state() const { return state_; }

bool MarkerLabeller::fits(const State& state) const noexcept {
  const Eigen::Index K = marker_count();
  return state.last.cols() == K && state.velocity.cols() == K && state.last_in_reference.cols() == K &&
         state.lost_frames.size() == labels_.size() && state.ever_seen.size() == labels_.size();
}

bool MarkerLabeller::save(State& state) const noexcept {
  if (!fits(state)) return false;
  state = state_;  // same sizes: no allocation
  return true;
}

bool MarkerLabeller::restore(const State& state) noexcept {
  if (!fits(state)) return false;
  state_ = state;
  return true;
}

void MarkerLabeller::predict() noexcept {
  for (Eigen::Index k = 0; k < marker_count(); ++k) {
    if (state_.lost_frames[std::size_t(k)] == 0)
      predicted_.col(k) = state_.last.col(k) + state_.velocity.col(k);
    else
      predicted_.col(k) = state_.set_pose_known ? state_.set_pose.apply(Eigen::Vector3d(state_.last_in_reference.col(k))) : Eigen::Vector3d(state_.last.col(k));
  }
}

int MarkerLabeller::assign(int n, std::span<const int> own_label, bool use_margin, double gate_scale) noexcept {
  const int K = int(marker_count());
  const int cols = n + K;
  const double big = 1e30;
  for (int k = 0; k < K; ++k) {
    const double gate =
        gate_scale * std::min(params_.gate + params_.gate_growth * double(state_.lost_frames[std::size_t(k)]), params_.max_gate);
    // Costs in units of each marker's own gate, "missing" at 1 for all: a lost marker's
    // wider gate lets it find its point again but does not make it dearer to leave
    // missing, so it does not outbid a tracked neighbour for the neighbour's own point.
    const double inv_gate2 = 1.0 / (gate * gate);
    double* row = cost_.data() + std::size_t(k) * std::size_t(cols);
    for (int j = 0; j < n; ++j) {
      double d = (points_.col(j) - predicted_.col(k)).norm();
      if (use_margin && own_label[std::size_t(j)] == k) d = std::max(0.0, d - params_.label_margin);
      row[j] = d <= gate ? d * d * inv_gate2 : big;
    }
    for (int j = 0; j < K; ++j) row[n + j] = j == k ? 1.0 : big;  // "missing" for marker k only
  }
  const double total = solver_.solve(K, cols, std::span<const double>(cost_.data(), std::size_t(K) * std::size_t(cols)), row_to_col_);
  int assigned = 0;
  for (int k = 0; k < K; ++k) {
    const int j = std::isnan(total) ? -1 : row_to_col_[std::size_t(k)];
    assigned_point_[std::size_t(k)] = j >= 0 && j < n ? j : -1;
    assigned += assigned_point_[std::size_t(k)] >= 0;
  }
  return assigned;
}

// Whole-set acquisition: move the reference onto the points (centroids, then repeated
// assignment and rigid fit), so the first frame needs no prediction.
void MarkerLabeller::acquire(int n) noexcept {
  const Eigen::Index K = marker_count();
  if (n == 0) return;
  const Eigen::Vector3d centre_points = points_.leftCols(n).rowwise().mean();
  const Eigen::Vector3d centre_ref = reference_.rowwise().mean();
  Similarity pose;
  pose.translation = centre_points - centre_ref;
  for (int it = 0; it < params_.initial_iterations; ++it) {
    for (Eigen::Index k = 0; k < K; ++k) predicted_.col(k) = pose.apply(Eigen::Vector3d(reference_.col(k)));
    std::fill(state_.lost_frames.begin(), state_.lost_frames.end(), 0);
    // Wide gates early, the normal gate at the end.
    const double scale = it + 1 < params_.initial_iterations ? params_.max_gate / params_.gate * 2.0 : 1.0;
    assign(n, no_label_, false, scale);
    for (Eigen::Index k = 0; k < K; ++k) {
      const int j = assigned_point_[std::size_t(k)];
      fit_weight_[std::size_t(k)] = j >= 0 ? 1.0 : 0.0;
      fit_src_.col(k) = reference_.col(k);
      fit_dst_.col(k) = j >= 0 ? Eigen::Vector3d(points_.col(j)) : Eigen::Vector3d::Zero();
    }
    Similarity next;
    if (!fit_similarity(fit_src_, fit_dst_, fit_weight_, false, next)) break;
    pose = next;
  }
}

void MarkerLabeller::update(int n) noexcept {
  for (Eigen::Index k = 0; k < marker_count(); ++k) {
    const std::size_t ks = std::size_t(k);
    const int j = assigned_point_[ks];
    if (j < 0) {
      state_.lost_frames[ks] = state_.lost_frames[ks] + 1;
      state_.velocity.col(k).setZero();
      continue;
    }
    state_.velocity.col(k) = state_.lost_frames[ks] == 0 && state_.ever_seen[ks] ? Eigen::Vector3d(points_.col(j) - state_.last.col(k))
                                                              : Eigen::Vector3d::Zero();
    state_.last.col(k) = points_.col(j);
    state_.lost_frames[ks] = 0;
    state_.ever_seen[ks] = 1;
  }
  // The set's rigid motion from the markers seen this frame; their last positions carried
  // back by it (a lost marker keeps the one it had when last seen).
  int seen = 0;
  for (Eigen::Index k = 0; k < marker_count(); ++k) {
    const bool found = assigned_point_[std::size_t(k)] >= 0;
    fit_weight_[std::size_t(k)] = found ? 1.0 : 0.0;
    fit_src_.col(k) = reference_.col(k);
    fit_dst_.col(k) = found ? Eigen::Vector3d(state_.last.col(k)) : Eigen::Vector3d::Zero();
    seen += found;
  }
  state_.set_pose_known = seen >= 3 && fit_similarity(fit_src_, fit_dst_, fit_weight_, false, state_.set_pose);
  if (!state_.set_pose_known) return;
  const Eigen::Matrix3d back = state_.set_pose.rotation.transpose();
  for (Eigen::Index k = 0; k < marker_count(); ++k)
    if (assigned_point_[std::size_t(k)] >= 0) state_.last_in_reference.col(k) = back * (state_.last.col(k) - state_.set_pose.translation);
}

LabelStats MarkerLabeller::label(std::span<const Eigen::Vector3d> points, MarkerFrame& out) noexcept {
  LabelStats stats;
  const Eigen::Index K = marker_count();
  int n = 0;
  for (const auto& p : points) {
    if (n >= params_.max_points) {
      ++stats.ghosts;
      continue;
    }
    if (!p.allFinite()) continue;
    points_.col(n++) = p;
  }
  int assigned = 0;
  if (state_.tracking) {
    predict();
    assigned = assign(n, no_label_, false, 1.0);
  }
  if (!state_.tracking || assigned < int(std::ceil(params_.reacquire_fraction * double(K)))) {
    acquire(n);
    // No prediction yet: the face may be far from the reference's expression, so the
    // widest gate; the optimal assignment keeps neighbours apart.
    assigned = assign(n, no_label_, false, params_.max_gate / params_.gate);
    stats.initialised = true;
  }
  state_.tracking = assigned >= int(std::ceil(params_.reacquire_fraction * double(K)));
  update(n);
  if (out.markers.size() != std::size_t(K)) out.markers.resize(std::size_t(K));  // allocates only the first time
  for (Eigen::Index k = 0; k < K; ++k) {
    Marker& m = out.markers[std::size_t(k)];
    m.id = int32_t(k);
    m.label.assign(labels_[std::size_t(k)]);
    const int j = assigned_point_[std::size_t(k)];
    if (j >= 0) {
      m.position = points_.col(j);
      m.flags = 0;
    } else {
      m.position.setConstant(std::numeric_limits<double>::quiet_NaN());
      m.flags = kMarkerMissing;
    }
  }
  stats.assigned = assigned;
  stats.missing = int(K) - assigned;
  stats.ghosts += n - assigned;
  return stats;
}

LabelStats MarkerLabeller::check(MarkerFrame& frame) noexcept {
  LabelStats stats;
  const Eigen::Index K = marker_count();
  if (frame.markers.size() != std::size_t(K)) return stats;
  int n = 0;
  for (Eigen::Index k = 0; k < K; ++k) {
    const Marker& m = frame.markers[std::size_t(k)];
    if (!m.present() || !m.position.allFinite()) continue;
    points_.col(n) = m.position;
    own_label_[std::size_t(n)] = int(k);
    ++n;
  }
  int assigned = 0;
  if (state_.tracking) {
    predict();
    assigned = assign(n, own_label_, true, 1.0);
  }
  if (!state_.tracking || assigned < int(std::ceil(params_.reacquire_fraction * double(K)))) {
    // No usable prediction: the reference shape moved onto the points decides, with the
    // labels' margin (so a take that starts swapped, or is swapped when the set is lost,
    // is corrected); a marker no gate gives a point keeps the one its label gives, if free.
    acquire(n);
    assign(n, own_label_, true, params_.max_gate / params_.gate);
    std::fill(claimed_.begin(), claimed_.begin() + n, uint8_t{0});
    for (Eigen::Index k = 0; k < K; ++k)
      if (assigned_point_[std::size_t(k)] >= 0) claimed_[std::size_t(assigned_point_[std::size_t(k)])] = 1;
    for (int j = 0; j < n; ++j) {
      const auto own = std::size_t(own_label_[std::size_t(j)]);
      if (!claimed_[std::size_t(j)] && assigned_point_[own] < 0) assigned_point_[own] = j, claimed_[std::size_t(j)] = 1;
    }
    assigned = int(std::count_if(assigned_point_.begin(), assigned_point_.end(), [](int j) { return j >= 0; }));
    stats.initialised = true;
  }
  state_.tracking = true;
  update(n);
  for (Eigen::Index k = 0; k < K; ++k) {
    Marker& m = frame.markers[std::size_t(k)];
    const int j = assigned_point_[std::size_t(k)];
    if (j < 0) {
      if (m.present()) m.flags |= kMarkerOutlier;  // a point no gate accepts
      m.flags |= kMarkerMissing;
      m.position.setConstant(std::numeric_limits<double>::quiet_NaN());
      continue;
    }
    if (own_label_[std::size_t(j)] != int(k)) {
      m.flags |= kMarkerRelabelled;
      ++stats.relabelled;
    }
    m.position = points_.col(j);
    m.flags &= ~uint32_t(kMarkerMissing);
  }
  stats.assigned = assigned;
  stats.missing = int(K) - assigned;
  stats.ghosts = n - assigned;
  return stats;
}

}  // namespace facecap::align
