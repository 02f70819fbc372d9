#include "solver/weights_stage.hpp"

#include "solver/solver_model.hpp"

namespace facecap {
namespace {

// sin and cos of angles in [0, 3] (marker path turns), to double precision: Taylor series
// about pi/2, branch-free so that the loop over every path vectorises.
void sin_cos_turns(const std::vector<double>& angles, std::vector<double>& sin_out, std::vector<double>& cos_out) noexcept {
  constexpr double kHalfPi = 1.57079632679489661923;
  for (std::size_t i = 0; i < angles.size(); ++i) {
    const double r = angles[i] - kHalfPi, r2 = r * r;  // |r| <= pi/2: the terms below reach 1e-18
    double s = 1.0 / 51090942171709440000.0, c = 1.0 / 2432902008176640000.0;  // 1/21!, 1/20!
    constexpr double kOdd[] = {1.0 / 121645100408832000.0, 1.0 / 355687428096000.0, 1.0 / 1307674368000.0,
                               1.0 / 6227020800.0, 1.0 / 39916800.0, 1.0 / 362880.0, 1.0 / 5040.0, 1.0 / 120.0,
                               1.0 / 6.0, 1.0};
    constexpr double kEven[] = {1.0 / 6402373705728000.0, 1.0 / 20922789888000.0, 1.0 / 87178291200.0,
                                1.0 / 479001600.0, 1.0 / 3628800.0, 1.0 / 40320.0, 1.0 / 720.0, 1.0 / 24.0, 0.5, 1.0};
    for (int k = 0; k < 10; ++k) {
      s = kOdd[k] - r2 * s;
      c = kEven[k] - r2 * c;
    }
    sin_out[i] = c;       // sin(a) = cos(r)
    cos_out[i] = -r * s;  // cos(a) = -sin(r)
  }
}

}  // namespace

WeightsStage::WeightsStage(const SolverModel& model, bool follow_paths)
    : model_(model),
      refinements_(follow_paths && !model.weights.marker_paths.empty() ? model.params.weight_refinements : 0),
      qp_(model.shape_count(), model.params.weight_qp_iteration_cap), H_(model.shape_count(), model.shape_count()),
      g_(model.shape_count()), previous_(Eigen::VectorXd::Zero(model.shape_count())), previous_linear_(previous_),
      residual_(3 * model.marker_count()), present_(model.marker_count()) {
  if (refinements_ > 0) {
    const std::size_t P = model.weights.marker_paths.size();
    gram_present_.resize(model.shape_count(), model.shape_count());
    turning_of_shape_.assign(std::size_t(model.shape_count()), -1);
    for (const auto& path : model.weights.marker_paths) {
      if (turning_of_shape_[std::size_t(path.shape)] >= 0) continue;
      turning_of_shape_[std::size_t(path.shape)] = int(turning_shapes_.size());
      turning_shapes_.push_back(path.shape);
    }
    cross_.resize(model.shape_count(), Eigen::Index(turning_shapes_.size()));
    path_turn_.resize(P);
    path_cos_.resize(P);
    path_sin_.resize(P);
    path_difference_.resize(3, Eigen::Index(P));
    path_start_.assign(std::size_t(model.marker_count()) + 1, 0);
    for (const auto& path : model.weights.marker_paths) ++path_start_[std::size_t(path.marker) + 1];
    for (std::size_t k = 0; k < std::size_t(model.marker_count()); ++k) path_start_[k + 1] += path_start_[k];
    path_of_marker_.resize(model.weights.marker_paths.size());
    std::vector<int> fill(path_start_.begin(), path_start_.end() - 1);
    for (std::size_t i = 0; i < model.weights.marker_paths.size(); ++i)
      path_of_marker_[std::size_t(fill[std::size_t(model.weights.marker_paths[i].marker)]++)] = int(i);
  }
}

// One Gauss-Newton step: linearise the marker model x0 + sum_i f_i(w_i) at w and solve
// the same box-constrained ridge problem for the new w. The Jacobian is B~ plus a
// 3-vector D_p per marker path, so J^T J is the Gram matrix already built plus sparse
// corrections rather than a dense product.
inline bool WeightsStage::refine(const Eigen::Matrix3Xd& targets, Eigen::VectorXd& w) noexcept {
  const SolverModel& m = model_;
  const Eigen::Index K = m.marker_count(), M = m.shape_count();
  const SolverParams& p = m.params;
  // c = m - x0 - f(w) + J w; start with the linear part, c = m - x0.
  for (Eigen::Index k = 0; k < K; ++k)
    residual_.segment<3>(3 * k) = present_[k] ? Eigen::Vector3d(targets.col(k) - m.weights.marker_neutral.segment<3>(3 * k))
                                              : Eigen::Vector3d::Zero();
  H_ = gram_present_;
  cross_.setZero();
  const auto& paths = m.weights.marker_paths;
  for (std::size_t i = 0; i < paths.size(); ++i) path_turn_[i] = w[paths[i].shape] * paths[i].angle;
  sin_cos_turns(path_turn_, path_sin_, path_cos_);
  for (std::size_t i = 0; i < paths.size(); ++i) {
    const MarkerPath& path = paths[i];
    if (!present_[path.marker]) { path_difference_.col(Eigen::Index(i)).setZero(); continue; }
    const double t = w[path.shape];
    const double c = path_cos_[i], sn = path_sin_[i];
    const Eigen::Vector3d turned = c * path.arm + sn * path.axis_cross_arm;  // exp(t r) arm
    const Eigen::Vector3d linear_delta = m.weights.marker_basis.block<3, 1>(3 * path.marker, path.shape);
    const Eigen::Vector3d slope = path.angle * (c * path.axis_cross_arm - sn * path.arm) + path.axial;  // r x turned + axial
    const Eigen::Vector3d difference = slope - linear_delta;  // D_p
    path_difference_.col(Eigen::Index(i)) = difference;
    // f(t) - t B~ replaced by its tangent: - (f(t) - t B~) + t D_p.
    residual_.segment<3>(3 * path.marker) -= turned - path.arm + t * path.axial - t * linear_delta - t * difference;
    // B~^T D_p into the shape's column of cross_, from the marker's three rows of B~.
    double* __restrict column = cross_.col(turning_of_shape_[std::size_t(path.shape)]).data();
    const double* rows = m.weights.marker_basis_rows.row(3 * path.marker).data();
    for (Eigen::Index j = 0; j < M; ++j)
      column[j] += rows[j] * difference[0] + rows[M + j] * difference[1] + rows[2 * M + j] * difference[2];
  }
  // J^T J = B~^T B~ + C + C^T + D^T D, C's nonzero columns being the turning shapes'.
  for (std::size_t i = 0; i < turning_shapes_.size(); ++i) {
    const int shape = turning_shapes_[i];
    H_.col(shape) += cross_.col(Eigen::Index(i));
    H_.row(shape) += cross_.col(Eigen::Index(i)).transpose();
  }
  // D_p^T D_q for the paths on each marker (each pair once, mirrored).
  for (Eigen::Index k = 0; k < K; ++k)
    for (int a = path_start_[std::size_t(k)]; a < path_start_[std::size_t(k) + 1]; ++a)
      for (int b = a; b < path_start_[std::size_t(k) + 1]; ++b) {
        const int i = path_of_marker_[std::size_t(a)], j = path_of_marker_[std::size_t(b)];
        const double d = path_difference_.col(i).dot(path_difference_.col(j));
        const int si = paths[std::size_t(i)].shape, sj = paths[std::size_t(j)].shape;
        H_(si, sj) += d;
        if (a != b) H_(sj, si) += d;
      }
  H_.diagonal().array() += p.alpha + p.mu;
  g_.noalias() = m.weights.marker_basis.transpose() * residual_;
  for (std::size_t i = 0; i < paths.size(); ++i)
    g_[paths[i].shape] += path_difference_.col(Eigen::Index(i)).dot(residual_.segment<3>(3 * paths[i].marker));
  g_ += p.alpha * previous_;
  return qp_.solve(H_, g_, 0.0, 1.0, w).converged;
}

WeightsStage::Result WeightsStage::solve(const Eigen::Matrix3Xd& targets, std::span<const uint8_t> present,
                                         Eigen::VectorXd& weights) noexcept {
  const SolverModel& m = model_;
  const Eigen::Index K = m.marker_count(), M = m.shape_count();
  const SolverParams& p = m.params;
  H_ = m.weights.gram_all;
  uint32_t used = 0;
  for (Eigen::Index k = 0; k < K; ++k) {
    present_[k] = present[std::size_t(k)] != 0 && targets.col(k).allFinite();
    if (present_[k]) {
      residual_.segment<3>(3 * k) = targets.col(k) - m.weights.marker_neutral.segment<3>(3 * k);
      ++used;
    } else {
      residual_.segment<3>(3 * k).setZero();
      H_ -= m.weights.gram_per_marker.middleCols(k * M, M);
    }
  }
  if (refinements_ > 0) gram_present_ = H_;
  H_.diagonal().array() += p.alpha + p.mu;
  g_.noalias() = m.weights.marker_basis.transpose() * residual_;
  g_ += p.alpha * previous_;
  // Warm start: the last frame's solution of this same problem, whose bounds are the
  // likeliest to hold again (the refined weights' differ more).
  weights = previous_linear_;
  bool converged = qp_.solve(H_, g_, 0.0, 1.0, weights).converged;
  previous_linear_ = weights;
  for (int i = 0; i < refinements_; ++i) converged &= refine(targets, weights);
  previous_ = weights;
  return {used, !converged};
}

void WeightsStage::reset() noexcept {
  previous_.setZero();
  previous_linear_.setZero();
}

bool WeightsStage::save(State& state) const noexcept {
  if (state.previous.size() != previous_.size() || state.previous_linear.size() != previous_linear_.size()) return false;
  state.previous = previous_;  // same sizes: no allocation
  state.previous_linear = previous_linear_;
  return true;
}

bool WeightsStage::restore(const State& state) noexcept {
  if (state.previous.size() != previous_.size() || state.previous_linear.size() != previous_linear_.size()) return false;
  previous_ = state.previous;
  previous_linear_ = state.previous_linear;
  return true;
}

bool WeightsStage::usable(std::span<const uint8_t> present, const Eigen::Matrix3Xd& targets) const noexcept {
  uint32_t n = 0;
  for (Eigen::Index k = 0; k < model_.marker_count(); ++k) n += present[std::size_t(k)] && targets.col(k).allFinite();
  return n >= kMinimumMarkers;
}

}  // namespace facecap
