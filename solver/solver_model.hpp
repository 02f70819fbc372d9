#pragma once
// Everything the per-frame solvers share, precomputed once per rig and marker layout
// (see build_solver_model). Read-only after construction; safe to share across threads.
#include <cstdint>
#include <memory>
#include <span>
#include <vector>

#include <Eigen/Core>

#include "core/huge_pages.hpp"
#include "solver/face_solver.hpp"
#include "solver/rig.hpp"
#include "solver/sparse_ldlt.hpp"

namespace facecap {

// Per-shape values on a mesh's elements (vertices for x0 + B w, triangles for Eq. 3),
// laid out for the per-frame weighted sum over shapes, which memory bandwidth bounds:
// elements in Morton order of their rest positions, cut into blocks of kBlock
// neighbours; per block, an entry for each shape that changes any of its elements.
// Slot b * kBlock + i of the order is element element_of_slot[slot] (-1: padding).
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
  // (components x kBlock).
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

// Columns of an N-row matrix as 16-bit fixed point, scale * q with one scale per column
// spanning its largest magnitude: rounding is at most 1/65534 of that, and a quarter of
// double's bytes stream through the per-frame sum.
struct PinColumns {
  Eigen::Index rows = 0;
  HugePageVector<int16_t> values;  // column-major
  std::vector<float> scale;        // per column

  Eigen::Index cols() const noexcept { return Eigen::Index(scale.size()); }
  void resize(Eigen::Index row_count, Eigen::Index col_count) {
    rows = row_count;
    values.assign(std::size_t(row_count * col_count), 0);
    scale.assign(std::size_t(col_count), 0.0f);
  }
  const int16_t* column(Eigen::Index c) const noexcept { return values.data() + std::size_t(c * rows); }
  void set_column(Eigen::Index c, const Eigen::Ref<const Eigen::VectorXd>& column);
};

// How a marker moves with one shape's weight t under Eq. 4 where the shape turns the
// surface under it: f(t) = (exp(t r) - I) arm + t axial, a screw motion that reaches the
// shape's delta at t = 1. Markers on shapes that do not turn move linearly (t delta).
struct MarkerPath {
  int marker = 0;
  int shape = 0;
  // The surface under the marker turns by r = angle * axis; with the arm perpendicular to
  // the axis, (exp(t r) - I) arm = (cos(t angle) - 1) arm + sin(t angle) axis_cross_arm.
  Eigen::Vector3d arm = Eigen::Vector3d::Zero();     // from the rotation axis, perpendicular to it
  Eigen::Vector3d axial = Eigen::Vector3d::Zero();   // slide along the axis at t = 1
  double angle = 0.0;                                // |r|
  Eigen::Vector3d axis_cross_arm = Eigen::Vector3d::Zero();
};

struct SolverSetupTimes {
  double gradients_s = 0, factor_s = 0, modifications_s = 0, total_s = 0;
};

class SolverModel {
 public:
  Rig rig;
  SolverParams params;
  std::vector<MarkerBinding> markers;

  // Eq. 2 on marker rows: marker k's rows 3k..3k+2 of B~ and x0~.
  Eigen::MatrixXd marker_basis;     // 3K x M
  Eigen::Matrix<double, Eigen::Dynamic, Eigen::Dynamic, Eigen::RowMajor> marker_basis_rows;  // the same, row-major
  Eigen::VectorXd marker_neutral;   // 3K
  Eigen::MatrixXd gram_all;         // M x M: B~^T B~ over all markers
  Eigen::MatrixXd gram_per_marker;  // M x (M K): marker k's B_k^T B_k in columns kM..kM+M-1

  std::vector<MarkerPath> marker_paths;         // (marker, shape) pairs that turn

  ShapeBlocks vertex_blocks;
  BlendTerms vertex_deltas;  // B's columns (x, y, z), for x0 + B w

  // Eq. 3-5: per triangle j, Q_j = area_j [grad phi_1, grad phi_2, grad phi_3] so the
  // right-hand side gains T_j Q_j on the triangle's three vertices. Q_j's columns lie in
  // the rest triangle's plane: with its rest frame (t1, t2, n), Q_j = t1 q1^T + t2 q2^T,
  // and only T_j t1 and T_j t2 reach the right-hand side.
  Eigen::Matrix<double, 9, Eigen::Dynamic> triangle_operator;  // 9 x T, column-major 3x3
  Eigen::Matrix<double, 9, Eigen::Dynamic> triangle_frames;    // 9 x T: t1, t2, n; zero if degenerate
  ShapeBlocks triangle_blocks;
  // Eq. 3: log R (x, y, z; world), then S - I in the rest frame: xx, yy, xy, xz, yz (its
  // zz, along the normal, is left out: it never reaches the right-hand side).
  BlendTerms triangle_nonlinear;
  // Deformation transfer: (F - I) t1, then (F - I) t2 (world).
  BlendTerms triangle_gradient;
  static constexpr int kNonlinearComponents = 8, kGradientComponents = 6;
  std::unique_ptr<SparseLdlt> factor;  // A0 = G^T W G + beta C^T C with every marker present

  // Low-rank modifications of A0 without refactoring: a marker dropping out removes
  // beta c_k c_k^T, a collision pin adds beta e_v e_v^T. Column k of marker_solution is
  // A0^-1 c_k; column i of pin_solution is A0^-1 e_v for v = collision_vertices[i] when
  // the region is small enough to precompute (the lips), otherwise pins are solved for as
  // they occur. pin_solution is 16-bit (PinColumns): it multiplies pin forces
  // beta (t_v - x_v), small next to positions, and the per-frame correction streams it.
  std::vector<int> collision_triangles;  // triangles the collision stage checks
  std::vector<int> collision_vertices;   // their vertices: the ones it may pin
  std::vector<int> vertex_to_collision;  // N: index into collision_vertices or -1
  // With collision handling: vertices held to the linear blend x0 + B w, through
  // kTangleWeight beta e_v e_v^T in A0 and kTangleWeight beta (x0 + B w)_v in the
  // right-hand side. They are the corners of triangles that already cross in the neutral
  // (ICT's lip corners), and one ring around them. Such crumpled triangles have no
  // meaningful rotation: blended, they fold through their neighbours where the linear
  // blend does not.
  static constexpr double kTangleWeight = 10.0;  // times beta: at beta alone they still cross by a hair
  std::vector<int> tangle_vertices;
  // The vertices whose linear blend (x0 + B w)_v each frame needs: the collision and the
  // tangle vertices, with B's rows there laid out like vertex_deltas. Element i of
  // reference_blocks is vertex reference_vertices[i].
  std::vector<int> reference_vertices;
  std::vector<int> vertex_to_reference;  // N: index into reference_vertices or -1
  ShapeBlocks reference_blocks;
  BlendTerms reference_deltas;
  Eigen::MatrixXd marker_solution;       // N x K
  PinColumns pin_solution;               // N x C, or empty
  bool collision_columns_precomputed() const {
    return !collision_vertices.empty() && pin_solution.cols() == Eigen::Index(collision_vertices.size());
  }

  SolverSetupTimes setup;

  Eigen::Index marker_count() const { return Eigen::Index(markers.size()); }
  // The rotation log of `shape` at `triangle`; zero where the shape leaves it unchanged.
  Eigen::Vector3d rotation_log(Eigen::Index shape, Eigen::Index triangle) const noexcept;
  // S - I in world coordinates from the rest-frame components triangle_nonlinear stores
  // (xx, yy, xy, xz, yz), with nothing along the normal.
  Eigen::Matrix3d world_stretch(Eigen::Index triangle, const double* local) const noexcept;
  Eigen::Index shape_count() const { return rig.shape_count(); }
  Eigen::Index vertex_count() const { return rig.vertex_count(); }
};

// The rest frame of a triangle (a0, b0, c0): t1 along a0 -> b0, the unit normal n and
// t2 = n x t1, as columns; zero for a degenerate triangle (twice its area at most
// degenerate_area).
Eigen::Matrix3d rest_frame(const Eigen::Vector3d& a0, const Eigen::Vector3d& b0, const Eigen::Vector3d& c0,
                           double degenerate_area);

// Deformation gradient (Sumner & Popovic 2004, fourth vertex along the normal) of one
// triangle from rest (a0, b0, c0) to deformed (a, b, c).
Eigen::Matrix3d deformation_gradient(const Eigen::Vector3d& a0, const Eigen::Vector3d& b0, const Eigen::Vector3d& c0,
                                     const Eigen::Vector3d& a, const Eigen::Vector3d& b, const Eigen::Vector3d& c);

// F = R S with R a proper rotation and S symmetric.
void polar_decomposition(const Eigen::Matrix3d& F, Eigen::Matrix3d& R, Eigen::Matrix3d& S);

// Rotation vector (axis * angle, angle in [0, pi]) of R, and its exponential.
Eigen::Vector3d rotation_log(const Eigen::Matrix3d& R);
Eigen::Matrix3d rotation_exp(const Eigen::Vector3d& r) noexcept;

// Of the rotation vectors equivalent to r (r and r - 2 pi r/|r|), the one nearest to
// `reference`: keeps a field of rotations near pi on one branch.
Eigen::Vector3d nearest_log_branch(const Eigen::Vector3d& r, const Eigen::Vector3d& reference);

}  // namespace facecap
