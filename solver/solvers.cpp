// The per-frame solvers: nonlinear (the paper), linear, dt and meshik baselines.
// Everything here after construction is real-time safe unless said otherwise.
#include <array>
#include <cmath>

#include <fmt/format.h>

#include "core/error.hpp"
#include "core/time.hpp"
#include "solver/box_qp.hpp"
#include "solver/face_solver.hpp"
#include "solver/solver_model.hpp"

namespace facecap {
namespace {

constexpr std::array<std::string_view, 4> kSolverNames = {"nonlinear", "linear", "dt", "meshik"};
constexpr uint32_t kMinimumMarkers = 3;  // fewer cannot pin position and orientation

class StageClock {
 public:
  explicit StageClock(SolveResult& out) : out_(out), start_(monotonic_now_ns()), last_(start_) { out.stage_ns.fill(0); }
  void lap(SolveStage stage) noexcept {
    const int64_t now = monotonic_now_ns();
    out_.stage_ns[std::size_t(stage)] += now - last_;
    last_ = now;
  }
  void finish() noexcept { out_.total_ns = monotonic_now_ns() - start_; }

 private:
  SolveResult& out_;
  int64_t start_, last_;
};

// Eq. 2: w = argmin |B~ w - (m - x0~)|^2 + alpha |w - w_prev|^2 + mu |w|^2, 0 <= w <= 1,
// on the rows of the present markers. H starts from the all-markers Gram matrix and
// loses the missing markers' blocks, so its cost follows the dropouts, not K.
class WeightsStage {
 public:
  // follow_paths: refine along the marker paths of the nonlinear blend (params.weight_refinements).
  WeightsStage(const SolverModel& model, bool follow_paths)
      : model_(model), refinements_(follow_paths && !model.marker_paths.empty() ? model.params.weight_refinements : 0),
        qp_(model.shape_count()), H_(model.shape_count(), model.shape_count()), g_(model.shape_count()),
        previous_(Eigen::VectorXd::Zero(model.shape_count())), residual_(3 * model.marker_count()),
        present_(model.marker_count()) {
    if (refinements_ > 0) {
      jacobian_.resize(3 * model.marker_count(), model.shape_count());
      predicted_.resize(3 * model.marker_count());
    }
  }

  // Returns the number of markers used. Real-time safe.
  uint32_t solve(const Eigen::Matrix3Xd& targets, std::span<const uint8_t> present, Eigen::VectorXd& weights) noexcept {
    const SolverModel& m = model_;
    const Eigen::Index K = m.marker_count(), M = m.shape_count();
    const SolverParams& p = m.params;
    H_ = m.gram_all;
    uint32_t used = 0;
    for (Eigen::Index k = 0; k < K; ++k) {
      present_[k] = present[std::size_t(k)] != 0 && targets.col(k).allFinite();
      if (present_[k]) {
        residual_.segment<3>(3 * k) = targets.col(k) - m.marker_neutral.segment<3>(3 * k);
        ++used;
      } else {
        residual_.segment<3>(3 * k).setZero();
        H_ -= m.gram_per_marker.middleCols(k * M, M);
      }
    }
    H_.diagonal().array() += p.alpha + p.mu;
    g_.noalias() = m.marker_basis.transpose() * residual_;
    g_ += p.alpha * previous_;
    weights = previous_;
    qp_.solve(H_, g_, 0.0, 1.0, weights);
    for (int i = 0; i < refinements_; ++i) refine(targets, weights);
    previous_ = weights;
    return used;
  }
  void reset() noexcept { previous_.setZero(); }
  bool usable(std::span<const uint8_t> present, const Eigen::Matrix3Xd& targets) const noexcept {
    uint32_t n = 0;
    for (Eigen::Index k = 0; k < model_.marker_count(); ++k) n += present[std::size_t(k)] && targets.col(k).allFinite();
    return n >= kMinimumMarkers;
  }

 private:
  // One Gauss-Newton step: linearise the marker model x0 + sum_i f_i(w_i) at w and solve
  // the same box-constrained ridge problem for the new w.
  void refine(const Eigen::Matrix3Xd& targets, Eigen::VectorXd& w) noexcept {
    const SolverModel& m = model_;
    const Eigen::Index K = m.marker_count();
    const SolverParams& p = m.params;
    jacobian_ = m.marker_basis;
    predicted_.noalias() = m.marker_basis * w;
    for (const MarkerPath& path : m.marker_paths) {
      const double t = w[path.shape];
      const Eigen::Matrix3d R = rotation_exp(t * path.rotation);
      const Eigen::Vector3d turned = R * path.arm;
      auto rows = predicted_.segment<3>(3 * path.marker);
      rows += turned - path.arm + t * path.axial - t * m.marker_basis.block<3, 1>(3 * path.marker, path.shape);
      jacobian_.block<3, 1>(3 * path.marker, path.shape) = path.rotation.cross(turned) + path.axial;
    }
    for (Eigen::Index k = 0; k < K; ++k) {
      if (present_[k]) {
        residual_.segment<3>(3 * k) = targets.col(k) - m.marker_neutral.segment<3>(3 * k) - predicted_.segment<3>(3 * k);
      } else {
        residual_.segment<3>(3 * k).setZero();
        jacobian_.middleRows<3>(3 * k).setZero();
      }
    }
    residual_.noalias() += jacobian_ * w;
    H_.noalias() = jacobian_.transpose() * jacobian_;
    H_.diagonal().array() += p.alpha + p.mu;
    g_.noalias() = jacobian_.transpose() * residual_;
    g_ += p.alpha * previous_;
    qp_.solve(H_, g_, 0.0, 1.0, w);
  }

  const SolverModel& model_;
  int refinements_;
  BoxQpSolver qp_;
  Eigen::MatrixXd H_, jacobian_;
  Eigen::VectorXd g_, previous_, residual_, predicted_;
  Eigen::Array<bool, Eigen::Dynamic, 1> present_;
};

// x0 + B w over the active weights and each shape's non-zero vertices.
void linear_blend(const SolverModel& m, const Eigen::VectorXd& w, Eigen::Matrix3Xd& out) noexcept {
  out = m.rig.neutral;
  double* x = out.data();
  for (Eigen::Index s = 0; s < m.shape_count(); ++s) {
    const double ws = w[s];
    if (ws <= m.params.active_weight) continue;
    const auto& d = m.shape_deltas[std::size_t(s)];
    const float* delta = d.deltas.data();
    for (std::size_t i = 0; i < d.vertices.size(); ++i) {
      double* p = x + 3 * d.vertices[i];
      p[0] += ws * delta[3 * i];
      p[1] += ws * delta[3 * i + 1];
      p[2] += ws * delta[3 * i + 2];
    }
  }
}

class LinearSolver final : public FaceSolver {
 public:
  explicit LinearSolver(std::shared_ptr<const SolverModel> model) : FaceSolver(std::move(model)), weights_(*model_, false) {}
  std::string_view name() const noexcept override { return "linear"; }
  void reset() noexcept override { weights_.reset(); }
  void solve(const Eigen::Matrix3Xd& targets, std::span<const uint8_t> present, SolveResult& out) noexcept override {
    StageClock clock(out);
    out.held = !weights_.usable(present, targets);
    out.collision_pairs = out.collision_constraints = 0;
    if (out.held) { clock.finish(); return; }
    out.markers_used = weights_.solve(targets, present, out.weights);
    clock.lap(SolveStage::kWeights);
    linear_blend(*model_, out.weights, out.vertices);
    clock.lap(SolveStage::kBlend);
    clock.finish();
  }
  void solve_with_weights(const Eigen::VectorXd& weights, const Eigen::Matrix3Xd&, std::span<const uint8_t>,
                          SolveResult& out) noexcept override {
    StageClock clock(out);
    out.held = false;
    out.weights = weights;
    linear_blend(*model_, out.weights, out.vertices);
    clock.lap(SolveStage::kBlend);
    clock.finish();
  }

 private:
  WeightsStage weights_;
};

// Eq. 4-5 with the matrix factored once: the right-hand side G^T W T(w) + beta C^T b is
// built over the triangles the active shapes touch, back-substituted, then corrected for
// missing markers and collision pins by a low-rank (Woodbury) update.
class PoissonSolver : public FaceSolver {
 public:
  enum class Blend { kNonlinear, kDeformationTransfer };

  PoissonSolver(std::shared_ptr<const SolverModel> model, Blend blend)
      : FaceSolver(std::move(model)), blend_(blend), weights_(*model_, blend == Blend::kNonlinear) {
    const SolverModel& m = *model_;
    const Eigen::Index T = m.rig.triangle_count(), N = m.vertex_count(), K = m.marker_count();
    blend_sum_.setZero(9, T);
    touched_flag_.assign(std::size_t(T), 0);
    touched_.reserve(std::size_t(T));
    // G^T W G x0, the right-hand side of T = I everywhere.
    identity_rhs_.setZero(3, N);
    for (Eigen::Index t = 0; t < T; ++t) {
      const Eigen::Map<const Eigen::Matrix3d> Q(m.triangle_operator.col(t).data());
      for (int k = 0; k < 3; ++k) identity_rhs_.col(m.rig.triangles(k, t)) += Q.col(k);
    }
    rhs_.resize(3, N);
    work_.resize(3, N);
    const Eigen::Index capacity = K + Eigen::Index(m.collision_vertices.size());
    modification_.resize(capacity);
    modification_scale_.resize(capacity);
    small_.resize(capacity, capacity);
    small_rhs_.resize(capacity, 3);
    pivot_.resize(capacity);
  }

  std::string_view name() const noexcept override { return blend_ == Blend::kNonlinear ? "nonlinear" : "dt"; }
  void reset() noexcept override { weights_.reset(); }

  void solve(const Eigen::Matrix3Xd& targets, std::span<const uint8_t> present, SolveResult& out) noexcept override {
    StageClock clock(out);
    out.held = !weights_.usable(present, targets);
    out.collision_pairs = out.collision_constraints = 0;
    if (out.held) { clock.finish(); return; }
    out.markers_used = weights_.solve(targets, present, out.weights);
    clock.lap(SolveStage::kWeights);
    solve_mesh(targets, present, out, clock);
  }

  void solve_with_weights(const Eigen::VectorXd& weights, const Eigen::Matrix3Xd& targets,
                          std::span<const uint8_t> present, SolveResult& out) noexcept override {
    StageClock clock(out);
    out.held = false;
    out.collision_pairs = out.collision_constraints = 0;
    out.weights = weights;
    solve_mesh(targets, present, out, clock);
  }

 private:
  // Eq. 4, Eq. 5 and collisions for out.weights.
  void solve_mesh(const Eigen::Matrix3Xd& targets, std::span<const uint8_t> present, SolveResult& out,
                  StageClock& clock) noexcept {
    const SolverModel& m = *model_;
    blend(out.weights);
    clock.lap(SolveStage::kBlend);

    rhs_ = identity_rhs_;
    for (int t : touched_) {
      const Eigen::Map<const Eigen::Matrix3d> Q(m.triangle_operator.col(t).data());
      const Eigen::Map<const Eigen::Matrix3d> T_minus_I(blend_sum_.col(t).data());
      const Eigen::Matrix3d contribution = T_minus_I * Q;
      for (int k = 0; k < 3; ++k) rhs_.col(m.rig.triangles(k, t)) += contribution.col(k);
    }
    modification_count_ = 0;
    const double beta = m.params.beta;
    for (Eigen::Index k = 0; k < m.marker_count(); ++k) {
      const auto& b = m.markers[std::size_t(k)];
      if (present[std::size_t(k)] && targets.col(k).allFinite()) {
        for (int a = 0; a < 3; ++a) rhs_.col(b.vertices[a]) += beta * b.barycentric[a] * targets.col(k);
      } else {
        add_modification(k, -beta);
      }
    }
    clock.lap(SolveStage::kRhs);

    m.factor->solve_in_place(rhs_, work_);
    apply_modifications(rhs_, out.vertices);
    clock.lap(SolveStage::kBacksolve);
    clock.lap(SolveStage::kCollide);
    clock.finish();
  }

  // Sums the active shapes' per-triangle terms, then turns each touched triangle's sum
  // into T_j - I: Eq. 4 for nonlinear, sum w_i (F_ij - I) for dt.
  void blend(const Eigen::VectorXd& w) noexcept {
    const SolverModel& m = *model_;
    for (int t : touched_) { blend_sum_.col(t).setZero(); touched_flag_[std::size_t(t)] = 0; }
    touched_.clear();
    for (Eigen::Index s = 0; s < m.shape_count(); ++s) {
      const double ws = w[s];
      if (ws <= m.params.active_weight) continue;
      const auto& terms = m.shape_terms[std::size_t(s)];
      const std::size_t n = terms.triangles.size();
      for (std::size_t e = 0; e < n; ++e) {
        const int t = terms.triangles[e];
        if (!touched_flag_[std::size_t(t)]) { touched_flag_[std::size_t(t)] = 1; touched_.push_back(t); }
        double* sum = blend_sum_.col(t).data();
        if (blend_ == Blend::kNonlinear) {
          const float* r = &terms.log_rotation[3 * e];
          const float* st = &terms.stretch[6 * e];
          for (int k = 0; k < 3; ++k) sum[k] += ws * r[k];
          for (int k = 0; k < 6; ++k) sum[3 + k] += ws * st[k];
        } else {
          const float* g = &terms.gradient[9 * e];
          for (int k = 0; k < 9; ++k) sum[k] += ws * g[k];
        }
      }
    }
    if (blend_ == Blend::kDeformationTransfer) return;
    for (int t : touched_) {
      double* sum = blend_sum_.col(t).data();
      const Eigen::Matrix3d R = rotation_exp(Eigen::Vector3d(sum[0], sum[1], sum[2]));
      Eigen::Matrix3d S;
      S << 1 + sum[3], sum[6], sum[7], sum[6], 1 + sum[4], sum[8], sum[7], sum[8], 1 + sum[5];
      Eigen::Map<Eigen::Matrix3d> T_minus_I(sum);
      T_minus_I = R * S - Eigen::Matrix3d::Identity();
    }
  }

  void add_modification(Eigen::Index column, double scale) noexcept {
    modification_[modification_count_] = int(column);
    modification_scale_[modification_count_] = scale;
    ++modification_count_;
  }

  // x = y - Z_S (D^-1 + U_S^T Z_S)^-1 U_S^T y: A0 modified by sum d_i u_i u_i^T, solved
  // without refactoring (Woodbury). y: A0^-1 r, 3 x N.
  void apply_modifications(const Eigen::Matrix3Xd& y, Eigen::Matrix3Xd& x) noexcept {
    const SolverModel& m = *model_;
    x = y;
    const Eigen::Index s = modification_count_;
    if (s == 0) return;
    const Eigen::Index K = m.marker_count();
    for (Eigen::Index i = 0; i < s; ++i) {
      const int ci = modification_[i];
      for (Eigen::Index j = 0; j < s; ++j) small_(i, j) = m.modification_gram(ci, modification_[j]);
      small_(i, i) += 1.0 / modification_scale_[i];
      Eigen::Vector3d uy = Eigen::Vector3d::Zero();
      if (ci < K) {
        const auto& b = m.markers[std::size_t(ci)];
        for (int a = 0; a < 3; ++a) uy += b.barycentric[a] * y.col(b.vertices[a]);
      } else {
        uy = y.col(m.collision_vertices[std::size_t(ci - K)]);
      }
      small_rhs_.row(i) = uy.transpose();
    }
    // Gaussian elimination with partial pivoting (the system is symmetric indefinite).
    for (Eigen::Index c = 0; c < s; ++c) {
      Eigen::Index p = c;
      for (Eigen::Index r = c + 1; r < s; ++r)
        if (std::abs(small_(r, c)) > std::abs(small_(p, c))) p = r;
      if (p != c) { small_.row(c).head(s).swap(small_.row(p).head(s)); small_rhs_.row(c).swap(small_rhs_.row(p)); }
      const double d = small_(c, c);
      if (d == 0.0) return;  // singular: keep the uncorrected solve
      for (Eigen::Index r = c + 1; r < s; ++r) {
        const double f = small_(r, c) / d;
        if (f == 0.0) continue;
        for (Eigen::Index k = c; k < s; ++k) small_(r, k) -= f * small_(c, k);
        small_rhs_.row(r) -= f * small_rhs_.row(c);
      }
    }
    for (Eigen::Index c = s - 1; c >= 0; --c) {
      Eigen::RowVector3d v = small_rhs_.row(c);
      for (Eigen::Index k = c + 1; k < s; ++k) v -= small_(c, k) * small_rhs_.row(k);
      small_rhs_.row(c) = v / small_(c, c);
    }
    for (Eigen::Index i = 0; i < s; ++i) {
      const auto z = m.modification_solution.col(modification_[i]);
      const Eigen::Vector3d q = small_rhs_.row(i).transpose();
      x.noalias() -= q * z.transpose();
    }
  }

  Blend blend_;
  WeightsStage weights_;
  Eigen::Matrix<double, 9, Eigen::Dynamic> blend_sum_;  // per triangle; T_j - I after blend()
  std::vector<uint8_t> touched_flag_;
  std::vector<int> touched_;
  Eigen::Matrix3Xd identity_rhs_, rhs_, work_;
  Eigen::VectorXi modification_;
  Eigen::VectorXd modification_scale_;
  Eigen::Index modification_count_ = 0;
  Eigen::MatrixXd small_;
  Eigen::Matrix<double, Eigen::Dynamic, 3> small_rhs_;
  Eigen::VectorXi pivot_;
};

}  // namespace

SolveResult FaceSolver::make_result() const {
  SolveResult r;
  r.weights.setZero(model_->shape_count());
  r.vertices = model_->rig.neutral;
  return r;
}

std::span<const std::string_view> solver_names() noexcept { return kSolverNames; }

std::unique_ptr<FaceSolver> make_solver(std::string_view name, std::shared_ptr<const SolverModel> model) {
  if (!model) throw Error("make_solver: no solver model");
  if (name == "nonlinear") return std::make_unique<PoissonSolver>(std::move(model), PoissonSolver::Blend::kNonlinear);
  if (name == "dt") return std::make_unique<PoissonSolver>(std::move(model), PoissonSolver::Blend::kDeformationTransfer);
  if (name == "linear") return std::make_unique<LinearSolver>(std::move(model));
  throw Error(fmt::format("unknown solver '{}': choose nonlinear, linear, dt or meshik", name));
}

}  // namespace facecap
