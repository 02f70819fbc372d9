#include "solver/collide/collider.hpp"

#include <algorithm>
#include <array>
#include <bit>
#include <cmath>

#include <fmt/format.h>

#include "core/error.hpp"
#include "solver/collide/bvh.hpp"
#include "solver/collide/geometry.hpp"
#include "solver/collide/pair_batch.hpp"
#include "solver/mesh_topology.hpp"

namespace facecap {
namespace {

// Pairs of `candidates` with a vertex of one within `edges` mesh edges of a vertex of the
// other, first < second, sorted and unique (pairs sharing a vertex included).
std::vector<TrianglePair> neighbour_pairs(const Eigen::Matrix3Xi& triangles, Eigen::Index vertex_count,
                                          std::span<const int32_t> candidates, int edges) {
  auto adjacent = std::vector<std::vector<int32_t>>(std::size_t(vertex_count));
  auto incident = std::vector<std::vector<int32_t>>(std::size_t(vertex_count));
  for (Eigen::Index t = 0; t < triangles.cols(); ++t)
    for (int k = 0; k < 3; ++k) {
      adjacent[std::size_t(triangles(k, t))].push_back(triangles((k + 1) % 3, t));
      adjacent[std::size_t(triangles((k + 1) % 3, t))].push_back(triangles(k, t));
    }
  for (int32_t t : candidates)
    for (int k = 0; k < 3; ++k) incident[std::size_t(triangles(k, t))].push_back(t);
  std::vector<TrianglePair> out;
  auto reached_by = std::vector<int32_t>(std::size_t(vertex_count), -1);
  std::vector<int32_t> reached, frontier;
  for (int32_t t : candidates) {
    reached.clear();
    for (int k = 0; k < 3; ++k)
      if (reached_by[std::size_t(triangles(k, t))] != t) {
        reached_by[std::size_t(triangles(k, t))] = t;
        reached.push_back(triangles(k, t));
      }
    std::size_t begin = 0;
    for (int depth = 0; depth < edges; ++depth) {
      const std::size_t end = reached.size();
      for (std::size_t i = begin; i < end; ++i)
        for (int32_t u : adjacent[std::size_t(reached[i])])
          if (reached_by[std::size_t(u)] != t) {
            reached_by[std::size_t(u)] = t;
            reached.push_back(u);
          }
      begin = end;
    }
    for (int32_t v : reached)
      for (int32_t u : incident[std::size_t(v)])
        if (u > t) out.push_back({t, u});
  }
  std::sort(out.begin(), out.end());
  out.erase(std::unique(out.begin(), out.end()), out.end());
  return out;
}

}  // namespace

struct TriangleCollider::State {
  bvh::Tree tree;
  ColliderConfig config;
  Eigen::Index vertex_count = 0;
  std::vector<int32_t> candidate_triangles;  // ascending
  std::vector<int32_t> candidate_vertices;   // ascending
  std::vector<TrianglePair> rest_contacts;   // sorted; left out when ignore_rest_contacts
  std::vector<uint32_t> vertex_stamp;        // N: frame stamp when a vertex was last collected
  uint32_t stamp = 0;
  int max_vertices = 0;
  // The box-overlapping slot pairs of the last traversal, and where the candidate
  // vertices were then (3 x candidate_vertices); valid while kept_valid.
  std::vector<std::array<int32_t, 2>> kept_pairs;
  int32_t kept_count = 0;
  bool kept_valid = false;
  Eigen::Matrix3Xd kept_positions;
};

TriangleCollider::TriangleCollider() = default;
TriangleCollider::~TriangleCollider() = default;
TriangleCollider::TriangleCollider(TriangleCollider&&) noexcept = default;
TriangleCollider& TriangleCollider::operator=(TriangleCollider&&) noexcept = default;

void TriangleCollider::configure(const Eigen::Matrix3Xi& triangles, const Eigen::Matrix3Xd& rest_positions,
                                 std::span<const int> candidate_triangles, const ColliderConfig& config) {
  const Eigen::Index n = rest_positions.cols();
  check_triangle_indices(triangles, n);
  if (!(config.epsilon >= 0.0) || !std::isfinite(config.epsilon))
    throw Error(fmt::format("collision epsilon {} must be a finite distance >= 0", config.epsilon));
  if (config.max_pairs < 0) throw Error(fmt::format("collision max_pairs {} must be >= 0", config.max_pairs));
  if (!rest_positions.allFinite()) throw Error("collision rest positions contain NaN or infinity");
  auto state = std::make_unique<State>();
  state->config = config;
  if (!state->config.kernels) state->config.kernels = &kernels::table(KernelPath::kAuto);
  state->vertex_count = n;
  state->candidate_triangles.reserve(candidate_triangles.size());
  for (int t : candidate_triangles) {
    if (t < 0 || t >= triangles.cols())
      throw Error(fmt::format("candidate triangle {} is not in [0, {})", t, triangles.cols()));
    state->candidate_triangles.push_back(t);
  }
  std::sort(state->candidate_triangles.begin(), state->candidate_triangles.end());
  state->candidate_triangles.erase(std::unique(state->candidate_triangles.begin(), state->candidate_triangles.end()),
                                   state->candidate_triangles.end());
  for (int32_t t : state->candidate_triangles)
    for (int k = 0; k < 3; ++k) state->candidate_vertices.push_back(triangles(k, t));
  std::sort(state->candidate_vertices.begin(), state->candidate_vertices.end());
  state->candidate_vertices.erase(std::unique(state->candidate_vertices.begin(), state->candidate_vertices.end()),
                                  state->candidate_vertices.end());
  const auto all_vertices = int(state->candidate_vertices.size());
  state->max_vertices = config.max_vertices < 0 ? all_vertices : std::min(config.max_vertices, all_vertices);
  state->vertex_stamp.assign(std::size_t(n), 0);
  if (config.neighbour_edges < 0) throw Error(fmt::format("collision neighbour_edges {} must be >= 0", config.neighbour_edges));
  if (!(config.skin >= 0.0) || !std::isfinite(config.skin))
    throw Error(fmt::format("collision skin {} must be a finite distance >= 0", config.skin));
  if (config.max_kept_pairs < 0) throw Error(fmt::format("collision max_kept_pairs {} must be >= 0", config.max_kept_pairs));
  if (config.skin > 0.0) {
    state->kept_pairs.resize(std::size_t(config.max_kept_pairs));
    state->kept_positions.resize(3, Eigen::Index(state->candidate_vertices.size()));
  }
  state->tree.build(triangles, rest_positions, state->candidate_triangles);
  std::vector<TrianglePair> skipped;
  if (config.neighbour_edges > 0) {
    skipped = neighbour_pairs(triangles, n, state->candidate_triangles, config.neighbour_edges);
    state->tree.skip_pairs(skipped);
  }
  if (config.ignore_rest_contacts) {
    State& s = *state;
    s.tree.refit(rest_positions, 0.5 * config.epsilon);
    s.tree.for_each_overlapping_pair([&](int32_t slot_a, int32_t slot_b) {
      const auto& va = s.tree.slot_vertices(slot_a);
      const auto& vb = s.tree.slot_vertices(slot_b);
      if (!triangles_closer_than(rest_positions.col(va[0]), rest_positions.col(va[1]), rest_positions.col(va[2]),
                                 rest_positions.col(vb[0]), rest_positions.col(vb[1]), rest_positions.col(vb[2]),
                                 config.epsilon))
        return;
      const int32_t ta = s.tree.slot_triangles()[std::size_t(slot_a)], tb = s.tree.slot_triangles()[std::size_t(slot_b)];
      s.rest_contacts.push_back({std::min(ta, tb), std::max(ta, tb)});
    });
    std::sort(s.rest_contacts.begin(), s.rest_contacts.end());
    skipped.insert(skipped.end(), s.rest_contacts.begin(), s.rest_contacts.end());
    s.tree.skip_pairs(skipped);
  }
  state_ = std::move(state);
}

CollisionResult TriangleCollider::make_result() const {
  CollisionResult out;
  if (!state_) return out;
  out.pairs.resize(std::size_t(state_->config.max_pairs));
  out.vertices.resize(std::size_t(state_->max_vertices));
  return out;
}

bool TriangleCollider::detect(const Eigen::Ref<const Eigen::Matrix3Xd>& positions, CollisionResult& out) noexcept {
  out.pair_count = out.vertex_count = out.pairs_found = out.vertices_found = out.pairs_tested = 0;
  out.traversed = false;
  if (!state_ || positions.cols() != state_->vertex_count) return false;
  State& s = *state_;
  // A NaN would poison the boxes above it and hide other pairs: refuse the frame.
  for (int32_t v : s.candidate_vertices)
    if (!positions.col(v).allFinite()) return false;
  const auto pair_capacity = int32_t(std::min<std::size_t>(out.pairs.size(), std::size_t(s.config.max_pairs)));
  const auto vertex_capacity = int32_t(std::min<std::size_t>(out.vertices.size(), std::size_t(s.max_vertices)));
  if (++s.stamp == 0) {  // wrapped: forget every old stamp
    std::fill(s.vertex_stamp.begin(), s.vertex_stamp.end(), 0u);
    s.stamp = 1;
  }
  const double epsilon = s.config.epsilon;
  // The kept pairs still hold every pair closer than epsilon while each candidate vertex
  // is within the skin of where it was at the traversal (each box then still holds its
  // triangle grown by epsilon / 2).
  bool reuse = s.kept_valid;
  if (reuse) {
    const double skin_sq = s.config.skin * s.config.skin;
    for (std::size_t i = 0; i < s.candidate_vertices.size() && reuse; ++i)
      reuse = (positions.col(s.candidate_vertices[i]) - s.kept_positions.col(Eigen::Index(i))).squaredNorm() <= skin_sq;
  }
  auto collect_vertex = [&](int32_t v) {
    if (s.vertex_stamp[std::size_t(v)] == s.stamp) return;
    s.vertex_stamp[std::size_t(v)] = s.stamp;
    if (out.vertex_count < vertex_capacity) out.vertices[std::size_t(out.vertex_count++)] = v;
    ++out.vertices_found;
  };
  const auto slot_triangles = s.tree.slot_triangles();
  // Candidates are tested kCloserBatch at a time.
  std::array<int32_t, 2> batch_slots[kCloserBatch];
  TrianglePairVertices batch[kCloserBatch];
  int batched = 0;
  auto test_batch = [&] {
    const uint32_t found = triangles_closer_than(*s.config.kernels, positions, std::span(batch, std::size_t(batched)), epsilon);
    for (uint32_t close = found; close != 0; close &= close - 1) {
      const auto [slot_a, slot_b] = batch_slots[std::countr_zero(close)];
      const int32_t ta = slot_triangles[std::size_t(slot_a)], tb = slot_triangles[std::size_t(slot_b)];
      if (out.pair_count < pair_capacity) out.pairs[std::size_t(out.pair_count++)] = {std::min(ta, tb), std::max(ta, tb)};
      ++out.pairs_found;
      for (int k = 0; k < 3; ++k) {
        collect_vertex(s.tree.slot_vertices(slot_a)[std::size_t(k)]);
        collect_vertex(s.tree.slot_vertices(slot_b)[std::size_t(k)]);
      }
    }
    batched = 0;
  };
  auto test_pair = [&](int32_t slot_a, int32_t slot_b) {
    batch_slots[batched] = {slot_a, slot_b};
    const auto& va = s.tree.slot_vertices(slot_a);
    const auto& vb = s.tree.slot_vertices(slot_b);
    batch[batched] = {{va[0], va[1], va[2]}, {vb[0], vb[1], vb[2]}};
    ++out.pairs_tested;
    if (++batched == kCloserBatch) test_batch();
  };
  bool complete = true;
  if (reuse) {
    for (int32_t k = 0; k < s.kept_count; ++k) test_pair(s.kept_pairs[std::size_t(k)][0], s.kept_pairs[std::size_t(k)][1]);
  } else {
    const bool keep = s.config.skin > 0.0;
    s.tree.refit(positions, 0.5 * epsilon + s.config.skin);  // boxes closer than epsilon overlap
    s.kept_count = 0;
    bool kept_all = keep;
    complete = s.tree.for_each_overlapping_pair([&](int32_t slot_a, int32_t slot_b) {
      if (kept_all && s.kept_count < int32_t(s.kept_pairs.size())) s.kept_pairs[std::size_t(s.kept_count++)] = {slot_a, slot_b};
      else kept_all = false;
      test_pair(slot_a, slot_b);
    });
    s.kept_valid = complete && kept_all;
    if (s.kept_valid)
      for (std::size_t i = 0; i < s.candidate_vertices.size(); ++i)
        s.kept_positions.col(Eigen::Index(i)) = positions.col(s.candidate_vertices[i]);
    out.traversed = true;
  }
  test_batch();
  // std::sort is in place (introsort): no allocation.
  std::sort(out.pairs.begin(), out.pairs.begin() + out.pair_count);
  std::sort(out.vertices.begin(), out.vertices.begin() + out.vertex_count);
  if (!complete) {
    // Unreachable by construction; report it as an overflow rather than a clean frame.
    out.pairs_found = std::max(out.pairs_found, out.pair_count + 1);
  }
  return true;
}

bool TriangleCollider::configured() const noexcept { return state_ != nullptr; }
double TriangleCollider::epsilon() const noexcept { return state_ ? state_->config.epsilon : 0.0; }
Eigen::Index TriangleCollider::vertex_count() const noexcept { return state_ ? state_->vertex_count : 0; }
std::span<const int32_t> TriangleCollider::candidate_triangles() const noexcept {
  return state_ ? std::span<const int32_t>(state_->candidate_triangles) : std::span<const int32_t>();
}
std::span<const int32_t> TriangleCollider::candidate_vertices() const noexcept {
  return state_ ? std::span<const int32_t>(state_->candidate_vertices) : std::span<const int32_t>();
}
int TriangleCollider::tree_depth() const noexcept { return state_ ? state_->tree.depth() : 0; }
std::span<const TrianglePair> TriangleCollider::rest_contacts() const noexcept {
  return state_ ? std::span<const TrianglePair>(state_->rest_contacts) : std::span<const TrianglePair>();
}

}  // namespace facecap
