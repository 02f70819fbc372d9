// The fold metric (solver/collide/folds.hpp) against a brute-force reading of its
// definition, and the stress corpus of the non-linear blend (solver/stress_corpus.hpp)
// solved without folds by the fold stage, where the paper's solve folds.
#include <algorithm>
#include <cmath>
#include <random>
#include <map>
#include <memory>
#include <numbers>

#include <catch2/catch.hpp>
#include <fmt/format.h>

#include "core/time.hpp"
#include "solver/builtin_face.hpp"
#include "solver/collide/folds.hpp"
#include "solver/face_solver.hpp"
#include "solver/kernels/kernels.hpp"
#include "solver/marker_layout.hpp"
#include "solver/solver_model.hpp"
#include "solver/stress_corpus.hpp"
#include "tests/solver_test_support.hpp"
#include "tests/test_support.hpp"

using namespace facecap;

namespace {

// A 4 x 4 grid of unit squares in the z = 0 plane, two triangles each, normals +z.
struct Grid {
  Eigen::Matrix3Xd vertices{3, 25};
  Eigen::Matrix3Xi triangles{3, 32};
  Grid() {
    for (int y = 0; y < 5; ++y)
      for (int x = 0; x < 5; ++x) vertices.col(5 * y + x) = Eigen::Vector3d(x, y, 0);
    int t = 0;
    for (int y = 0; y < 4; ++y)
      for (int x = 0; x < 4; ++x) {
        const int a = 5 * y + x;
        triangles.col(t++) = Eigen::Vector3i(a, a + 1, a + 6);
        triangles.col(t++) = Eigen::Vector3i(a, a + 6, a + 5);
      }
  }
};

struct CorpusCount {
  int poses = 0, folded_poses = 0, flagged = 0;
  std::map<std::string, int> folded_by_kind;
  uint32_t most_fold_pins = 0, most_released = 0;
  uint32_t worst = 0;
  std::string worst_pose;
  double max_stretch_mm = 0;
};

// A solver of `method` over 60 markers spread on the rig, the corpus's layout.
struct CorpusSolver {
  std::vector<MarkerBinding> layout;
  std::unique_ptr<FaceSolver> solver;
  CorpusSolver(const Rig& rig, SolverMethod method, const SolverParams& params = {})
      : layout(spread_marker_layout(rig, 60)), solver(make_solver(method, build_solver_model(rig, layout, params))) {}
};

// The corpus solved with `params` by `method`, folds measured by a detector of its own
// against the rig's linear blend.
CorpusCount solve_corpus(const Rig& rig, SolverMethod method, const SolverParams& params) {
  const CorpusSolver corpus(rig, method, params);
  const auto& layout = corpus.layout;
  const auto& solver = corpus.solver;
  SolveResult out = solver->make_result();
  FoldDetector folds;
  folds.configure(rig.triangles, triangle_regions(rig), 90.0, fold_tolerance(rig));
  const std::vector<uint8_t> present(layout.size(), 1);
  CorpusCount count;
  for (const StressPose& pose : stress_corpus(rig, layout)) {
    solver->solve_with_weights(pose.weights, pose.targets, present, out);
    const FoldReport& r = folds.measure(out.vertices, rig.linear_blend(pose.weights));
    ++count.poses;
    count.folded_poses += r.folded > 0;
    if (r.folded > 0) ++count.folded_by_kind[pose.kind];
    count.most_fold_pins = std::max(count.most_fold_pins, out.fold_pins);
    count.most_released = std::max(count.most_released, out.markers_released);
    count.flagged += (out.status & kSolvedFolded) != 0;
    count.max_stretch_mm = std::max(count.max_stretch_mm, r.max_edge_stretch / rig_units_per_mm(rig));
    if (r.folded > count.worst) count.worst = r.folded, count.worst_pose = pose.name;
  }
  return count;
}

void check_corpus(const Rig& rig) {
  SolverParams paper;  // today's solve: folds measured, nothing pinned for them
  paper.fold_max_pins = 0;
  const CorpusCount before = solve_corpus(rig, SolverMethod::kNonlinear, paper);
  const CorpusCount after = solve_corpus(rig, SolverMethod::kNonlinear, {});
  auto kinds = [](const CorpusCount& c) {
    std::string out;
    for (const auto& [kind, n] : c.folded_by_kind) out += fmt::format(" {} {}", kind, n);
    return out;
  };
  const std::string figures = fmt::format(
      "{}: {} poses; nonlinear without fold pins folds {} ({}; worst {}: {} triangles, flagged {}), with them {} ({}; "
      "worst {}: {}, flagged {}; at most {} fold pins and {} markers released a pose); largest edge stretch {:.2f} -> {:.2f} mm",
      rig.name, before.poses, before.folded_poses, kinds(before), before.worst_pose, before.worst, before.flagged,
      after.folded_poses, kinds(after), after.worst_pose, after.worst, after.flagged, after.most_fold_pins, after.most_released, before.max_stretch_mm, after.max_stretch_mm);
  INFO(figures);
  WARN(figures);
  CHECK(before.folded_poses > 0);  // the corpus finds folds in the paper's solve ...
  CHECK(before.flagged == before.folded_poses);  // ... the solver flags each ...
  CHECK(after.folded_poses == 0);  // ... and the fold stage leaves none
  CHECK(after.flagged == 0);
}

}  // namespace

TEST_CASE("the fold metric finds a flipped triangle, a crease past the threshold and the largest edge stretch") {
  const Grid g;
  FoldDetector folds;
  folds.configure(g.triangles, {});
  CHECK(folds.measure(g.vertices, g.vertices).folded == 0);

  // Vertex 12 (the middle) pushed through to the far side of its neighbours flips the
  // six triangles around it.
  Eigen::Matrix3Xd flipped = g.vertices;
  flipped.col(12) = Eigen::Vector3d(3.5, 3.5, 0.0);
  const FoldReport& r = folds.measure(flipped, g.vertices);
  int brute = 0;
  for (Eigen::Index t = 0; t < g.triangles.cols(); ++t) {
    auto normal = [&](const Eigen::Matrix3Xd& x) {
      return Eigen::Vector3d((x.col(g.triangles(1, t)) - x.col(g.triangles(0, t))).cross(x.col(g.triangles(2, t)) - x.col(g.triangles(0, t))));
    };
    brute += normal(flipped).dot(normal(g.vertices)) < 0;
  }
  CHECK(brute > 0);
  CHECK(int(r.flipped) == brute);
  CHECK(r.max_edge_stretch == Approx((Eigen::Vector3d(3.5, 3.5, 0) - Eigen::Vector3d(1, 1, 0)).norm() - std::sqrt(2.0)));

  // A V along the line y = 2: each half turned by `degrees` about it, the upper up and the
  // lower down, so that the crease is twice that and no triangle turns 90 degrees.
  auto bend = [&](double degrees) {
    Eigen::Matrix3Xd x = g.vertices;
    const double a = degrees * std::numbers::pi / 180.0;
    for (Eigen::Index v = 0; v < x.cols(); ++v) {
      const double d = g.vertices(1, v) - 2.0, side = d > 0 ? a : -a;
      x.col(v) = Eigen::Vector3d(g.vertices(0, v), 2.0 + d * std::cos(side), d * std::sin(side));
    }
    return x;
  };
  const Eigen::Matrix3Xd creased = bend(60.0), bent = bend(30.0);
  const FoldReport& c = folds.measure(creased, g.vertices);
  CHECK(c.flipped == 0);
  CHECK(c.folded == 8);  // the two triangles on each side of the 4 edges on the line
  CHECK(c.folded_by_region[kRegionElsewhere] == 8);
  CHECK(c.max_edge_stretch == Approx(0.0).margin(1e-6));  // float: rounding of unit edges
  CHECK(folds.measure(creased, creased).folded == 0);  // the reference creased alike: no fold
  CHECK(folds.measure(bent, g.vertices).folded == 0);  // 60 degrees: below the default 90
  FoldDetector sharp;
  sharp.configure(g.triangles, {}, 45.0);
  CHECK(sharp.measure(bent, g.vertices).folded == 8);

  // measure_again against the reference of the last measure gives what measure gives.
  for (FoldDetector* d : {&folds, &sharp}) {
    d->measure(g.vertices, g.vertices);
    for (const Eigen::Matrix3Xd* solved : std::initializer_list<const Eigen::Matrix3Xd*>{&flipped, &creased, &bent}) {
      const FoldReport again = d->measure_again(*solved);
      const FoldReport fresh = d->measure(*solved, g.vertices);
      CHECK(again.folded == fresh.folded);
      CHECK(again.flipped == fresh.flipped);
      CHECK(again.folded_by_region == fresh.folded_by_region);
      CHECK(again.max_edge_stretch == fresh.max_edge_stretch);
    }
  }
}

namespace {

// The metric's definition read in double precision, pair by pair and edge by edge: a
// triangle whose corners are all within `tolerance` of the reference's counts as the
// reference's.
FoldReport brute_force_folds(const Eigen::Matrix3Xi& triangles, const Eigen::Matrix3Xd& solved, const Eigen::Matrix3Xd& reference,
                             double crease_degrees, double tolerance) {
  const Eigen::Index T = triangles.cols();
  auto normal = [&](const Eigen::Matrix3Xd& x, Eigen::Index t) {
    return Eigen::Vector3d((x.col(triangles(1, t)) - x.col(triangles(0, t))).cross(x.col(triangles(2, t)) - x.col(triangles(0, t))));
  };
  auto visible = [&](Eigen::Index t) {
    for (int j = 0; j < 3; ++j)
      if ((solved.col(triangles(j, t)) - reference.col(triangles(j, t))).norm() > tolerance) return true;
    return false;
  };
  auto judged = [&](Eigen::Index t) { return visible(t) ? normal(solved, t) : normal(reference, t); };
  auto angle = [](const Eigen::Vector3d& a, const Eigen::Vector3d& b) {
    const double n = a.norm() * b.norm();
    return n > 0 ? std::acos(std::clamp(a.dot(b) / n, -1.0, 1.0)) : 0.0;
  };
  std::vector<uint8_t> folded(std::size_t(T), 0);
  FoldReport r;
  for (Eigen::Index t = 0; t < T; ++t)
    if (judged(t).dot(normal(reference, t)) < 0) folded[std::size_t(t)] = 1, ++r.flipped;
  std::map<std::pair<int, int>, Eigen::Index> first;
  for (Eigen::Index t = 0; t < T; ++t)
    for (int j = 0; j < 3; ++j) {
      const int a = triangles(j, t), b = triangles((j + 1) % 3, t);
      r.max_edge_stretch = std::max(r.max_edge_stretch, std::abs((solved.col(a) - solved.col(b)).norm() - (reference.col(a) - reference.col(b)).norm()));
      const auto [it, inserted] = first.try_emplace(std::minmax(a, b), t);
      if (inserted) continue;
      const Eigen::Index u = it->second;
      if (angle(judged(u), judged(t)) - angle(normal(reference, u), normal(reference, t)) > crease_degrees * std::numbers::pi / 180)
        folded[std::size_t(u)] = folded[std::size_t(t)] = 1;
    }
  for (const uint8_t f : folded) r.folded += f;
  return r;
}

}  // namespace

TEST_CASE("every kernel path measures folds on a whole face as a double-precision reading of the definition does") {
  // Without a tolerance, and with one that leaves out most of the slightly moved triangles.
  const Rig& rig = BuiltinFace::instance().rig();
  std::mt19937 rng(11);
  std::uniform_real_distribution<double> unit(0.0, 1.0);
  std::normal_distribution<double> jitter(0.0, 1.0);
  const double scale = 0.01 * (rig.neutral.rowwise().maxCoeff() - rig.neutral.rowwise().minCoeff()).norm();
  for (int pose = 0; pose < 6; ++pose) {
    Eigen::VectorXd w(rig.shape_count());
    for (Eigen::Index s = 0; s < w.size(); ++s) w[s] = unit(rng) < 0.7 ? 0.0 : unit(rng);
    const Eigen::Matrix3Xd reference = rig.linear_blend(w);
    // Every vertex moved a little and one in twenty far: flips, creases and stretch.
    Eigen::Matrix3Xd solved = reference;
    for (Eigen::Index v = 0; v < solved.cols(); ++v)
      solved.col(v) += (v % 20 == pose ? 0.5 : 0.005) * scale * Eigen::Vector3d(jitter(rng), jitter(rng), jitter(rng));
    for (const auto& [crease, tolerance] : std::initializer_list<std::pair<double, double>>{{90.0, 0.0}, {45.0, 0.0}, {120.0, 0.0}, {90.0, 0.01 * scale}}) {
      const FoldReport expected = brute_force_folds(rig.triangles, solved, reference, crease, tolerance);
      CHECK(expected.flipped > 0);
      CHECK(expected.folded > expected.flipped);
      for (const KernelPath path : facecap::test::runnable_kernel_paths()) {
        FoldDetector detector;
        detector.configure(rig.triangles, {}, crease, tolerance, &kernels::table(path));
        const FoldReport got = detector.measure(solved, reference);
        INFO("pose " << pose << ", crease " << crease << " degrees, tolerance " << tolerance << ", kernels " << kKernelPaths.name(path));
        CHECK(got.flipped == expected.flipped);
        CHECK(got.folded == expected.folded);
        CHECK(got.max_edge_stretch == Approx(expected.max_edge_stretch).epsilon(1e-5));
        CHECK(int(detector.folded_triangles().size()) == int(expected.folded));
      }
    }
  }
}

TEST_CASE("the built-in face's stress corpus folds in the paper's solve and not with the fold stage") {
  check_corpus(BuiltinFace::instance().rig());
}

TEST_CASE("ICT FaceKit's stress corpus folds in the paper's solve and not with the fold stage", "[data]") {
  FACECAP_REQUIRE_SHARED_DATA(dir, "ict-face");
  check_corpus(load_rig(dir.string()));
}

TEST_CASE("a fold stage past its deadline starts no round and flags the fold; without a deadline it undoes it, and a re-solve "
          "told where it stopped stops there") {
  const Rig& rig = BuiltinFace::instance().rig();
  const CorpusSolver corpus(rig, SolverMethod::kNonlinear);
  const auto& layout = corpus.layout;
  const auto& solver = corpus.solver;
  SolveResult out = solver->make_result();
  const std::vector<uint8_t> present(layout.size(), 1);
  // The first pose of the corpus the paper's solve folds (the unbounded stage undoes it).
  for (const StressPose& pose : stress_corpus(rig, layout)) {
    solver->set_deadline(0);
    solver->solve_with_weights(pose.weights, pose.targets, present, out);
    if (out.fold_pins == 0) continue;
    INFO(pose.name << ": " << out.fold_pins << " fold pins without a deadline");
    CHECK((out.status & kSolvedFolded) == 0);
    CHECK_FALSE(out.fold_stopped_at_deadline);

    solver->set_deadline(monotonic_now_ns() - 1);  // already passed
    solver->solve_with_weights(pose.weights, pose.targets, present, out);
    CHECK(out.fold_stopped_at_deadline);
    CHECK(out.fold_rounds == 0);
    CHECK(out.fold_pins == 0);
    CHECK(out.folds.folded > 0);
    CHECK((out.status & kSolvedFolded) != 0);

    // A re-solve without the deadline stops where it stopped (SolvedFrame::fold_deadline_rounds).
    const Eigen::Matrix3Xd stopped = out.vertices;
    solver->set_deadline(0);
    solver->stop_folds_after(int(out.fold_rounds));
    solver->solve_with_weights(pose.weights, pose.targets, present, out);
    CHECK(out.fold_stopped_at_deadline);
    CHECK(out.vertices == stopped);
    solver->stop_folds_after(1);
    solver->solve_with_weights(pose.weights, pose.targets, present, out);
    CHECK(out.fold_rounds == 1);
    CHECK(out.fold_pins > 0);
    solver->stop_folds_after(-1);
    return;
  }
  FAIL("no pose of the built-in corpus needed fold pins");
}
