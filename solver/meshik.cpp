// MeshIK baseline: Gauss-Newton on the weights with the mesh eliminated (variable
// projection). See meshik.hpp for the energy.
#include "solver/meshik.hpp"

#include <algorithm>
#include <array>
#include <cmath>

#include <Eigen/LU>

#include "core/error.hpp"
#include "core/time.hpp"
#include "solver/box_qp.hpp"
#include "solver/solver_model.hpp"

namespace facecap {
namespace {

using Matrix32 = Eigen::Matrix<double, 3, 2>;

// S from its six stored entries (xx, yy, zz, xy, xz, yz), plus `diagonal` on the diagonal.
Eigen::Matrix3d symmetric_from6(const double* s, double diagonal) {
  Eigen::Matrix3d S;
  S << diagonal + s[0], s[3], s[4], s[3], diagonal + s[1], s[5], s[4], s[5], diagonal + s[2];
  return S;
}

// Calls f(triangle, v) for every triangle `shape` changes, v being its Eq. 3 terms: the
// rotation log, then S - I in world coordinates (xx, yy, zz, xy, xz, yz; nothing along
// the rest normal, which no residual sees).
template <class F>
void for_each_changed_triangle(const SolverModel& m, Eigen::Index shape, F&& f) {
  constexpr int B = ShapeBlocks::kBlock;
  constexpr int C = BlendData::kNonlinearComponents;
  double stored[C * B];
  for (const int32_t e : m.blend.triangle_blocks.entries_of_shape(shape)) {
    const std::size_t first = std::size_t(m.blend.triangle_blocks.entries[std::size_t(e)].block) * B;
    m.blend.triangle_nonlinear.decode(e, stored);
    for (int i = 0; i < B; ++i) {
      const int32_t t = m.blend.triangle_blocks.element_of_slot[first + std::size_t(i)];
      if (t < 0) continue;
      double local[C];
      bool changes = false;
      for (int c = 0; c < C; ++c) {
        local[c] = stored[c * B + i];
        changes = changes || local[c] != 0.0;
      }
      if (!changes) continue;
      const Eigen::Matrix3d s = m.blend.world_stretch(t, local + 3);
      const std::array<double, 9> v = {local[0], local[1], local[2], s(0, 0), s(1, 1), s(2, 2), s(0, 1), s(0, 2), s(1, 2)};
      f(Eigen::Index(t), v);
    }
  }
}

}  // namespace

struct MeshIkSolver::State {
  State(const SolverModel& model, const MeshIkOptions& opts, std::unique_ptr<FaceSolver> eq2_solver)
      : m(model), options(opts), eq2(std::move(eq2_solver)), qp(model.shape_count(), model.params.weight_qp_iteration_cap) {}

  const SolverModel& m;
  MeshIkOptions options;
  std::unique_ptr<FaceSolver> eq2;  // the linear solver: its Eq. 2 weights start Gauss-Newton
  SolveResult eq2_result;
  BoxQpSolver qp;

  Eigen::Index N = 0, T = 0, K = 0, M = 0;
  double sqrt_beta = 0.0;
  // The hold A0 has (CollisionData::held_vertices held to x0 + B w with h_v beta): its
  // share of the right-hand side and its residual rows.
  Eigen::Index V = 0;                // held vertices
  Eigen::VectorXd hold_weight;       // V: h_v beta
  Eigen::Matrix3Xd held_reference;   // 3 x V: (x0 + B w)_v at the current point
  std::vector<uint8_t> shape_moves;  // M: the shape deforms a triangle or moves a held vertex

  // Per triangle j (column j), both 3 x 2 column-major: sqrt(area) grad^T E and
  // sqrt(area) E, with E an orthonormal basis of the rest triangle's plane, so that the
  // triangle's residual is X_j vertex_projection - T_j target_projection.
  Eigen::Matrix<double, 6, Eigen::Dynamic> vertex_projection, target_projection;
  std::vector<int> live_triangles;    // non-degenerate: the ones with a residual
  std::vector<int> shaped_triangles;  // touched by at least one shape
  Eigen::Matrix3Xd identity_rhs;      // right-hand side of T = I everywhere

  // The current point of evaluate(): per-triangle blend sums and transforms.
  Eigen::Matrix<double, 3, Eigen::Dynamic> log_sum;      // sum_i w_i log R_ij
  Eigen::Matrix<double, 6, Eigen::Dynamic> stretch_sum;  // sum_i w_i (S_ij - I)
  Eigen::Matrix<double, 9, Eigen::Dynamic> rotation, stretch, transform;  // R_j, S_j, T_j
  Eigen::Matrix3Xd rhs, x, column_rhs;
  Eigen::Matrix4Xd work;
  Eigen::VectorXd residual;  // 6 T triangle entries, 3 K marker entries, 3 V held entries
  Eigen::MatrixXd jacobian;  // residual rows x M
  std::vector<double> transform_derivative;  // 9 per triangle of the shape being differentiated

  Eigen::MatrixXd JtJ, H;
  Eigen::VectorXd Jtf, g, w, trial, damping;

  // Missing markers: A = A0 - beta sum_{k missing} c_k c_k^T by Woodbury.
  const Eigen::Matrix3Xd* targets = nullptr;
  std::vector<uint8_t> usable;  // K
  std::vector<int> missing;
  Eigen::PartialPivLU<Eigen::MatrixXd> woodbury;
  Eigen::Matrix<double, Eigen::Dynamic, 3> small_rhs, small_solution;

  // Stage timing of the current solve.
  std::array<int64_t, kSolveStageCount>* stage_ns = nullptr;
  int64_t last_lap_ns = 0;
  MeshIkReport report;
  bool qp_iteration_cap = false;  // a Gauss-Newton step's box QP stopped at its cap

  void lap(SolveStage stage) noexcept {
    const int64_t now = monotonic_now_ns();
    if (stage_ns) (*stage_ns)[std::size_t(stage)] += now - last_lap_ns;
    last_lap_ns = now;
  }

  void configure() {
    const Rig& rig = m.rig;
    N = m.vertex_count();
    T = rig.triangle_count();
    K = m.marker_count();
    M = m.shape_count();
    sqrt_beta = std::sqrt(m.params.beta);
    V = Eigen::Index(m.collision.held_vertices.size());
    hold_weight = Eigen::Map<const Eigen::VectorXd>(m.collision.held_weights.data(), V) * m.params.beta;
    held_reference.resize(3, V);
    vertex_projection.setZero(6, T);
    target_projection.setZero(6, T);
    identity_rhs.setZero(3, N);
    const double scale = bounding_box(rig.neutral).size().squaredNorm();
    for (Eigen::Index t = 0; t < T; ++t) {
      const Eigen::Vector3i tri = rig.triangles.col(t);
      const Eigen::Vector3d x0 = rig.neutral.col(tri[0]), x1 = rig.neutral.col(tri[1]), x2 = rig.neutral.col(tri[2]);
      const Eigen::Vector3d n = (x1 - x0).cross(x2 - x0);
      const double twice_area = n.norm();
      // The same test as the model's operator: a degenerate triangle constrains nothing.
      if (twice_area <= 1e-14 * scale || m.blend.triangle_operator.col(t).isZero(0.0)) continue;
      const Eigen::Vector3d unit = n / twice_area;
      Eigen::Matrix3d grad;
      grad.col(0) = unit.cross(x2 - x1) / twice_area;
      grad.col(1) = unit.cross(x0 - x2) / twice_area;
      grad.col(2) = unit.cross(x1 - x0) / twice_area;
      Matrix32 E;
      E.col(0) = (x1 - x0).normalized();
      E.col(1) = unit.cross(E.col(0));
      const double root_area = std::sqrt(0.5 * twice_area);
      Eigen::Map<Matrix32>(vertex_projection.col(t).data()) = root_area * grad.transpose() * E;
      Eigen::Map<Matrix32>(target_projection.col(t).data()) = root_area * E;
      live_triangles.push_back(int(t));
      const Eigen::Map<const Eigen::Matrix3d> Q(m.blend.triangle_operator.col(t).data());
      for (int k = 0; k < 3; ++k) identity_rhs.col(tri[k]) += Q.col(k);
    }
    std::vector<uint8_t> shaped(std::size_t(T), 0);
    for (Eigen::Index i = 0; i < M; ++i)
      for_each_changed_triangle(m, i, [&](Eigen::Index t, const std::array<double, 9>&) { shaped[std::size_t(t)] = 1; });
    for (Eigen::Index t = 0; t < T; ++t)
      if (shaped[std::size_t(t)]) shaped_triangles.push_back(int(t));
    shape_moves.assign(std::size_t(M), 0);
    for (Eigen::Index i = 0; i < M; ++i) {
      bool moves = !m.blend.triangle_blocks.entries_of_shape(i).empty();
      for (const int v : m.collision.held_vertices) moves = moves || !rig.deltas.block<3, 1>(3 * v, i).isZero(0.0);
      shape_moves[std::size_t(i)] = moves;
    }
    log_sum.setZero(3, T);
    stretch_sum.setZero(6, T);
    const Eigen::Matrix3d I = Eigen::Matrix3d::Identity();
    rotation = Eigen::Map<const Eigen::Matrix<double, 9, 1>>(I.data()).replicate(1, T);
    stretch = rotation;
    transform = rotation;
    rhs.resize(3, N);
    x.resize(3, N);
    work.resize(4, N);
    column_rhs.resize(3, N);
    residual.resize(6 * T + 3 * K + 3 * V);
    jacobian.resize(6 * T + 3 * K + 3 * V, M);
    transform_derivative.resize(9 * std::size_t(T));
    JtJ.resize(M, M);
    H.resize(M, M);
    Jtf.resize(M);
    g.resize(M);
    w.resize(M);
    trial.resize(M);
    damping.resize(M);
    usable.assign(std::size_t(K), 0);
    missing.reserve(std::size_t(K));
    eq2_result = eq2->make_result();
  }

  // Which markers pin this frame, and the Woodbury system for the ones that do not.
  void prepare(const Eigen::Matrix3Xd& frame_targets, std::span<const uint8_t> present) {
    targets = &frame_targets;
    missing.clear();
    for (Eigen::Index k = 0; k < K; ++k) {
      const bool ok = present[std::size_t(k)] != 0 && frame_targets.col(k).allFinite();
      usable[std::size_t(k)] = ok;
      if (!ok) missing.push_back(int(k));
    }
    const Eigen::Index s = Eigen::Index(missing.size());
    if (s == 0) return;
    Eigen::MatrixXd small(s, s);
    for (Eigen::Index i = 0; i < s; ++i)
      for (Eigen::Index j = 0; j < s; ++j) {
        const auto& marker = m.markers[std::size_t(missing[std::size_t(i)])];  // c_i^T A0^-1 c_j
        const auto z = m.poisson.marker_solution.col(missing[std::size_t(j)]);
        small(i, j) = marker.barycentric[0] * z[marker.vertices[0]] + marker.barycentric[1] * z[marker.vertices[1]] +
                      marker.barycentric[2] * z[marker.vertices[2]];
      }
    small.diagonal().array() -= 1.0 / m.params.beta;
    woodbury.compute(small);
    small_rhs.resize(s, 3);
    small_solution.resize(s, 3);
  }

  // b = A^-1 b in place, A the matrix with this frame's missing markers removed.
  void solve_system(Eigen::Matrix3Xd& b) {
    m.poisson.factor->solve_in_place(b, work);
    const Eigen::Index s = Eigen::Index(missing.size());
    if (s == 0) return;
    for (Eigen::Index i = 0; i < s; ++i) {
      const auto& marker = m.markers[std::size_t(missing[std::size_t(i)])];
      Eigen::Vector3d uy = Eigen::Vector3d::Zero();
      for (int a = 0; a < 3; ++a) uy += marker.barycentric[a] * b.col(marker.vertices[a]);
      small_rhs.row(i) = uy.transpose();
    }
    small_solution = woodbury.solve(small_rhs);
    for (Eigen::Index i = 0; i < s; ++i) {
      const auto z = m.poisson.marker_solution.col(missing[std::size_t(i)]);
      b.noalias() -= small_solution.row(i).transpose() * z.transpose();
    }
  }

  // T_j(w) on every triangle a shape touches (all weights, however small).
  void blend(const Eigen::VectorXd& weights) {
    for (int t : shaped_triangles) { log_sum.col(t).setZero(); stretch_sum.col(t).setZero(); }
    for (Eigen::Index s = 0; s < M; ++s) {
      const double ws = weights[s];
      if (ws == 0.0) continue;
      for_each_changed_triangle(m, s, [&](Eigen::Index t, const std::array<double, 9>& v) {
        for (int k = 0; k < 3; ++k) log_sum(k, t) += ws * v[std::size_t(k)];
        for (int k = 0; k < 6; ++k) stretch_sum(k, t) += ws * v[std::size_t(3 + k)];
      });
    }
    for (int t : shaped_triangles) {
      const Eigen::Matrix3d R = rotation_exp(log_sum.col(t));
      const Eigen::Matrix3d S = symmetric_from6(stretch_sum.col(t).data(), 1.0);
      Eigen::Map<Eigen::Matrix3d>(rotation.col(t).data()) = R;
      Eigen::Map<Eigen::Matrix3d>(stretch.col(t).data()) = S;
      Eigen::Map<Eigen::Matrix3d>(transform.col(t).data()) = R * S;
    }
  }

  // E(x(w), w): leaves x(w), T(w) and the residual of w in the state.
  double evaluate(const Eigen::VectorXd& weights) {
    ++report.energy_evaluations;
    blend(weights);
    lap(SolveStage::kBlend);
    const Rig& rig = m.rig;
    rhs = identity_rhs;
    for (int t : shaped_triangles) {
      const Eigen::Map<const Eigen::Matrix3d> Q(m.blend.triangle_operator.col(t).data());
      const Eigen::Matrix3d contribution =
          (Eigen::Map<const Eigen::Matrix3d>(transform.col(t).data()) - Eigen::Matrix3d::Identity()) * Q;
      for (int k = 0; k < 3; ++k) rhs.col(rig.triangles(k, t)) += contribution.col(k);
    }
    const double beta = m.params.beta;
    for (Eigen::Index k = 0; k < K; ++k) {
      if (!usable[std::size_t(k)]) continue;
      const auto& b = m.markers[std::size_t(k)];
      for (int a = 0; a < 3; ++a) rhs.col(b.vertices[a]) += beta * b.barycentric[a] * targets->col(k);
    }
    for (Eigen::Index j = 0; j < V; ++j) {
      const int v = m.collision.held_vertices[std::size_t(j)];
      held_reference.col(j) = rig.neutral.col(v) + rig.deltas.middleRows<3>(3 * v) * weights;
      rhs.col(v) += hold_weight[j] * held_reference.col(j);
    }
    lap(SolveStage::kRhs);
    x = rhs;
    solve_system(x);
    lap(SolveStage::kBacksolve);
    triangle_residuals(x, residual, /*with_targets=*/true);
    for (Eigen::Index k = 0; k < K; ++k) {
      auto r = residual.segment<3>(6 * T + 3 * k);
      if (!usable[std::size_t(k)]) { r.setZero(); continue; }
      r = -targets->col(k);
      const auto& b = m.markers[std::size_t(k)];
      for (int a = 0; a < 3; ++a) r += b.barycentric[a] * x.col(b.vertices[a]);
      r *= sqrt_beta;
    }
    for (Eigen::Index j = 0; j < V; ++j)
      residual.segment<3>(6 * T + 3 * K + 3 * j) =
          std::sqrt(hold_weight[j]) * (x.col(m.collision.held_vertices[std::size_t(j)]) - held_reference.col(j));
    lap(SolveStage::kWeights);  // the residual belongs to the Gauss-Newton step
    return residual.squaredNorm();
  }

  // Triangle rows of the residual (X_j P_j - T_j B_j), or of its x part only.
  template <typename Out>
  void triangle_residuals(const Eigen::Matrix3Xd& positions, Out&& out, bool with_targets) {
    const Rig& rig = m.rig;
    for (int t : live_triangles) {
      const Eigen::Map<const Matrix32> P(vertex_projection.col(t).data());
      Matrix32 r = positions.col(rig.triangles(0, t)) * P.row(0) + positions.col(rig.triangles(1, t)) * P.row(1) +
                   positions.col(rig.triangles(2, t)) * P.row(2);
      if (with_targets)
        r.noalias() -= Eigen::Map<const Eigen::Matrix3d>(transform.col(t).data()) *
                       Eigen::Map<const Matrix32>(target_projection.col(t).data());
      out.template segment<6>(6 * t) = Eigen::Map<const Eigen::Matrix<double, 6, 1>>(r.data());
    }
  }

  // d residual / d w at the last evaluated point, column by column.
  void build_jacobian() {
    const Rig& rig = m.rig;
    const double h = options.difference_step;
    jacobian.setZero();
    for (Eigen::Index i = 0; i < M; ++i) {
      if (!shape_moves[std::size_t(i)]) continue;  // its column is zero
      column_rhs.setZero();
      for_each_changed_triangle(m, i, [&](Eigen::Index t, const std::array<double, 9>& v) {
        Eigen::Map<Eigen::Matrix3d> dT(&transform_derivative[9 * std::size_t(t)]);
        const Eigen::Vector3d L = log_sum.col(t);
        const Eigen::Vector3d l(v[0], v[1], v[2]);
        const Eigen::Matrix3d dR = (rotation_exp(L + h * l) - rotation_exp(L - h * l)) / (2.0 * h);
        double s[6];
        for (int k = 0; k < 6; ++k) s[k] = v[std::size_t(3 + k)];
        dT = dR * Eigen::Map<const Eigen::Matrix3d>(stretch.col(t).data()) +
             Eigen::Map<const Eigen::Matrix3d>(rotation.col(t).data()) * symmetric_from6(s, 0.0);
        const Eigen::Map<const Eigen::Matrix3d> Q(m.blend.triangle_operator.col(t).data());
        const Eigen::Matrix3d contribution = dT * Q;
        for (int k = 0; k < 3; ++k) column_rhs.col(rig.triangles(k, t)) += contribution.col(k);
      });
      for (Eigen::Index j = 0; j < V; ++j) {
        const int v = m.collision.held_vertices[std::size_t(j)];
        column_rhs.col(v) += hold_weight[j] * rig.deltas.block<3, 1>(3 * v, i);
      }
      solve_system(column_rhs);  // dx / dw_i
      auto column = jacobian.col(i);
      triangle_residuals(column_rhs, column, /*with_targets=*/false);
      for_each_changed_triangle(m, i, [&](Eigen::Index t, const std::array<double, 9>&) {
        const Eigen::Map<const Eigen::Matrix3d> dT(&transform_derivative[9 * std::size_t(t)]);
        Matrix32 d = dT * Eigen::Map<const Matrix32>(target_projection.col(t).data());
        column.segment<6>(6 * t) -= Eigen::Map<const Eigen::Matrix<double, 6, 1>>(d.data());
      });
      for (Eigen::Index k = 0; k < K; ++k) {
        if (!usable[std::size_t(k)]) continue;
        const auto& b = m.markers[std::size_t(k)];
        Eigen::Vector3d r = Eigen::Vector3d::Zero();
        for (int a = 0; a < 3; ++a) r += b.barycentric[a] * column_rhs.col(b.vertices[a]);
        column.segment<3>(6 * T + 3 * k) = sqrt_beta * r;
      }
      for (Eigen::Index j = 0; j < V; ++j) {
        const int v = m.collision.held_vertices[std::size_t(j)];
        column.segment<3>(6 * T + 3 * K + 3 * j) =
            std::sqrt(hold_weight[j]) * (column_rhs.col(v) - rig.deltas.block<3, 1>(3 * v, i));
      }
    }
  }

  // Levenberg-damped Gauss-Newton from `w`, each step a box QP. Leaves the state at w.
  void minimise() {
    double energy = evaluate(w);
    report.initial_energy = energy;
    double lambda = 1e-6;
    for (int iteration = 0; iteration < options.max_iterations && energy > 0.0; ++iteration) {
      build_jacobian();
      JtJ.noalias() = jacobian.transpose() * jacobian;
      Jtf.noalias() = jacobian.transpose() * residual;
      const double mean_diagonal = std::max(JtJ.diagonal().mean(), 1e-300);
      damping = JtJ.diagonal().array() + 1e-9 * mean_diagonal;
      lap(SolveStage::kWeights);
      bool accepted = false;
      double trial_energy = energy;
      for (int attempt = 0; attempt < 12 && !accepted; ++attempt) {
        H = JtJ;
        H.diagonal() += lambda * damping;
        g.noalias() = H * w;
        g -= Jtf;
        trial = w;
        if (!qp.solve(H, g, 0.0, 1.0, trial).converged) qp_iteration_cap = true;
        lap(SolveStage::kWeights);
        if ((trial - w).cwiseAbs().maxCoeff() < 1e-12) break;  // no step left to take
        trial_energy = evaluate(trial);
        if (trial_energy < energy) {
          accepted = true;
          lambda = std::max(lambda * 0.25, 1e-12);
        } else {
          lambda *= 8.0;
        }
      }
      if (!accepted) {
        evaluate(w);  // restore the state of the best point
        break;
      }
      const double decrease = energy - trial_energy;
      w = trial;
      energy = trial_energy;
      ++report.iterations;
      if (decrease <= options.relative_tolerance * (energy + decrease)) break;
    }
    report.final_energy = energy;
  }
};

MeshIkSolver::MeshIkSolver(std::shared_ptr<const SolverModel> model, const MeshIkOptions& options)
    : FaceSolver(std::move(model)) {
  if (!(options.difference_step > 0) || options.max_iterations < 0)
    throw Error("meshik: the difference step must be > 0 and the iteration count >= 0");
  state_ = std::make_unique<State>(*model_, options, make_solver(SolverMethod::kLinear, model_));
  state_->configure();
}

MeshIkSolver::~MeshIkSolver() = default;

void MeshIkSolver::reset() noexcept { state_->eq2->reset(); }
FaceSolver::State MeshIkSolver::make_state() const { return state_->eq2->make_state(); }
bool MeshIkSolver::save_state(FaceSolver::State& state) const noexcept { return state_->eq2->save_state(state); }
bool MeshIkSolver::restore_state(const FaceSolver::State& state) noexcept { return state_->eq2->restore_state(state); }

const MeshIkReport& MeshIkSolver::last_report() const noexcept { return state_->report; }

void MeshIkSolver::solve(const Eigen::Matrix3Xd& targets, std::span<const uint8_t> present, SolveResult& out) noexcept {
  State& s = *state_;
  const int64_t start = monotonic_now_ns();
  out.stage_ns.fill(0);
  out.collision_pairs = out.collision_constraints = 0;
  s.report = {};
  s.qp_iteration_cap = false;
  s.eq2->solve(targets, present, s.eq2_result);  // Eq. 2: the starting weights
  out.status = s.eq2_result.status;
  if (out.status & kSolvedTooFewMarkers) { out.total_ns = monotonic_now_ns() - start; return; }
  out.markers_used = s.eq2_result.markers_used;
  s.stage_ns = &out.stage_ns;
  s.last_lap_ns = start;
  s.lap(SolveStage::kWeights);
  s.prepare(targets, present);
  s.w = s.eq2_result.weights;
  s.minimise();
  out.weights = s.w;
  out.vertices = s.x;
  if (s.qp_iteration_cap) out.status |= kSolvedQpIterationCap;
  s.lap(SolveStage::kWeights);
  s.stage_ns = nullptr;
  out.total_ns = monotonic_now_ns() - start;
}

void MeshIkSolver::solve_with_weights(const Eigen::VectorXd& weights, const Eigen::Matrix3Xd& targets,
                                      std::span<const uint8_t> present, SolveResult& out) noexcept {
  State& s = *state_;
  const int64_t start = monotonic_now_ns();
  out.stage_ns.fill(0);
  out.collision_pairs = out.collision_constraints = 0;
  out.status = 0;
  s.report = {};
  s.stage_ns = &out.stage_ns;
  s.last_lap_ns = start;
  s.prepare(targets, present);
  s.report.initial_energy = s.report.final_energy = s.evaluate(weights);
  out.weights = weights;
  out.vertices = s.x;
  s.stage_ns = nullptr;
  out.total_ns = monotonic_now_ns() - start;
}

double MeshIkSolver::energy(const Eigen::VectorXd& weights, const Eigen::Matrix3Xd& targets,
                            std::span<const uint8_t> present) {
  if (weights.size() != model_->shape_count() || targets.cols() != model_->marker_count() ||
      Eigen::Index(present.size()) != model_->marker_count())
    throw Error("meshik: energy() needs M weights, K targets and K present flags");
  state_->prepare(targets, present);
  return state_->evaluate(weights);
}

std::unique_ptr<FaceSolver> make_meshik_solver(std::shared_ptr<const SolverModel> model) {
  return make_meshik_solver(std::move(model), MeshIkOptions{});
}

std::unique_ptr<FaceSolver> make_meshik_solver(std::shared_ptr<const SolverModel> model, const MeshIkOptions& options) {
  if (!model) throw Error("make_meshik_solver: no solver model");
  return std::make_unique<MeshIkSolver>(std::move(model), options);
}

}  // namespace facecap
