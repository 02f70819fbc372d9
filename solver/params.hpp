#pragma once
// The solver's settings and its closed choices, readable without the solver itself (no
// CHOLMOD, no Qhull): target facecap_solver_params links only facecap_core, so that the
// configuration and the tools can parse, list and document solver names from the same
// tables the solver uses. SolverParams' member initialisers are the defaults.
#include <array>
#include <cstdint>
#include <string_view>

#include "core/enum_table.hpp"

namespace facecap {

enum class SolverMethod : uint8_t { kNonlinear, kLinear, kDt, kMeshik };

inline constexpr EnumTable kSolverMethods{std::array{
    EnumEntry{SolverMethod::kNonlinear, "nonlinear",
              "the paper's non-linear blendshape interpolation: Eq. 2 weights, Eq. 4 blend, Eq. 5 mesh, collisions"},
    EnumEntry{SolverMethod::kLinear, "linear", "direct manipulation: the linear blend x0 + B w of the Eq. 2 weights"},
    EnumEntry{SolverMethod::kDt, "dt", "deformation transfer (Sumner & Popovic 2004) through the same Eq. 5 solve"},
    EnumEntry{SolverMethod::kMeshik, "meshik",
              "MeshIK (Sumner et al. 2005), weights and mesh optimised together: an offline baseline, far too "
              "slow for the loop"}}};

// Whether a method keeps up with a fixed-rate loop. meshik does not: it takes M
// back-substitutions per Gauss-Newton step, seconds a frame on a production rig.
constexpr bool solver_method_is_realtime(SolverMethod method) noexcept { return method != SolverMethod::kMeshik; }

// The triangles the collision stage checks.
enum class CollisionRegion : uint8_t { kNone, kLips, kFace };

inline constexpr EnumTable kCollisionRegions{std::array{
    EnumEntry{CollisionRegion::kNone, "none", "no collision handling"},
    EnumEntry{CollisionRegion::kLips, "lips", "the triangles around the mouth opening, found from the rig's shapes"},
    EnumEntry{CollisionRegion::kFace, "face", "every triangle of the face (slower: pins are solved for as they occur)"}}};

// Which compiled set of per-frame kernels the solver runs (solver/kernels/kernels.hpp):
// the widest the CPU has, or one forced, so that a machine with AVX-512 can run and
// measure the AVX2 path.
enum class KernelPath : uint8_t { kAuto, kAvx512, kAvx2, kPortable };

inline constexpr EnumTable kKernelPaths{std::array{
    EnumEntry{KernelPath::kAuto, "auto", "the widest this CPU runs: avx512, else avx2, else portable"},
    EnumEntry{KernelPath::kAvx512, "avx512", "AVX-512 F/BW/VL/DQ (x86-64-v4): Intel Xeon and recent desktops, AMD Zen 4 on"},
    EnumEntry{KernelPath::kAvx2, "avx2", "AVX2 with FMA and F16C (x86-64-v3): most capture boxes"},
    EnumEntry{KernelPath::kPortable, "portable", "the baseline (x86-64-v2, SSE4.2): runs on any x86-64 CPU facecap supports"}}};

// The value named `name`; throws Error naming the allowed names when there is none.
SolverMethod parse_solver_method(std::string_view name);
CollisionRegion parse_collision_region(std::string_view name);

// SolverParams values that the rig decides unless given (see build_solver_model).
inline constexpr int kByRig = -1;

struct SolverParams {
  double alpha = 0.1;     // temporal weight regularisation (Eq. 2)
  double mu = 0.001;      // weight magnitude regularisation (Eq. 2)
  double beta = 100.0;    // marker pinning strength (Eq. 5)
  CollisionRegion collision_region = CollisionRegion::kLips;
  double collision_epsilon = 0.01;  // rig units: triangle pairs closer than this collide
  // Vertices pinned per frame at most: bounds the collision stage's cost. Lip poses that
  // need more keep some crossings (ICT: one pose in 41 needs 100) and are flagged
  // kSolvedPinsBeyondCapacity.
  int collision_max_pins = 64;
  // How far the collision stage's box-overlap pairs stay valid: the tree is traversed
  // again only once a lip vertex has moved farther than this since the last traversal
  // (solver/collide/collider.hpp); 0 traverses every frame. Results do not depend on it,
  // only the time. Off by default: at 0.15 mm facecapd missed the built-in face's 120 Hz
  // (docs/solver.md, "Kernels").
  double collision_skin_mm = 0.0;
  double active_weight = 1e-4;      // weights below this are left out of T(w)
  // A shape whose weight moves no vertex by more than this (its weight times its largest
  // displacement) is left out of T(w) and x0 + B w for that frame; its weight is still
  // solved and sent. Off by default: at 0.01 mm facecapd missed the built-in face's 120 Hz
  // (the fold and collision stages then did more; docs/solver.md, "Kernels").
  double negligible_displacement_mm = 0.0;
  // The two settings below default to kByRig: the rig's own choice, by whether its shapes
  // swing parts about hinges as a real jaw does (Rig::hinged: the built-in face) or are an
  // artist's linear blend (ICT, ARKit and MetaHuman heads). build_solver_model decides.
  //
  // The mesh's outer boundary loop held to the linear blend x0 + B w at this times beta
  // (0: free). Eq. 5 leaves it free, so where a marker near it is missing the pinned solve
  // carries the others' motion out to it: on EyebrowsMoCap, nonlinear's held-out p95 is
  // 7.26 mm free and 6.12 held, linear's 7.13. By rig: 0.003, and 0 for a hinged rig,
  // whose edge may swing with the hinge (docs/solver.md, "The mesh's outer edge").
  double boundary_hold = kByRig;
  // Gauss-Newton refinements of Eq. 2 for the nonlinear solver, fitting markers along
  // the paths the rotations of Eq. 4 move them (a hinge swings, it does not slide);
  // 0 gives the paper's linear fit. By rig: 2 for a hinged rig (0 more than doubles the
  // built-in face's truth error), else 0: on an artist's rig they re-mix its own poses
  // and on real takes they help on none (docs/solver.md, "Weight refinements on real
  // takes").
  int weight_refinements = kByRig;
  // Iterations Eq. 2's box QP may take per solve; 0: 10 M + 10, far more than the few it
  // takes. A solve stopped at the cap keeps its last feasible iterate and is flagged
  // kSolvedQpIterationCap.
  int weight_qp_iteration_cap = 0;
  // The kernels the model's solvers run; a path the CPU lacks is refused when the model
  // is built.
  KernelPath kernels = KernelPath::kAuto;
  // The fold stage (docs/solver.md "Folds"): a triangle the solve flips against the
  // linear blend of the same weights, or creases across an edge more than
  // fold_crease_degrees beyond that blend's bend there, counts as folded; its vertices
  // are pinned to the linear blend, at most fold_max_pins a frame (ICT's stress corpus
  // needs up to 146), and a marker pinning a fold the pins cannot undo is released for
  // the frame; 0: measure only, the paper's solve. A frame still folded is flagged
  // kSolvedFolded.
  int fold_max_pins = 256;
  double fold_crease_degrees = 90.0;
};

}  // namespace facecap
