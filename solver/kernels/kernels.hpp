#pragma once
// The per-frame kernels, compiled once per instruction set and chosen at run time
// (docs/solver.md, "Kernels"): the build targets a baseline CPU (x86-64-v2) and each
// kernel exists as
//   avx512    AVX-512 F/BW/VL/DQ (x86-64-v4), 16 float lanes
//   avx2      AVX2 with FMA and F16C (x86-64-v3), 8 float lanes
//   portable  the baseline, 4 float lanes (SSE4.1 on x86-64, plain C++ elsewhere)
// in kernels_impl.inl, compiled by kernels_<path>.cpp with that path's flags into a
// namespace of its own, so that nothing compiled for a wider CPU can reach a narrower
// one (tests/check_kernel_symbols.cmake checks the objects). A SolverModel holds the
// table of the path it was built with (SolverParams::kernels).
//
// The kernels see plain views (pointers and sizes), never Eigen or std containers: the
// callers own the data and make the views once. Every kernel is real-time safe.
#include <cstddef>
#include <cstdint>
#include <string_view>

#include "solver/params.hpp"

namespace facecap::kernels {

inline constexpr int kBlockSlots = 32;  // ShapeBlocks::kBlock: elements per block
inline constexpr int kWidths = 3;       // stored value widths: 8-bit, 16-bit, float

// One block's run of stored values (BlendTerms): its first value's byte offset (64-byte
// aligned), its first position and its entries per width.
struct BlockRun {
  std::size_t values = 0;
  int32_t first = 0;
  int32_t count[kWidths] = {};
};

// BlendTerms as the kernels read it.
struct BlendTermsView {
  const BlockRun* blocks = nullptr;
  const int32_t* shape = nullptr;     // per position
  const uint16_t* scales = nullptr;   // per position and component: half floats times kScaleUnit
  const float* offsets = nullptr;     // per position and component
  const std::byte* values = nullptr;
};
inline constexpr float kScaleUnit = 1.0f / 32768.0f;

// x0 + B w for one block of a ShapeBlocks: out column e = neutral column (vertices ?
// vertices[e] : e) + the block's sum, for e = element_of_slot[slot] (-1: padding).
struct LinearBlendView {
  BlendTermsView terms;
  const int32_t* element_of_slot = nullptr;
  const double* neutral = nullptr;  // 3 x N, column-major
  const int* vertices = nullptr;    // per element its rig vertex, or null: element e is vertex e
};

// The triangles' share of Eq. 5's right-hand side, G^T W (T(w) - I), added to rhs:
// per block, the active shapes' terms summed, turned into (T_j - I) Q_j from the rest
// frames in `operators` (9 per slot: t1, t2, (L, u, v) / 2, component-major per block)
// and scattered onto the slots' corners (-1: padding).
struct TriangleBlendView {
  BlendTermsView terms;
  int block_count = 0;
  bool nonlinear = true;                      // Eq. 4 (8 components), else deformation transfer (6)
  const float* operators = nullptr;
  const int32_t (*slot_corners)[3] = nullptr;
};
inline constexpr int kNonlinearComponents = 8, kGradientComponents = 6, kOperatorComponents = 9;

// A factor A = P^T L D L^T P (SparseLdlt): L's strictly lower entries by column, rows
// 16-bit (row16) or 32-bit (row32, when row16 is null).
struct LdltView {
  int64_t n = 0;
  const int* perm = nullptr;
  const int* col_start = nullptr;
  const uint16_t* row16 = nullptr;
  const int* row32 = nullptr;
  const double* values = nullptr;
  const double* inv_diagonal = nullptr;
};

// Up to 16 triangle pairs for the float pass of the closeness test (pair_batch.cpp):
// per pair the five corners after a's first, relative to it, and the pair's extent.
inline constexpr int kPairLanes = 16;
struct alignas(64) PairLanes {
  float corner[5][3][kPairLanes];
  float extent[kPairLanes];
};
struct PairVerdict {
  uint32_t close = 0;  // closer than epsilon for certain
  uint32_t apart = 0;  // apart by more than epsilon for certain
};

// The fold metric's per-triangle pass (collide/folds.hpp) over `count` triangles (a
// multiple of kFoldPadding; padding triangles have three equal corners). Positions are
// float, coordinate-major (x of every vertex, then y, then z: vertex_stride apart), as are
// the normals (normal_stride apart). A triangle is visible where a corner of the solve is
// further than the tolerance from the reference's. Lists, ascending, the visible triangles
// whose solved normal points against the reference's (flipped) and those turned from it
// by more than half the crease angle or without a reference normal (turned: only they can
// make a crease, since angles between normals obey the triangle inequality).
inline constexpr int kFoldPadding = 16;
struct FoldTrianglesView {
  int64_t count = 0;
  const int32_t* corner[3] = {};
  const float* solved = nullptr;
  const float* reference = nullptr;
  int64_t vertex_stride = 0;
  float* solved_normals = nullptr;     // written
  float* reference_normals = nullptr;  // written, or read when known
  int64_t normal_stride = 0;
  float cos_half_crease = 0.0f;        // >= 0
  float tolerance_squared = 0.0f;
  int32_t* flipped = nullptr;          // room for count each
  int32_t* turned = nullptr;
};
struct FoldTrianglesResult {
  float max_edge_stretch = 0.0f;  // the largest | |e| - |e_ref| | over the triangles' edges
  int64_t flipped = 0, turned = 0;
};

struct KernelTable {
  KernelPath path = KernelPath::kPortable;
  // One block of x0 + B w into out (3 x elements, column-major).
  void (*linear_blend_block)(const LinearBlendView& view, const float* weights, int block, double* out) noexcept = nullptr;
  // rhs (3 x N, column-major) += G^T W (T(w) - I).
  void (*triangle_rhs)(const TriangleBlendView& view, const float* weights, double* rhs) noexcept = nullptr;
  // xyz (3 x N) = A^-1 xyz in place; work holds 4 x N doubles.
  void (*ldlt_solve)(const LdltView& factor, double* xyz, double* work) noexcept = nullptr;
  // The float pass over `count` (<= 16) pairs.
  PairVerdict (*pair_float_pass)(const PairLanes& lanes, int count, float epsilon) noexcept = nullptr;
  // The fold metric's triangle pass; reference_known: reference_normals hold this
  // reference's normals already (another solve measured against it).
  FoldTrianglesResult (*fold_triangles)(const FoldTrianglesView& view, bool reference_known) noexcept = nullptr;
};

// Whether this CPU (and its OS) can run `path`'s kernels; kAuto always.
bool cpu_runs(KernelPath path) noexcept;
// The widest path this CPU runs.
KernelPath best_path() noexcept;
// The table of `path` (kAuto: best_path()). Throws Error naming the path and what the CPU
// lacks when it cannot run it.
const KernelTable& table(KernelPath path);
// What the CPU offers, for logs: e.g. "avx2 fma f16c" or "avx512 avx2 fma f16c".
std::string_view cpu_features() noexcept;

}  // namespace facecap::kernels
