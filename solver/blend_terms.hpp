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
#include "solver/kernels/kernels.hpp"

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
  static constexpr int kWidths = kernels::kWidths;
  static constexpr int kBytesPerValue[kWidths] = {1, 2, 4};
  static constexpr float kScaleUnit = kernels::kScaleUnit;  // float entries' scale, 1, is the half 32768
  // Per block: the byte offset of its first value (64-byte aligned), its first position,
  // its 8-bit, 16-bit and float entries, in that order.
  using BlockRun = kernels::BlockRun;

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
  // As the per-frame kernels read it. Valid while this lives unchanged.
  kernels::BlendTermsView view() const noexcept {
    return {blocks.data(), shape.data(), scales.data(), offsets.data(), values.data()};
  }

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
// active_weight and where the weight times the shape's reach (its largest vertex
// displacement, M) stays within `negligible`, so that their entries are skipped. out: M.
// Real-time safe.
void active_weights(const Eigen::VectorXd& w, double active_weight, const Eigen::VectorXd& reach, double negligible,
                    std::vector<float>& out) noexcept;

// x0 + B w over the active weights (from active_weights) for the elements of `blocks`,
// one block at a time, by the kernels of `table`: element e is rig vertex vertices[e], or
// vertex e when vertices is empty; out column e.
class LinearBlend {
 public:
  // Keeps references to its arguments. Not real-time.
  LinearBlend(const kernels::KernelTable& table, const ShapeBlocks& blocks, const BlendTerms& terms,
              const Eigen::Matrix3Xd& neutral, std::span<const int> vertices = {}) noexcept
      : table_(table), blocks_(blocks),
        view_{terms.view(), blocks.element_of_slot.data(), neutral.data(), vertices.empty() ? nullptr : vertices.data()} {}
  int block_count() const noexcept { return blocks_.block_count(); }
  // One block into out (3 x elements). Real-time safe.
  void block(const float* weights, int block, Eigen::Matrix3Xd& out) const noexcept {
    table_.linear_blend_block(view_, weights, block, out.data());
  }
  // Every block. Real-time safe.
  void all(const float* weights, Eigen::Matrix3Xd& out) const noexcept {
    for (int b = 0; b < block_count(); ++b) block(weights, b, out);
  }

 private:
  const kernels::KernelTable& table_;
  const ShapeBlocks& blocks_;
  kernels::LinearBlendView view_;
};

}  // namespace facecap
