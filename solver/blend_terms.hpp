#pragma once
// Per-shape values on a mesh's elements laid out for the per-frame weighted sum over
// shapes, which memory bandwidth bounds (docs/solver.md, "Blend"), and the kernels that
// sum them: the blend of Eq. 3-4 over triangles and the linear blend x0 + B w over
// vertices both read this layout. The layouts are built once by build_solver_model();
// everything that reads them per frame is real-time safe.
#include <cstddef>
#include <cstdint>
#include <cstring>
#include <span>
#include <type_traits>
#include <vector>

#include <Eigen/Core>

#include "core/huge_pages.hpp"
#include "solver/simd.hpp"

namespace facecap {

// Elements in Morton order of their rest positions, cut into blocks of kBlock neighbours;
// per block, an entry for each shape that changes any of its elements. Slot
// b * kBlock + i of the order is element element_of_slot[slot] (-1: padding).
struct ShapeBlocks {
  static constexpr int kBlock = 32;
  struct Entry {
    int32_t shape = 0, block = 0;
  };
  std::vector<int32_t> element_of_slot, slot_of_element;
  std::vector<Entry> entries;        // grouped by block, shapes ascending within a block
  std::vector<int32_t> block_begin;  // blocks + 1: block b's entries are [block_begin[b], block_begin[b + 1])
  std::vector<int32_t> shape_begin;  // shapes + 1: shape s's entries are shape_entries[shape_begin[s] ..]
  std::vector<int32_t> shape_entries;

  int block_count() const noexcept { return block_begin.empty() ? 0 : int(block_begin.size()) - 1; }
  std::span<const int32_t> entries_of_shape(Eigen::Index shape) const noexcept {
    return {shape_entries.data() + shape_begin[std::size_t(shape)],
            std::size_t(shape_begin[std::size_t(shape) + 1] - shape_begin[std::size_t(shape)])};
  }
  // The entry of `shape` in `block`, or -1.
  int32_t find_entry(Eigen::Index shape, int block) const noexcept;
};

// `components` values per element for every entry of a ShapeBlocks, laid out for the
// per-frame weighted sum: a frame reads each block's active entries once, front to back.
// Each entry stores component c of slot i at [c * kBlock + i] (component-major) as
// offset + scale * q, one offset and scale per entry and component spanning that
// block's values (a block holds neighbours, so its range is usually small):
// - 8-bit q where half a step of range / 254 stays within the tolerance given at build,
// - 16-bit q (range / 65534 steps) where that is too coarse,
// - plain float (offset 0, scale 1) where even 16 bits would be.
// Per block the 8-bit entries come first, then the 16-bit and the float ones, their
// values in one contiguous run. Every value costs the same: one widening load, one
// conversion and one multiply-add. The scales are IEEE half floats in units of
// kScaleUnit (the smallest at least the step needed; 11 bits keep them within 0.1%),
// the offsets floats.
struct BlendTerms {
  static constexpr int kWidths = 3;
  static constexpr int kBytesPerValue[kWidths] = {1, 2, 4};
  static constexpr float kScaleUnit = 1.0f / 32768.0f;  // float entries' scale, 1, is the half 32768
  struct BlockRun {
    std::size_t values = 0;       // byte offset of the block's first value (64-byte aligned)
    int32_t first = 0;            // its first position
    int32_t count[kWidths] = {};  // its 8-bit, 16-bit and float entries, in that order
  };

  int components = 0;
  std::vector<BlockRun> blocks;
  // Per position (entries in stored order):
  std::vector<int32_t> shape;
  HugePageVector<uint16_t> scales;  // components: half floats, times kScaleUnit
  HugePageVector<float> offsets;    // components
  HugePageVector<std::byte> values;
  std::vector<int32_t> position_of_entry;  // per ShapeBlocks entry

  // The stored value of a ShapeBlocks entry; all of them, component-major
  // (components x kBlock). Not on the per-frame path.
  double at(int32_t entry, int component, int slot) const noexcept;
  void decode(int32_t entry, std::span<double> out) const noexcept;

 private:
  struct Located {
    std::size_t position = 0, values = 0;  // the entry's position and its first value's byte
    int width = 0;
  };
  Located locate(int32_t entry) const noexcept;
  double stored(const Located& entry, int component, int slot) const noexcept;
};

// IEEE half-precision floats (BlendTerms' scales): the value of h, and the smallest
// half at least x (0 <= x <= 65504).
float half_to_float(uint16_t h) noexcept;
uint16_t half_at_least(float x) noexcept;

// Per frame, each shape's weight as the blend reads it: 0 for weights at or below
// active_weight, so that their entries are skipped. out: M. Real-time safe.
void active_weights(const Eigen::VectorXd& w, double active_weight, std::vector<float>& out) noexcept;

// x0 + B w over the active weights (from active_weights) for the elements in one block
// of `blocks`: element e is rig vertex vertices[e], or vertex e when vertices is empty;
// out column e. Real-time safe.
void linear_blend_block(const ShapeBlocks& blocks, const BlendTerms& terms, const Eigen::Matrix3Xd& neutral,
                        std::span<const int> vertices, const float* weights, int block, Eigen::Matrix3Xd& out) noexcept;

namespace blend_kernel {

using simd::FloatX16;

// 16 stored values as floats: 8-bit and 16-bit ones widened and converted (GCC 12 turns
// __builtin_convertvector from small integers into scalar code, so AVX-512 gets the two
// instructions spelled out).
template <int Width>
FloatX16 load_values(const std::byte* p) noexcept {
#if defined(__AVX512F__)
  if constexpr (Width == 0)
    return FloatX16(_mm512_cvtepi32_ps(_mm512_cvtepi8_epi32(_mm_load_si128(reinterpret_cast<const __m128i*>(p)))));
  else if constexpr (Width == 1)
    return FloatX16(_mm512_cvtepi32_ps(_mm512_cvtepi16_epi32(_mm256_load_si256(reinterpret_cast<const __m256i*>(p)))));
  else
    return FloatX16(_mm512_load_ps(p));
#else
  using Stored = std::conditional_t<Width == 0, int8_t, std::conditional_t<Width == 1, int16_t, float>>;
  Stored v[16];
  std::memcpy(v, p, sizeof v);
  FloatX16 out;
  for (int i = 0; i < 16; ++i) out[i] = float(v[i]);
  return out;
#endif
}

// `Components` floats from p into the first lanes, zeros after.
template <int Components>
FloatX16 load_head(const float* p) noexcept {
  static_assert(Components <= 16);
#if defined(__AVX512F__)
  return FloatX16(_mm512_maskz_loadu_ps(__mmask16((1u << Components) - 1), p));
#else
  FloatX16 out = {};
  for (int i = 0; i < Components; ++i) out[i] = p[i];
  return out;
#endif
}

// `Components` half floats from p as floats into the first lanes, zeros after.
template <int Components>
FloatX16 load_half_head(const uint16_t* p) noexcept {
  static_assert(Components <= 16);
#if defined(__AVX512F__) && defined(__AVX512BW__) && defined(__AVX512VL__)
  return FloatX16(_mm512_cvtph_ps(_mm256_maskz_loadu_epi16(__mmask16((1u << Components) - 1), p)));
#else
  FloatX16 out = {};
  for (int i = 0; i < Components; ++i) out[i] = half_to_float(p[i]);
  return out;
#endif
}

}  // namespace blend_kernel

// sum over the active entries of `block` of w_shape * value, component-major (BlendTerms),
// in FloatX16 lanes so that the block's sums stay in registers. An entry's weighted scales
// and offsets take one vector operation each; every value one load, conversion and
// multiply-add. weights: per shape, from active_weights. Always inlined, so that the
// sums stay in registers for the caller's next step (out of line the blend measured 10%
// slower). Real-time safe.
template <int Components>
[[gnu::always_inline]] inline void sum_block(const BlendTerms& terms, int block, const float* weights, float (&sum)[Components * ShapeBlocks::kBlock]) noexcept {
  using simd::FloatX16;
  constexpr int B = ShapeBlocks::kBlock, L = B / 16;  // FloatX16 per component
  static_assert(L * 16 == B);
  FloatX16 lanes[Components][L] = {};
  FloatX16 offsets = {};  // lane c: the weighted offsets of component c
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
      const FloatX16 wv = FloatX16{} + w;
      offsets += wv * blend_kernel::load_head<Components>(terms.offsets.data() + at);
      const FloatX16 f = (wv * BlendTerms::kScaleUnit) * blend_kernel::load_half_head<Components>(terms.scales.data() + at);
      std::memcpy(factor, &f, sizeof f);
#pragma GCC unroll 16
      for (int c = 0; c < Components; ++c)
#pragma GCC unroll 2
        for (int l = 0; l < L; ++l)
          lanes[c][l] += factor[c] * blend_kernel::load_values<Width>(values + (c * L + l) * kLaneBytes);
    }
  };
  add_entries(std::integral_constant<int, 0>{});
  add_entries(std::integral_constant<int, 1>{});
  add_entries(std::integral_constant<int, 2>{});
  for (int c = 0; c < Components; ++c)
    for (int l = 0; l < L; ++l) {
      const FloatX16 v = lanes[c][l] + offsets[c];
      std::memcpy(sum + (c * L + l) * 16, &v, sizeof v);
    }
}

}  // namespace facecap
