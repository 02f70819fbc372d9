#include "solver/triangle_blend.hpp"

#include <algorithm>
#include <cmath>

#include "solver/blend_terms.hpp"
#include "solver/simd.hpp"
#include "solver/solver_model.hpp"

namespace facecap {
namespace {

using simd::FloatX16;

// The rows q1, q2 of Q_j = t1 q1^T + t2 q2^T for the slots of a block from t.
template <class V>
void rest_gradients(const float* frame, int t, V (&q1)[3], V (&q2)[3]) noexcept {
  constexpr int B = ShapeBlocks::kBlock;
  const V half_l = simd::load<V>(frame + 6 * B + t), half_u = simd::load<V>(frame + 7 * B + t),
          half_v = simd::load<V>(frame + 8 * B + t);
  q1[0] = -half_v, q1[1] = half_v, q1[2] = V{};
  q2[0] = half_u - half_l, q2[1] = -half_u, q2[2] = half_l;
}

// out = (F - I) Q_j = g1 q1^T + g2 q2^T per slot of a block: deformation transfer, with
// g1 = sum w_i (F_i - I) t1 and g2 the same for t2.
void transfer_block(const float* sum, const float* frame, float* out) noexcept {
  constexpr int B = ShapeBlocks::kBlock;
  for (int t = 0; t < B; t += 16) {
    FloatX16 q1[3], q2[3];
    rest_gradients(frame, t, q1, q2);
    for (int r = 0; r < 3; ++r) {
      const FloatX16 g1 = simd::load<FloatX16>(sum + r * B + t), g2 = simd::load<FloatX16>(sum + (3 + r) * B + t);
      for (int k = 0; k < 3; ++k) simd::store(out + (3 * k + r) * B + t, g1 * q1[k] + g2 * q2[k]);
    }
  }
}

// out = (R (I + S) - I) Q_j for the triangles of a block from slot t (16 of them with
// V = FloatX16, one with V = float), R = I + a [r]x + b [r]x^2 and S - I from its
// rest-frame components (xx, yy, xy, xz, yz at sum[3..7]). With U = (S - I) in the rest
// frame times q and W = frame U: R (I + S) Q - Q = (R - I)(Q + W) + W, R - I and W
// small, so nothing cancels against I.
template <class V>
void finish_triangles(int t, V rx, V ry, V rz, V x, V a, V b, const float* sum, const float* frame, float* out) noexcept {
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

// out = (exp(sum_log) (I + sum_stretch) - I) Q_j per slot of a block (Eq. 4), in float,
// 16 triangles at a time: the rounding (1e-7 of T) is far below the stored terms'.
void nonlinear_block(const float* sum, const float* frame, float* out) noexcept {
  constexpr int B = ShapeBlocks::kBlock;
  constexpr float kLargestSeriesAngleSq = 6.25f;
  for (int t = 0; t < B; t += 16) {
    const FloatX16 rx = simd::load<FloatX16>(sum + t), ry = simd::load<FloatX16>(sum + B + t), rz = simd::load<FloatX16>(sum + 2 * B + t);
    const FloatX16 x = rx * rx + ry * ry + rz * rz;
    // sin(theta)/theta and (1 - cos(theta))/theta^2 as series in theta^2, exact to float
    // precision for theta <= 2.5; larger turns are redone with sin and cos below.
    FloatX16 a = FloatX16{} + 1.0f / 6227020800.0f, b = FloatX16{} + 1.0f / 87178291200.0f;  // 1/13!, 1/14!
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

}  // namespace

TriangleBlend::TriangleBlend(const SolverModel& model, Kind kind) : model_(model), kind_(kind) {
  const SolverModel& m = model_;
  const Eigen::Index T = m.rig.triangle_count(), N = m.vertex_count();
  constexpr std::size_t B = ShapeBlocks::kBlock;
  operator_.assign(std::size_t(m.blend.triangle_blocks.block_count()) * kOperatorComponents * B, 0.0f);
  slot_corners_.assign(m.blend.triangle_blocks.element_of_slot.size(), {-1, -1, -1});
  // G^T W G x0, the right-hand side of T = I everywhere.
  identity_rhs_.setZero(3, N);
  for (Eigen::Index t = 0; t < T; ++t) {
    const Eigen::Map<const Eigen::Matrix3d> Q(m.blend.triangle_operator.col(t).data());
    const auto corners = m.rig.triangles.col(t);
    for (int k = 0; k < 3; ++k) identity_rhs_.col(corners[k]) += Q.col(k);
    // The rest frame's t1, t2 and half the rest corners' coordinates in it, (0, 0),
    // (L, 0) and (u, v): Q_j = t1 q1^T + t2 q2^T with q1 = (-v, v, 0) / 2 and
    // q2 = (u - L, -u, L) / 2 (area times the hat functions' gradients).
    const Eigen::Map<const Eigen::Matrix3d> frame(m.blend.triangle_frames.col(t).data());
    const Eigen::Vector3d edge = m.rig.neutral.col(corners[1]) - m.rig.neutral.col(corners[0]);
    const Eigen::Vector3d other = m.rig.neutral.col(corners[2]) - m.rig.neutral.col(corners[0]);
    const double values[kOperatorComponents] = {frame(0, 0), frame(1, 0), frame(2, 0), frame(0, 1), frame(1, 1), frame(2, 1),
                                                0.5 * edge.dot(frame.col(0)), 0.5 * other.dot(frame.col(0)),
                                                0.5 * other.dot(frame.col(1))};
    const auto slot = std::size_t(m.blend.triangle_blocks.slot_of_element[std::size_t(t)]);
    for (int c = 0; c < kOperatorComponents; ++c)
      operator_[(slot / B * kOperatorComponents + std::size_t(c)) * B + slot % B] = float(values[c]);
    slot_corners_[slot] = {corners[0], corners[1], corners[2]};
  }
  const BlendTerms& terms = kind_ == Kind::kNonlinear ? m.blend.triangle_nonlinear : m.blend.triangle_gradient;
  streamed_ = {std::as_bytes(std::span(terms.values)), std::as_bytes(std::span(terms.scales)),
               std::as_bytes(std::span(terms.offsets)), std::as_bytes(std::span(operator_))};
}

// Block by block: sums the active shapes' terms in vector registers, turns each sum into
// T_j - I (Eq. 4 for nonlinear, sum w_i (F_ij - I) for dt), multiplies by Q_j and adds
// that to rhs (which starts as the T = I right-hand side). The terms are read once,
// front to back: memory bandwidth is what bounds the stage.
void TriangleBlend::right_hand_side(const float* weights, Eigen::Matrix3Xd& rhs) const noexcept {
  const SolverModel& m = model_;
  rhs = identity_rhs_;
  const ShapeBlocks& blocks = m.blend.triangle_blocks;
  const BlendTerms& terms = kind_ == Kind::kNonlinear ? m.blend.triangle_nonlinear : m.blend.triangle_gradient;
  constexpr int B = ShapeBlocks::kBlock;
  constexpr int kNonlinear = BlendData::kNonlinearComponents, kGradient = BlendData::kGradientComponents;
  alignas(64) float sum[std::max(kNonlinear, kGradient) * B];
  alignas(64) float out[9 * B];  // (T_j - I) Q_j: column k, row r at [(3 k + r) B + slot]
  for (int block = 0; block < blocks.block_count(); ++block) {
    const float* frame = operator_.data() + std::size_t(block) * kOperatorComponents * B;
    if (kind_ == Kind::kDeformationTransfer) {
      sum_block<kGradient>(terms, block, weights, reinterpret_cast<float(&)[kGradient * B]>(sum));
      transfer_block(sum, frame, out);
    } else {
      sum_block<kNonlinear>(terms, block, weights, reinterpret_cast<float(&)[kNonlinear * B]>(sum));
      nonlinear_block(sum, frame, out);
    }
    const std::array<int32_t, 3>* corners = slot_corners_.data() + std::size_t(block) * B;
    for (int i = 0; i < B; ++i) {
      if (corners[i][0] < 0) continue;  // padding
      for (int k = 0; k < 3; ++k) {
        double* column = rhs.data() + 3 * std::size_t(corners[i][std::size_t(k)]);
        for (int r = 0; r < 3; ++r) column[r] += out[(3 * k + r) * B + i];
      }
    }
  }
}

}  // namespace facecap
