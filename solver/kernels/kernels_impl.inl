// The per-frame kernels' bodies (kernels.hpp), written once for every path: each
// kernels_<path>.cpp defines FACECAP_KERNEL_NS and includes this file, compiled with its
// path's flags. Vectors are GCC vector extensions of kLanes floats, the widest register
// the path has; the few operations the compiler does not map well (widening loads, half
// floats, lane masks) are spelled out per instruction set below.
//
// Everything here has internal linkage or lives in facecap::kernels::FACECAP_KERNEL_NS,
// and uses no Eigen or std template: an inline function instantiated here would be
// compiled for this path's CPU and could be the copy the linker keeps for every caller
// (tests/check_kernel_symbols.cmake checks the objects for such symbols).
#ifndef FACECAP_KERNEL_NS
#error "define FACECAP_KERNEL_NS before including kernels_impl.inl"
#endif

#include <cmath>
#include <cstring>
#include <type_traits>

#if defined(__SSE4_1__)
#include <immintrin.h>
#endif

#include "solver/kernels/kernels.hpp"

namespace facecap::kernels::FACECAP_KERNEL_NS {
namespace {

#if defined(__AVX512F__) && defined(__AVX512BW__) && defined(__AVX512VL__) && defined(__AVX512DQ__)
constexpr KernelPath kPath = KernelPath::kAvx512;
constexpr int kLanes = 16;
constexpr int kAccumulators = 24;  // of 32 zmm registers, the rest for loads and factors
#elif defined(__AVX2__) && defined(__FMA__) && defined(__F16C__)
constexpr KernelPath kPath = KernelPath::kAvx2;
constexpr int kLanes = 8;
constexpr int kAccumulators = 12;  // of 16 ymm registers
#else
constexpr KernelPath kPath = KernelPath::kPortable;
constexpr int kLanes = 4;
constexpr int kAccumulators = 12;  // of 16 xmm registers
#endif

using Float = float __attribute__((vector_size(kLanes * sizeof(float))));
using Mask = int32_t __attribute__((vector_size(kLanes * sizeof(float))));
// x, y, z and a pad lane of one vertex: one vector operation per factor entry. Aligned to
// 8 only: Eigen may align the storage it points into to 16.
using DoubleX4 = double __attribute__((vector_size(32), aligned(8)));

constexpr int B = kBlockSlots;
constexpr int kBytesPerValue[kWidths] = {1, 2, 4};

template <class V>
inline V load(const float* p) noexcept {
  V v;
  std::memcpy(&v, p, sizeof v);
  return v;
}
template <class V>
inline void store(float* p, const V& v) noexcept {
  std::memcpy(p, &v, sizeof v);
}
inline Float broadcast(float x) noexcept { return Float{} + x; }
inline Float vmin(const Float& a, const Float& b) noexcept { return a < b ? a : b; }
inline Float vmax(const Float& a, const Float& b) noexcept { return a > b ? a : b; }

// Bit i set where lane i of m is set.
inline uint32_t lane_bits(const Mask& m) noexcept {
#if defined(__AVX512F__)
  return uint32_t(_mm512_movepi32_mask(__m512i(m)));
#elif defined(__AVX2__)
  return uint32_t(_mm256_movemask_ps(__m256(m)));
#elif defined(__SSE4_1__)
  return uint32_t(_mm_movemask_ps(__m128(m)));
#else
  uint32_t bits = 0;
  for (int i = 0; i < kLanes; ++i) bits |= uint32_t(m[i] != 0) << i;
  return bits;
#endif
}

// kLanes stored values from p as floats: 8-bit (Width 0) and 16-bit (1) ones sign-extended
// and converted, floats (2) loaded.
template <int Width>
inline Float load_values(const std::byte* p) noexcept {
#if defined(__AVX512F__)
  if constexpr (Width == 0)
    return Float(_mm512_cvtepi32_ps(_mm512_cvtepi8_epi32(_mm_loadu_si128(reinterpret_cast<const __m128i*>(p)))));
  else if constexpr (Width == 1)
    return Float(_mm512_cvtepi32_ps(_mm512_cvtepi16_epi32(_mm256_loadu_si256(reinterpret_cast<const __m256i*>(p)))));
  else
    return Float(_mm512_loadu_ps(p));
#elif defined(__AVX2__)
  if constexpr (Width == 0)
    return Float(_mm256_cvtepi32_ps(_mm256_cvtepi8_epi32(_mm_loadl_epi64(reinterpret_cast<const __m128i*>(p)))));
  else if constexpr (Width == 1)
    return Float(_mm256_cvtepi32_ps(_mm256_cvtepi16_epi32(_mm_loadu_si128(reinterpret_cast<const __m128i*>(p)))));
  else
    return Float(_mm256_loadu_ps(reinterpret_cast<const float*>(p)));
#elif defined(__SSE4_1__)
  if constexpr (Width == 0) {
    int32_t four;
    std::memcpy(&four, p, sizeof four);
    return Float(_mm_cvtepi32_ps(_mm_cvtepi8_epi32(_mm_cvtsi32_si128(four))));
  } else if constexpr (Width == 1) {
    return Float(_mm_cvtepi32_ps(_mm_cvtepi16_epi32(_mm_loadl_epi64(reinterpret_cast<const __m128i*>(p)))));
  } else {
    return Float(_mm_loadu_ps(reinterpret_cast<const float*>(p)));
  }
#else
  using Stored = std::conditional_t<Width == 0, int8_t, std::conditional_t<Width == 1, int16_t, float>>;
  Float out;
  for (int i = 0; i < kLanes; ++i) {
    Stored v;
    std::memcpy(&v, p + i * kBytesPerValue[Width], sizeof v);
    out[i] = float(v);
  }
  return out;
#endif
}

// An IEEE half float's value (BlendTerms' scales: finite).
inline float half_value(uint16_t h) noexcept {
#if defined(__F16C__)
  return _cvtsh_ss(h);
#else
  // The half's exponent and mantissa moved into a float's place are the value times
  // 2^-112, subnormals included.
  const uint32_t bits = uint32_t(h & 0x7fffu) << 13;
  float f;
  std::memcpy(&f, &bits, sizeof f);
  f *= 0x1p112f;
  return (h & 0x8000u) ? -f : f;
#endif
}

// ---- The weighted sum over shapes (Eq. 4's sums, x0 + B w) --------------------------

// A block's active entries, gathered so that each value is one load, conversion and
// multiply-add: their values, and per component w * scale.
constexpr int kChunk = 64;
template <int C>
struct Chunk {
  alignas(64) float factor[kChunk][C];
  const std::byte* values[kChunk];
  int8_t width[kChunk];  // ascending: the stored order
  int count = 0;
};

// Vectors per component summed in one pass over a chunk's entries: as many as keep the
// C components' accumulators in registers.
template <int C>
constexpr int vectors_per_pass() noexcept {
  int fit = kAccumulators / C, vectors = 1;
  while (vectors * 2 <= fit && vectors * 2 * kLanes <= B) vectors *= 2;
  return vectors;
}

template <int C, int Width, int V>
inline void add_entries(const Chunk<C>& chunk, int first, int end, int slot, Float (&acc)[C][V]) noexcept {
  for (int e = first; e < end; ++e) {
    const std::byte* values = chunk.values[e];
#pragma GCC unroll 8
    for (int c = 0; c < C; ++c) {
      const Float f = broadcast(chunk.factor[e][c]);
#pragma GCC unroll 4
      for (int v = 0; v < V; ++v)
        acc[c][v] += f * load_values<Width>(values + std::size_t(c * B + slot + v * kLanes) * kBytesPerValue[Width]);
    }
  }
}

// sum (C x B, component-major) += the chunk's weighted values.
template <int C>
void add_chunk(const Chunk<C>& chunk, float* sum) noexcept {
  constexpr int V = vectors_per_pass<C>();
  int end[kWidths] = {0, 0, 0};
  for (int w = 0, e = 0; w < kWidths; ++w) {
    while (e < chunk.count && chunk.width[e] == w) ++e;
    end[w] = e;
  }
  for (int slot = 0; slot < B; slot += V * kLanes) {
    Float acc[C][V];
    for (int c = 0; c < C; ++c)
      for (int v = 0; v < V; ++v) acc[c][v] = load<Float>(sum + c * B + slot + v * kLanes);
    add_entries<C, 0>(chunk, 0, end[0], slot, acc);
    add_entries<C, 1>(chunk, end[0], end[1], slot, acc);
    add_entries<C, 2>(chunk, end[1], end[2], slot, acc);
    for (int c = 0; c < C; ++c)
      for (int v = 0; v < V; ++v) store(sum + c * B + slot + v * kLanes, acc[c][v]);
  }
}

// sum (C x B) = over the active entries of `block`, w_shape * (offset + scale * q), in
// the stored order (8-bit entries, then 16-bit, then float), offsets added last: every
// path adds the same terms in the same order.
template <int C>
void sum_block(const BlendTermsView& terms, int block, const float* weights, float* sum) noexcept {
  Chunk<C> chunk;
  float offsets[C] = {};
  for (int i = 0; i < C * B; ++i) sum[i] = 0.0f;
  const BlockRun& run = terms.blocks[block];
  const std::byte* values = terms.values + run.values;
  int32_t position = run.first;
  for (int w = 0; w < kWidths; ++w) {
    const std::size_t entry_bytes = std::size_t(C) * B * std::size_t(kBytesPerValue[w]);
    for (const int32_t end = position + run.count[w]; position < end; ++position, values += entry_bytes) {
      const float weight = weights[terms.shape[position]];
      if (weight == 0.0f) continue;
      if (chunk.count == kChunk) {
        add_chunk(chunk, sum);
        chunk.count = 0;
      }
      const std::size_t at = std::size_t(position) * C;
      const float scaled_weight = weight * kScaleUnit;
      for (int c = 0; c < C; ++c) {
        offsets[c] += weight * terms.offsets[at + std::size_t(c)];
        chunk.factor[chunk.count][c] = scaled_weight * half_value(terms.scales[at + std::size_t(c)]);
      }
      chunk.values[chunk.count] = values;
      chunk.width[chunk.count] = int8_t(w);
      ++chunk.count;
    }
  }
  add_chunk(chunk, sum);
  for (int c = 0; c < C; ++c)
    for (int s = 0; s < B; s += kLanes) store(sum + c * B + s, load<Float>(sum + c * B + s) + offsets[c]);
}

void linear_blend_block(const LinearBlendView& view, const float* weights, int block, double* out) noexcept {
  alignas(64) float sum[3 * B];
  sum_block<3>(view.terms, block, weights, sum);
  for (int i = 0; i < B; ++i) {
    const int32_t e = view.element_of_slot[block * B + i];
    if (e < 0) continue;
    const int64_t v = view.vertices ? view.vertices[e] : e;
    for (int c = 0; c < 3; ++c) out[3 * int64_t(e) + c] = view.neutral[3 * v + c] + double(sum[c * B + i]);
  }
}

// ---- Eq. 4 per triangle --------------------------------------------------------------

// The rows q1, q2 of Q_j = t1 q1^T + t2 q2^T for the slots of a block from t.
template <class V>
inline void rest_gradients(const float* frame, int t, V (&q1)[3], V (&q2)[3]) noexcept {
  const V half_l = load<V>(frame + 6 * B + t), half_u = load<V>(frame + 7 * B + t), half_v = load<V>(frame + 8 * B + t);
  q1[0] = -half_v, q1[1] = half_v, q1[2] = V{};
  q2[0] = half_u - half_l, q2[1] = -half_u, q2[2] = half_l;
}

// out = (F - I) Q_j = g1 q1^T + g2 q2^T per slot of a block: deformation transfer, with
// g1 = sum w_i (F_i - I) t1 and g2 the same for t2.
void transfer_block(const float* sum, const float* frame, float* out) noexcept {
  for (int t = 0; t < B; t += kLanes) {
    Float q1[3], q2[3];
    rest_gradients(frame, t, q1, q2);
    for (int r = 0; r < 3; ++r) {
      const Float g1 = load<Float>(sum + r * B + t), g2 = load<Float>(sum + (3 + r) * B + t);
      for (int k = 0; k < 3; ++k) store(out + (3 * k + r) * B + t, g1 * q1[k] + g2 * q2[k]);
    }
  }
}

// out = (R (I + S) - I) Q_j for the triangles of a block from slot t (kLanes of them
// with V = Float, one with V = float), R = I + a [r]x + b [r]x^2 and S - I from its
// rest-frame components (xx, yy, xy, xz, yz at sum[3..7]). With U = (S - I) in the rest
// frame times q and W = frame U: R (I + S) Q - Q = (R - I)(Q + W) + W, R - I and W
// small, so nothing cancels against I.
template <class V>
inline void finish_triangles(int t, V rx, V ry, V rz, V x, V a, V b, const float* sum, const float* frame, float* out) noexcept {
  V D[9];  // R - I, column-major
  D[0] = b * (rx * rx - x);     D[3] = -a * rz + b * rx * ry;  D[6] = a * ry + b * rx * rz;
  D[1] = a * rz + b * rx * ry;  D[4] = b * (ry * ry - x);      D[7] = -a * rx + b * ry * rz;
  D[2] = -a * ry + b * rx * rz; D[5] = a * rx + b * ry * rz;   D[8] = b * (rz * rz - x);
  const V t1[3] = {load<V>(frame + t), load<V>(frame + B + t), load<V>(frame + 2 * B + t)};
  const V t2[3] = {load<V>(frame + 3 * B + t), load<V>(frame + 4 * B + t), load<V>(frame + 5 * B + t)};
  const V n[3] = {t1[1] * t2[2] - t1[2] * t2[1], t1[2] * t2[0] - t1[0] * t2[2], t1[0] * t2[1] - t1[1] * t2[0]};
  V q1[3], q2[3];
  rest_gradients(frame, t, q1, q2);
  const V sxx = load<V>(sum + 3 * B + t), syy = load<V>(sum + 4 * B + t), sxy = load<V>(sum + 5 * B + t);
  const V sxz = load<V>(sum + 6 * B + t), syz = load<V>(sum + 7 * B + t);
  for (int k = 0; k < 3; ++k) {
    const V u0 = sxx * q1[k] + sxy * q2[k], u1 = sxy * q1[k] + syy * q2[k], u2 = sxz * q1[k] + syz * q2[k];
    V w[3], y[3];  // W and Q + W, column k
    for (int r = 0; r < 3; ++r) {
      w[r] = t1[r] * u0 + t2[r] * u1 + n[r] * u2;
      y[r] = t1[r] * q1[k] + t2[r] * q2[k] + w[r];
    }
    for (int r = 0; r < 3; ++r) store(out + (3 * k + r) * B + t, D[r] * y[0] + D[3 + r] * y[1] + D[6 + r] * y[2] + w[r]);
  }
}

// out = (exp(sum_log) (I + sum_stretch) - I) Q_j per slot of a block (Eq. 4), in float:
// the rounding (1e-7 of T) is far below the stored terms'.
void nonlinear_block(const float* sum, const float* frame, float* out) noexcept {
  constexpr float kLargestSeriesAngleSq = 6.25f;
  for (int t = 0; t < B; t += kLanes) {
    const Float rx = load<Float>(sum + t), ry = load<Float>(sum + B + t), rz = load<Float>(sum + 2 * B + t);
    const Float x = rx * rx + ry * ry + rz * rz;
    // sin(theta)/theta and (1 - cos(theta))/theta^2 as series in theta^2, exact to float
    // precision for theta <= 2.5; larger turns are redone with sin and cos below.
    Float a = broadcast(1.0f / 6227020800.0f), b = broadcast(1.0f / 87178291200.0f);  // 1/13!, 1/14!
    constexpr float kInvFactorial[] = {1.0f / 39916800.0f, 1.0f / 362880.0f, 1.0f / 5040.0f, 1.0f / 120.0f, 1.0f / 6.0f, 1.0f};
    constexpr float kInvFactorialEven[] = {1.0f / 479001600.0f, 1.0f / 3628800.0f, 1.0f / 40320.0f, 1.0f / 720.0f, 1.0f / 24.0f, 0.5f};
    for (int i = 0; i < 6; ++i) {
      a = kInvFactorial[i] - x * a;
      b = kInvFactorialEven[i] - x * b;
    }
    finish_triangles(t, rx, ry, rz, x, a, b, sum, frame, out);
    uint32_t large = lane_bits(x > kLargestSeriesAngleSq);
    for (; large != 0; large &= large - 1) {
      const int i = __builtin_ctz(large);
      const double theta = std::sqrt(double(x[i]));
      finish_triangles(t + i, rx[i], ry[i], rz[i], x[i], float(std::sin(theta) / theta),
                       float((1.0 - std::cos(theta)) / double(x[i])), sum, frame, out);
    }
  }
}

void triangle_rhs(const TriangleBlendView& view, const float* weights, double* rhs) noexcept {
  alignas(64) float sum[kNonlinearComponents * B];
  alignas(64) float out[9 * B];  // (T_j - I) Q_j: column k, row r at [(3 k + r) B + slot]
  for (int block = 0; block < view.block_count; ++block) {
    const float* frame = view.operators + std::size_t(block) * kOperatorComponents * B;
    if (view.nonlinear) {
      sum_block<kNonlinearComponents>(view.terms, block, weights, sum);
      nonlinear_block(sum, frame, out);
    } else {
      sum_block<kGradientComponents>(view.terms, block, weights, sum);
      transfer_block(sum, frame, out);
    }
    const int32_t (*corners)[3] = view.slot_corners + std::size_t(block) * B;
    for (int i = 0; i < B; ++i) {
      if (corners[i][0] < 0) continue;  // padding
      for (int k = 0; k < 3; ++k) {
        double* column = rhs + 3 * int64_t(corners[i][k]);
        for (int r = 0; r < 3; ++r) column[r] += double(out[(3 * k + r) * B + i]);
      }
    }
  }
}

// ---- Eq. 5's back-substitution -------------------------------------------------------

// Both triangular solves walk L by columns. L y = b scatters each solved entry down its
// column (independent updates, so no chain of dependent additions); L^T u = z gathers
// with four partial sums to keep the adds' latency from bounding the loop.
template <class Row>
void solve_lanes(const LdltView& f, const Row* rows, double* xyz, double* work) noexcept {
  DoubleX4* w = reinterpret_cast<DoubleX4*>(work);
  const int64_t n = f.n;
  const int* col_start = f.col_start;
  const double* vals = f.values;
  for (int64_t k = 0; k < n; ++k) {
    const double* src = xyz + 3 * int64_t(f.perm[k]);
    w[k] = DoubleX4{src[0], src[1], src[2], 0.0};
  }
  for (int64_t j = 0; j < n; ++j) {
    const DoubleX4 y = w[j];
    for (int k = col_start[j]; k < col_start[j + 1]; ++k) w[rows[k]] -= vals[k] * y;
  }
  for (int64_t j = n - 1; j >= 0; --j) {
    DoubleX4 s0 = w[j] * f.inv_diagonal[j], s1{}, s2{}, s3{};
    int k = col_start[j];
    const int end = col_start[j + 1];
    for (; k + 4 <= end; k += 4) {
      s0 -= vals[k] * w[rows[k]];
      s1 -= vals[k + 1] * w[rows[k + 1]];
      s2 -= vals[k + 2] * w[rows[k + 2]];
      s3 -= vals[k + 3] * w[rows[k + 3]];
    }
    for (; k < end; ++k) s0 -= vals[k] * w[rows[k]];
    w[j] = (s0 + s1) + (s2 + s3);
  }
  for (int64_t k = 0; k < n; ++k) {
    double* dst = xyz + 3 * int64_t(f.perm[k]);
    const DoubleX4 v = w[k];
    dst[0] = v[0], dst[1] = v[1], dst[2] = v[2];
  }
}

void ldlt_solve(const LdltView& factor, double* xyz, double* work) noexcept {
  if (factor.row16) solve_lanes(factor, factor.row16, xyz, work);
  else solve_lanes(factor, factor.row32, xyz, work);
}

// ---- The collision test's float pass ------------------------------------------------

// Per lane a 3-vector: one coordinate per Float.
struct Lanes3 {
  Float x, y, z;
};
inline Lanes3 operator+(const Lanes3& a, const Lanes3& b) noexcept { return {a.x + b.x, a.y + b.y, a.z + b.z}; }
inline Lanes3 operator-(const Lanes3& a, const Lanes3& b) noexcept { return {a.x - b.x, a.y - b.y, a.z - b.z}; }
inline Lanes3 operator*(const Lanes3& a, const Float& s) noexcept { return {a.x * s, a.y * s, a.z * s}; }
inline Float dot(const Lanes3& a, const Lanes3& b) noexcept { return a.x * b.x + a.y * b.y + a.z * b.z; }
inline Lanes3 cross(const Lanes3& a, const Lanes3& b) noexcept {
  return {a.y * b.z - a.z * b.y, a.z * b.x - a.x * b.z, a.x * b.y - a.y * b.x};
}
inline Lanes3 select(const Mask& m, const Lanes3& a, const Lanes3& b) noexcept {
  return {m ? a.x : b.x, m ? a.y : b.y, m ? a.z : b.z};
}

// point_triangle_sq per lane (Ericson 5.1.5), every Voronoi region computed and the first
// one that holds chosen. Degenerate triangles give meaningless values: callers leave
// them out.
Float point_triangle_sq(const Lanes3& p, const Lanes3& a, const Lanes3& b, const Lanes3& c) noexcept {
  const Lanes3 ab = b - a, ac = c - a, ap = p - a, bp = p - b, cp = p - c;
  const Float d1 = dot(ab, ap), d2 = dot(ac, ap), d3 = dot(ab, bp), d4 = dot(ac, bp), d5 = dot(ab, cp), d6 = dot(ac, cp);
  const Float va = d3 * d6 - d5 * d4, vb = d5 * d2 - d1 * d6, vc = d1 * d4 - d3 * d2;
  const Float denom = 1.0f / (va + vb + vc);
  Lanes3 q = a + ab * (vb * denom) + ac * (vc * denom);  // inside
  const Float e43 = d4 - d3, e56 = d5 - d6;
  q = select((va <= 0.0f) & (e43 >= 0.0f) & (e56 >= 0.0f), b + (c - b) * (e43 / (e43 + e56)), q);
  q = select((vb <= 0.0f) & (d2 >= 0.0f) & (d6 <= 0.0f), a + ac * (d2 / (d2 - d6)), q);
  q = select((d6 >= 0.0f) & (d5 <= d6), c, q);
  q = select((vc <= 0.0f) & (d1 >= 0.0f) & (d3 <= 0.0f), a + ab * (d1 / (d1 - d3)), q);
  q = select((d3 >= 0.0f) & (d4 <= d3), b, q);
  q = select((d1 <= 0.0f) & (d2 <= 0.0f), a, q);
  const Lanes3 d = p - q;
  return dot(d, d);
}

// segment_segment_sq per lane (Ericson 5.1.9): always the distance between two points of
// the segments, so it never falls below the true one by more than rounding.
Float segment_segment_sq(const Lanes3& p1, const Lanes3& q1, const Lanes3& p2, const Lanes3& q2) noexcept {
  const Lanes3 d1 = q1 - p1, d2 = q2 - p2, r = p1 - p2;
  const Float a = dot(d1, d1), e = dot(d2, d2), f = dot(d2, r), c = dot(d1, r), b = dot(d1, d2);
  auto clamp01 = [](const Float& x) { return vmin(vmax(x, Float{}), broadcast(1.0f)); };
  const Float denom = a * e - b * b;
  Float s = (denom > 1e-6f * a * e) ? clamp01((b * f - c * e) / denom) : Float{};
  Float t = (b * s + f) / e;
  const Mask below = t < 0.0f, above = t > 1.0f;
  s = below ? clamp01(-c / a) : (above ? clamp01((b - c) / a) : s);
  t = clamp01(t);
  const Lanes3 d = (p1 + d1 * s) - (p2 + d2 * t);
  return dot(d, d);
}

// Whether the projections of a and b on `axis` are at least `gap` * |axis| apart.
Mask separated_along(const Lanes3& axis, const Lanes3* a, const Lanes3* b, const Float& gap) noexcept {
  const Float a0 = dot(axis, a[0]), a1 = dot(axis, a[1]), a2 = dot(axis, a[2]);
  const Float b0 = dot(axis, b[0]), b1 = dot(axis, b[1]), b2 = dot(axis, b[2]);
  const Float between = vmax(vmin(vmin(b0, b1), b2) - vmax(vmax(a0, a1), a2), vmin(vmin(a0, a1), a2) - vmax(vmax(b0, b1), b2));
  return (between > 0.0f) & (between * between >= gap * gap * dot(axis, axis));
}

// The float pass over kLanes pairs from lane `first`: which are close for certain (a
// corner's distance to the other triangle or an edge's to an edge, with a margin far
// above float rounding) and which apart (a separating axis: centroids, normals, edge
// pairs).
PairVerdict float_pass_lanes(const PairLanes& lanes, int first, float eps) noexcept {
  auto corner = [&](int k) {
    return Lanes3{load<Float>(lanes.corner[k][0] + first), load<Float>(lanes.corner[k][1] + first),
                  load<Float>(lanes.corner[k][2] + first)};
  };
  const Lanes3 a[3] = {Lanes3{}, corner(0), corner(1)}, b[3] = {corner(2), corner(3), corner(4)};
  const Float scale = load<Float>(lanes.extent + first);
  // Float rounding here stays below 1e-5 of the pair's extent; the margin covers it.
  const Float margin = 1e-3f * eps + 1e-5f * scale;
  const Float apart_gap = eps + margin, close_distance = vmax(eps - margin, Float{});
  Mask apart = separated_along((b[0] + b[1] + b[2]) - (a[1] + a[2]), a, b, apart_gap);
  const Lanes3 na = cross(a[1], a[2]), nb = cross(b[1] - b[0], b[2] - b[0]);
  apart |= separated_along(na, a, b, apart_gap) | separated_along(nb, a, b, apart_gap);
  for (int i = 0; i < 3; ++i)
    for (int j = 0; j < 3; ++j)
      apart |= separated_along(cross(a[(i + 1) % 3] - a[i], b[(j + 1) % 3] - b[j]), a, b, apart_gap);
  // Corner-to-triangle distances only for well-shaped triangles (sine of the corner
  // angle above 1e-4), where the float closest point lies on the triangle.
  const Lanes3 eb1 = b[1] - b[0], eb2 = b[2] - b[0];
  const Mask shaped = (dot(na, na) > 1e-8f * dot(a[1], a[1]) * dot(a[2], a[2])) &
                      (dot(nb, nb) > 1e-8f * dot(eb1, eb1) * dot(eb2, eb2));
  Float nearest = point_triangle_sq(a[0], b[0], b[1], b[2]);
  for (int k = 1; k < 3; ++k) nearest = vmin(nearest, point_triangle_sq(a[k], b[0], b[1], b[2]));
  for (int k = 0; k < 3; ++k) nearest = vmin(nearest, point_triangle_sq(b[k], a[0], a[1], a[2]));
  Float nearest_edges = segment_segment_sq(a[0], a[1], b[0], b[1]);
  for (int i = 0; i < 3; ++i)
    for (int j = 0; j < 3; ++j)
      nearest_edges = vmin(nearest_edges, segment_segment_sq(a[i], a[(i + 1) % 3], b[j], b[(j + 1) % 3]));
  const Mask close = (shaped & (nearest < close_distance * close_distance)) | (nearest_edges < close_distance * close_distance);
  return {lane_bits(close) << first, lane_bits(apart) << first};
}

PairVerdict pair_float_pass(const PairLanes& lanes, int count, float epsilon) noexcept {
  PairVerdict verdict;
  for (int first = 0; first < count; first += kLanes) {
    const PairVerdict part = float_pass_lanes(lanes, first, epsilon);
    verdict.close |= part.close;
    verdict.apart |= part.apart;
  }
  const uint32_t used = count >= 32 ? ~0u : (1u << count) - 1;
  verdict.close &= used;
  verdict.apart &= used;
  return verdict;
}

// ---- The fold metric (collide/folds.hpp) ------------------------------------------------

inline Mask load_indices(const int32_t* p) noexcept {
  Mask m;
  std::memcpy(&m, p, sizeof m);
  return m;
}

// base[index[i]] per lane.
inline Float gather(const float* base, const Mask& index) noexcept {
#if defined(__AVX512F__)
  return Float(_mm512_i32gather_ps(__m512i(index), base, 4));
#elif defined(__AVX2__)
  return Float(_mm256_i32gather_ps(base, __m256i(index), 4));
#else
  Float out;
  for (int i = 0; i < kLanes; ++i) out[i] = base[index[i]];
  return out;
#endif
}

inline Float vsqrt(const Float& x) noexcept {
#if defined(__AVX512F__)
  return Float(_mm512_sqrt_ps(__m512(x)));
#elif defined(__AVX2__)
  return Float(_mm256_sqrt_ps(__m256(x)));
#elif defined(__SSE4_1__)
  return Float(_mm_sqrt_ps(__m128(x)));
#else
  Float out;
  for (int i = 0; i < kLanes; ++i) out[i] = std::sqrt(x[i]);
  return out;
#endif
}

inline Lanes3 gather3(const float* coordinates, int64_t stride, const Mask& index) noexcept {
  return {gather(coordinates, index), gather(coordinates + stride, index), gather(coordinates + 2 * stride, index)};
}
inline Lanes3 load3(const float* p, int64_t stride) noexcept {
  return {load<Float>(p), load<Float>(p + stride), load<Float>(p + 2 * stride)};
}
inline void store3(float* p, int64_t stride, const Lanes3& v) noexcept {
  store(p, v.x);
  store(p + stride, v.y);
  store(p + 2 * stride, v.z);
}
// | |a| - |b| | per lane, from squared lengths.
inline Float length_change(const Float& a2, const Float& b2) noexcept {
  const Float d = vsqrt(a2) - vsqrt(b2);
  return vmax(d, -d);
}

// Appends the indices first + i of the lanes set in `m` to list.
inline int64_t append_lanes(const Mask& m, int64_t first, int32_t* list, int64_t count) noexcept {
  for (uint32_t bits = lane_bits(m); bits != 0; bits &= bits - 1) list[count++] = int32_t(first + __builtin_ctz(bits));
  return count;
}

FoldTrianglesResult fold_triangles(const FoldTrianglesView& v, bool reference_known) noexcept {
  Float stretch{};
  FoldTrianglesResult result;
  const float cos2 = v.cos_half_crease * v.cos_half_crease;
  for (int64_t t = 0; t < v.count; t += kLanes) {
    const Mask ia = load_indices(v.corner[0] + t), ib = load_indices(v.corner[1] + t), ic = load_indices(v.corner[2] + t);
    const Lanes3 sa = gather3(v.solved, v.vertex_stride, ia), sb = gather3(v.solved, v.vertex_stride, ib),
                 sc = gather3(v.solved, v.vertex_stride, ic);
    const Lanes3 ra = gather3(v.reference, v.vertex_stride, ia), rb = gather3(v.reference, v.vertex_stride, ib),
                 rc = gather3(v.reference, v.vertex_stride, ic);
    const Lanes3 su = sb - sa, sv = sc - sa, sw = sc - sb, ru = rb - ra, rv = rc - ra, rw = rc - rb;
    const Lanes3 solved_normal = cross(su, sv);
    Lanes3 reference_normal;
    if (reference_known) {
      reference_normal = load3(v.reference_normals + t, v.normal_stride);
    } else {
      reference_normal = cross(ru, rv);
      store3(v.reference_normals + t, v.normal_stride, reference_normal);
    }
    store3(v.solved_normals + t, v.normal_stride, solved_normal);
    const Lanes3 da = sa - ra, db = sb - rb, dc = sc - rc;
    const Mask visible = vmax(vmax(dot(da, da), dot(db, db)), dot(dc, dc)) > v.tolerance_squared;
    const Float d = dot(solved_normal, reference_normal), reference2 = dot(reference_normal, reference_normal);
    const Mask flipped = visible & (d < 0.0f);
    const Mask turned = visible & ((d < 0.0f) | (d * d < cos2 * dot(solved_normal, solved_normal) * reference2) | (reference2 == 0.0f));
    result.flipped = append_lanes(flipped, t, v.flipped, result.flipped);
    result.turned = append_lanes(turned, t, v.turned, result.turned);
    stretch = vmax(stretch, length_change(dot(su, su), dot(ru, ru)));
    stretch = vmax(stretch, length_change(dot(sv, sv), dot(rv, rv)));
    stretch = vmax(stretch, length_change(dot(sw, sw), dot(rw, rw)));
  }
  for (int k = 0; k < kLanes; ++k) result.max_edge_stretch = result.max_edge_stretch > stretch[k] ? result.max_edge_stretch : stretch[k];
  return result;
}

constexpr KernelTable kTable{kPath, linear_blend_block, triangle_rhs, ldlt_solve, pair_float_pass, fold_triangles};

}  // namespace

const KernelTable& kernel_table() noexcept { return kTable; }

}  // namespace facecap::kernels::FACECAP_KERNEL_NS
