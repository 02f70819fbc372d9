#include <algorithm>
#include <cmath>
#include <iterator>
#include <numbers>
#include <random>

#include <catch2/catch.hpp>
#include <fmt/format.h>
#include <Eigen/Geometry>
#include <Eigen/SparseCholesky>

#include "solver/box_qp.hpp"
#include "solver/builtin_face.hpp"
#include "solver/face_solver.hpp"
#include "solver/marker_layout.hpp"
#include "solver/mesh_topology.hpp"
#include "solver/solver_model.hpp"
#include "solver/sparse_ldlt.hpp"
#include "tests/solver_test_support.hpp"
#include "tests/test_support.hpp"

using namespace facecap;

using test::all_present;
using test::markers_of;
using test::max_error;
using test::mean_error;

TEST_CASE("box QP results satisfy the KKT conditions on random problems") {
  std::mt19937 rng(7);
  std::normal_distribution<double> normal;
  for (int trial = 0; trial < 200; ++trial) {
    const int n = 1 + trial % 60;
    Eigen::MatrixXd A(n + 5, n);
    for (int i = 0; i < A.size(); ++i) A.data()[i] = normal(rng);
    if (trial % 3 == 0) A.col(0).setZero();  // a shape the markers cannot see
    Eigen::MatrixXd H = A.transpose() * A;
    H.diagonal().array() += 0.101;
    Eigen::VectorXd g(n);
    for (int i = 0; i < n; ++i) g[i] = 3.0 * normal(rng);
    Eigen::VectorXd w = Eigen::VectorXd::Constant(n, 0.5);
    BoxQpSolver qp(n);
    const auto result = qp.solve(H, g, 0.0, 1.0, w);
    REQUIRE(result.converged);
    const Eigen::VectorXd gradient = H * w - g;
    for (int i = 0; i < n; ++i) {
      INFO("trial " << trial << " variable " << i << " w " << w[i] << " gradient " << gradient[i]);
      REQUIRE(w[i] >= 0.0);
      REQUIRE(w[i] <= 1.0);
      if (w[i] > 1e-12 && w[i] < 1 - 1e-12) REQUIRE(std::abs(gradient[i]) < 1e-8);
      if (w[i] <= 1e-12) REQUIRE(gradient[i] > -1e-8);   // multiplier of w >= 0
      if (w[i] >= 1 - 1e-12) REQUIRE(gradient[i] < 1e-8);  // multiplier of w <= 1
    }
  }
}

TEST_CASE("rotation logs near pi stay on one branch") {
  const Eigen::Vector3d axis = Eigen::Vector3d(1, 2, 0.5).normalized();
  Eigen::Vector3d previous = Eigen::Vector3d::Zero();
  double largest_step = 0;
  for (double angle = 2.6; angle < 3.7; angle += 0.01) {
    const Eigen::Matrix3d R = Eigen::AngleAxisd(angle, axis).toRotationMatrix();
    const Eigen::Vector3d raw = rotation_log(R);
    CHECK(raw.norm() <= std::numbers::pi + 1e-9);
    const Eigen::Vector3d chosen = angle == 2.6 ? raw : nearest_log_branch(raw, previous);
    CHECK((rotation_exp(chosen) - R).norm() < 1e-9);
    if (angle > 2.6) largest_step = std::max(largest_step, (chosen - previous).norm());
    previous = chosen;
  }
  CHECK(largest_step < 0.02);  // continuous through pi: no jump to the other side
  CHECK(previous.dot(axis) > 3.6);
}

TEST_CASE("solvers reproduce the neutral and every built-in shape exactly") {
  const Rig& rig = BuiltinFace::instance().rig();
  const auto layout = spread_marker_layout(rig, 60);
  const auto model = build_solver_model(rig, layout);
  const auto present = all_present(60);
  for (const SolverMethod method : {SolverMethod::kNonlinear, SolverMethod::kDt, SolverMethod::kLinear}) {
    auto solver = make_solver(method, model);
    SolveResult out = solver->make_result();
    Eigen::VectorXd w = Eigen::VectorXd::Zero(rig.shape_count());
    solver->solve_with_weights(w, markers_of(rig.neutral, layout), present, out);
    INFO(kSolverMethods.name(method));
    CHECK(max_error(out.vertices, rig.neutral) < 1e-5);
    for (Eigen::Index s = 0; s < rig.shape_count(); ++s) {
      w.setZero();
      w[s] = 1.0;
      const Eigen::Matrix3Xd shape = rig.shape_positions(s);
      solver->solve_with_weights(w, markers_of(shape, layout), present, out);
      INFO(rig.shape_names[std::size_t(s)]);
      CHECK(max_error(out.vertices, shape) < 1e-5);
    }
  }
}

// The same on a real rig: ICT's shapes turn triangles by up to pi, and its Eq. 3 terms are
// stored as 16-bit fixed point; both must stay within 1e-5 cm of each shape.
TEST_CASE("nonlinear and dt reproduce every ICT FaceKit shape within 1e-5 cm") {
  FACECAP_REQUIRE_SHARED_DATA(dir, "ict-face");
  const Rig rig = load_rig(dir.string());
  const auto layout = spread_marker_layout(rig, 60);
  SolverParams params;
  params.collision_region = CollisionRegion::kNone;  // the shapes themselves have lip contacts
  const auto model = build_solver_model(rig, layout, params);
  for (const SolverMethod method : {SolverMethod::kNonlinear, SolverMethod::kDt}) {
    auto solver = make_solver(method, model);
    SolveResult out = solver->make_result();
    Eigen::VectorXd w = Eigen::VectorXd::Zero(rig.shape_count());
    double worst = 0.0;
    std::string worst_shape;
    for (Eigen::Index s = 0; s < rig.shape_count(); ++s) {
      w.setZero();
      w[s] = 1.0;
      const Eigen::Matrix3Xd shape = rig.shape_positions(s);
      solver->solve_with_weights(w, markers_of(shape, layout), all_present(60), out);
      const double error = max_error(out.vertices, shape);
      if (error > worst) { worst = error; worst_shape = rig.shape_names[std::size_t(s)]; }
    }
    INFO(kSolverMethods.name(method) << ": largest error " << worst << " cm, on " << worst_shape);
    CHECK(worst < 1e-5);
  }
}

// Deformation transfer is linear in the weights, so a mix of small weights must equal
// the same mix of the single-shape solves: the blend's stored terms and its float sums
// stay within the tolerance however the weights are spread.
TEST_CASE("dt with small ICT FaceKit weights equals the mix of single-shape solves within 1e-5 cm") {
  FACECAP_REQUIRE_SHARED_DATA(dir, "ict-face");
  const Rig rig = load_rig(dir.string());
  const auto layout = spread_marker_layout(rig, 60);
  SolverParams params;
  params.collision_region = CollisionRegion::kNone;
  params.negligible_displacement_mm = 0.0;  // every small weight blended: the mix must be exact
  params.fold_max_pins = 0;                 // the blend alone
  const auto model = build_solver_model(rig, layout, params);
  auto solver = make_solver(SolverMethod::kDt, model);
  SolveResult out = solver->make_result();
  const Eigen::Index M = rig.shape_count();
  Eigen::VectorXd w = Eigen::VectorXd::Zero(M);
  solver->solve_with_weights(w, markers_of(rig.neutral, layout), all_present(60), out);
  const Eigen::Matrix3Xd rest = out.vertices;
  auto single = std::vector<Eigen::Matrix3Xd>(std::size_t(M));
  for (Eigen::Index s = 0; s < M; ++s) {
    w.setZero();
    w[s] = 1.0;
    solver->solve_with_weights(w, markers_of(rig.shape_positions(s), layout), all_present(60), out);
    single[std::size_t(s)] = out.vertices - rest;
  }
  std::mt19937 rng(11);
  std::uniform_real_distribution<double> small(0.0, 0.05);
  double worst = 0.0;
  for (int mix = 0; mix < 5; ++mix) {
    for (Eigen::Index s = 0; s < M; ++s) w[s] = small(rng);
    Eigen::Matrix3Xd expected = rest;
    for (Eigen::Index s = 0; s < M; ++s) expected += w[s] * single[std::size_t(s)];
    solver->solve_with_weights(w, markers_of(rig.linear_blend(w), layout), all_present(60), out);
    worst = std::max(worst, max_error(out.vertices, expected));
  }
  INFO("largest difference " << worst << " cm");
  CHECK(worst < 1e-5);
}

TEST_CASE("a missing marker gives the same mesh as a layout without it") {
  const Rig& rig = BuiltinFace::instance().rig();
  const auto layout = spread_marker_layout(rig, 40);
  auto without = layout;
  without.erase(without.begin() + 7);
  without.erase(without.begin() + 20);
  const auto full_model = build_solver_model(rig, layout);
  const auto small_model = build_solver_model(rig, without);
  Eigen::VectorXd w = BuiltinFace::instance().motion_weights(1.3);
  const Eigen::Matrix3Xd pose = BuiltinFace::instance().articulated_pose(w);
  auto present = all_present(40);
  present[7] = present[21] = 0;
  for (const SolverMethod method : {SolverMethod::kNonlinear, SolverMethod::kDt}) {
    auto a = make_solver(method, full_model);
    auto b = make_solver(method, small_model);
    SolveResult ra = a->make_result(), rb = b->make_result();
    Eigen::Matrix3Xd targets = markers_of(pose, layout);
    targets.col(7).setConstant(std::numeric_limits<double>::quiet_NaN());
    a->solve(targets, present, ra);
    b->solve(markers_of(pose, without), all_present(38), rb);
    INFO(kSolverMethods.name(method));
    CHECK(ra.markers_used == 38);
    CHECK((ra.weights - rb.weights).cwiseAbs().maxCoeff() < 1e-9);
    CHECK(max_error(ra.vertices, rb.vertices) < 1e-8);
  }
}

TEST_CASE("pinned vertices end near their targets") {
  const Rig& rig = BuiltinFace::instance().rig();
  const auto layout = spread_marker_layout(rig, 60);
  const auto model = build_solver_model(rig, layout);
  auto solver = make_solver(SolverMethod::kNonlinear, model);
  SolveResult out = solver->make_result();
  // Targets 2 mm off the neutral at every marker, in alternating directions.
  Eigen::Matrix3Xd targets = markers_of(rig.neutral, layout);
  for (Eigen::Index k = 0; k < targets.cols(); ++k) targets(2, k) += (k % 2 ? 0.2 : -0.2);
  solver->solve_with_weights(Eigen::VectorXd::Zero(rig.shape_count()), targets, all_present(60), out);
  const Eigen::Matrix3Xd reached = markers_of(out.vertices, layout);
  INFO("max pin residual " << max_error(reached, targets) << " cm");
  CHECK(max_error(reached, targets) < 0.02);  // beta = 100 holds pins within 0.2 mm
}

TEST_CASE("nonlinear with weight refinements matches the articulated jaw better than linear") {
  const BuiltinFace& face = BuiltinFace::instance();
  const Rig& rig = face.rig();
  const auto layout = spread_marker_layout(rig, 60);
  SolverParams refined;
  // The built-in face's own choice (kByRig, it is hinged), given here since the test is
  // about them: two refinements, and the outer edge free, which runs under the chin the jaw
  // swings (held to the linear blend, it triples this error).
  refined.weight_refinements = 2;
  refined.boundary_hold = 0.0;
  const auto model = build_solver_model(rig, layout, refined);
  Eigen::VectorXd w = Eigen::VectorXd::Zero(rig.shape_count());
  w[*rig.shape_index("jawOpen")] = 0.5;
  const Eigen::Matrix3Xd truth = face.articulated_pose(w);
  const Eigen::Matrix3Xd targets = markers_of(truth, layout);
  double error[2];
  int i = 0;
  for (const SolverMethod method : {SolverMethod::kNonlinear, SolverMethod::kLinear}) {
    auto solver = make_solver(method, model);
    SolveResult out = solver->make_result();
    solver->solve(targets, all_present(60), out);
    error[i++] = mean_error(out.vertices, truth);
  }
  INFO("mean vertex error: nonlinear " << error[0] * 10 << " mm, linear " << error[1] * 10 << " mm");
  CHECK(error[0] < 0.5 * error[1]);
  CHECK(error[0] < 0.03);  // under 0.3 mm
}

TEST_CASE("too few markers hold the previous result and unknown solvers are rejected") {
  const Rig& rig = BuiltinFace::instance().rig();
  const auto layout = spread_marker_layout(rig, 10);
  const auto model = build_solver_model(rig, layout);
  auto solver = make_solver(SolverMethod::kNonlinear, model);
  SolveResult out = solver->make_result();
  std::vector<uint8_t> present(10, 0);
  present[0] = present[1] = 1;
  solver->solve(markers_of(rig.neutral, layout), present, out);
  CHECK(out.status == kSolvedTooFewMarkers);
  CHECK_THROWS_WITH(parse_solver_method("magic"), Catch::Contains("unknown solver 'magic': choose nonlinear, linear, dt, meshik"));
  CHECK_THROWS_WITH(build_solver_model(rig, {MarkerBinding::at_vertex("bad", 1 << 30)}), Catch::Contains("marker 'bad'"));
  SolverParams too_many;
  too_many.collision_max_pins = 2000;
  CHECK_THROWS_WITH(build_solver_model(rig, layout, too_many), Catch::Contains("collision_max_pins 2000 is not in [0, 1024]"));
}

TEST_CASE("half floats decode exactly and half_at_least gives the smallest half not below x") {
  CHECK(half_to_float(0x3c00) == 1.0f);
  CHECK(half_to_float(0x0001) == std::ldexp(1.0f, -24));  // smallest subnormal
  CHECK(half_to_float(0x0400) == std::ldexp(1.0f, -14));  // smallest normal
  CHECK(half_to_float(0x7bff) == 65504.0f);
  CHECK(half_to_float(0xc000) == -2.0f);
  CHECK(half_at_least(32768.0f) == 0x7800);  // BlendTerms' float entries: scale 1 in units of 2^-15
  std::mt19937 rng(5);
  std::uniform_real_distribution<float> exponent(-26.0f, 15.9f);
  for (int i = 0; i < 2000; ++i) {
    const float x = std::exp2(exponent(rng));
    const uint16_t h = half_at_least(x);
    INFO("x " << x << " half " << h);
    CHECK(half_to_float(h) >= x);
    if (h > 0) CHECK(half_to_float(uint16_t(h - 1)) < x);
    if (x >= std::ldexp(1.0f, -14)) CHECK(half_to_float(h) <= x * (1.0f + std::ldexp(1.0f, -10)));  // normal: 10-bit mantissa
  }
}

TEST_CASE("the Poisson solvers stream their blend's terms and operators, the linear solver nothing") {
  const Rig& rig = BuiltinFace::instance().rig();
  const auto model = build_solver_model(rig, spread_marker_layout(rig, 60));
  const std::size_t operators = std::size_t(model->blend.triangle_blocks.block_count()) * 9 * ShapeBlocks::kBlock * sizeof(float);
  auto bytes_of = [](const BlendTerms& t) {
    return t.values.size() + t.scales.size() * sizeof(uint16_t) + t.offsets.size() * sizeof(float);
  };
  auto streamed = [&](SolverMethod method) {
    const auto solver = make_solver(method, model);
    std::size_t total = 0;
    for (const auto range : solver->streamed_memory()) total += range.size();
    return total;
  };
  CHECK(streamed(SolverMethod::kNonlinear) == bytes_of(model->blend.triangle_nonlinear) + operators);
  CHECK(streamed(SolverMethod::kDt) == bytes_of(model->blend.triangle_gradient) + operators);
  CHECK(streamed(SolverMethod::kLinear) == 0);
  CHECK(bytes_of(model->blend.triangle_nonlinear) > 1'000'000);  // megabytes: more than a core's L2 keeps
}

#include "tests/alloc_counter.hpp"

TEST_CASE("solving a frame allocates nothing even with dropouts and NaN markers") {
  const BuiltinFace& face = BuiltinFace::instance();
  const Rig& rig = face.rig();
  const auto layout = spread_marker_layout(rig, 60);
  const auto model = build_solver_model(rig, layout);
  for (const SolverMethod method : {SolverMethod::kNonlinear, SolverMethod::kLinear, SolverMethod::kDt}) {
    auto solver = make_solver(method, model);
    SolveResult out = solver->make_result();
    auto present = all_present(60);
    std::vector<Eigen::Matrix3Xd> frames;
    for (int f = 0; f < 30; ++f) frames.push_back(markers_of(face.articulated_pose(face.motion_weights(f * 0.05)), layout));
    frames[5].col(3).setConstant(std::numeric_limits<double>::quiet_NaN());
    int64_t allocations = 0;
    {
      test::CountAllocations counter;
      for (int f = 0; f < 30; ++f) {
        present[std::size_t(f % 60)] = f % 3 ? 1 : 0;  // some frames lose a marker
        solver->solve(frames[std::size_t(f)], present, out);
      }
      allocations = counter.count();
    }
    INFO(kSolverMethods.name(method));
    CHECK(allocations == 0);
    CHECK(out.status == 0);
  }
  // The counter itself works.
  test::CountAllocations counter;
  std::vector<int> v(100);
  CHECK(counter.count() >= 1);
}

#include "solver/collide/metrics.hpp"

TEST_CASE("collision handling removes the lip intersections the nonlinear blend makes") {
  const Rig& rig = BuiltinFace::instance().rig();
  const auto layout = spread_marker_layout(rig, 60);
  SolverParams without;
  without.collision_region = CollisionRegion::kNone;
  auto handled = make_solver(SolverMethod::kNonlinear, build_solver_model(rig, layout));
  auto unhandled = make_solver(SolverMethod::kNonlinear, build_solver_model(rig, layout, without));
  Eigen::VectorXd w = Eigen::VectorXd::Zero(rig.shape_count());
  w[*rig.shape_index("mouthPucker")] = 1.0;
  w[*rig.shape_index("mouthClose")] = 1.0;
  const Eigen::Matrix3Xd targets = markers_of(rig.linear_blend(w), layout);
  SolveResult a = handled->make_result(), b = unhandled->make_result();
  handled->solve_with_weights(w, targets, all_present(60), a);
  unhandled->solve_with_weights(w, targets, all_present(60), b);
  const int64_t before = count_intersecting_pairs(rig.triangles, b.vertices);
  const int64_t after = count_intersecting_pairs(rig.triangles, a.vertices);
  INFO("intersecting pairs without handling " << before << ", with " << after << "; pins " << a.collision_constraints);
  CHECK(count_intersecting_pairs(rig.triangles, rig.linear_blend(w)) == 0);  // the blend itself is clean
  CHECK(before > 10);
  CHECK(after == 0);
  CHECK(a.collision_pairs > 0);
  CHECK(a.collision_constraints > 0);
  CHECK(b.collision_constraints == 0);
}

TEST_CASE("whole-face collision handling solves its pins per frame and removes the built-in lip crossings") {
  const Rig& rig = BuiltinFace::instance().rig();
  const auto layout = spread_marker_layout(rig, 60);
  SolverParams face;
  face.collision_region = CollisionRegion::kFace;  // too many vertices to precompute columns for
  const auto model = build_solver_model(rig, layout, face);
  REQUIRE_FALSE(model->pin_columns_precomputed());
  auto solver = make_solver(SolverMethod::kNonlinear, model);
  Eigen::VectorXd w = Eigen::VectorXd::Zero(rig.shape_count());
  w[*rig.shape_index("mouthPucker")] = 1.0;
  w[*rig.shape_index("mouthClose")] = 1.0;
  SolveResult out = solver->make_result();
  solver->solve_with_weights(w, markers_of(rig.linear_blend(w), layout), all_present(60), out);
  INFO("pins " << out.collision_constraints << ", pairs " << out.collision_pairs);
  CHECK(out.collision_constraints > 0);
  CHECK(count_intersecting_pairs(rig.triangles, out.vertices) == 0);
}

// An ICT FaceKit pose solved by the non-linear solver with and without collision
// handling, for the lip-pose tests below.
struct LipPoseSolves {
  using Pose = std::vector<std::pair<const char*, double>>;
  // The collision stage alone: the fold stage, which also undoes crossings, is off in both
  // (test_folds covers it).
  explicit LipPoseSolves(const Rig& rig_, SolverParams params = {})
      : rig(rig_), layout(spread_marker_layout(rig, 60)) {
    params.fold_max_pins = 0;
    SolverParams without = params;
    without.collision_region = CollisionRegion::kNone;
    model = build_solver_model(rig, layout, params);
    handled = make_solver(SolverMethod::kNonlinear, model);
    unhandled = make_solver(SolverMethod::kNonlinear, build_solver_model(rig, layout, without));
    with_handling = handled->make_result();
    without_handling = unhandled->make_result();
  }
  // Solves `pose` (shape, weight) both ways, with marker targets on its linear blend.
  // Returns the pose's name, "shape=weight ...".
  std::string solve(const Pose& pose) {
    Eigen::VectorXd w = Eigen::VectorXd::Zero(rig.shape_count());
    std::string name;
    for (const auto& [shape, value] : pose) {
      w[*rig.shape_index(shape)] = value;
      name += fmt::format("{}={} ", shape, value);
    }
    linear = rig.linear_blend(w);
    const Eigen::Matrix3Xd targets = markers_of(linear, layout);
    handled->solve_with_weights(w, targets, all_present(60), with_handling);
    unhandled->solve_with_weights(w, targets, all_present(60), without_handling);
    return name;
  }
  int64_t new_crossings(const Eigen::Matrix3Xd& positions) const {
    return count_new_intersecting_pairs(rig.triangles, rig.neutral, positions);
  }
  const Rig& rig;
  std::vector<MarkerBinding> layout;
  std::shared_ptr<const SolverModel> model;
  std::unique_ptr<FaceSolver> handled, unhandled;
  SolveResult with_handling, without_handling;
  Eigen::Matrix3Xd linear;  // the last pose's linear blend
};

// ICT FaceKit poses where the non-linear blend crosses at the lips and the linear blend,
// the collision stage's reference, does not. Found by a search over 350 random mixes of
// two or three jaw* and mouth* shapes at weights 0.25..1: 41 such poses, 40 of which end
// with zero new crossings. The 41st (jawOpen=1 mouthPress_L=0.5 mouthShrugLower=1,
// 241 -> 15) needs 100 pins, more than a frame's 64.
TEST_CASE("ICT FaceKit poses whose linear blend is clean: collision handling leaves no lip crossings") {
  FACECAP_REQUIRE_SHARED_DATA(dir, "ict-face");
  const Rig rig = load_rig(dir.string());
  LipPoseSolves solves(rig);
  const std::vector<LipPoseSolves::Pose> poses{
      {{"jawOpen", 1.0}, {"mouthPress_R", 0.5}, {"mouthShrugLower", 0.5}},
      {{"jawForward", 0.75}, {"jawOpen", 0.75}},
      {{"jawOpen", 0.5}, {"mouthPucker", 1.0}, {"mouthRollLower", 0.75}},
      {{"mouthLeft", 0.5}, {"mouthPress_L", 0.5}, {"mouthUpperUp_L", 0.25}},
      {{"jawOpen", 0.5}, {"mouthShrugLower", 0.5}, {"mouthSmile_L", 0.5}},
      {{"jawLeft", 1.0}, {"jawOpen", 0.75}},
      {{"jawLeft", 0.75}, {"jawOpen", 0.5}, {"mouthRollUpper", 0.5}},
      {{"jawOpen", 1.0}, {"mouthFunnel", 0.5}, {"mouthPucker", 0.5}},
      {{"jawOpen", 0.25}, {"mouthRollLower", 0.75}},
      {{"jawOpen", 0.75}, {"mouthPress_R", 0.5}, {"mouthRollUpper", 0.5}},
  };
  std::string table = "ICT new intersecting pairs, nonlinear without -> with handling (the linear blend has none):\n";
  for (const auto& pose : poses) {
    const std::string name = solves.solve(pose);
    const int64_t before = solves.new_crossings(solves.without_handling.vertices);
    const int64_t after = solves.new_crossings(solves.with_handling.vertices);
    table += fmt::format("  {}: {} -> {} ({} pins)\n", name, before, after, solves.with_handling.collision_constraints);
    INFO(name);
    CHECK(solves.new_crossings(solves.linear) == 0);
    CHECK(before > 0);
    CHECK(after == 0);
  }
  WARN(table);
}

TEST_CASE("a lip pose that needs more than 64 pins ends with no crossings at collision_max_pins 128") {
  FACECAP_REQUIRE_SHARED_DATA(dir, "ict-face");
  const Rig rig = load_rig(dir.string());
  const LipPoseSolves::Pose pose{{"jawOpen", 1.0}, {"mouthPress_L", 0.5}, {"mouthShrugLower", 1.0}};
  LipPoseSolves by_default(rig);
  by_default.solve(pose);
  SolverParams more;
  more.collision_max_pins = 128;
  LipPoseSolves with_more(rig, more);
  with_more.solve(pose);
  const int64_t before = by_default.new_crossings(by_default.without_handling.vertices);
  const int64_t at_64 = by_default.new_crossings(by_default.with_handling.vertices);
  const int64_t at_128 = with_more.new_crossings(with_more.with_handling.vertices);
  WARN(fmt::format("{} new crossing pairs without handling, {} with 64 pins, {} with {} of 128", before, at_64, at_128,
                   with_more.with_handling.collision_constraints));
  CHECK(with_more.new_crossings(with_more.linear) == 0);
  CHECK(by_default.with_handling.collision_constraints == 64);
  CHECK(at_64 > 0);
  CHECK(with_more.with_handling.collision_constraints > 64);
  CHECK(at_128 == 0);
}

// ICT FaceKit's own shapes cross at the lips in these poses (its linear blend does, and
// most of the crossing pairs reach beyond the lip region into the mouth), so zero
// crossings is out of reach of pins to the linear blend: handling moves the solve
// towards the linear blend's count. The stage must still not make things worse overall,
// nor move the face far from the lips. The counts are printed for the record.
TEST_CASE("ICT FaceKit lip poses with and without collision handling") {
  FACECAP_REQUIRE_SHARED_DATA(dir, "ict-face");
  const Rig rig = load_rig(dir.string());
  LipPoseSolves solves(rig);
  std::vector<uint8_t> lip_region(std::size_t(rig.vertex_count()), 0);
  for (const int v : solves.model->collision.vertices) lip_region[std::size_t(v)] = 1;
  const std::vector<LipPoseSolves::Pose> poses{
      {{"mouthClose", 1.0}},
      {{"jawOpen", 0.3}, {"mouthClose", 1.0}},
      {{"mouthPress_L", 1.0}},
      {{"mouthRollLower", 1.0}, {"mouthRollUpper", 1.0}},
      {{"jawOpen", 0.15}, {"mouthPucker", 1.0}},
  };
  int64_t total_before = 0, total_after = 0;
  std::string table = "ICT new intersecting pairs (linear blend; nonlinear without -> with handling):\n";
  for (const auto& pose : poses) {
    const std::string name = solves.solve(pose);
    const SolveResult& a = solves.with_handling;
    const SolveResult& b = solves.without_handling;
    const int64_t reference = solves.new_crossings(solves.linear);
    const int64_t before = solves.new_crossings(b.vertices);
    const int64_t after = solves.new_crossings(a.vertices);
    double far_move = 0;  // largest move outside the lip region
    for (Eigen::Index v = 0; v < rig.vertex_count(); ++v)
      if (!lip_region[std::size_t(v)]) far_move = std::max(far_move, (a.vertices.col(v) - b.vertices.col(v)).norm());
    table += fmt::format("  {}: {}; {} -> {} ({} pairs closer than epsilon, {} pins, {:.3f} mm moved outside the lips)\n",
                         name, reference, before, after, a.collision_pairs, a.collision_constraints, 10 * far_move);
    total_before += before;
    total_after += after;
    INFO(name);
    CHECK(before > 0);      // every pose here crosses at the lips without handling
    CHECK(far_move < 0.2);  // under 2 mm away from the lips (measured: up to 1.6 mm)
  }
  table += fmt::format("  total {} -> {}\n", total_before, total_after);
  WARN(table);
  CHECK(total_after <= total_before);
}

// A path graph's Laplacian plus a diagonal: factored with both row-index widths (16-bit
// up to 65,536 rows, 32-bit beyond), the solves of every kernel path this CPU runs must
// match Eigen's own LDL^T.
TEST_CASE("SparseLdlt solves match Eigen's with 16-bit and 32-bit row indices") {
  for (const auto& [n, path] : [] {
         std::vector<std::pair<Eigen::Index, KernelPath>> cases;
         for (const KernelPath p : facecap::test::runnable_kernel_paths())
           for (const Eigen::Index size : {Eigen::Index(1000), Eigen::Index(70000)}) cases.push_back({size, p});
         return cases;
       }()) {
    INFO("kernels " << kKernelPaths.name(path) << ", " << n << " rows");
    std::vector<Eigen::Triplet<double>> entries;
    for (Eigen::Index i = 0; i < n; ++i) {
      entries.emplace_back(i, i, 2.0 + 0.01 * double(i % 7));
      if (i + 1 < n) entries.emplace_back(i, i + 1, -1.0), entries.emplace_back(i + 1, i, -1.0);
      if (i + 97 < n) entries.emplace_back(i, i + 97, -0.5), entries.emplace_back(i + 97, i, -0.5);
    }
    Eigen::SparseMatrix<double> A(n, n);
    A.setFromTriplets(entries.begin(), entries.end());
    for (Eigen::Index i = 0; i < n; ++i) A.coeffRef(i, i) += 1.0;  // diagonally dominant
    const facecap::SparseLdlt factor(A, facecap::kernels::table(path));
    Eigen::SimplicialLDLT<Eigen::SparseMatrix<double>> reference(A);
    REQUIRE(reference.info() == Eigen::Success);

    std::mt19937 rng(7);
    std::uniform_real_distribution<double> uniform(-1.0, 1.0);
    Eigen::Matrix3Xd b(3, n);
    for (Eigen::Index i = 0; i < b.size(); ++i) b.data()[i] = uniform(rng);
    Eigen::Matrix3Xd x = b;
    Eigen::Matrix4Xd work(4, n);
    factor.solve_in_place(x, work);
    const Eigen::MatrixXd expected = reference.solve(Eigen::MatrixXd(b.transpose())).transpose();
    CHECK((x - expected).cwiseAbs().maxCoeff() < 1e-10);

    Eigen::VectorXd one = b.row(1).transpose();
    Eigen::VectorXd one_work(n);
    factor.solve_in_place(one, one_work);
    CHECK((one - expected.row(1).transpose()).cwiseAbs().maxCoeff() < 1e-10);

    // Columns of the inverse, the first, last and a middle row of A (the forward pass of
    // solve_unit starts at the row's place in the fill-reducing order).
    for (const Eigen::Index i : {Eigen::Index(0), n / 2, n - 1}) {
      Eigen::VectorXd column(n);
      factor.solve_unit(i, column, one_work);
      const Eigen::VectorXd expected_column = reference.solve(Eigen::VectorXd::Unit(n, i));
      CHECK((column - expected_column).cwiseAbs().maxCoeff() < 1e-10);
    }
  }
}

// ---- The solve's status bits (SolveResult::status, core/frame.hpp SolvedFlags) ----------

TEST_CASE("a normal frame raises no status bit; too few markers raise kSolvedTooFewMarkers alone") {
  const BuiltinFace& face = BuiltinFace::instance();
  const Rig& rig = face.rig();
  const auto layout = spread_marker_layout(rig, 60);
  const auto model = build_solver_model(rig, layout);
  const Eigen::Matrix3Xd targets = markers_of(face.articulated_pose(face.motion_weights(0.8)), layout);
  std::vector<uint8_t> three(60, 0);
  three[0] = three[1] = three[2] = 1;
  std::vector<uint8_t> two = three;
  two[2] = 0;
  for (const SolverMethod method : {SolverMethod::kNonlinear, SolverMethod::kLinear, SolverMethod::kDt}) {
    INFO(kSolverMethods.name(method));
    auto solver = make_solver(method, model);
    SolveResult out = solver->make_result();
    solver->solve(targets, all_present(60), out);
    CHECK(out.status == 0);
    CHECK(out.markers_used == 60);
    const Eigen::Matrix3Xd solved = out.vertices;
    solver->solve(targets, two, out);
    CHECK(out.status == kSolvedTooFewMarkers);
    CHECK(out.vertices == solved);  // the previous face is kept
    solver->solve(targets, three, out);
    CHECK((out.status & kSolvedTooFewMarkers) == 0);
    CHECK(out.markers_used == 3);
  }
}

TEST_CASE("Eq. 2's box QP stopped at an iteration cap of 1 raises kSolvedQpIterationCap") {
  const BuiltinFace& face = BuiltinFace::instance();
  const Rig& rig = face.rig();
  const auto layout = spread_marker_layout(rig, 60);
  SolverParams capped;
  capped.weight_qp_iteration_cap = 1;
  const auto model = build_solver_model(rig, layout);
  const auto capped_model = build_solver_model(rig, layout, capped);
  const Eigen::Matrix3Xd targets = markers_of(face.articulated_pose(face.motion_weights(1.3)), layout);
  for (const SolverMethod method : {SolverMethod::kNonlinear, SolverMethod::kLinear, SolverMethod::kDt}) {
    INFO(kSolverMethods.name(method));
    auto solver = make_solver(method, model);
    auto capped_solver = make_solver(method, capped_model);
    SolveResult out = solver->make_result(), capped_out = capped_solver->make_result();
    solver->solve(targets, all_present(60), out);
    capped_solver->solve(targets, all_present(60), capped_out);
    CHECK(out.status == 0);
    CHECK(capped_out.status == kSolvedQpIterationCap);
    // What it keeps is feasible, just not the optimum.
    CHECK(capped_out.weights.minCoeff() >= 0.0);
    CHECK(capped_out.weights.maxCoeff() <= 1.0);
    CHECK((capped_out.weights - out.weights).cwiseAbs().maxCoeff() > 1e-6);
  }
  SolverParams negative;
  negative.weight_qp_iteration_cap = -1;
  CHECK_THROWS_WITH(build_solver_model(rig, layout, negative), Catch::Contains("weight_qp_iteration_cap -1 must be >= 0"));
}

TEST_CASE("a colliding pose that wants more pins than collision_max_pins raises kSolvedPinsBeyondCapacity") {
  const Rig& rig = BuiltinFace::instance().rig();
  const auto layout = spread_marker_layout(rig, 60);
  Eigen::VectorXd w = Eigen::VectorXd::Zero(rig.shape_count());
  w[*rig.shape_index("mouthPucker")] = 1.0;
  w[*rig.shape_index("mouthClose")] = 1.0;
  const Eigen::Matrix3Xd targets = markers_of(rig.linear_blend(w), layout);
  SolverParams few;
  few.collision_max_pins = 4;
  auto by_default = make_solver(SolverMethod::kNonlinear, build_solver_model(rig, layout));
  auto limited = make_solver(SolverMethod::kNonlinear, build_solver_model(rig, layout, few));
  SolveResult a = by_default->make_result(), b = limited->make_result();
  by_default->solve_with_weights(w, targets, all_present(60), a);
  limited->solve_with_weights(w, targets, all_present(60), b);
  INFO("pins: " << a.collision_constraints << " by default, " << b.collision_constraints << " at most 4");
  CHECK(a.collision_constraints > 4);
  CHECK(a.collision_constraints < 64);
  CHECK(a.status == 0);
  CHECK(b.collision_constraints == 4);
  CHECK(b.status == kSolvedPinsBeyondCapacity);
  // The same capacity on a pose that needs none: no flag.
  limited->solve_with_weights(Eigen::VectorXd::Zero(rig.shape_count()), markers_of(rig.neutral, layout), all_present(60), b);
  CHECK(b.collision_constraints == 0);
  CHECK(b.status == 0);
}

// A marker on a vertex no triangle uses: that vertex is held by the marker alone, so the
// marker dropping out leaves Eq. 5 singular there and its low-rank correction with it.
TEST_CASE("a missing marker whose vertex nothing else holds raises kSolvedSingularCorrection") {
  Rig rig = BuiltinFace::instance().rig();
  auto layout = spread_marker_layout(rig, 60);
  const Eigen::Index stray = rig.vertex_count();
  rig.neutral.conservativeResize(3, stray + 1);
  rig.neutral.col(stray) = rig.neutral.rowwise().mean();
  rig.deltas.conservativeResize(3 * (stray + 1), rig.shape_count());
  rig.deltas.bottomRows(3).setZero();
  layout.push_back(MarkerBinding::at_vertex("stray", int(stray)));
  const auto model = build_solver_model(rig, layout);
  const Eigen::Matrix3Xd targets = markers_of(rig.neutral, layout);
  auto present = all_present(61);
  for (const SolverMethod method : {SolverMethod::kNonlinear, SolverMethod::kDt}) {
    INFO(kSolverMethods.name(method));
    auto solver = make_solver(method, model);
    SolveResult out = solver->make_result();
    present[60] = 1;
    solver->solve(targets, present, out);
    CHECK(out.status == 0);
    present[60] = 0;
    solver->solve(targets, present, out);
    CHECK(out.status == kSolvedSingularCorrection);
    // Another marker missing instead: a regular correction.
    present[60] = 1;
    present[10] = 0;
    solver->solve(targets, present, out);
    CHECK(out.status == 0);
    present[10] = 1;
  }
}

// ---- The parameter tables (solver/params.hpp) ------------------------------------------

TEST_CASE("solver methods and collision regions parse and print from one table") {
  std::vector<std::string_view> names;
  for (const auto& entry : kSolverMethods.entries()) {
    names.push_back(entry.name);
    CHECK(kSolverMethods.parse(entry.name) == entry.value);
    CHECK(parse_solver_method(entry.name) == entry.value);
    CHECK_FALSE(entry.description.empty());
  }
  CHECK(names == std::vector<std::string_view>{"nonlinear", "linear", "dt", "meshik"});
  CHECK(solver_method_is_realtime(SolverMethod::kNonlinear));
  CHECK(solver_method_is_realtime(SolverMethod::kLinear));
  CHECK(solver_method_is_realtime(SolverMethod::kDt));
  CHECK_FALSE(solver_method_is_realtime(SolverMethod::kMeshik));
  CHECK_THROWS_WITH(parse_solver_method("Nonlinear"), Catch::Contains("unknown solver 'Nonlinear': choose nonlinear, linear, dt, meshik"));

  names.clear();
  for (const auto& entry : kCollisionRegions.entries()) {
    names.push_back(entry.name);
    CHECK(parse_collision_region(entry.name) == entry.value);
    CHECK_FALSE(entry.description.empty());
  }
  CHECK(names == std::vector<std::string_view>{"none", "lips", "face"});
  CHECK_THROWS_WITH(parse_collision_region("mouth"), Catch::Contains("unknown collision region 'mouth': choose none, lips, face"));

  // Every solver calls itself by its table name.
  const Rig& rig = BuiltinFace::instance().rig();
  const auto model = build_solver_model(rig, spread_marker_layout(rig, 20));
  for (const auto& entry : kSolverMethods.entries()) CHECK(make_solver(entry.value, model)->name() == entry.name);
}

TEST_CASE("Shapes left out of the weight fit stay at exactly 0 and the rest still fit") {
  const BuiltinFace& face = BuiltinFace::instance();
  const Rig& rig = face.rig();
  const auto layout = spread_marker_layout(rig, 60);
  const Eigen::Index jaw = *rig.shape_index("jawOpen");
  const std::string left_out = rig.shape_names[std::size_t(jaw == 0 ? 1 : 0)];
  Eigen::VectorXd w = Eigen::VectorXd::Zero(rig.shape_count());
  w[jaw] = 0.5;
  w[*rig.shape_index(left_out)] = 0.8;  // present in the pose, but the fit may not use it
  const Eigen::Matrix3Xd targets = markers_of(rig.linear_blend(w), layout);
  const auto model = build_solver_model(rig, layout, SolverParams{}, {left_out});
  CHECK(model->weights.fitted[std::size_t(*rig.shape_index(left_out))] == 0);
  for (const SolverMethod method : {SolverMethod::kNonlinear, SolverMethod::kLinear, SolverMethod::kDt}) {
    INFO(kSolverMethods.name(method));
    auto solver = make_solver(method, model);
    SolveResult out = solver->make_result();
    for (int frame = 0; frame < 3; ++frame) solver->solve(targets, all_present(60), out);
    CHECK(out.weights[*rig.shape_index(left_out)] == 0.0);
    CHECK(out.weights[jaw] > 0.3);
  }
  CHECK_THROWS_WITH(build_solver_model(rig, layout, SolverParams{}, {"noSuchShape"}),
                    Catch::Contains("shape 'noSuchShape' to leave out of the weight fit"));
}

TEST_CASE("the outer boundary is a mesh's longest run of open edges, not a hole in it") {
  // A 4 x 4 grid of quads (5 x 5 vertices) with its centre quad cut out: a 16-vertex outer
  // edge and a 4-vertex hole.
  std::vector<Eigen::Vector3i> triangles;
  Eigen::Matrix3Xd vertices(3, 25);
  for (int y = 0; y < 5; ++y)
    for (int x = 0; x < 5; ++x) vertices.col(5 * y + x) = Eigen::Vector3d(x, y, 0.0);
  for (int y = 0; y < 4; ++y)
    for (int x = 0; x < 4; ++x) {
      if ((x == 1 || x == 2) && (y == 1 || y == 2) && !(x == 1 && y == 1)) continue;  // the hole: 3 quads
      const int a = 5 * y + x;
      triangles.emplace_back(a, a + 1, a + 6);
      triangles.emplace_back(a, a + 6, a + 5);
    }
  Eigen::Matrix3Xi T(3, Eigen::Index(triangles.size()));
  for (std::size_t t = 0; t < triangles.size(); ++t) T.col(Eigen::Index(t)) = triangles[t];
  std::vector<int> perimeter;
  for (int v = 0; v < 25; ++v)
    if (v % 5 == 0 || v % 5 == 4 || v / 5 == 0 || v / 5 == 4) perimeter.push_back(v);
  CHECK(boundary_edges(T).size() == 16 + 8);  // the hole's edge: 8 edges around 3 quads
  CHECK(outer_boundary_vertices(T, vertices) == perimeter);

  Eigen::Matrix3Xi tetrahedron(3, 4);
  tetrahedron << 0, 0, 0, 1, 1, 2, 3, 2, 2, 3, 1, 3;
  CHECK(boundary_edges(tetrahedron).empty());
  CHECK(outer_boundary_vertices(tetrahedron, Eigen::Matrix3Xd::Random(3, 4)).empty());
}

// SolverParams::boundary_hold: a pinned solve moves the outer edge as the triangles
// around it say; held, it follows the rig's linear blend of the same weights.
TEST_CASE("held strongly, the outer edge of nonlinear, dt and meshik solves lies on the linear blend") {
  const Rig& rig = BuiltinFace::instance().rig();
  const auto layout = spread_marker_layout(rig, 60);
  Eigen::VectorXd w = Eigen::VectorXd::Constant(rig.shape_count(), 0.4);
  const Eigen::Matrix3Xd blend = rig.linear_blend(w);
  // Markers off the blend, as real ones are (noise, a face that is not the rig's): the
  // pinned solve carries their offsets out to the edge.
  std::mt19937 random(7);
  std::uniform_real_distribution<double> offset(-0.1, 0.1);
  Eigen::Matrix3Xd targets = markers_of(blend, layout);
  for (double& c : targets.reshaped()) c += offset(random);
  SolverParams free_edge, held_edge;
  free_edge.boundary_hold = 0.0;
  held_edge.boundary_hold = 1e4;
  const auto free_model = build_solver_model(rig, layout, free_edge);
  const auto held_model = build_solver_model(rig, layout, held_edge);
  CHECK(free_model->collision.boundary_vertices.empty());
  const std::vector<int>& edge = held_model->collision.boundary_vertices;
  REQUIRE(edge.size() > 10);
  auto edge_error = [&](const Eigen::Matrix3Xd& vertices) {
    double worst = 0.0;
    for (const int v : edge) worst = std::max(worst, (vertices.col(v) - blend.col(v)).norm());
    return worst;
  };
  for (const SolverMethod method : {SolverMethod::kNonlinear, SolverMethod::kDt, SolverMethod::kMeshik}) {
    INFO(kSolverMethods.name(method));
    auto free_solver = make_solver(method, free_model), held_solver = make_solver(method, held_model);
    SolveResult free_out = free_solver->make_result(), held_out = held_solver->make_result();
    free_solver->solve_with_weights(w, targets, all_present(60), free_out);
    held_solver->solve_with_weights(w, targets, all_present(60), held_out);
    const double free_mm = edge_error(free_out.vertices), held_mm = edge_error(held_out.vertices);
    INFO("outer edge from the linear blend: free " << free_mm << ", held " << held_mm << " (rig units)");
    CHECK(free_mm > 0.01);
    CHECK(held_mm < 0.01 * free_mm);
    CHECK(mean_error(held_out.vertices, free_out.vertices) < 0.5 * free_mm);  // the rest of the face moves far less
  }
}

TEST_CASE("ICT's outer boundary is its outer edge, not its eye and mouth openings", "[data]") {
  FACECAP_REQUIRE_SHARED_DATA(dir, "ict-face");
  const Rig rig = load_rig(dir.string());
  const std::vector<int> outer = outer_boundary_vertices(rig.triangles, rig.neutral);
  std::vector<int> open;  // every vertex on an open edge
  for (const auto& [a, b] : boundary_edges(rig.triangles)) open.insert(open.end(), {a, b});
  std::sort(open.begin(), open.end());
  open.erase(std::unique(open.begin(), open.end()), open.end());
  std::vector<int> openings;  // on an open edge, not on the outer one
  std::set_difference(open.begin(), open.end(), outer.begin(), outer.end(), std::back_inserter(openings));
  const BoundingBox box = bounding_box(rig.neutral);
  double outer_top = -1e300, openings_top = -1e300;
  for (const int v : outer) outer_top = std::max(outer_top, rig.neutral(1, v));
  for (const int v : openings) openings_top = std::max(openings_top, rig.neutral(1, v));
  INFO(outer.size() << " outer edge vertices up to y " << outer_top << ", " << openings.size() << " on openings up to y "
                    << openings_top << "; the face spans y " << box.min.y() << " to " << box.max.y());
  CHECK(outer.size() == 138);
  CHECK(openings.size() == 2 * 42 + 74);  // two eyes and the mouth
  CHECK(outer_top == box.max.y());        // the forehead's top edge
  CHECK(openings_top < outer_top - 1);    // the eyes' openings are well below it (cm)
}

// Issue 20's finding, why an authored rig gets no refinements by default: fitted along the
// nonlinear blend's marker paths, its own poses (its linear blend) come back re-mixed: jawOpen 0.5 gains
// mouthLowerDown_R 0.24 and the mesh moves 2.4 mm. The plain fit gives them back.
TEST_CASE("ICT's own poses come back with their weights from the plain weight fit", "[data]") {
  FACECAP_REQUIRE_SHARED_DATA(dir, "ict-face");
  const Rig rig = load_rig(dir.string());
  const auto layout = spread_marker_layout(rig, 60);
  const double mm = 1.0 / rig_units_per_mm(rig);
  const std::vector<std::vector<std::pair<const char*, double>>> poses{
      {{"jawOpen", 0.5}}, {{"jawOpen", 0.6}, {"mouthPucker", 0.8}}, {{"mouthSmile_L", 0.7}, {"mouthSmile_R", 0.7}}};
  for (const int refinements : {0, 2}) {
    SolverParams params;
    params.weight_refinements = refinements;
    auto solver = make_solver(SolverMethod::kNonlinear, build_solver_model(rig, layout, params));
    SolveResult out = solver->make_result();
    double worst_weight = 0.0, worst_vertex_mm = 0.0;
    for (const auto& pose : poses) {
      Eigen::VectorXd w = Eigen::VectorXd::Zero(rig.shape_count());
      for (const auto& [name, weight] : pose) w[*rig.shape_index(name)] = weight;
      const Eigen::Matrix3Xd truth = rig.linear_blend(w);
      solver->reset();
      for (int frame = 0; frame < 3; ++frame) solver->solve(markers_of(truth, layout), all_present(60), out);  // alpha settles
      Eigen::Index shape = 0;
      const double weight_error = (out.weights - w).cwiseAbs().maxCoeff(&shape);
      const double vertex_mm = max_error(out.vertices, truth) * mm;
      WARN(fmt::format("weight_refinements {}, {}: largest weight error {:.3f} ({}), largest vertex error {:.2f} mm",
                       refinements, pose.front().first, weight_error, rig.shape_names[std::size_t(shape)], vertex_mm));
      worst_weight = std::max(worst_weight, weight_error);
      worst_vertex_mm = std::max(worst_vertex_mm, vertex_mm);
    }
    if (refinements == 0) {
      CHECK(worst_weight < 0.05);
      CHECK(worst_vertex_mm < 1.0);
    } else {
      CHECK(worst_weight > 0.15);  // the re-mix docs/solver.md reports; gone, the docs need rewriting
    }
  }
}

TEST_CASE("weight_refinements and boundary_hold left to the rig: 2 and a free edge when it is hinged, else 0 and 0.003") {
  const Rig& hinged = BuiltinFace::instance().rig();
  REQUIRE(hinged.hinged);
  Rig authored = hinged;
  authored.hinged = false;
  const auto layout = spread_marker_layout(hinged, 60);
  const SolverParams by_rig;
  REQUIRE(by_rig.weight_refinements == kByRig);
  REQUIRE(by_rig.boundary_hold == kByRig);
  const auto hinged_model = build_solver_model(hinged, layout, by_rig);
  CHECK(hinged_model->params.weight_refinements == 2);
  CHECK(hinged_model->params.boundary_hold == 0.0);
  CHECK(hinged_model->collision.boundary_vertices.empty());
  const auto authored_model = build_solver_model(authored, layout, by_rig);
  CHECK(authored_model->params.weight_refinements == 0);
  CHECK(authored_model->params.boundary_hold == 0.003);
  CHECK(!authored_model->collision.boundary_vertices.empty());
  SolverParams given;
  given.weight_refinements = 1;
  given.boundary_hold = 0.01;
  for (const Rig* rig : std::array<const Rig*, 2>{&hinged, &authored}) {
    const auto model = build_solver_model(*rig, layout, given);
    CHECK(model->params.weight_refinements == 1);
    CHECK(model->params.boundary_hold == 0.01);
  }
  SolverParams wrong;
  wrong.weight_refinements = -2;
  CHECK_THROWS_WITH(build_solver_model(hinged, layout, wrong), Catch::Contains("weight_refinements -2 must be >= 0, or -1"));
}
