// The per-frame solvers: nonlinear (the paper), linear, dt and meshik baselines.
// Everything here after construction is real-time safe unless said otherwise.
#include <algorithm>
#include <array>
#include <cmath>
#include <cstring>
#include <immintrin.h>

#include <fmt/format.h>

#include "core/error.hpp"
#include "core/time.hpp"
#include "solver/box_qp.hpp"
#include "solver/collide/collider.hpp"
#include "solver/collide/geometry.hpp"
#include "solver/collide/pair_batch.hpp"
#include "solver/face_solver.hpp"
#include "solver/mesh_topology.hpp"
#include "solver/meshik.hpp"
#include "solver/simd.hpp"
#include "solver/solver_model.hpp"

namespace facecap {
namespace {

constexpr uint32_t kMinimumMarkers = 3;  // fewer cannot pin position and orientation

// 16 slots of one component of a ShapeBlocks block.
using Lanes16 = simd::FloatX16;

// 16 stored values as floats: 8-bit and 16-bit ones widened and converted (GCC 12 turns
// __builtin_convertvector from small integers into scalar code, so AVX-512 gets the two
// instructions spelled out).
template <int Width>
Lanes16 load_values(const std::byte* p) noexcept {
#if defined(__AVX512F__)
  if constexpr (Width == 0)
    return Lanes16(_mm512_cvtepi32_ps(_mm512_cvtepi8_epi32(_mm_load_si128(reinterpret_cast<const __m128i*>(p)))));
  else if constexpr (Width == 1)
    return Lanes16(_mm512_cvtepi32_ps(_mm512_cvtepi16_epi32(_mm256_load_si256(reinterpret_cast<const __m256i*>(p)))));
  else
    return Lanes16(_mm512_load_ps(p));
#else
  using Stored = std::conditional_t<Width == 0, int8_t, std::conditional_t<Width == 1, int16_t, float>>;
  Stored v[16];
  std::memcpy(v, p, sizeof v);
  Lanes16 out;
  for (int i = 0; i < 16; ++i) out[i] = float(v[i]);
  return out;
#endif
}

// `Components` floats from p into the first lanes, zeros after.
template <int Components>
Lanes16 load_head(const float* p) noexcept {
  static_assert(Components <= 16);
#if defined(__AVX512F__)
  return Lanes16(_mm512_maskz_loadu_ps(__mmask16((1u << Components) - 1), p));
#else
  Lanes16 out = {};
  for (int i = 0; i < Components; ++i) out[i] = p[i];
  return out;
#endif
}

// `Components` half floats from p as floats into the first lanes, zeros after.
template <int Components>
Lanes16 load_half_head(const uint16_t* p) noexcept {
  static_assert(Components <= 16);
#if defined(__AVX512F__) && defined(__AVX512BW__) && defined(__AVX512VL__)
  return Lanes16(_mm512_cvtph_ps(_mm256_maskz_loadu_epi16(__mmask16((1u << Components) - 1), p)));
#else
  Lanes16 out = {};
  for (int i = 0; i < Components; ++i) out[i] = half_to_float(p[i]);
  return out;
#endif
}

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

// Eq. 2: w = argmin |B~ w - (m - x0~)|^2 + alpha |w - w_prev|^2 + mu |w|^2, 0 <= w <= 1,
// on the rows of the present markers. H starts from the all-markers Gram matrix and
// loses the missing markers' blocks, so its cost follows the dropouts, not K.
class WeightsStage {
 public:
  // follow_paths: refine along the marker paths of the nonlinear blend (params.weight_refinements).
  WeightsStage(const SolverModel& model, bool follow_paths)
      : model_(model), refinements_(follow_paths && !model.marker_paths.empty() ? model.params.weight_refinements : 0),
        qp_(model.shape_count()), H_(model.shape_count(), model.shape_count()), g_(model.shape_count()),
        previous_(Eigen::VectorXd::Zero(model.shape_count())), previous_linear_(previous_), residual_(3 * model.marker_count()),
        present_(model.marker_count()) {
    if (refinements_ > 0) {
      const std::size_t P = model.marker_paths.size();
      gram_present_.resize(model.shape_count(), model.shape_count());
      turning_of_shape_.assign(std::size_t(model.shape_count()), -1);
      for (const auto& path : model.marker_paths) {
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
      for (const auto& path : model.marker_paths) ++path_start_[std::size_t(path.marker) + 1];
      for (std::size_t k = 0; k < std::size_t(model.marker_count()); ++k) path_start_[k + 1] += path_start_[k];
      path_of_marker_.resize(model.marker_paths.size());
      std::vector<int> fill(path_start_.begin(), path_start_.end() - 1);
      for (std::size_t i = 0; i < model.marker_paths.size(); ++i)
        path_of_marker_[std::size_t(fill[std::size_t(model.marker_paths[i].marker)]++)] = int(i);
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
    if (refinements_ > 0) gram_present_ = H_;
    H_.diagonal().array() += p.alpha + p.mu;
    g_.noalias() = m.marker_basis.transpose() * residual_;
    g_ += p.alpha * previous_;
    // Warm start: the last frame's solution of this same problem, whose bounds are the
    // likeliest to hold again (the refined weights' differ more).
    weights = previous_linear_;
    qp_.solve(H_, g_, 0.0, 1.0, weights);
    previous_linear_ = weights;
    for (int i = 0; i < refinements_; ++i) refine(targets, weights);
    previous_ = weights;
    return used;
  }
  void reset() noexcept {
    previous_.setZero();
    previous_linear_.setZero();
  }
  bool usable(std::span<const uint8_t> present, const Eigen::Matrix3Xd& targets) const noexcept {
    uint32_t n = 0;
    for (Eigen::Index k = 0; k < model_.marker_count(); ++k) n += present[std::size_t(k)] && targets.col(k).allFinite();
    return n >= kMinimumMarkers;
  }

 private:
  // One Gauss-Newton step: linearise the marker model x0 + sum_i f_i(w_i) at w and solve
  // the same box-constrained ridge problem for the new w. The Jacobian is B~ plus a
  // 3-vector D_p per marker path, so J^T J is the Gram matrix already built plus sparse
  // corrections rather than a dense product.
  void refine(const Eigen::Matrix3Xd& targets, Eigen::VectorXd& w) noexcept {
    const SolverModel& m = model_;
    const Eigen::Index K = m.marker_count(), M = m.shape_count();
    const SolverParams& p = m.params;
    // c = m - x0 - f(w) + J w; start with the linear part, c = m - x0.
    for (Eigen::Index k = 0; k < K; ++k)
      residual_.segment<3>(3 * k) = present_[k] ? Eigen::Vector3d(targets.col(k) - m.marker_neutral.segment<3>(3 * k))
                                                : Eigen::Vector3d::Zero();
    H_ = gram_present_;
    cross_.setZero();
    const auto& paths = m.marker_paths;
    for (std::size_t i = 0; i < paths.size(); ++i) path_turn_[i] = w[paths[i].shape] * paths[i].angle;
    sin_cos_turns(path_turn_, path_sin_, path_cos_);
    for (std::size_t i = 0; i < paths.size(); ++i) {
      const MarkerPath& path = paths[i];
      if (!present_[path.marker]) { path_difference_.col(Eigen::Index(i)).setZero(); continue; }
      const double t = w[path.shape];
      const double c = path_cos_[i], sn = path_sin_[i];
      const Eigen::Vector3d turned = c * path.arm + sn * path.axis_cross_arm;  // exp(t r) arm
      const Eigen::Vector3d linear_delta = m.marker_basis.block<3, 1>(3 * path.marker, path.shape);
      const Eigen::Vector3d slope = path.angle * (c * path.axis_cross_arm - sn * path.arm) + path.axial;  // r x turned + axial
      const Eigen::Vector3d difference = slope - linear_delta;  // D_p
      path_difference_.col(Eigen::Index(i)) = difference;
      // f(t) - t B~ replaced by its tangent: - (f(t) - t B~) + t D_p.
      residual_.segment<3>(3 * path.marker) -= turned - path.arm + t * path.axial - t * linear_delta - t * difference;
      // B~^T D_p into the shape's column of cross_, from the marker's three rows of B~.
      double* __restrict column = cross_.col(turning_of_shape_[std::size_t(path.shape)]).data();
      const double* rows = m.marker_basis_rows.row(3 * path.marker).data();
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
    g_.noalias() = m.marker_basis.transpose() * residual_;
    for (std::size_t i = 0; i < paths.size(); ++i)
      g_[paths[i].shape] += path_difference_.col(Eigen::Index(i)).dot(residual_.segment<3>(3 * paths[i].marker));
    g_ += p.alpha * previous_;
    qp_.solve(H_, g_, 0.0, 1.0, w);
  }

  const SolverModel& model_;
  int refinements_;
  BoxQpSolver qp_;
  Eigen::MatrixXd H_, gram_present_;
  Eigen::MatrixXd cross_;                 // M x turning shapes: B~^T D's nonzero columns
  std::vector<int> turning_shapes_;       // shapes with marker paths
  std::vector<int> turning_of_shape_;     // per shape: index into turning_shapes_ or -1
  std::vector<double> path_turn_, path_cos_, path_sin_;  // per marker path: w_shape * angle, its cos and sin
  Eigen::VectorXd g_, previous_;
  Eigen::VectorXd previous_linear_;  // the last Eq. 2 solution before refinement
  Eigen::VectorXd residual_;
  Eigen::Matrix3Xd path_difference_;
  std::vector<int> path_start_, path_of_marker_;  // marker paths grouped by marker (CSR)
  Eigen::Array<bool, Eigen::Dynamic, 1> present_;
};

// Per frame, each shape's weight as the blend reads it: 0 for weights at or below
// active_weight, so that their entries are skipped. Real-time safe.
void active_weights(const Eigen::VectorXd& w, double active_weight, std::vector<float>& out) noexcept {
  for (Eigen::Index i = 0; i < w.size(); ++i) out[std::size_t(i)] = w[i] > active_weight ? float(w[i]) : 0.0f;
}

// sum over the active entries of `block` of w_shape * value, component-major (BlendTerms),
// in Lanes16 so that the block's sums stay in registers. An entry's weighted scales and
// offsets take one vector operation each; every value one load, conversion and
// multiply-add.
template <int Components>
void sum_block(const BlendTerms& terms, int block, const float* weights, float (&sum)[Components * ShapeBlocks::kBlock]) noexcept {
  constexpr int B = ShapeBlocks::kBlock, L = B / 16;  // Lanes16 per component
  static_assert(L * 16 == B);
  Lanes16 lanes[Components][L] = {};
  Lanes16 offsets = {};  // lane c: the weighted offsets of component c
  alignas(64) float factor[16];
  const BlendTerms::BlockRun& run = terms.blocks[std::size_t(block)];
  const std::byte* values = terms.values.data() + run.values;
  int32_t position = run.first;
  auto add_entries = [&]<int Width>(std::integral_constant<int, Width>) {
    constexpr std::size_t kEntryBytes = std::size_t(Components) * B * BlendTerms::kBytesPerValue[Width];
    constexpr std::size_t kLaneBytes = 16 * BlendTerms::kBytesPerValue[Width];
    for (const int32_t end = position + run.count[Width]; position < end; ++position, values += kEntryBytes) {
      const float w = weights[terms.shape[std::size_t(position)]];
      if (w == 0.0f) continue;
      const auto at = std::size_t(position) * Components;
      const Lanes16 wv = Lanes16{} + w;
      offsets += wv * load_head<Components>(terms.offsets.data() + at);
      const Lanes16 f = (wv * BlendTerms::kScaleUnit) * load_half_head<Components>(terms.scales.data() + at);
      std::memcpy(factor, &f, sizeof f);
#pragma GCC unroll 16
      for (int c = 0; c < Components; ++c)
#pragma GCC unroll 2
        for (int l = 0; l < L; ++l) lanes[c][l] += factor[c] * load_values<Width>(values + (c * L + l) * kLaneBytes);
    }
  };
  add_entries(std::integral_constant<int, 0>{});
  add_entries(std::integral_constant<int, 1>{});
  add_entries(std::integral_constant<int, 2>{});
  for (int c = 0; c < Components; ++c)
    for (int l = 0; l < L; ++l) {
      const Lanes16 v = lanes[c][l] + offsets[c];
      std::memcpy(sum + (c * L + l) * 16, &v, sizeof v);
    }
}

// x0 + B w over the active weights (from active_weights) for the elements in one block
// of `blocks`: element e is rig vertex vertices[e], or vertex e when vertices is empty;
// out column e.
void linear_blend_block(const ShapeBlocks& blocks, const BlendTerms& terms, const Eigen::Matrix3Xd& neutral,
                        std::span<const int> vertices, const float* weights, int block, Eigen::Matrix3Xd& out) noexcept {
  constexpr int B = ShapeBlocks::kBlock;
  alignas(64) float sum[3 * B];
  sum_block<3>(terms, block, weights, sum);
  for (int i = 0; i < B; ++i) {
    const int32_t e = blocks.element_of_slot[std::size_t(block) * B + std::size_t(i)];
    if (e < 0) continue;
    const int v = vertices.empty() ? e : vertices[std::size_t(e)];
    for (int c = 0; c < 3; ++c) out(c, e) = neutral(c, v) + double(sum[c * B + i]);
  }
}

class LinearSolver final : public FaceSolver {
 public:
  explicit LinearSolver(std::shared_ptr<const SolverModel> model)
      : FaceSolver(std::move(model)), weights_(*model_, false), active_(std::size_t(model_->shape_count())) {}
  std::string_view name() const noexcept override { return kSolverMethods.name(SolverMethod::kLinear); }
  void reset() noexcept override { weights_.reset(); }
  void solve(const Eigen::Matrix3Xd& targets, std::span<const uint8_t> present, SolveResult& out) noexcept override {
    StageClock clock(out);
    out.held = !weights_.usable(present, targets);
    out.collision_pairs = out.collision_constraints = 0;
    if (out.held) { clock.finish(); return; }
    out.markers_used = weights_.solve(targets, present, out.weights);
    clock.lap(SolveStage::kWeights);
    blend(out);
    clock.lap(SolveStage::kBlend);
    clock.finish();
  }
  void solve_with_weights(const Eigen::VectorXd& weights, const Eigen::Matrix3Xd&, std::span<const uint8_t>,
                          SolveResult& out) noexcept override {
    StageClock clock(out);
    out.held = false;
    out.weights = weights;
    blend(out);
    clock.lap(SolveStage::kBlend);
    clock.finish();
  }

 private:
  void blend(SolveResult& out) noexcept {
    const SolverModel& m = *model_;
    active_weights(out.weights, m.params.active_weight, active_);
    for (int block = 0; block < m.vertex_blocks.block_count(); ++block)
      linear_blend_block(m.vertex_blocks, m.vertex_deltas, m.rig.neutral, {}, active_.data(), block, out.vertices);
  }

  WeightsStage weights_;
  std::vector<float> active_;  // per shape: its weight, 0 if inactive
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
    constexpr std::size_t B = ShapeBlocks::kBlock;
    operator_.assign(std::size_t(m.triangle_blocks.block_count()) * kOperatorComponents * B, 0.0f);
    slot_corners_.assign(m.triangle_blocks.element_of_slot.size(), {-1, -1, -1});
    // G^T W G x0, the right-hand side of T = I everywhere.
    identity_rhs_.setZero(3, N);
    for (Eigen::Index t = 0; t < T; ++t) {
      const Eigen::Map<const Eigen::Matrix3d> Q(m.triangle_operator.col(t).data());
      const auto corners = m.rig.triangles.col(t);
      for (int k = 0; k < 3; ++k) identity_rhs_.col(corners[k]) += Q.col(k);
      // The rest frame's t1, t2 and half the rest corners' coordinates in it, (0, 0),
      // (L, 0) and (u, v): Q_j = t1 q1^T + t2 q2^T with q1 = (-v, v, 0) / 2 and
      // q2 = (u - L, -u, L) / 2 (area times the hat functions' gradients).
      const Eigen::Map<const Eigen::Matrix3d> frame(m.triangle_frames.col(t).data());
      const Eigen::Vector3d edge = m.rig.neutral.col(corners[1]) - m.rig.neutral.col(corners[0]);
      const Eigen::Vector3d other = m.rig.neutral.col(corners[2]) - m.rig.neutral.col(corners[0]);
      const double values[kOperatorComponents] = {frame(0, 0), frame(1, 0), frame(2, 0), frame(0, 1), frame(1, 1), frame(2, 1),
                                                  0.5 * edge.dot(frame.col(0)), 0.5 * other.dot(frame.col(0)),
                                                  0.5 * other.dot(frame.col(1))};
      const auto slot = std::size_t(m.triangle_blocks.slot_of_element[std::size_t(t)]);
      for (int c = 0; c < kOperatorComponents; ++c)
        operator_[(slot / B * kOperatorComponents + std::size_t(c)) * B + slot % B] = float(values[c]);
      slot_corners_[slot] = {corners[0], corners[1], corners[2]};
    }
    rhs_.resize(3, N);
    work_.resize(4, N);
    reference_.resize(3, Eigen::Index(m.reference_vertices.size()));
    reference_stamp_.assign(std::size_t(m.reference_blocks.block_count()), 0);
    if (!m.collision_triangles.empty()) {
      ColliderConfig config;
      config.epsilon = m.params.collision_epsilon;
      config.ignore_rest_contacts = true;  // a neutral that already touches is the artist's intent
      config.neighbour_edges = 2;
      collider_.configure(m.rig.triangles, m.rig.neutral, m.collision_triangles, config);
      pin_stamp_.assign(std::size_t(N), 0);
      collisions_ = collider_.make_result();
      const TriangleAdjacency adjacency(m.rig.triangles);
      const auto candidates = collider_.candidate_triangles();
      std::vector<int> candidate_index(std::size_t(T), -1);
      for (std::size_t i = 0; i < candidates.size(); ++i) candidate_index[std::size_t(candidates[i])] = int(i);
      for (std::size_t i = 0; i < candidates.size(); ++i)
        for (const int u : adjacency.neighbours(candidates[i]))
          if (candidate_index[std::size_t(u)] > int(i)) fold_edges_.push_back({int(i), candidate_index[std::size_t(u)]});
      fold_normals_.resize(3, Eigen::Index(candidates.size()));
    }
    // Pins beyond capacity are left out (and counted); markers always fit.
    pin_capacity_ = std::min<Eigen::Index>(Eigen::Index(m.collision_vertices.size()), m.params.collision_max_pins);
    const Eigen::Index capacity = K + pin_capacity_;
    modifications_.resize(std::size_t(capacity));
    small_.resize(capacity, capacity);
    small_rhs_.resize(capacity, 3);
    if (!m.collision_columns_precomputed()) pin_columns_.resize(N, pin_capacity_);
    pin_work_.resize(N);
    correction_.resize(N, 3);
    active_.resize(std::size_t(m.shape_count()));
    const BlendTerms& terms = blend_ == Blend::kNonlinear ? m.triangle_nonlinear : m.triangle_gradient;
    streamed_ = {std::as_bytes(std::span(terms.values)), std::as_bytes(std::span(terms.scales)),
                 std::as_bytes(std::span(terms.offsets)), std::as_bytes(std::span(operator_))};
  }

  std::string_view name() const noexcept override {
    return kSolverMethods.name(blend_ == Blend::kNonlinear ? SolverMethod::kNonlinear : SolverMethod::kDt);
  }
  void reset() noexcept override { weights_.reset(); }
  std::span<const std::span<const std::byte>> streamed_memory() const noexcept override { return streamed_; }

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
    blend(out.weights);  // also the triangles' share of the right-hand side
    clock.lap(SolveStage::kBlend);

    modification_count_ = 0;
    const double beta = m.params.beta;
    for (Eigen::Index k = 0; k < m.marker_count(); ++k) {
      const auto& b = m.markers[std::size_t(k)];
      if (present[std::size_t(k)] && targets.col(k).allFinite()) {
        for (int a = 0; a < 3; ++a) rhs_.col(b.vertices[a]) += beta * b.barycentric[a] * targets.col(k);
      } else {
        add_modification({b.vertices, b.barycentric, m.marker_solution.col(k).data(), nullptr, 0.0f, -beta});
      }
    }
    if (++frame_stamp_ == 0) {  // wrapped: forget every old stamp
      std::fill(pin_stamp_.begin(), pin_stamp_.end(), 0u);
      std::fill(reference_stamp_.begin(), reference_stamp_.end(), 0u);
      frame_stamp_ = 1;
    }
    for (const int v : m.tangle_vertices) rhs_.col(v) += SolverModel::kTangleWeight * beta * reference(v);
    clock.lap(SolveStage::kRhs);

    m.factor->solve_in_place(rhs_, work_);  // rhs_ now holds y = A0^-1 r
    apply_modifications(rhs_, out.vertices);
    clock.lap(SolveStage::kBacksolve);
    collide(out);
    clock.lap(SolveStage::kCollide);
    clock.finish();
  }

  // Block by block: sums the active shapes' terms in vector registers, turns each sum into
  // T_j - I (Eq. 4 for nonlinear, sum w_i (F_ij - I) for dt), multiplies by Q_j and adds
  // that to rhs_ (which starts as the T = I right-hand side). The terms are read once,
  // front to back: memory bandwidth is what bounds the stage.
  void blend(const Eigen::VectorXd& w) noexcept {
    const SolverModel& m = *model_;
    rhs_ = identity_rhs_;
    const ShapeBlocks& blocks = m.triangle_blocks;
    const BlendTerms& terms = blend_ == Blend::kNonlinear ? m.triangle_nonlinear : m.triangle_gradient;
    active_weights(w, m.params.active_weight, active_);
    constexpr int B = ShapeBlocks::kBlock;
    constexpr int kNonlinear = SolverModel::kNonlinearComponents, kGradient = SolverModel::kGradientComponents;
    alignas(64) float sum[std::max(kNonlinear, kGradient) * B];
    alignas(64) float out[9 * B];  // (T_j - I) Q_j: column k, row r at [(3 k + r) B + slot]
    for (int block = 0; block < blocks.block_count(); ++block) {
      const float* frame = operator_.data() + std::size_t(block) * kOperatorComponents * B;
      if (blend_ == Blend::kDeformationTransfer) {
        sum_block<kGradient>(terms, block, active_.data(), reinterpret_cast<float(&)[kGradient * B]>(sum));
        transfer_block(sum, frame, out);
      } else {
        sum_block<kNonlinear>(terms, block, active_.data(), reinterpret_cast<float(&)[kNonlinear * B]>(sum));
        nonlinear_block(sum, frame, out);
      }
      const std::array<int32_t, 3>* corners = slot_corners_.data() + std::size_t(block) * B;
      for (int i = 0; i < B; ++i) {
        if (corners[i][0] < 0) continue;  // padding
        for (int k = 0; k < 3; ++k) {
          double* column = rhs_.data() + 3 * std::size_t(corners[i][std::size_t(k)]);
          for (int r = 0; r < 3; ++r) column[r] += out[(3 * k + r) * B + i];
        }
      }
    }
  }

  // The rows q1, q2 of Q_j = t1 q1^T + t2 q2^T for the slots of a block from t.
  template <class V>
  static void rest_gradients(const float* frame, int t, V (&q1)[3], V (&q2)[3]) noexcept {
    constexpr int B = ShapeBlocks::kBlock;
    const V half_l = simd::load<V>(frame + 6 * B + t), half_u = simd::load<V>(frame + 7 * B + t),
            half_v = simd::load<V>(frame + 8 * B + t);
    q1[0] = -half_v, q1[1] = half_v, q1[2] = V{};
    q2[0] = half_u - half_l, q2[1] = -half_u, q2[2] = half_l;
  }

  // out = (F - I) Q_j = g1 q1^T + g2 q2^T per slot of a block: deformation transfer, with
  // g1 = sum w_i (F_i - I) t1 and g2 the same for t2.
  static void transfer_block(const float* sum, const float* frame, float* out) noexcept {
    constexpr int B = ShapeBlocks::kBlock;
    for (int t = 0; t < B; t += 16) {
      Lanes16 q1[3], q2[3];
      rest_gradients(frame, t, q1, q2);
      for (int r = 0; r < 3; ++r) {
        const Lanes16 g1 = simd::load<Lanes16>(sum + r * B + t), g2 = simd::load<Lanes16>(sum + (3 + r) * B + t);
        for (int k = 0; k < 3; ++k) simd::store(out + (3 * k + r) * B + t, g1 * q1[k] + g2 * q2[k]);
      }
    }
  }

  // out = (exp(sum_log) (I + sum_stretch) - I) Q_j per slot of a block (Eq. 4), in float,
  // 16 triangles at a time: the rounding (1e-7 of T) is far below the stored terms'.
  static void nonlinear_block(const float* sum, const float* frame, float* out) noexcept {
    constexpr int B = ShapeBlocks::kBlock;
    constexpr float kLargestSeriesAngleSq = 6.25f;
    for (int t = 0; t < B; t += 16) {
      const Lanes16 rx = simd::load<Lanes16>(sum + t), ry = simd::load<Lanes16>(sum + B + t), rz = simd::load<Lanes16>(sum + 2 * B + t);
      const Lanes16 x = rx * rx + ry * ry + rz * rz;
      // sin(theta)/theta and (1 - cos(theta))/theta^2 as series in theta^2, exact to float
      // precision for theta <= 2.5; larger turns are redone with sin and cos below.
      Lanes16 a = Lanes16{} + 1.0f / 6227020800.0f, b = Lanes16{} + 1.0f / 87178291200.0f;  // 1/13!, 1/14!
      constexpr float kInvFactorial[] = {1.0f / 39916800.0f, 1.0f / 362880.0f, 1.0f / 5040.0f, 1.0f / 120.0f, 1.0f / 6.0f, 1.0f};
      constexpr float kInvFactorialEven[] = {1.0f / 479001600.0f, 1.0f / 3628800.0f, 1.0f / 40320.0f, 1.0f / 720.0f, 1.0f / 24.0f, 0.5f};
      for (int i = 0; i < 6; ++i) {
        a = kInvFactorial[i] - x * a;
        b = kInvFactorialEven[i] - x * b;
      }
      finish_triangles(t, rx, ry, rz, x, a, b, sum, frame, out);
      for (int i = 0; i < 16; ++i) {
        if (x[i] <= kLargestSeriesAngleSq) continue;
        const double theta = std::sqrt(double(x[i]));
        finish_triangles(t + i, rx[i], ry[i], rz[i], x[i], float(std::sin(theta) / theta),
                         float((1.0 - std::cos(theta)) / double(x[i])), sum, frame, out);
      }
    }
  }

  // out = (R (I + S) - I) Q_j for the triangles of a block from slot t (16 of them with
  // V = Lanes16, one with V = float), R = I + a [r]x + b [r]x^2 and S - I from its
  // rest-frame components (xx, yy, xy, xz, yz at sum[3..7]). With U = (S - I) in the rest
  // frame times q and W = frame U: R (I + S) Q - Q = (R - I)(Q + W) + W, R - I and W
  // small, so nothing cancels against I.
  template <class V>
  static void finish_triangles(int t, V rx, V ry, V rz, V x, V a, V b, const float* sum, const float* frame,
                               float* out) noexcept {
    constexpr int B = ShapeBlocks::kBlock;
    V D[9];  // R - I, column-major
    D[0] = b * (rx * rx - x);     D[3] = -a * rz + b * rx * ry;  D[6] = a * ry + b * rx * rz;
    D[1] = a * rz + b * rx * ry;  D[4] = b * (ry * ry - x);      D[7] = -a * rx + b * ry * rz;
    D[2] = -a * ry + b * rx * rz; D[5] = a * rx + b * ry * rz;   D[8] = b * (rz * rz - x);
    const V t1[3] = {simd::load<V>(frame + t), simd::load<V>(frame + B + t), simd::load<V>(frame + 2 * B + t)};
    const V t2[3] = {simd::load<V>(frame + 3 * B + t), simd::load<V>(frame + 4 * B + t), simd::load<V>(frame + 5 * B + t)};
    const V n[3] = {t1[1] * t2[2] - t1[2] * t2[1], t1[2] * t2[0] - t1[0] * t2[2], t1[0] * t2[1] - t1[1] * t2[0]};
    V q1[3], q2[3];
    rest_gradients(frame, t, q1, q2);
    const V sxx = simd::load<V>(sum + 3 * B + t), syy = simd::load<V>(sum + 4 * B + t), sxy = simd::load<V>(sum + 5 * B + t);
    const V sxz = simd::load<V>(sum + 6 * B + t), syz = simd::load<V>(sum + 7 * B + t);
    for (int k = 0; k < 3; ++k) {
      const V u0 = sxx * q1[k] + sxy * q2[k], u1 = sxy * q1[k] + syy * q2[k], u2 = sxz * q1[k] + syz * q2[k];
      V w[3], y[3];  // W and Q + W, column k
      for (int r = 0; r < 3; ++r) {
        w[r] = t1[r] * u0 + t2[r] * u1 + n[r] * u2;
        y[r] = t1[r] * q1[k] + t2[r] * q2[k] + w[r];
      }
      for (int r = 0; r < 3; ++r) simd::store(out + (3 * k + r) * B + t, D[r] * y[0] + D[3 + r] * y[1] + D[6 + r] * y[2] + w[r]);
    }
  }

  // Triangle pairs closer than epsilon pin their vertices to the linear blend
  // (x0 + B w)_v, the paper's collision-free reference: A0 gains beta e_v e_v^T, the
  // right-hand side beta e_v p_v^T, and the mesh is solved again through the same
  // low-rank update. Only pairs in a worse state than in the reference are pinned:
  // closer than epsilon where the linear blend keeps them apart, or crossing where it
  // only touches. Lips that rest in contact (ICT) touch in both, and where the linear
  // blend itself crosses (ICT's own shapes do) it is no reference.
  void collide(SolveResult& out) noexcept {
    const SolverModel& m = *model_;
    if (!collider_.configured() || !collider_.detect(out.vertices, collisions_)) return;
    out.collision_pairs = uint32_t(collisions_.pairs_found);
    const double epsilon = m.params.collision_epsilon;
    Eigen::Index pins = 0;
    // A pair whose six vertices are pinned already, or any pair once capacity is
    // reached, cannot add a pin: its reference is not worth testing.
    auto adds_pins = [&](const auto& ta, const auto& tb) {
      if (pins == pin_capacity_) return false;
      for (const int v : {ta[0], ta[1], ta[2], tb[0], tb[1], tb[2]})
        if (pin_stamp_[std::size_t(v)] != frame_stamp_) return true;
      return false;
    };
    // The pairs' references are tested kCloserBatch at a time, the pins then made in order.
    TrianglePairCorners batch[kCloserBatch];
    const TrianglePair* batch_pairs[kCloserBatch];
    int batched = 0;
    auto pin_batch = [&] {
      const uint32_t close = triangles_closer_than(std::span(batch, std::size_t(batched)), epsilon);
      for (int k = 0; k < batched; ++k) {
        const auto ta = m.rig.triangles.col(batch_pairs[k]->first), tb = m.rig.triangles.col(batch_pairs[k]->second);
        if (!adds_pins(ta, tb)) continue;
        if ((close >> k) & 1u) {
          // The reference is in contact too: pin only if the solve crosses where it does not.
          const auto& [a, b] = batch[k];
          if (triangles_intersect(a[0], a[1], a[2], b[0], b[1], b[2]) ||
              !triangles_intersect(out.vertices.col(ta[0]), out.vertices.col(ta[1]), out.vertices.col(ta[2]),
                                   out.vertices.col(tb[0]), out.vertices.col(tb[1]), out.vertices.col(tb[2])))
            continue;
        }
        for (const int v : {ta[0], ta[1], ta[2], tb[0], tb[1], tb[2]}) pin(v, pins);
      }
      batched = 0;
    };
    for (const TrianglePair& pair : collisions_.valid_pairs()) {
      const auto ta = m.rig.triangles.col(pair.first), tb = m.rig.triangles.col(pair.second);
      if (!adds_pins(ta, tb)) continue;
      batch[batched] = {{reference(ta[0]), reference(ta[1]), reference(ta[2])}, {reference(tb[0]), reference(tb[1]), reference(tb[2])}};
      batch_pairs[batched] = &pair;
      if (++batched == kCloserBatch) pin_batch();
    }
    pin_batch();
    // Folds: neighbours across an edge turned more than 90 degrees against each other
    // where the linear blend keeps them less than 90 degrees apart. Such a crease folds
    // the skin through itself within a few triangles, where pairs are too near to test.
    const auto candidates = collider_.candidate_triangles();
    for (std::size_t i = 0; i < candidates.size(); ++i)
      fold_normals_.col(Eigen::Index(i)) = triangle_normal(out.vertices, m.rig.triangles.col(candidates[i]));
    for (const auto& [first, second] : fold_edges_) {
      if (fold_normals_.col(first).dot(fold_normals_.col(second)) >= 0.0) continue;
      const auto ta = m.rig.triangles.col(candidates[std::size_t(first)]), tb = m.rig.triangles.col(candidates[std::size_t(second)]);
      if (!adds_pins(ta, tb)) continue;
      const Eigen::Vector3d la = (reference(ta[1]) - reference(ta[0])).cross(reference(ta[2]) - reference(ta[0]));
      const Eigen::Vector3d lb = (reference(tb[1]) - reference(tb[0])).cross(reference(tb[2]) - reference(tb[0]));
      if (la.dot(lb) < 0.0) continue;
      for (const int v : {ta[0], ta[1], ta[2], tb[0], tb[1], tb[2]}) pin(v, pins);
    }
    out.collision_constraints = uint32_t(pins);
    if (pins > 0) apply_modifications(rhs_, out.vertices);
  }

  static Eigen::Vector3d triangle_normal(const Eigen::Matrix3Xd& x, const Eigen::Ref<const Eigen::Vector3i>& t) noexcept {
    return (x.col(t[1]) - x.col(t[0])).cross(x.col(t[2]) - x.col(t[0]));
  }

  // Pins vertex v to the linear blend, once per frame and while capacity lasts.
  void pin(int v, Eigen::Index& pins) noexcept {
    const SolverModel& m = *model_;
    if (pin_stamp_[std::size_t(v)] == frame_stamp_ || pins == pin_capacity_) return;
    pin_stamp_[std::size_t(v)] = frame_stamp_;
    const double* column = nullptr;
    const int16_t* pin_column = nullptr;
    float pin_scale = 0.0f;
    if (m.collision_columns_precomputed()) {
      const auto c = Eigen::Index(m.vertex_to_collision[std::size_t(v)]);
      pin_column = m.pin_solution.column(c);
      pin_scale = m.pin_solution.scale[std::size_t(c)];
    } else {
      auto z = pin_columns_.col(pins);
      z.setZero();
      z[v] = 1.0;
      m.factor->solve_in_place(z, pin_work_);
      column = z.data();
    }
    add_modification({{v, v, v}, Eigen::Vector3d(1.0, 0.0, 0.0), column, pin_column, pin_scale, m.params.beta, reference(v)});
    ++pins;
  }

  // This frame's (x0 + B w)_v at a collision or tangle vertex, its block of
  // reference_blocks blended on first use.
  Eigen::Vector3d reference(int v) noexcept {
    const SolverModel& m = *model_;
    const int i = m.vertex_to_reference[std::size_t(v)];
    const int block = m.reference_blocks.slot_of_element[std::size_t(i)] / ShapeBlocks::kBlock;
    if (reference_stamp_[std::size_t(block)] != frame_stamp_) {
      reference_stamp_[std::size_t(block)] = frame_stamp_;
      linear_blend_block(m.reference_blocks, m.reference_deltas, m.rig.neutral, m.reference_vertices, active_.data(), block, reference_);
    }
    return reference_.col(i);
  }

  // A change d u u^T of A0 with u = sum_a weight_a e_{vertex_a}; A0^-1 u is `column`, or
  // pin_scale * pin_column for a precomputed pin. The right-hand side gains d u target^T
  // (a pin's target; zero for a marker dropping out).
  struct Modification {
    std::array<int, 3> vertices;
    Eigen::Vector3d weights;
    const double* column;
    const int16_t* pin_column;  // with pin_scale
    float pin_scale;
    double scale;
    Eigen::Vector3d target = Eigen::Vector3d::Zero();
    double column_at(int v) const noexcept { return column ? column[v] : double(pin_scale) * double(pin_column[v]); }
  };

  void add_modification(const Modification& modification) noexcept { modifications_[std::size_t(modification_count_++)] = modification; }

  // The solve of A0 + U D U^T with right-hand side r + U D T from y = A0^-1 r, without
  // refactoring (Woodbury): with Z = A0^-1 U and y' = y + Z D T,
  //   x = y' - Z (D^-1 + U^T Z)^-1 U^T y' = y + Z (D T - (D^-1 + U^T Z)^-1 U^T y'),
  // where U^T y' = U^T y + (U^T Z) D T needs Z only at the modified vertices, so the
  // whole mesh is touched once, by the last sum. y, x: 3 x N.
  void apply_modifications(const Eigen::Matrix3Xd& y, Eigen::Matrix3Xd& x) noexcept {
    const SolverModel& m = *model_;
    x = y;
    const Eigen::Index s = modification_count_;
    if (s == 0) return;
    auto u_dot = [](const Modification& u, const Modification& z) {
      double sum = 0.0;  // a pin has one vertex (weights 1, 0, 0), a marker up to three
      for (int a = 0; a < 3; ++a)
        if (u.weights[a] != 0.0) sum += u.weights[a] * z.column_at(u.vertices[a]);
      return sum;
    };
    // U^T Z = U^T A0^-1 U is symmetric: its lower triangle, mirrored.
    for (Eigen::Index i = 0; i < s; ++i)
      for (Eigen::Index j = 0; j <= i; ++j)
        small_(i, j) = small_(j, i) = u_dot(modifications_[std::size_t(i)], modifications_[std::size_t(j)]);
    for (Eigen::Index i = 0; i < s; ++i) {
      const Modification& mi = modifications_[std::size_t(i)];
      Eigen::Vector3d uy = Eigen::Vector3d::Zero();
      for (int a = 0; a < 3; ++a) uy += mi.weights[a] * y.col(mi.vertices[a]);
      for (Eigen::Index j = 0; j < s; ++j) {
        const Modification& mj = modifications_[std::size_t(j)];
        uy += small_(i, j) * mj.scale * mj.target;
      }
      small_(i, i) += 1.0 / mi.scale;
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
      const Modification& mi = modifications_[std::size_t(i)];
      small_rhs_.row(i) = mi.scale * mi.target.transpose() - small_rhs_.row(i);
    }
    // x += Z C, summed coordinate by coordinate (contiguous, so vectorised) into sums that
    // stay in L2 while each column streams through once, front to back.
    const Eigen::Index N = m.vertex_count();
    correction_.setZero();
    double* __restrict sx = correction_.col(0).data();
    double* __restrict sy = correction_.col(1).data();
    double* __restrict sz = correction_.col(2).data();
    Eigen::Index i = 0;
    // Double columns first (markers, pins solved this frame), then precomputed pins.
    for (; i < s && modifications_[std::size_t(i)].column; ++i) {
      const double* __restrict z = modifications_[std::size_t(i)].column;
      const double cx = small_rhs_(i, 0), cy = small_rhs_(i, 1), cz = small_rhs_(i, 2);
      for (Eigen::Index j = 0; j < N; ++j) {
        sx[j] += cx * z[j];
        sy[j] += cy * z[j];
        sz[j] += cz * z[j];
      }
    }
    // Float sums of eight pin columns at a time: one pass over the sums per eight columns
    // (four measured 20% slower, sixteen no faster).
    auto add_pins = [&]<int Count>(std::integral_constant<int, Count>) {
      const int16_t* __restrict z[Count];
      float cx[Count], cy[Count], cz[Count];
      for (int k = 0; k < Count; ++k) {
        const Modification& mk = modifications_[std::size_t(i + k)];
        z[k] = mk.pin_column;
        cx[k] = float(mk.pin_scale * small_rhs_(i + k, 0));
        cy[k] = float(mk.pin_scale * small_rhs_(i + k, 1));
        cz[k] = float(mk.pin_scale * small_rhs_(i + k, 2));
      }
      for (Eigen::Index j = 0; j < N; ++j) {
        float x_sum = 0.0f, y_sum = 0.0f, z_sum = 0.0f;
        for (int k = 0; k < Count; ++k) {
          const float zj = float(z[k][j]);
          x_sum += cx[k] * zj;
          y_sum += cy[k] * zj;
          z_sum += cz[k] * zj;
        }
        sx[j] += x_sum;
        sy[j] += y_sum;
        sz[j] += z_sum;
      }
      i += Count;
    };
    while (i + 8 <= s) add_pins(std::integral_constant<int, 8>{});
    while (i < s) add_pins(std::integral_constant<int, 1>{});
    x += correction_.transpose();
  }

  Blend blend_;
  WeightsStage weights_;
  std::vector<std::span<const std::byte>> streamed_;  // the blend's terms and Q_j (streamed_memory)
  std::vector<float> active_;                         // per shape: its weight, 0 if inactive
  // Per slot of triangle_blocks, component-major per block: the rest frame's t1 and t2 and
  // (L, u, v) / 2, from which Q_j = t1 q1^T + t2 q2^T (see the constructor).
  static constexpr int kOperatorComponents = 9;
  std::vector<float> operator_;
  std::vector<std::array<int32_t, 3>> slot_corners_;  // per slot of triangle_blocks: its vertices, -1 for padding
  Eigen::Matrix3Xd identity_rhs_, rhs_;
  Eigen::Matrix4Xd work_;
  std::vector<Modification> modifications_;
  Eigen::Index modification_count_ = 0;
  Eigen::Matrix<double, Eigen::Dynamic, Eigen::Dynamic, Eigen::RowMajor> small_;  // row operations in the elimination
  Eigen::Matrix<double, Eigen::Dynamic, 3> small_rhs_;
  TriangleCollider collider_;
  CollisionResult collisions_;
  std::vector<std::pair<int, int>> fold_edges_;  // candidate triangles sharing an edge (indices into the candidates)
  Eigen::Matrix3Xd fold_normals_;                // per candidate triangle: this frame's normal (not unit)
  Eigen::Index pin_capacity_ = 0;
  Eigen::MatrixXd pin_columns_;  // A0^-1 e_v solved per frame when not precomputed
  Eigen::Matrix3Xd reference_;        // the linear blend at the model's reference_vertices (reference())
  uint32_t frame_stamp_ = 0;
  std::vector<uint32_t> pin_stamp_;        // per vertex: the frame it was last pinned
  std::vector<uint32_t> reference_stamp_;  // per block of reference_blocks: the frame it was last blended
  Eigen::VectorXd pin_work_;
  Eigen::Matrix<double, Eigen::Dynamic, 3> correction_;  // N x 3: Z C, coordinate by coordinate
};

}  // namespace

SolveResult FaceSolver::make_result() const {
  SolveResult r;
  r.weights.setZero(model_->shape_count());
  r.vertices = model_->rig.neutral;
  return r;
}

std::unique_ptr<FaceSolver> make_solver(SolverMethod method, std::shared_ptr<const SolverModel> model) {
  if (!model) throw Error("make_solver: no solver model");
  switch (method) {
    case SolverMethod::kNonlinear: return std::make_unique<PoissonSolver>(std::move(model), PoissonSolver::Blend::kNonlinear);
    case SolverMethod::kDt:
      return std::make_unique<PoissonSolver>(std::move(model), PoissonSolver::Blend::kDeformationTransfer);
    case SolverMethod::kLinear: return std::make_unique<LinearSolver>(std::move(model));
    case SolverMethod::kMeshik: return make_meshik_solver(std::move(model));
  }
  throw Error("make_solver: not a solver method");
}

}  // namespace facecap
