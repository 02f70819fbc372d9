#include "solver/collide/bvh.hpp"

#include <algorithm>
#include <cmath>
#include <limits>
#include <numeric>

namespace facecap::bvh {
namespace {

Box merge(const Box& a, const Box& b) noexcept {
  Box m;
  for (int k = 0; k < 3; ++k) {
    m.lo[k] = std::min(a.lo[k], b.lo[k]);
    m.hi[k] = std::max(a.hi[k], b.hi[k]);
  }
  return m;
}

// A float no larger (smaller) than x: the relative margin exceeds float's rounding
// error (2^-24), the absolute one keeps it so near 0.
float float_below(double x) noexcept { return float(x - (std::abs(x) * 0x1p-22 + 1e-30)); }
float float_above(double x) noexcept { return float(x + (std::abs(x) * 0x1p-22 + 1e-30)); }

bool share_vertex(const std::array<int32_t, 3>& s, const std::array<int32_t, 3>& t) noexcept {
  return (s[0] == t[0]) | (s[0] == t[1]) | (s[0] == t[2]) | (s[1] == t[0]) | (s[1] == t[1]) | (s[1] == t[2]) |
         (s[2] == t[0]) | (s[2] == t[1]) | (s[2] == t[2]);
}

}  // namespace

void Tree::build(const Eigen::Matrix3Xi& triangles, const Eigen::Matrix3Xd& positions,
                 std::span<const int32_t> triangle_indices) {
  const auto count = triangle_indices.size();
  slot_triangle_.assign(triangle_indices.begin(), triangle_indices.end());
  BuildInput input;
  input.centroid.resize(count);
  input.lo.resize(count);
  input.hi.resize(count);
  for (std::size_t i = 0; i < count; ++i) {
    const auto t = slot_triangle_[i];
    const Vec3 p0 = positions.col(triangles(0, t)), p1 = positions.col(triangles(1, t)), p2 = positions.col(triangles(2, t));
    input.centroid[i] = (p0 + p1 + p2) / 3.0;
    input.lo[i] = p0.cwiseMin(p1).cwiseMin(p2);
    input.hi[i] = p0.cwiseMax(p1).cwiseMax(p2);
  }
  input.order.resize(count);
  std::iota(input.order.begin(), input.order.end(), 0);
  std::vector<BuildNode> binary;
  binary.reserve(2 * count + 1);
  leaves_.clear();
  nodes_.clear();
  depth_ = 0;
  if (count > 0) {
    build_binary(input, binary, 0, int32_t(count));
    root_ = collapse(binary, 0, 1);
  }
  // Slots in leaf order, with each triangle's vertices stored beside it.
  std::vector<int32_t> sorted(count);
  for (std::size_t i = 0; i < count; ++i) sorted[i] = slot_triangle_[std::size_t(input.order[i])];
  slot_triangle_ = std::move(sorted);
  slot_vertices_.resize(count);
  for (std::size_t i = 0; i < count; ++i)
    for (int k = 0; k < 3; ++k) slot_vertices_[i][std::size_t(k)] = triangles(k, slot_triangle_[i]);
  const float inf = std::numeric_limits<float>::infinity();
  leaf_boxes_.resize(leaves_.size());
  for (LeafBoxes& leaf : leaf_boxes_)
    for (int k = 0; k < 3; ++k)
      for (int lane = 0; lane < kMaxLeafSize; ++lane) {
        leaf.lo[k][lane] = inf;
        leaf.hi[k][lane] = -inf;
      }
  leaf_box_.assign(leaves_.size(), Box{{inf, inf, inf}, {-inf, -inf, -inf}});
  slot_box_.assign(count, Box{{inf, inf, inf}, {-inf, -inf, -inf}});
  node_box_.assign(nodes_.size(), Box{{inf, inf, inf}, {-inf, -inf, -inf}});
  build_skip_masks({});
  // A popped pair pushes at most 16; at most 15 stay pending per level of the pair
  // recursion, whose levels (the sum of both elements' depths) number below 2 * depth.
  stack_.resize(std::size_t(32 * depth_ + 32));
}

void Tree::refit(const Eigen::Ref<const Eigen::Matrix3Xd>& positions, double margin) noexcept {
  for (std::size_t l = 0; l < leaves_.size(); ++l) {
    const Leaf& leaf = leaves_[l];
    LeafBoxes& lanes = leaf_boxes_[l];
    for (int32_t lane = 0; lane < leaf.count; ++lane) {
      const auto& v = slot_vertices_[std::size_t(leaf.first + lane)];
      const double* p0 = &positions.coeffRef(0, v[0]);
      const double* p1 = &positions.coeffRef(0, v[1]);
      const double* p2 = &positions.coeffRef(0, v[2]);
      Box& slot = slot_box_[std::size_t(leaf.first + lane)];
      for (int k = 0; k < 3; ++k) {
        slot.lo[k] = lanes.lo[k][lane] = float_below(std::min({p0[k], p1[k], p2[k]}) - margin);
        slot.hi[k] = lanes.hi[k][lane] = float_above(std::max({p0[k], p1[k], p2[k]}) + margin);
      }
    }
    Box& box = leaf_box_[l];
    for (int k = 0; k < 3; ++k) {
      box.lo[k] = lanes.lo[k][0];
      box.hi[k] = lanes.hi[k][0];
      for (int32_t lane = 1; lane < leaf.count; ++lane) {
        box.lo[k] = std::min(box.lo[k], lanes.lo[k][lane]);
        box.hi[k] = std::max(box.hi[k], lanes.hi[k][lane]);
      }
    }
  }
  // Children follow their parent, so a reverse sweep sees children first.
  for (auto n = int32_t(nodes_.size()) - 1; n >= 0; --n) {
    Node4& node = nodes_[std::size_t(n)];
    Box& total = node_box_[std::size_t(n)];
    for (int i = 0; i < node.child_count; ++i) {
      const Ref c = node.child[i];
      const Box& b = is_leaf(c) ? leaf_box_[std::size_t(leaf_of(c))] : node_box_[std::size_t(c)];
      for (int k = 0; k < 3; ++k) {
        node.lo[k][i] = b.lo[k];
        node.hi[k][i] = b.hi[k];
      }
      total = i == 0 ? b : merge(total, b);
    }
  }
}

int32_t Tree::build_binary(BuildInput& in, std::vector<BuildNode>& out, int32_t begin, int32_t end) {
  const auto index = int32_t(out.size());
  out.emplace_back();
  out[std::size_t(index)].first = begin;
  out[std::size_t(index)].count = end - begin;
  Vec3 lo = in.lo[std::size_t(in.order[std::size_t(begin)])], hi = in.hi[std::size_t(in.order[std::size_t(begin)])];
  for (int32_t i = begin; i < end; ++i) {
    lo = lo.cwiseMin(in.lo[std::size_t(in.order[std::size_t(i)])]);
    hi = hi.cwiseMax(in.hi[std::size_t(in.order[std::size_t(i)])]);
  }
  out[std::size_t(index)].area = half_area(lo, hi);
  if (end - begin <= kMaxLeafSize) return index;
  // Surface area heuristic: sort by centroid on each axis, sweep every split.
  const int32_t n = end - begin;
  std::vector<int32_t> sorted(in.order.begin() + begin, in.order.begin() + end);
  std::vector<double> right_area(static_cast<std::size_t>(n));
  double best_cost = std::numeric_limits<double>::infinity();
  int best_axis = 0;
  int32_t best_split = n / 2;
  auto by_axis = [&](int axis) {
    return [&in, this, axis](int32_t x, int32_t y) {
      const double cx = in.centroid[std::size_t(x)][axis], cy = in.centroid[std::size_t(y)][axis];
      return cx < cy || (cx == cy && slot_triangle_[std::size_t(x)] < slot_triangle_[std::size_t(y)]);
    };
  };
  for (int axis = 0; axis < 3; ++axis) {
    std::sort(sorted.begin(), sorted.end(), by_axis(axis));
    Vec3 r_lo = in.lo[std::size_t(sorted.back())], r_hi = in.hi[std::size_t(sorted.back())];
    for (int32_t i = n - 1; i >= 0; --i) {
      r_lo = r_lo.cwiseMin(in.lo[std::size_t(sorted[std::size_t(i)])]);
      r_hi = r_hi.cwiseMax(in.hi[std::size_t(sorted[std::size_t(i)])]);
      right_area[std::size_t(i)] = half_area(r_lo, r_hi);
    }
    Vec3 l_lo = in.lo[std::size_t(sorted[0])], l_hi = in.hi[std::size_t(sorted[0])];
    for (int32_t split = 1; split < n; ++split) {
      l_lo = l_lo.cwiseMin(in.lo[std::size_t(sorted[std::size_t(split - 1)])]);
      l_hi = l_hi.cwiseMax(in.hi[std::size_t(sorted[std::size_t(split - 1)])]);
      const double cost = half_area(l_lo, l_hi) * split + right_area[std::size_t(split)] * (n - split);
      if (cost < best_cost) {
        best_cost = cost;
        best_axis = axis;
        best_split = split;
      }
    }
  }
  std::sort(in.order.begin() + begin, in.order.begin() + end, by_axis(best_axis));
  const int32_t left = build_binary(in, out, begin, begin + best_split);
  const int32_t right = build_binary(in, out, begin + best_split, end);
  out[std::size_t(index)].left = left;
  out[std::size_t(index)].right = right;
  return index;
}

Ref Tree::collapse(const std::vector<BuildNode>& binary, int32_t index, int depth) {
  depth_ = std::max(depth_, depth);
  const BuildNode& b = binary[std::size_t(index)];
  if (b.left < 0) {
    leaves_.push_back({b.first, b.count});
    return ~int32_t(leaves_.size() - 1);
  }
  std::vector<int32_t> children{b.left, b.right};
  while (children.size() < std::size_t(kArity)) {
    int best = -1;
    for (int i = 0; i < int(children.size()); ++i) {
      const BuildNode& c = binary[std::size_t(children[std::size_t(i)])];
      if (c.left >= 0 && (best < 0 || c.area > binary[std::size_t(children[std::size_t(best)])].area)) best = i;
    }
    if (best < 0) break;
    const BuildNode& opened = binary[std::size_t(children[std::size_t(best)])];
    children[std::size_t(best)] = opened.left;
    children.insert(children.begin() + best + 1, opened.right);
  }
  const auto node = int32_t(nodes_.size());
  nodes_.emplace_back();
  const float inf = std::numeric_limits<float>::infinity();
  for (int k = 0; k < 3; ++k)
    for (int lane = 0; lane < kArity; ++lane) {
      nodes_[std::size_t(node)].lo[k][lane] = inf;
      nodes_[std::size_t(node)].hi[k][lane] = -inf;
    }
  nodes_[std::size_t(node)].child_count = int32_t(children.size());
  for (std::size_t i = 0; i < children.size(); ++i) {
    const Ref ref = collapse(binary, children[i], depth + 1);
    nodes_[std::size_t(node)].child[i] = ref;
  }
  return node;
}

void Tree::build_skip_masks(std::span<const TrianglePair> extra_skipped) {
  const auto leaf_count = int32_t(leaves_.size());
  std::vector<int32_t> slot_leaf(slot_triangle_.size());
  for (int32_t l = 0; l < leaf_count; ++l)
    for (int32_t s = 0; s < leaves_[std::size_t(l)].count; ++s) slot_leaf[std::size_t(leaves_[std::size_t(l)].first + s)] = l;
  std::vector<std::pair<int32_t, int32_t>> leaf_pairs;   // (leaf, leaf with pairs to skip), both ways
  std::vector<std::pair<int32_t, int32_t>> vertex_leaf;  // (vertex, leaf)
  for (std::size_t s = 0; s < slot_vertices_.size(); ++s)
    for (int32_t v : slot_vertices_[s]) vertex_leaf.emplace_back(v, slot_leaf[s]);
  std::sort(vertex_leaf.begin(), vertex_leaf.end());
  vertex_leaf.erase(std::unique(vertex_leaf.begin(), vertex_leaf.end()), vertex_leaf.end());
  for (std::size_t i = 0; i < vertex_leaf.size();) {
    std::size_t j = i;
    while (j < vertex_leaf.size() && vertex_leaf[j].first == vertex_leaf[i].first) ++j;
    for (std::size_t p = i; p < j; ++p)
      for (std::size_t q = i; q < j; ++q) leaf_pairs.emplace_back(vertex_leaf[p].second, vertex_leaf[q].second);
    i = j;
  }
  // Triangle -> slot, for the extra pairs (which name triangles).
  std::vector<std::pair<int32_t, int32_t>> triangle_slot(slot_triangle_.size());
  for (std::size_t s = 0; s < slot_triangle_.size(); ++s) triangle_slot[s] = {slot_triangle_[s], int32_t(s)};
  std::sort(triangle_slot.begin(), triangle_slot.end());
  auto slot_of = [&](int32_t triangle) {
    auto it = std::lower_bound(triangle_slot.begin(), triangle_slot.end(), std::pair<int32_t, int32_t>{triangle, INT32_MIN});
    return it != triangle_slot.end() && it->first == triangle ? it->second : -1;
  };
  std::vector<std::pair<int32_t, int32_t>> extra_slots;
  for (const TrianglePair& pair : extra_skipped) {
    const int32_t sa = slot_of(pair.first), sb = slot_of(pair.second);
    if (sa < 0 || sb < 0) continue;
    extra_slots.emplace_back(sa, sb);
    extra_slots.emplace_back(sb, sa);
    leaf_pairs.emplace_back(slot_leaf[std::size_t(sa)], slot_leaf[std::size_t(sb)]);
    leaf_pairs.emplace_back(slot_leaf[std::size_t(sb)], slot_leaf[std::size_t(sa)]);
  }
  std::sort(extra_slots.begin(), extra_slots.end());
  std::sort(leaf_pairs.begin(), leaf_pairs.end());
  leaf_pairs.erase(std::unique(leaf_pairs.begin(), leaf_pairs.end()), leaf_pairs.end());
  // Each leaf's list padded with -1 to whole groups of kSkipGroup, compared at once.
  skip_offset_.assign(std::size_t(leaf_count) + 1, 0);
  skip_leaf_.clear();
  skip_mask_.clear();
  std::size_t next = 0;
  for (int32_t a = 0; a < leaf_count; ++a) {
    skip_offset_[std::size_t(a)] = int32_t(skip_leaf_.size());
    for (; next < leaf_pairs.size() && leaf_pairs[next].first == a; ++next) {
      const int32_t b = leaf_pairs[next].second;
      const Leaf& la = leaves_[std::size_t(a)];
      const Leaf& lb = leaves_[std::size_t(b)];
      PairMask mask;
      for (int32_t s = 0; s < la.count; ++s)
        for (int32_t t = 0; t < lb.count; ++t) {
          const int32_t sa = la.first + s, sb = lb.first + t;
          if (share_vertex(slot_vertices_[std::size_t(sa)], slot_vertices_[std::size_t(sb)]) ||
              std::binary_search(extra_slots.begin(), extra_slots.end(), std::pair<int32_t, int32_t>{sa, sb}))
            mask.row[s] = uint16_t(mask.row[s] | (1u << t));
        }
      skip_leaf_.push_back(b);
      skip_mask_.push_back(mask);
    }
    while (skip_leaf_.size() % kSkipGroup != 0) {
      skip_leaf_.push_back(-1);
      skip_mask_.push_back({});
    }
  }
  skip_offset_[std::size_t(leaf_count)] = int32_t(skip_leaf_.size());
}
}  // namespace facecap::bvh
