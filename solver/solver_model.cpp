#include "solver/solver_model.hpp"

#include <algorithm>
#include <cstring>
#include <iterator>
#include <chrono>
#include <limits>
#include <cmath>
#include <numbers>
#include <numeric>
#include <queue>
#include <thread>

#include <Eigen/Geometry>
#include <Eigen/SVD>
#include <Eigen/SparseCore>
#include <fmt/format.h>

#include "core/error.hpp"
#include "solver/collide/lip_region.hpp"
#include "solver/collide/metrics.hpp"
#include "solver/mesh_topology.hpp"

namespace facecap {
namespace {

using Clock = std::chrono::steady_clock;
double seconds_since(Clock::time_point t) { return std::chrono::duration<double>(Clock::now() - t).count(); }

// SolverParams' kByRig settings decided for `rig`.
SolverParams params_for_rig(SolverParams params, const Rig& rig) {
  if (params.weight_refinements == kByRig) params.weight_refinements = rig.hinged ? 2 : 0;
  if (params.boundary_hold == kByRig) params.boundary_hold = rig.hinged ? 0.0 : 0.003;
  return params;
}

void validate(const Rig& rig, const std::vector<MarkerBinding>& markers, const SolverParams& params) {
  if (rig.vertex_count() == 0 || rig.triangle_count() == 0) throw Error("solver: the rig has no mesh");
  if (markers.empty()) throw Error("solver: no markers to solve from");
  if (params.collision_max_pins < 0 || params.collision_max_pins > 1024)
    throw Error(fmt::format("solver: collision_max_pins {} is not in [0, 1024]", params.collision_max_pins));
  if (params.fold_max_pins < 0 || params.fold_max_pins > 1024)
    throw Error(fmt::format("solver: fold_max_pins {} is not in [0, 1024]", params.fold_max_pins));
  if (!(params.fold_crease_degrees >= 10 && params.fold_crease_degrees <= 180))
    throw Error(fmt::format("solver: fold_crease_degrees {} is not in [10, 180]", params.fold_crease_degrees));
  if (params.weight_refinements < 0)
    throw Error(fmt::format("solver: weight_refinements {} must be >= 0, or {} for the rig's choice", params.weight_refinements, kByRig));
  if (params.weight_qp_iteration_cap < 0)
    throw Error(fmt::format("solver: weight_qp_iteration_cap {} must be >= 0", params.weight_qp_iteration_cap));
  if (!(params.collision_skin_mm >= 0) || !std::isfinite(params.collision_skin_mm))
    throw Error(fmt::format("solver: collision_skin_mm {} must be a distance >= 0", params.collision_skin_mm));
  if (!(params.negligible_displacement_mm >= 0) || !std::isfinite(params.negligible_displacement_mm))
    throw Error(fmt::format("solver: negligible_displacement_mm {} must be a distance >= 0", params.negligible_displacement_mm));
  if (!(params.beta > 0) || !(params.alpha >= 0) || !(params.mu >= 0) || !(params.boundary_hold >= 0) ||
      !std::isfinite(params.boundary_hold))
    throw Error(fmt::format("solver: beta must be > 0 and alpha, mu, boundary_hold >= 0 (beta {}, alpha {}, mu {}, "
                            "boundary_hold {}; {} for the rig's choice)", params.beta, params.alpha, params.mu,
                            params.boundary_hold, kByRig));
  for (const auto& m : markers) {
    for (int v : m.vertices)
      if (v < 0 || v >= rig.vertex_count())
        throw Error(fmt::format("solver: marker '{}' is bound to vertex {}, the rig has {}", m.label, v, rig.vertex_count()));
    if (!m.barycentric.allFinite() || std::abs(m.barycentric.sum() - 1.0) > 1e-6)
      throw Error(fmt::format("solver: marker '{}' has barycentric coordinates that do not sum to 1", m.label));
  }
}

// Marker rows of x0 and B (Eq. 2) and the Gram matrices of the weights problem.
void build_marker_rows(SolverModel& model) {
  const Rig& rig = model.rig;
  const Eigen::Index K = model.marker_count(), M = rig.shape_count();
  model.weights.marker_basis.setZero(3 * K, M);
  model.weights.marker_neutral.setZero(3 * K);
  for (Eigen::Index k = 0; k < K; ++k) {
    const auto& m = model.markers[std::size_t(k)];
    for (int i = 0; i < 3; ++i) {
      model.weights.marker_basis.middleRows(3 * k, 3) += m.barycentric[i] * rig.deltas.middleRows(3 * m.vertices[i], 3);
      model.weights.marker_neutral.segment<3>(3 * k) += m.barycentric[i] * rig.neutral.col(m.vertices[i]);
    }
  }
  for (Eigen::Index s = 0; s < M; ++s)
    if (!model.weights.fitted[std::size_t(s)]) model.weights.marker_basis.col(s).setZero();
  model.weights.marker_basis_rows = model.weights.marker_basis;
  model.weights.gram_all = model.weights.marker_basis.transpose() * model.weights.marker_basis;
  model.weights.gram_per_marker.resize(M, M * K);
  for (Eigen::Index k = 0; k < K; ++k)
    model.weights.gram_per_marker.middleCols(k * M, M) =
        model.weights.marker_basis.middleRows(3 * k, 3).transpose() * model.weights.marker_basis.middleRows(3 * k, 3);
}

// Twice the area below which a triangle is degenerate: it constrains nothing.
double degenerate_area(const Rig& rig) { return 1e-14 * bounding_box(rig.neutral).size().squaredNorm(); }

void build_triangle_frames(SolverModel& model) {
  const Rig& rig = model.rig;
  const double degenerate = degenerate_area(rig);
  model.blend.triangle_frames.setZero(9, rig.triangle_count());
  for (Eigen::Index t = 0; t < rig.triangle_count(); ++t) {
    const Eigen::Vector3i tri = rig.triangles.col(t);
    Eigen::Map<Eigen::Matrix3d>(model.blend.triangle_frames.col(t).data()) =
        rest_frame(rig.neutral.col(tri[0]), rig.neutral.col(tri[1]), rig.neutral.col(tri[2]), degenerate);
  }
}

// Q_j and the Laplacian-like G^T W G.
Eigen::SparseMatrix<double> build_triangle_operators(SolverModel& model) {
  const Rig& rig = model.rig;
  const Eigen::Index T = rig.triangle_count();
  model.blend.triangle_operator.setZero(9, T);
  std::vector<Eigen::Triplet<double>> entries;
  entries.reserve(std::size_t(T) * 9);
  const double degenerate = degenerate_area(rig);
  for (Eigen::Index t = 0; t < T; ++t) {
    const Eigen::Vector3i tri = rig.triangles.col(t);
    const Eigen::Vector3d x0 = rig.neutral.col(tri[0]), x1 = rig.neutral.col(tri[1]), x2 = rig.neutral.col(tri[2]);
    const Eigen::Vector3d n = (x1 - x0).cross(x2 - x0);
    const double twice_area = n.norm();
    if (twice_area <= degenerate) continue;  // constrains nothing
    const Eigen::Vector3d unit = n / twice_area;
    Eigen::Matrix3d grad;  // columns: gradients of the hat functions of x0, x1, x2
    grad.col(0) = unit.cross(x2 - x1) / twice_area;
    grad.col(1) = unit.cross(x0 - x2) / twice_area;
    grad.col(2) = unit.cross(x1 - x0) / twice_area;
    const double area = 0.5 * twice_area;
    Eigen::Map<Eigen::Matrix3d>(model.blend.triangle_operator.col(t).data()) = area * grad;
    const Eigen::Matrix3d local = area * grad.transpose() * grad;
    for (int a = 0; a < 3; ++a)
      for (int b = 0; b < 3; ++b) entries.emplace_back(tri[a], tri[b], local(a, b));
  }
  Eigen::SparseMatrix<double> L(rig.vertex_count(), rig.vertex_count());
  L.setFromTriplets(entries.begin(), entries.end());
  return L;
}

// One shape's Eq. 3 terms on every triangle (built, then regrouped).
struct ShapeDeformation {
  std::vector<uint8_t> changed;  // T
  std::vector<float> nonlinear;  // kNonlinearComponents x T, triangle-major (BlendData::triangle_nonlinear)
  std::vector<float> gradient;   // kGradientComponents x T (BlendData::triangle_gradient)
};

// Deformation of every (shape, triangle) that changes, with rotation logs kept on one
// branch across the mesh: triangles turning less than pi/2 fix the branch, and the rest
// take the branch nearest their already-decided neighbours, breadth first.
ShapeDeformation build_shape_deformation(const SolverModel& model, Eigen::Index shape, const TriangleAdjacency& adjacency) {
  const Rig& rig = model.rig;
  const Eigen::Index T = rig.triangle_count();
  const Eigen::Matrix3Xd posed = rig.shape_positions(shape);
  std::vector<Eigen::Vector3d> logs(std::size_t(T), Eigen::Vector3d::Zero());
  const std::size_t triangle_count = std::size_t(T);
  std::vector<Eigen::Matrix3d> stretch(triangle_count), gradient(triangle_count);
  std::vector<uint8_t> changed(std::size_t(T), 0), decided(std::size_t(T), 1);
  const auto& d = rig.deltas.col(shape);
  for (Eigen::Index t = 0; t < T; ++t) {
    const Eigen::Vector3i tri = rig.triangles.col(t);
    if (d.segment<3>(3 * tri[0]).isZero(0.0) && d.segment<3>(3 * tri[1]).isZero(0.0) && d.segment<3>(3 * tri[2]).isZero(0.0))
      continue;
    const Eigen::Matrix3d F = deformation_gradient(rig.neutral.col(tri[0]), rig.neutral.col(tri[1]), rig.neutral.col(tri[2]),
                                                   posed.col(tri[0]), posed.col(tri[1]), posed.col(tri[2]));
    if (!F.allFinite() || (F - Eigen::Matrix3d::Identity()).cwiseAbs().maxCoeff() < 1e-9) continue;
    Eigen::Matrix3d R, S;
    polar_decomposition(F, R, S);
    const std::size_t i = std::size_t(t);
    changed[i] = 1;
    logs[i] = rotation_log(R);
    stretch[i] = S - Eigen::Matrix3d::Identity();
    gradient[i] = F - Eigen::Matrix3d::Identity();
    if (logs[i].norm() > 0.5 * std::numbers::pi) decided[i] = 0;
  }
  std::queue<int> frontier;
  for (Eigen::Index t = 0; t < T; ++t)
    if (decided[std::size_t(t)]) frontier.push(int(t));
  auto propagate = [&] {
    while (!frontier.empty()) {
      const int t = frontier.front();
      frontier.pop();
      for (int n : adjacency.neighbours(t)) {
        if (decided[std::size_t(n)]) continue;
        logs[std::size_t(n)] = nearest_log_branch(logs[std::size_t(n)], logs[std::size_t(t)]);
        decided[std::size_t(n)] = 1;
        frontier.push(n);
      }
    }
  };
  propagate();
  for (Eigen::Index t = 0; t < T; ++t)  // islands rotating more than pi/2 everywhere
    if (!decided[std::size_t(t)]) { decided[std::size_t(t)] = 1; frontier.push(int(t)); propagate(); }

  constexpr auto kNonlinear = std::size_t(BlendData::kNonlinearComponents);
  constexpr auto kGradient = std::size_t(BlendData::kGradientComponents);
  ShapeDeformation out;
  out.changed = std::move(changed);
  out.nonlinear.assign(kNonlinear * triangle_count, 0.0f);
  out.gradient.assign(kGradient * triangle_count, 0.0f);
  for (std::size_t i = 0; i < triangle_count; ++i) {
    if (!out.changed[i]) continue;
    const Eigen::Map<const Eigen::Matrix3d> frame(model.blend.triangle_frames.col(Eigen::Index(i)).data());
    const Eigen::Matrix3d s = frame.transpose() * stretch[i] * frame;
    const double nonlinear[kNonlinear] = {logs[i][0], logs[i][1], logs[i][2], s(0, 0), s(1, 1), s(0, 1), s(0, 2), s(1, 2)};
    const Eigen::Matrix<double, 3, 2> planar = gradient[i] * frame.leftCols<2>();
    for (std::size_t c = 0; c < kNonlinear; ++c) out.nonlinear[kNonlinear * i + c] = float(nonlinear[c]);
    for (std::size_t c = 0; c < kGradient; ++c) out.gradient[kGradient * i + c] = float(planar.data()[c]);
  }
  return out;
}

// Indices of `points` (3 x n) in Morton order: near points end up near in the order.
std::vector<int32_t> morton_order(const Eigen::Matrix3Xd& points) {
  const BoundingBox box = bounding_box(points);
  const Eigen::Array3d extent = box.size().array().max(1e-12);
  auto spread = [](uint64_t v) {  // 21 bits -> every third bit
    v &= 0x1fffff;
    v = (v | v << 32) & 0x1f00000000ffffULL;
    v = (v | v << 16) & 0x1f0000ff0000ffULL;
    v = (v | v << 8) & 0x100f00f00f00f00fULL;
    v = (v | v << 4) & 0x10c30c30c30c30c3ULL;
    v = (v | v << 2) & 0x1249249249249249ULL;
    return v;
  };
  auto keyed = std::vector<std::pair<uint64_t, int32_t>>(std::size_t(points.cols()));
  for (Eigen::Index i = 0; i < points.cols(); ++i) {
    const Eigen::Array3d unit = ((points.col(i) - box.min).array() / extent).min(1.0).max(0.0);
    uint64_t code = 0;
    for (int a = 0; a < 3; ++a) code |= spread(uint64_t(unit[a] * 2097151.0)) << a;
    keyed[std::size_t(i)] = {code, int32_t(i)};
  }
  std::sort(keyed.begin(), keyed.end());
  auto order = std::vector<int32_t>(keyed.size());
  for (std::size_t i = 0; i < order.size(); ++i) order[i] = keyed[i].second;
  return order;
}

// Blocks over elements at `positions` (3 x n); changes(shape, element) says which get entries.
template <class Changes>
ShapeBlocks make_shape_blocks(const Eigen::Matrix3Xd& positions, Eigen::Index shapes, Changes&& changes) {
  constexpr int B = ShapeBlocks::kBlock;
  const std::vector<int32_t> order = morton_order(positions);
  const int blocks = int((order.size() + B - 1) / B);
  ShapeBlocks out;
  out.element_of_slot.assign(std::size_t(blocks) * B, -1);
  std::copy(order.begin(), order.end(), out.element_of_slot.begin());
  out.slot_of_element.resize(order.size());
  for (std::size_t i = 0; i < order.size(); ++i) out.slot_of_element[std::size_t(order[i])] = int32_t(i);
  out.block_begin.push_back(0);
  for (int b = 0; b < blocks; ++b) {
    const int32_t* slots = out.element_of_slot.data() + std::size_t(b) * B;
    for (Eigen::Index s = 0; s < shapes; ++s)
      if (std::any_of(slots, slots + B, [&](int32_t e) { return e >= 0 && changes(s, e); }))
        out.entries.push_back({int32_t(s), int32_t(b)});
    out.block_begin.push_back(int32_t(out.entries.size()));
  }
  out.shape_begin.assign(std::size_t(shapes) + 1, 0);
  for (const auto& e : out.entries) ++out.shape_begin[std::size_t(e.shape) + 1];
  for (std::size_t s = 0; s < std::size_t(shapes); ++s) out.shape_begin[s + 1] += out.shape_begin[s];
  out.shape_entries.resize(out.entries.size());
  std::vector<int32_t> fill(out.shape_begin.begin(), out.shape_begin.end() - 1);
  for (std::size_t e = 0; e < out.entries.size(); ++e)
    out.shape_entries[std::size_t(fill[std::size_t(out.entries[e].shape)]++)] = int32_t(e);
  return out;
}

// The scale BlendTerms stores for a step of at least `step`.
float stored_scale(double step) noexcept {
  return half_to_float(half_at_least(float(step / double(BlendTerms::kScaleUnit)))) * BlendTerms::kScaleUnit;
}

// value(shape, element, component) stored entry by entry within `tolerance` (BlendTerms).
template <class Value>
BlendTerms quantise(const ShapeBlocks& blocks, int components, double tolerance, Value&& value) {
  constexpr int B = ShapeBlocks::kBlock;
  constexpr double kLevels[2] = {254.0, 65534.0};  // steps over the range: 8-bit, 16-bit
  constexpr std::size_t kAlign = 64;
  BlendTerms out;
  out.components = components;
  const auto C = std::size_t(components);
  const std::size_t entries = blocks.entries.size();
  std::vector<int> width(entries);
  std::vector<double> low(entries * C, std::numeric_limits<double>::infinity());
  std::vector<double> high(entries * C, -std::numeric_limits<double>::infinity());
  for (std::size_t e = 0; e < entries; ++e) {
    const int32_t* slots = blocks.element_of_slot.data() + std::size_t(blocks.entries[e].block) * B;
    double widest = 0.0;
    for (std::size_t c = 0; c < C; ++c) {
      for (int i = 0; i < B; ++i) {
        if (slots[i] < 0) continue;
        const double v = value(blocks.entries[e].shape, slots[i], int(c));
        low[e * C + c] = std::min(low[e * C + c], v);
        high[e * C + c] = std::max(high[e * C + c], v);
      }
      widest = std::max(widest, high[e * C + c] - low[e * C + c]);
    }
    auto fits = [&](double levels) { return 0.5 * double(stored_scale(widest / levels)) <= tolerance; };
    width[e] = fits(kLevels[0]) ? 0 : fits(kLevels[1]) ? 1 : 2;
  }
  // Positions: per block its entries by width; each block's values start on a cache line.
  out.position_of_entry.resize(entries);
  out.shape.resize(entries);
  out.scales.resize(entries * C);
  out.offsets.resize(entries * C);
  std::vector<std::size_t> value_at(entries);
  std::size_t bytes = 0;
  int32_t position = 0;
  for (int b = 0; b < blocks.block_count(); ++b) {
    BlendTerms::BlockRun run;
    run.values = bytes;
    run.first = position;
    for (int w = 0; w < BlendTerms::kWidths; ++w)
      for (int32_t e = blocks.block_begin[std::size_t(b)]; e < blocks.block_begin[std::size_t(b) + 1]; ++e) {
        if (width[std::size_t(e)] != w) continue;
        out.position_of_entry[std::size_t(e)] = position;
        out.shape[std::size_t(position)] = blocks.entries[std::size_t(e)].shape;
        value_at[std::size_t(e)] = bytes;
        bytes += C * B * std::size_t(BlendTerms::kBytesPerValue[w]);
        ++run.count[w];
        ++position;
      }
    bytes = (bytes + kAlign - 1) / kAlign * kAlign;
    out.blocks.push_back(run);
  }
  out.values.assign(bytes, std::byte{0});
  std::vector<float> scale(C);
  for (std::size_t e = 0; e < entries; ++e) {
    const int32_t* slots = blocks.element_of_slot.data() + std::size_t(blocks.entries[e].block) * B;
    const std::size_t position = std::size_t(out.position_of_entry[e]);
    float* offset = out.offsets.data() + position * C;
    std::byte* values = out.values.data() + value_at[e];
    for (std::size_t c = 0; c < C; ++c) {
      const double range = high[e * C + c] - low[e * C + c];
      if (width[e] == 2) {
        scale[c] = 1.0f;
        offset[c] = 0.0f;
      } else {
        offset[c] = float(0.5 * (low[e * C + c] + high[e * C + c]));
        scale[c] = range > 0.0 ? stored_scale(range / kLevels[width[e]]) : 1.0f;
      }
      out.scales[position * C + c] = half_at_least(scale[c] / BlendTerms::kScaleUnit);
      const long limit = width[e] == 0 ? 127 : 32767;
      for (int i = 0; i < B; ++i) {
        const double v = slots[i] < 0 ? double(offset[c]) : value(blocks.entries[e].shape, slots[i], int(c));
        const std::size_t k = c * B + std::size_t(i);
        if (width[e] == 2) {
          const float f = float(v);
          std::memcpy(values + 4 * k, &f, sizeof f);
          continue;
        }
        const long q = std::clamp(std::lround((v - double(offset[c])) / double(scale[c])), -limit, limit);
        if (width[e] == 0) {
          values[k] = std::byte(uint8_t(int8_t(q)));
        } else {
          const auto q16 = int16_t(q);
          std::memcpy(values + 2 * k, &q16, sizeof q16);
        }
      }
    }
  }
  return out;
}

// B's rows at `vertices` (all of them when empty) as blend terms over those vertices,
// rounded by at most 1e-7 of the face's size (about 3e-6 cm on a face).
void build_vertex_terms(const Rig& rig, std::span<const int> vertices, ShapeBlocks& blocks, BlendTerms& terms) {
  auto vertex = [&](int32_t element) { return vertices.empty() ? element : vertices[std::size_t(element)]; };
  Eigen::Matrix3Xd positions(3, vertices.empty() ? rig.vertex_count() : Eigen::Index(vertices.size()));
  for (Eigen::Index i = 0; i < positions.cols(); ++i) positions.col(i) = rig.neutral.col(vertex(int32_t(i)));
  blocks = make_shape_blocks(positions, rig.shape_count(), [&](Eigen::Index s, int32_t e) {
    return !rig.deltas.col(s).segment<3>(3 * vertex(e)).isZero(0.0);
  });
  const double tolerance = 1e-7 * bounding_box(rig.neutral).size().norm();
  terms = quantise(blocks, 3, tolerance, [&](Eigen::Index s, int32_t e, int c) { return rig.deltas(3 * vertex(e) + c, s); });
}

void build_triangle_terms(SolverModel& model, const std::vector<ShapeDeformation>& shapes) {
  const Rig& rig = model.rig;
  Eigen::Matrix3Xd centroids = Eigen::Matrix3Xd::Zero(3, rig.triangle_count());
  for (Eigen::Index t = 0; t < rig.triangle_count(); ++t)
    for (int k = 0; k < 3; ++k) centroids.col(t) += rig.neutral.col(rig.triangles(k, t)) / 3.0;
  model.blend.triangle_blocks = make_shape_blocks(centroids, rig.shape_count(), [&](Eigen::Index s, int32_t t) {
    return shapes[std::size_t(s)].changed[std::size_t(t)] != 0;
  });
  // Rotation logs and stretches are relative: 1e-5 rad moves a triangle's far corner by
  // 1e-5 of its size (ICT: at most 4.5e-6 cm on any vertex, docs/solver.md).
  constexpr double kTolerance = 1e-5;
  constexpr int kNonlinear = BlendData::kNonlinearComponents, kGradient = BlendData::kGradientComponents;
  model.blend.triangle_nonlinear = quantise(model.blend.triangle_blocks, kNonlinear, kTolerance, [&](Eigen::Index s, int32_t t, int c) {
    return double(shapes[std::size_t(s)].nonlinear[std::size_t(kNonlinear * t + c)]);
  });
  model.blend.triangle_gradient = quantise(model.blend.triangle_blocks, kGradient, kTolerance, [&](Eigen::Index s, int32_t t, int c) {
    return double(shapes[std::size_t(s)].gradient[std::size_t(kGradient * t + c)]);
  });
}

// Marker paths from the shapes' per-triangle rotations around each marker's vertices.
void build_marker_paths(SolverModel& model) {
  const Rig& rig = model.rig;
  const Eigen::Index K = model.marker_count(), M = rig.shape_count();
  std::vector<std::vector<int>> incident(std::size_t(rig.vertex_count()));
  for (Eigen::Index t = 0; t < rig.triangle_count(); ++t)
    for (int k = 0; k < 3; ++k) incident[std::size_t(rig.triangles(k, t))].push_back(int(t));
  constexpr double kTurning = 0.05;  // radians; below this a straight path is as good
  for (Eigen::Index s = 0; s < M; ++s) {
    if (!model.weights.fitted[std::size_t(s)]) continue;
    for (Eigen::Index k = 0; k < K; ++k) {
      const auto& b = model.markers[std::size_t(k)];
      Eigen::Vector3d r = Eigen::Vector3d::Zero();
      for (int a = 0; a < 3; ++a) {
        const auto& tris = incident[std::size_t(b.vertices[a])];
        Eigen::Vector3d sum = Eigen::Vector3d::Zero();
        for (int t : tris) sum += model.blend.rotation_log(s, t);
        if (!tris.empty()) r += b.barycentric[a] * sum / double(tris.size());
      }
      const double theta = r.norm();
      if (theta < kTurning || theta > 3.0) continue;  // near pi the axis is too uncertain to follow
      const Eigen::Vector3d axis = r / theta;
      const Eigen::Vector3d delta = model.weights.marker_basis.block(3 * k, s, 3, 1);
      const Eigen::Vector3d axial = axis.dot(delta) * axis;
      // (exp(r) - I) arm = delta - axial with arm perpendicular to the axis.
      const Eigen::Matrix3d turn = (rotation_exp(r) - Eigen::Matrix3d::Identity()) *
                                       (Eigen::Matrix3d::Identity() - axis * axis.transpose()) + axis * axis.transpose();
      const Eigen::Vector3d arm = turn.inverse() * (delta - axial);
      model.weights.marker_paths.push_back({int(k), int(s), arm, axial, theta, axis.cross(arm)});
    }
  }
}

// Candidate triangles for the collision stage and the vertices it may pin.
void choose_collision_region(SolverModel& model) {
  const Rig& rig = model.rig;
  model.collision.vertex_index.assign(std::size_t(rig.vertex_count()), -1);
  switch (model.params.collision_region) {
    case CollisionRegion::kNone: return;
    case CollisionRegion::kFace: model.collision.triangles = all_triangles(rig.triangle_count()); break;
    case CollisionRegion::kLips: model.collision.triangles = lip_region_triangles(rig); break;
  }
  for (int t : model.collision.triangles)
    for (int k = 0; k < 3; ++k) {
      const int v = rig.triangles(k, t);
      if (model.collision.vertex_index[std::size_t(v)] >= 0) continue;
      model.collision.vertex_index[std::size_t(v)] = int(model.collision.vertices.size());
      model.collision.vertices.push_back(v);
    }
}

// CollisionData::reference_*: the collision and held vertices, whose linear-blend
// positions every frame needs.
void build_reference_terms(SolverModel& model) {
  model.collision.reference_index.assign(std::size_t(model.vertex_count()), -1);
  for (const auto* vertices : {&model.collision.vertices, &model.collision.held_vertices})
    for (const int v : *vertices) {
      if (model.collision.reference_index[std::size_t(v)] >= 0) continue;
      model.collision.reference_index[std::size_t(v)] = int(model.collision.reference_vertices.size());
      model.collision.reference_vertices.push_back(v);
    }
  if (!model.collision.reference_vertices.empty())
    build_vertex_terms(model.rig, model.collision.reference_vertices, model.collision.reference_blocks, model.collision.reference_deltas);
}

// CollisionData::tangle_vertices: the corners of triangles crossing in the neutral, grown
// by kTangleRings rings of mesh edges (with none, ICT's lip corners still fold on 7 of
// 20 test poses; with one, on none).
void find_tangle_vertices(SolverModel& model) {
  constexpr int kTangleRings = 1;
  const Rig& rig = model.rig;
  if (model.params.collision_region == CollisionRegion::kNone) return;
  std::vector<uint8_t> tangled(std::size_t(rig.vertex_count()), 0);
  for (const TrianglePair& pair : intersecting_pairs(rig.triangles, rig.neutral))
    for (const int t : {pair.first, pair.second})
      for (int k = 0; k < 3; ++k) tangled[std::size_t(rig.triangles(k, t))] = 1;
  for (int ring = 0; ring < kTangleRings; ++ring) {
    std::vector<uint8_t> grown = tangled;
    for (Eigen::Index t = 0; t < rig.triangle_count(); ++t) {
      const auto c = rig.triangles.col(t);
      if (tangled[std::size_t(c[0])] || tangled[std::size_t(c[1])] || tangled[std::size_t(c[2])])
        for (int k = 0; k < 3; ++k) grown[std::size_t(c[k])] = 1;
    }
    tangled.swap(grown);
  }
  for (Eigen::Index v = 0; v < rig.vertex_count(); ++v)
    if (tangled[std::size_t(v)]) model.collision.tangle_vertices.push_back(int(v));
}

// CollisionData::held_*: the tangle vertices and the outer boundary, a vertex in both
// held by the sum of its weights.
void find_held_vertices(SolverModel& model) {
  CollisionData& c = model.collision;
  find_tangle_vertices(model);
  if (model.params.boundary_hold > 0) c.boundary_vertices = outer_boundary_vertices(model.rig.triangles, model.rig.neutral);
  std::vector<double> weight(std::size_t(model.vertex_count()), 0.0);
  for (const int v : c.tangle_vertices) weight[std::size_t(v)] += CollisionData::kTangleWeight;
  for (const int v : c.boundary_vertices) weight[std::size_t(v)] += model.params.boundary_hold;
  for (std::size_t v = 0; v < weight.size(); ++v)
    if (weight[v] > 0) {
      c.held_vertices.push_back(int(v));
      c.held_weights.push_back(weight[v]);
    }
}

}  // namespace

Eigen::Vector3d BlendData::rotation_log(Eigen::Index shape, Eigen::Index triangle) const noexcept {
  const int32_t slot = triangle_blocks.slot_of_element[std::size_t(triangle)];
  const int32_t e = triangle_blocks.find_entry(shape, slot / ShapeBlocks::kBlock);
  if (e < 0) return Eigen::Vector3d::Zero();
  const int i = slot % ShapeBlocks::kBlock;
  return {triangle_nonlinear.at(e, 0, i), triangle_nonlinear.at(e, 1, i), triangle_nonlinear.at(e, 2, i)};
}

Eigen::Matrix3d BlendData::world_stretch(Eigen::Index triangle, const double* local) const noexcept {
  Eigen::Matrix3d s;
  s << local[0], local[2], local[3], local[2], local[1], local[4], local[3], local[4], 0.0;
  const Eigen::Map<const Eigen::Matrix3d> frame(triangle_frames.col(triangle).data());
  return frame * s * frame.transpose();
}

Eigen::Matrix3d rest_frame(const Eigen::Vector3d& a0, const Eigen::Vector3d& b0, const Eigen::Vector3d& c0,
                           double degenerate_area) {
  const Eigen::Vector3d n = (b0 - a0).cross(c0 - a0);
  const double twice_area = n.norm();
  if (!(twice_area > degenerate_area)) return Eigen::Matrix3d::Zero();
  Eigen::Matrix3d frame;
  frame.col(0) = (b0 - a0).normalized();
  frame.col(2) = n / twice_area;
  frame.col(1) = frame.col(2).cross(frame.col(0));
  return frame;
}

Eigen::Matrix3d deformation_gradient(const Eigen::Vector3d& a0, const Eigen::Vector3d& b0, const Eigen::Vector3d& c0,
                                     const Eigen::Vector3d& a, const Eigen::Vector3d& b, const Eigen::Vector3d& c) {
  auto frame = [](const Eigen::Vector3d& p, const Eigen::Vector3d& q, const Eigen::Vector3d& r) {
    Eigen::Matrix3d V;
    V.col(0) = q - p;
    V.col(1) = r - p;
    const Eigen::Vector3d n = V.col(0).cross(V.col(1));
    V.col(2) = n / std::sqrt(n.norm());
    return V;
  };
  return frame(a, b, c) * frame(a0, b0, c0).inverse();
}

void polar_decomposition(const Eigen::Matrix3d& F, Eigen::Matrix3d& R, Eigen::Matrix3d& S) {
  Eigen::JacobiSVD<Eigen::Matrix3d> svd(F, Eigen::ComputeFullU | Eigen::ComputeFullV);
  Eigen::Matrix3d U = svd.matrixU();
  const Eigen::Matrix3d V = svd.matrixV();
  Eigen::Vector3d sigma = svd.singularValues();
  if ((U * V.transpose()).determinant() < 0) {  // reflection: flip the weakest direction
    U.col(2) = -U.col(2);
    sigma[2] = -sigma[2];
  }
  R = U * V.transpose();
  S = V * sigma.asDiagonal() * V.transpose();
}

Eigen::Vector3d rotation_log(const Eigen::Matrix3d& R) {
  const Eigen::AngleAxisd aa(R);
  return aa.axis() * aa.angle();
}

Eigen::Matrix3d rotation_exp(const Eigen::Vector3d& r) noexcept {
  const double theta2 = r.squaredNorm();
  Eigen::Matrix3d K;
  K << 0, -r.z(), r.y(), r.z(), 0, -r.x(), -r.y(), r.x(), 0;
  if (theta2 < 1e-16) return Eigen::Matrix3d::Identity() + K + 0.5 * K * K;
  const double theta = std::sqrt(theta2);
  return Eigen::Matrix3d::Identity() + (std::sin(theta) / theta) * K + ((1.0 - std::cos(theta)) / theta2) * K * K;
}

Eigen::Vector3d nearest_log_branch(const Eigen::Vector3d& r, const Eigen::Vector3d& reference) {
  const double theta = r.norm();
  if (theta < 1e-12) return r;
  const Eigen::Vector3d other = r * ((theta - 2.0 * std::numbers::pi) / theta);
  return (other - reference).squaredNorm() < (r - reference).squaredNorm() ? other : r;
}

std::shared_ptr<const SolverModel> build_solver_model(const Rig& rig, std::vector<MarkerBinding> markers,
                                                      const SolverParams& requested,
                                                      const std::vector<std::string>& unfitted_shapes) {
  const SolverParams params = params_for_rig(requested, rig);
  validate(rig, markers, params);
  const auto start = Clock::now();
  auto model = std::make_shared<SolverModel>();
  model->rig = rig;
  model->params = params;
  model->kernels = &kernels::table(params.kernels);
  model->markers = std::move(markers);
  model->weights.fitted.assign(std::size_t(rig.shape_count()), 1);
  for (const std::string& name : unfitted_shapes) {
    const auto s = rig.shape_index(name);
    if (!s) throw Error(fmt::format("solver: shape '{}' to leave out of the weight fit is not a shape of rig '{}'", name, rig.name));
    model->weights.fitted[std::size_t(*s)] = 0;
  }
  model->blend.shape_reach = max_shape_displacement(rig);
  model->blend.negligible_reach = params.negligible_displacement_mm * rig_units_per_mm(rig);
  build_marker_rows(*model);
  build_vertex_terms(rig, {}, model->blend.vertex_blocks, model->blend.vertex_deltas);

  const TriangleAdjacency adjacency(rig.triangles);
  {
    const auto t0 = Clock::now();
    build_triangle_frames(*model);
    const Eigen::Index M = rig.shape_count();
    auto shapes = std::vector<ShapeDeformation>(std::size_t(M));
    const unsigned threads = std::max(1u, std::min(std::thread::hardware_concurrency(), unsigned(M)));
    std::vector<std::thread> pool;
    for (unsigned w = 0; w < threads; ++w)
      pool.emplace_back([&, w] {
        for (Eigen::Index s = w; s < M; s += threads) shapes[std::size_t(s)] = build_shape_deformation(*model, s, adjacency);
      });
    for (auto& t : pool) t.join();
    build_triangle_terms(*model, shapes);
    model->setup.gradients_s = seconds_since(t0);
  }

  build_marker_paths(*model);
  const Eigen::Index N = rig.vertex_count(), K = model->marker_count();
  {
    const auto t0 = Clock::now();
    Eigen::SparseMatrix<double> A = build_triangle_operators(*model);
    std::vector<Eigen::Triplet<double>> pins;
    for (const auto& m : model->markers)
      for (int a = 0; a < 3; ++a)
        for (int b = 0; b < 3; ++b)
          pins.emplace_back(m.vertices[a], m.vertices[b], params.beta * m.barycentric[a] * m.barycentric[b]);
    find_held_vertices(*model);
    const CollisionData& c = model->collision;
    for (std::size_t j = 0; j < c.held_vertices.size(); ++j)
      pins.emplace_back(c.held_vertices[j], c.held_vertices[j], c.held_weights[j] * params.beta);
    Eigen::SparseMatrix<double> P(N, N);
    P.setFromTriplets(pins.begin(), pins.end());
    A += P;
    model->poisson.factor = std::make_unique<SparseLdlt>(A, *model->kernels);
    model->setup.factor_s = seconds_since(t0);
  }
  {
    const auto t0 = Clock::now();
    choose_collision_region(*model);
    build_reference_terms(*model);
    // Beyond this many candidate vertices (a whole-face region) the columns would take
    // too much memory; pins are then solved for per frame.
    constexpr std::size_t kMaxPrecomputedPins = 3000;
    const Eigen::Index C = model->collision.vertices.size() <= kMaxPrecomputedPins
                               ? Eigen::Index(model->collision.vertices.size()) : 0;
    // Three columns per back-substitution (the solver's x, y, z kernel).
    auto solve_columns = [&](Eigen::Index count, auto&& unit, auto&& store) {
      Eigen::Matrix3Xd b(3, N);
      Eigen::Matrix4Xd work(4, N);
      for (Eigen::Index first = 0; first < count; first += 3) {
        b.setZero();
        for (Eigen::Index r = 0; r < 3 && first + r < count; ++r) unit(first + r, b.row(r));
        model->poisson.factor->solve_in_place(b, work);
        for (Eigen::Index r = 0; r < 3 && first + r < count; ++r) store(first + r, b.row(r).transpose());
      }
    };
    model->poisson.marker_solution.resize(N, K);
    solve_columns(
        K,
        [&](Eigen::Index k, auto row) {
          for (int a = 0; a < 3; ++a) row[model->markers[std::size_t(k)].vertices[a]] += model->markers[std::size_t(k)].barycentric[a];
        },
        [&](Eigen::Index k, const auto& column) { model->poisson.marker_solution.col(k) = column; });
    model->poisson.pin_solution.resize(N, C);
    solve_columns(
        C, [&](Eigen::Index c, auto row) { row[model->collision.vertices[std::size_t(c)]] = 1.0; },
        [&](Eigen::Index c, const auto& column) { model->poisson.pin_solution.set_column(c, column); });
    model->setup.modifications_s = seconds_since(t0);
  }
  model->setup.total_s = seconds_since(start);
  return model;
}

}  // namespace facecap
