#pragma once
// Everything the per-frame solvers share, precomputed once per rig and marker layout
// (see build_solver_model). Read-only after construction; safe to share across threads.
#include <cstdint>
#include <memory>
#include <span>
#include <vector>

#include <Eigen/Core>

#include "solver/blend_terms.hpp"
#include "solver/face_solver.hpp"
#include "solver/pin_update.hpp"
#include "solver/rig.hpp"
#include "solver/sparse_ldlt.hpp"

namespace facecap {

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

// Eq. 2 on the marker rows (K markers, M shapes): marker k's rows are 3k..3k+2.
struct WeightsData {
  Eigen::MatrixXd marker_basis;  // 3K x M: B~, the shapes' deltas at the markers
  Eigen::Matrix<double, Eigen::Dynamic, Eigen::Dynamic, Eigen::RowMajor> marker_basis_rows;  // 3K x M: B~, row-major
  Eigen::VectorXd marker_neutral;   // 3K: x0~
  Eigen::MatrixXd gram_all;         // M x M: B~^T B~ over all markers
  Eigen::MatrixXd gram_per_marker;  // M x (M K): marker k's B_k^T B_k in columns kM..kM+M-1
  std::vector<MarkerPath> marker_paths;  // (marker, shape) pairs that turn: the refinement's arcs
  // M: 0 for the shapes left out of Eq. 2 (their columns of B~ are zero, they have no
  // marker paths, so their weights stay 0), else 1.
  std::vector<uint8_t> fitted;
};

// Eq. 3-4, and the linear blend x0 + B w (N vertices, T triangles, M shapes).
struct BlendData {
  Eigen::VectorXd shape_reach;   // M: each shape's largest vertex displacement, rig units
  double negligible_reach = 0;   // SolverParams::negligible_displacement_mm in rig units
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
  static constexpr int kNonlinearComponents = kernels::kNonlinearComponents, kGradientComponents = kernels::kGradientComponents;

  // The rotation log of `shape` at `triangle`; zero where the shape leaves it unchanged.
  Eigen::Vector3d rotation_log(Eigen::Index shape, Eigen::Index triangle) const noexcept;
  // S - I in world coordinates from the rest-frame components triangle_nonlinear stores
  // (xx, yy, xy, xz, yz), with nothing along the normal.
  Eigen::Matrix3d world_stretch(Eigen::Index triangle, const double* local) const noexcept;
};

// Eq. 5: x = A^-1 (G^T W T(w) + beta C^T b), A factored once as A0 with every marker
// present; per frame a PinUpdate (solver/pin_update.hpp) removes missing markers and adds
// collision pins from the columns A0^-1 u precomputed here.
struct PoissonData {
  // A0 = G^T W G + beta C^T C, plus h_v beta e_v e_v^T at the held vertices
  // (CollisionData::held_vertices). N x N.
  std::unique_ptr<SparseLdlt> factor;
  Eigen::MatrixXd marker_solution;  // N x K: column k is A0^-1 c_k
  // N x C: column i is A0^-1 e_v for v = CollisionData::vertices[i] when the region is
  // small enough to precompute (the lips), otherwise empty and pins are solved for as
  // they occur.
  PinColumns pin_solution;
};

// Collisions (DESIGN.md step 4): the triangles checked, the vertices that may be pinned
// and the linear blend (x0 + B w) at them, the pins' targets.
struct CollisionData {
  std::vector<int> triangles;     // the candidate set the collision stage checks
  std::vector<int> vertices;      // their vertices: the ones it may pin (C)
  std::vector<int> vertex_index;  // N: index into vertices or -1
  // Vertices held to the linear blend x0 + B w in every frame, through h_v beta e_v e_v^T
  // in A0 and h_v beta (x0 + B w)_v in the right-hand side:
  // - the tangle vertices, h = kTangleWeight: the corners of triangles that already cross
  //   in the neutral (ICT's lip corners), and one ring around them. Such crumpled
  //   triangles have no meaningful rotation: blended, they fold through their neighbours
  //   where the linear blend does not.
  // - the outer boundary loop, h = SolverParams::boundary_hold: beyond the markers
  //   nothing else holds it.
  static constexpr double kTangleWeight = 10.0;  // times beta: at beta alone they still cross by a hair
  std::vector<int> tangle_vertices;
  std::vector<int> boundary_vertices;  // empty when boundary_hold is 0 or the mesh is closed
  std::vector<int> held_vertices;      // both, ascending, each once
  std::vector<double> held_weights;    // h_v of held_vertices[i] (A0 and the rhs scale it by beta)
  // The vertices whose linear blend (x0 + B w)_v each frame needs: the collision and the
  // held vertices, with B's rows there laid out like BlendData::vertex_deltas.
  // Element i of reference_blocks is vertex reference_vertices[i].
  std::vector<int> reference_vertices;
  std::vector<int> reference_index;  // N: index into reference_vertices or -1
  ShapeBlocks reference_blocks;
  BlendTerms reference_deltas;
};

// The data of every stage, libigl style: one struct per stage, read-only once built.
class SolverModel {
 public:
  Rig rig;
  SolverParams params;
  std::vector<MarkerBinding> markers;  // K
  // The per-frame kernels of params.kernels (kAuto decided for this CPU); never null.
  const kernels::KernelTable* kernels = nullptr;

  WeightsData weights;
  BlendData blend;
  PoissonData poisson;
  CollisionData collision;

  SolverSetupTimes setup;

  Eigen::Index marker_count() const { return Eigen::Index(markers.size()); }
  Eigen::Index shape_count() const { return rig.shape_count(); }
  Eigen::Index vertex_count() const { return rig.vertex_count(); }
  // Whether poisson.pin_solution holds A0^-1 e_v for every collision vertex.
  bool pin_columns_precomputed() const {
    return !collision.vertices.empty() && poisson.pin_solution.cols() == Eigen::Index(collision.vertices.size());
  }
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
