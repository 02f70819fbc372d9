#pragma once
// The bounding volume hierarchy under the collider and the intersection metrics
// (internal to solver/collide/): axis-aligned boxes over a set of triangles, built once
// on the rest mesh, refitted per frame, traversed for the pairs whose boxes overlap.
#include <array>
#include <bit>
#include <cstdint>
#include <span>
#include <utility>
#include <vector>

#include <Eigen/Core>

#include "solver/collide/triangle_pair.hpp"
#include "solver/simd.hpp"

namespace facecap::bvh {

using Vec3 = Eigen::Vector3d;

inline constexpr int kMaxLeafSize = simd::kFloatX16Lanes;

// Boxes are stored in float, rounded outwards, so that sixteen leaf slots fit one AVX-512
// register; every decision about a pair is still made in double by the exact test.
struct Box {
  float lo[3];
  float hi[3];
};

// The boxes of one leaf's slots, one lane per slot. Unused lanes hold empty boxes
// (lo = +inf, hi = -inf) that overlap nothing.
struct alignas(64) LeafBoxes {
  simd::FloatX16 lo[3];
  simd::FloatX16 hi[3];
};

// Which slots of `leaf` overlap `box`, as bits.
[[gnu::always_inline]] inline uint32_t slots_overlapping(const LeafBoxes& leaf, const Box& box) noexcept {
  const simd::MaskX16 m = (leaf.lo[0] <= box.hi[0]) & (leaf.hi[0] >= box.lo[0]) & (leaf.lo[1] <= box.hi[1]) &
                          (leaf.hi[1] >= box.lo[1]) & (leaf.lo[2] <= box.hi[2]) & (leaf.hi[2] >= box.lo[2]);
  return simd::lane_bits(m);
}

// Four child boxes of an inner node, one lane each.
inline constexpr int kArity = 4;

// A reference to a tree element: >= 0 an inner node, < 0 the leaf ~ref.
using Ref = int32_t;
inline bool is_leaf(Ref r) noexcept { return r < 0; }
inline int32_t leaf_of(Ref r) noexcept { return ~r; }

struct alignas(16) Node4 {
  simd::FloatX4 lo[3];  // child boxes; unused lanes are empty and overlap nothing
  simd::FloatX4 hi[3];
  Ref child[kArity] = {0, 0, 0, 0};
  int32_t child_count = 0;
};

// Which children of `node` overlap `box`, as bits.
inline uint32_t children_overlapping(const Node4& node, const Box& box) noexcept {
  const simd::MaskX4 m = (node.lo[0] <= box.hi[0]) & (node.hi[0] >= box.lo[0]) & (node.lo[1] <= box.hi[1]) &
                         (node.hi[1] >= box.lo[1]) & (node.lo[2] <= box.hi[2]) & (node.hi[2] >= box.lo[2]);
  return simd::lane_bits(m);
}

inline Box child_box(const Node4& node, int lane) noexcept {
  return {{node.lo[0][lane], node.lo[1][lane], node.lo[2][lane]}, {node.hi[0][lane], node.hi[1][lane], node.hi[2][lane]}};
}

struct Leaf {
  int32_t first = 0;  // first slot
  int32_t count = 0;  // slots, 1..kMaxLeafSize
};

// A tree of boxes over triangles stored in "slots" (leaf order), up to kMaxLeafSize per
// leaf, four children per inner node. Built once on the rest pose: top-down binary
// splits by the surface area heuristic (every split of the centroid order on each
// axis; ties broken by triangle index, so the tree depends only on its input), then
// collapsed to four-wide nodes so one SIMD compare tests four boxes. Refitting keeps
// the topology and only recomputes boxes.
class Tree {
 public:
  // triangle_indices: the triangles to hold, in any order; positions: where to build.
  void build(const Eigen::Matrix3Xi& triangles, const Eigen::Matrix3Xd& positions,
             std::span<const int32_t> triangle_indices);

  // New boxes from positions, each grown by `margin` on every side. Real-time safe.
  void refit(const Eigen::Ref<const Eigen::Matrix3Xd>& positions, double margin) noexcept;

  // Calls visit(slot_a, slot_b) for every pair of distinct slots whose boxes overlap,
  // whose triangles share no vertex and that are not skipped, each pair once.
  // Real-time safe when visit is: it allocates nothing itself. Returns false if the
  // traversal stack ran out, which the bound in build() rules out.
  template <typename Visit>
  bool for_each_overlapping_pair(Visit&& visit) {
    if (leaves_.empty()) return true;
    std::size_t top = 0;
    const std::size_t capacity = stack_.size();
    stack_[top++] = {root_, root_};
    while (top > 0) {
      const auto [a, b] = stack_[--top];
      if (top + 16 > capacity) return false;
      if (a == b) {
        if (is_leaf(a)) {
          visit_within_leaf(leaf_of(a), visit);
          continue;
        }
        const Node4& node = nodes_[std::size_t(a)];
        for (int i = 0; i < node.child_count; ++i) {
          stack_[top++] = {node.child[i], node.child[i]};
          uint32_t later = children_overlapping(node, child_box(node, i)) & ~((2u << i) - 1);
          for (; later != 0; later &= later - 1) stack_[top++] = {node.child[i], node.child[std::countr_zero(later)]};
        }
      } else if (is_leaf(a) && is_leaf(b)) {
        visit_between_leaves(leaf_of(a), leaf_of(b), visit);
      } else if (!is_leaf(a) && !is_leaf(b)) {
        const Node4& na = nodes_[std::size_t(a)];
        const Node4& nb = nodes_[std::size_t(b)];
        for (int i = 0; i < na.child_count; ++i) {
          uint32_t hits = children_overlapping(nb, child_box(na, i));
          for (; hits != 0; hits &= hits - 1) stack_[top++] = {na.child[i], nb.child[std::countr_zero(hits)]};
        }
      } else {
        const Ref inner = is_leaf(a) ? b : a, leaf = is_leaf(a) ? a : b;
        const Node4& node = nodes_[std::size_t(inner)];
        uint32_t hits = children_overlapping(node, leaf_box_[std::size_t(leaf_of(leaf))]);
        for (; hits != 0; hits &= hits - 1) stack_[top++] = {node.child[std::countr_zero(hits)], leaf};
      }
    }
    return true;
  }

  // Also skip these triangle pairs from now on (pairs of triangles not in the tree are
  // ignored). Not real-time.
  void skip_pairs(std::span<const TrianglePair> pairs) { build_skip_masks(pairs); }

  std::span<const int32_t> slot_triangles() const noexcept { return slot_triangle_; }
  const std::array<int32_t, 3>& slot_vertices(int32_t slot) const noexcept { return slot_vertices_[std::size_t(slot)]; }
  int depth() const noexcept { return depth_; }

 private:
  // Bit t of row s of a leaf-pair mask stands for slot s of the first leaf and slot t of
  // the second.
  struct PairMask {
    uint16_t row[kMaxLeafSize] = {};
  };
  static_assert(kMaxLeafSize <= 16);
  static constexpr int32_t kSkipGroup = 16;  // skip_leaf_ entries compared at once (one AVX-512 register)

  struct BuildInput {
    std::vector<Vec3> centroid, lo, hi;  // per triangle (index into the input order)
    std::vector<int32_t> order;          // permutation, leaf order once built
  };
  struct BuildNode {
    int32_t left = -1, right = -1;  // children in the binary tree; -1 for a leaf
    int32_t first = 0, count = 0;   // range of `order` below this node
    double area = 0.0;              // half the surface area of its box
  };

  static double half_area(const Vec3& lo, const Vec3& hi) {
    const Vec3 d = hi - lo;
    return d.x() * d.y() + d.y() * d.z() + d.z() * d.x();
  }

  int32_t build_binary(BuildInput& in, std::vector<BuildNode>& out, int32_t begin, int32_t end);

  // Turns binary node `index` into a four-wide node (pre-order: children after their
  // parent) by repeatedly opening the largest inner child; returns its reference.
  Ref collapse(const std::vector<BuildNode>& binary, int32_t index, int depth);

  // For every pair of leaves holding slot pairs to skip (triangles sharing a vertex, a
  // leaf with itself included, and the extra skipped pairs), which slot pairs those
  // are. Most box-overlapping pairs are such neighbours; the masks drop them without
  // looking at their boxes.
  void build_skip_masks(std::span<const TrianglePair> extra_skipped);

  [[gnu::always_inline]] const PairMask& skip_mask(int32_t leaf_a, int32_t leaf_b) const noexcept {
    static constexpr PairMask kNone{};
    const int32_t end = skip_offset_[std::size_t(leaf_a) + 1];
    for (int32_t k = skip_offset_[std::size_t(leaf_a)]; k < end; k += kSkipGroup) {
#if defined(__AVX512F__)
      const __mmask16 hit = _mm512_cmpeq_epi32_mask(_mm512_loadu_si512(skip_leaf_.data() + k), _mm512_set1_epi32(leaf_b));
      if (hit != 0) return skip_mask_[std::size_t(k + std::countr_zero(unsigned(hit)))];
#elif defined(__SSE2__)
      const __m128i wanted = _mm_set1_epi32(leaf_b);
      uint32_t hit = 0;
      for (int q = 0; q < 4; ++q) {
        const __m128i four = _mm_loadu_si128(reinterpret_cast<const __m128i*>(skip_leaf_.data() + k + 4 * q));
        hit |= uint32_t(_mm_movemask_ps(_mm_castsi128_ps(_mm_cmpeq_epi32(four, wanted)))) << (4 * q);
      }
      if (hit != 0) return skip_mask_[std::size_t(k + std::countr_zero(hit))];
#else
      for (int32_t i = k; i < k + kSkipGroup; ++i)
        if (skip_leaf_[std::size_t(i)] == leaf_b) return skip_mask_[std::size_t(i)];
#endif
    }
    return kNone;
  }

  template <typename Visit>
  void visit_between_leaves(int32_t la, int32_t lb, Visit& visit) noexcept {
    const Leaf& a = leaves_[std::size_t(la)];
    const Leaf& b = leaves_[std::size_t(lb)];
    const LeafBoxes& boxes_a = leaf_boxes_[std::size_t(la)];
    const LeafBoxes& boxes_b = leaf_boxes_[std::size_t(lb)];
    // Only slots reaching into the other leaf's box can pair up.
    uint32_t a_slots = slots_overlapping(boxes_a, leaf_box_[std::size_t(lb)]);
    const uint32_t b_slots = slots_overlapping(boxes_b, leaf_box_[std::size_t(la)]);
    if (a_slots == 0 || b_slots == 0) return;
    const PairMask& skipped = skip_mask(la, lb);
    for (; a_slots != 0; a_slots &= a_slots - 1) {
      const int s = std::countr_zero(a_slots);
      uint32_t row = slots_overlapping(boxes_b, slot_box_[std::size_t(a.first + s)]) & b_slots & ~uint32_t(skipped.row[s]);
      for (; row != 0; row &= row - 1) visit(a.first + s, b.first + std::countr_zero(row));
    }
  }

  template <typename Visit>
  void visit_within_leaf(int32_t l, Visit& visit) noexcept {
    const Leaf& a = leaves_[std::size_t(l)];
    const LeafBoxes& boxes = leaf_boxes_[std::size_t(l)];
    const PairMask& skipped = skip_mask(l, l);
    for (int s = 0; s + 1 < a.count; ++s) {
      // Slots after s (unused lanes never overlap), not skipped.
      uint32_t row = slots_overlapping(boxes, slot_box_[std::size_t(a.first + s)]) & ~((2u << s) - 1) &
                     ~uint32_t(skipped.row[s]);
      for (; row != 0; row &= row - 1) visit(a.first + s, a.first + std::countr_zero(row));
    }
  }

  std::vector<Node4> nodes_;                          // pre-order: children after their parent
  std::vector<Box> node_box_;                         // per inner node: union of its children
  std::vector<Leaf> leaves_;
  std::vector<LeafBoxes> leaf_boxes_;                 // per leaf: its slots' boxes, refitted
  std::vector<Box> leaf_box_;                         // per leaf: union of its slots
  std::vector<Box> slot_box_;                         // per slot, the same boxes as leaf_boxes_
  Ref root_ = 0;
  std::vector<int32_t> slot_triangle_;                // triangle index per slot
  std::vector<std::array<int32_t, 3>> slot_vertices_;
  std::vector<int32_t> skip_offset_;                  // per leaf: range in skip_leaf_/skip_mask_
  std::vector<int32_t> skip_leaf_;                    // leaves with pairs to skip, ascending per leaf, then -1s
  std::vector<PairMask> skip_mask_;                   // slot pairs to skip
  std::vector<std::pair<Ref, Ref>> stack_;            // traversal scratch, sized at build
  int depth_ = 0;
};


}  // namespace facecap::bvh
