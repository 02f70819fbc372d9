// The per-frame kernels chosen at run time (solver/kernels/kernels.hpp): every path this
// CPU runs must solve as the portable path does, to float rounding, on the built-in face
// and on ICT, for each real-time solver and with collisions, missing markers and
// far-from-neutral poses; a path the CPU lacks is refused by name.
#include <random>

#include <catch2/catch.hpp>

#include "solver/builtin_face.hpp"
#include "solver/face_solver.hpp"
#include "solver/kernels/kernels.hpp"
#include "solver/marker_layout.hpp"
#include "solver/rig.hpp"
#include "solver/solver_model.hpp"
#include "tests/solver_test_support.hpp"
#include "tests/test_support.hpp"

using namespace facecap;
using facecap::test::markers_of;

namespace {

struct PathSolve {
  std::vector<Eigen::VectorXd> weights;
  std::vector<Eigen::Matrix3Xd> vertices;
  uint32_t collision_pins = 0;
};

// Each frame: random weights (some at 1, the rest small or zero) posed by the rig's linear
// blend, marker targets from that pose with every eighth frame missing a marker; solved
// by `method` with the kernels of `path`.
PathSolve solve_frames(const Rig& rig, const std::vector<MarkerBinding>& layout, SolverMethod method, KernelPath path) {
  SolverParams params;
  params.kernels = path;
  const auto model = build_solver_model(rig, layout, params);
  REQUIRE(model->kernels->path == path);
  auto solver = make_solver(method, model);
  SolveResult out = solver->make_result();
  std::mt19937 rng(5);
  std::uniform_real_distribution<double> unit(0.0, 1.0);
  PathSolve result;
  for (int frame = 0; frame < 24; ++frame) {
    Eigen::VectorXd w(rig.shape_count());
    for (Eigen::Index s = 0; s < w.size(); ++s) {
      const double u = unit(rng);
      w[s] = u < 0.5 ? 0.0 : u < 0.9 ? 0.3 * unit(rng) : 1.0;
    }
    Eigen::Matrix3Xd pose = rig.neutral;
    for (Eigen::Index s = 0; s < w.size(); ++s) pose += w[s] * (rig.shape_positions(s) - rig.neutral);
    auto present = facecap::test::all_present(Eigen::Index(layout.size()));
    if (frame % 8 == 7) present[std::size_t(frame) % present.size()] = 0;
    solver->solve(markers_of(pose, layout), present, out);
    result.weights.push_back(out.weights);
    result.vertices.push_back(out.vertices);
    result.collision_pins += out.collision_constraints;
  }
  return result;
}

// Every runnable path against the portable one: weights and vertices within `tolerance`
// (rig units; float rounding of the blend's sums is about 1e-7 of the face's size).
void check_paths_agree(const Rig& rig, double tolerance) {
  const auto layout = spread_marker_layout(rig, 60);
  const auto paths = facecap::test::runnable_kernel_paths();
  if (paths.size() < 2) WARN("this CPU runs only the portable kernels: nothing to compare them with");
  for (const SolverMethod method : {SolverMethod::kNonlinear, SolverMethod::kDt, SolverMethod::kLinear}) {
    const PathSolve portable = solve_frames(rig, layout, method, KernelPath::kPortable);
    for (const KernelPath path : paths) {
      if (path == KernelPath::kPortable) continue;
      const PathSolve other = solve_frames(rig, layout, method, path);
      double vertex_difference = 0.0, weight_difference = 0.0;
      for (std::size_t f = 0; f < portable.vertices.size(); ++f) {
        vertex_difference = std::max(vertex_difference, (other.vertices[f] - portable.vertices[f]).cwiseAbs().maxCoeff());
        weight_difference = std::max(weight_difference, (other.weights[f] - portable.weights[f]).cwiseAbs().maxCoeff());
      }
      INFO(rig.name << ", " << kSolverMethods.name(method) << ": " << kKernelPaths.name(path)
                    << " against portable: vertices differ by " << vertex_difference << ", weights by " << weight_difference);
      CHECK(vertex_difference <= tolerance);
      CHECK(weight_difference <= 1e-6);
      CHECK(other.collision_pins == portable.collision_pins);
    }
  }
}

}  // namespace

TEST_CASE("every kernel path this CPU runs solves the built-in face as the portable path does") {
  check_paths_agree(BuiltinFace::instance().rig(), 1e-6);
}

TEST_CASE("every kernel path this CPU runs solves ICT FaceKit as the portable path does") {
  FACECAP_REQUIRE_SHARED_DATA(dir, "ict-face");
  check_paths_agree(load_rig(dir.string()), 1e-6);
}

TEST_CASE("a kernel path the CPU cannot run is refused by name, and auto picks the widest it runs") {
  CHECK(kernels::cpu_runs(KernelPath::kPortable));
  const KernelPath best = kernels::best_path();
  CHECK(kernels::table(KernelPath::kAuto).path == best);
  CHECK(kernels::cpu_runs(best));
  if (best == KernelPath::kAvx512) CHECK(kernels::cpu_runs(KernelPath::kAvx2));
  for (const KernelPath path : {KernelPath::kAvx512, KernelPath::kAvx2}) {
    if (kernels::cpu_runs(path)) {
      CHECK(kernels::table(path).path == path);
      continue;
    }
    const std::string name(kKernelPaths.name(path));
    CHECK_THROWS_WITH(kernels::table(path), Catch::Contains("kernels \"" + name + "\": this CPU cannot run them"));
    SolverParams params;
    params.kernels = path;
    const Rig& rig = BuiltinFace::instance().rig();
    CHECK_THROWS_WITH(build_solver_model(rig, spread_marker_layout(rig, 20), params), Catch::Contains(name));
  }
}
