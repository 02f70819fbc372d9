// Alignment: similarity fits, hulls, surface queries, calibration (paper Algorithm 1 from
// any capture frame), identity mismatch, head stabilisation, labelling, auto-neutral,
// calibration profiles, and clear errors on bad input. Real-data checks on AnimFace with
// the ICT face are in test_align_data.cpp.
#include <algorithm>
#include <numeric>
#include <random>

#include <catch2/catch.hpp>
#include <fmt/format.h>

#include "core/error.hpp"
#include "core/units.hpp"
#include "solver/align/calibrate.hpp"
#include "solver/align/hull.hpp"
#include "solver/align/label.hpp"
#include "pipeline/marker_mapper.hpp"
#include "solver/align/neutral.hpp"
#include "solver/align/calibrate_take.hpp"
#include "solver/align/profile.hpp"
#include "solver/align/stabilise.hpp"
#include "solver/align/surface.hpp"
#include "tests/align_test_support.hpp"
#include "tests/head_rig_check.hpp"
#include "tests/alloc_counter.hpp"
#include "tests/test_support.hpp"

using namespace facecap;
using namespace facecap::align;
using facecap::test::make_synthetic_take;
using facecap::test::SyntheticTakeOptions;

namespace {

Eigen::Matrix3Xd positions_of(const MarkerFrame& f, std::vector<uint8_t>& present) {
  Eigen::Matrix3Xd P(3, Eigen::Index(f.markers.size()));
  present.assign(f.markers.size(), 0);
  for (std::size_t k = 0; k < f.markers.size(); ++k) P.col(Eigen::Index(k)) = f.markers[k].position, present[k] = f.markers[k].present();
  return P;
}

// The calibrate command's pipeline (auto-neutral, stable markers found).
Calibration calibrate_whole_take(const Rig& rig, const std::vector<std::string>& labels, const std::vector<MarkerFrame>& frames,
                                 double rate_hz, double mm_per_unit_hint) {
  TakeCalibrationOptions o;
  o.neutral.rate_hz = rate_hz;
  o.neutral.take_mm_per_unit = mm_per_unit_hint;
  return calibrate_take(rig, labels, frames, o).calibration;
}

}  // namespace

TEST_CASE("Similarity fit recovers a scaled rotation and refuses collinear points") {
  std::mt19937 rng(3);
  std::normal_distribution<double> g;
  Eigen::Matrix3Xd src(3, 12);
  for (Eigen::Index i = 0; i < src.size(); ++i) src.data()[i] = g(rng);
  Similarity truth;
  truth.rotation = test::random_rotation(rng);
  truth.scale = 0.1;
  truth.translation = {4, -2, 7};
  const Eigen::Matrix3Xd dst = truth.apply(src);
  Similarity fit;
  REQUIRE(fit_similarity(src, dst, {}, true, fit));
  CHECK(rotation_angle(fit.rotation.transpose() * truth.rotation) < 1e-9);
  CHECK(fit.scale == Approx(0.1).epsilon(1e-12));
  CHECK((fit.translation - truth.translation).norm() < 1e-9);
  // Rigid: the best rotation is still found, scale stays 1.
  REQUIRE(fit_similarity(src, truth.apply(src) / 0.1, {}, false, fit));
  CHECK(fit.scale == 1.0);
  CHECK(rotation_angle(fit.rotation.transpose() * truth.rotation) < 1e-6);
  // Weights: a zero-weighted wild point changes nothing.
  Eigen::Matrix3Xd bad = dst;
  bad.col(0) += Eigen::Vector3d(100, 0, 0);
  std::vector<double> w(12, 1.0);
  w[0] = 0.0;
  REQUIRE(fit_similarity(src, bad, w, true, fit));
  CHECK(fit.scale == Approx(0.1).epsilon(1e-9));
  // Collinear points leave a rotation undetermined.
  Eigen::Matrix3Xd line(3, 5);
  for (int i = 0; i < 5; ++i) line.col(i) = Eigen::Vector3d(i, 2 * i, 3 * i);
  CHECK_FALSE(fit_similarity(line, line, {}, true, fit));
  // The 24 axis rotations are distinct proper rotations.
  const auto& R = axis_rotations();
  for (std::size_t i = 0; i < R.size(); ++i) {
    CHECK(R[i].determinant() == Approx(1.0));
    for (std::size_t j = 0; j < i; ++j) CHECK((R[i] - R[j]).norm() > 0.5);
  }
}

TEST_CASE("Convex hull finds the corners of a cube and rejects flat point sets") {
  std::mt19937 rng(5);
  std::uniform_real_distribution<double> u(-0.9, 0.9);
  Eigen::Matrix3Xd pts(3, 58);
  int c = 0;
  for (int x : {-1, 1})
    for (int y : {-1, 1})
      for (int z : {-1, 1}) pts.col(c++) = Eigen::Vector3d(x, y, z);
  for (; c < 58; ++c) pts.col(c) = Eigen::Vector3d(u(rng), u(rng), u(rng));
  const auto hull = convex_hull_vertices(pts);
  CHECK(hull == std::vector<int>({0, 1, 2, 3, 4, 5, 6, 7}));
  Eigen::Matrix3Xd flat = pts;
  flat.row(2).setZero();
  CHECK_THROWS_WITH(convex_hull_vertices(flat), Catch::Contains("flat or degenerate"));
  CHECK_THROWS_WITH(convex_hull_vertices(pts.leftCols(3)), Catch::Contains("at least 4"));
}

TEST_CASE("Closest surface point agrees with exhaustive search on the built-in face") {
  const Rig& rig = BuiltinFace::instance().rig();
  const SurfaceIndex surface(rig.neutral, rig.triangles);
  std::mt19937 rng(11);
  std::uniform_int_distribution<int> vertex(0, int(rig.vertex_count()) - 1);
  std::normal_distribution<double> g(0.0, 0.3);
  for (int i = 0; i < 300; ++i) {
    const Eigen::Vector3d p = rig.neutral.col(vertex(rng)) + Eigen::Vector3d(g(rng), g(rng), g(rng));
    const SurfacePoint fast = surface.closest(p), exact = surface.closest_exhaustive(p);
    INFO("query " << i);
    CHECK(fast.distance == Approx(exact.distance).margin(1e-9));
    const Eigen::Vector3d rebuilt = fast.barycentric[0] * rig.neutral.col(rig.triangles(0, fast.triangle)) +
                                    fast.barycentric[1] * rig.neutral.col(rig.triangles(1, fast.triangle)) +
                                    fast.barycentric[2] * rig.neutral.col(rig.triangles(2, fast.triangle));
    CHECK((rebuilt - fast.position).norm() < 1e-9);
  }
}

TEST_CASE("Synthetic take in any pose and units calibrates back within 1 mm") {
  const Rig& rig = BuiltinFace::instance().rig();
  double worst = 0.0;
  for (unsigned seed = 1; seed <= 6; ++seed) {
    SyntheticTakeOptions o;
    o.seed = seed;
    o.take_mm_per_unit = std::array<double, 3>{1.0, 10.0, 1000.0}[seed % 3];
    o.noise_mm = 0.3;
    o.rest_frames = 60;
    o.head_sway_deg = 3.0;
    const auto take = make_synthetic_take(o);
    // No units given: the neutral search guesses them from the face's size (as the
    // calibrate command does) and the calibration detects them from the hulls.
    std::vector<uint8_t> present;
    const auto guess = millimetres_per_unit(guess_face_units(bounding_box(positions_of(take.frames[0], present))));
    REQUIRE(guess);
    const Calibration cal = calibrate_whole_take(rig, take.labels, take.frames, 60.0, *guess);
    INFO("seed " << seed << " units " << o.take_mm_per_unit << " start " << cal.start_index);
    CHECK(cal.units_detected);
    CHECK(cal.take_mm_per_unit == o.take_mm_per_unit);
    REQUIRE(cal.markers.size() == take.layout.size());
    for (std::size_t k = 0; k < take.layout.size(); ++k) {
      const double err_mm = (cal.markers[k].bound_point - test::layout_point(take.layout[k], rig.neutral)).norm() * 10.0;
      INFO("marker " << take.labels[k] << " bound " << err_mm << " mm from the truth");
      CHECK(err_mm < 1.0);
      worst = std::max(worst, err_mm);
    }
    // The scale undoes the unit change (the rotation also holds the head's sway at the
    // calibration frame, so it is checked through the bound points above).
    const Similarity E = cal.take_to_rig * take.rig_to_take;
    CHECK(std::abs(E.scale - 1.0) < 0.01);
  }
  WARN("synthetic calibration: worst bound point " << worst << " mm from the truth (0.3 mm noise, 6 poses, mm/cm/m)");
}

TEST_CASE("A take with a head rig 40 mm off the skin and a 1 percent ghost slot calibrates at faces 0.8 to 1.25x the rig's") {
  const Rig& rig = BuiltinFace::instance().rig();
  double worst = 0.0;
  unsigned seed = 1;
  for (const double face_scale : {0.8, 0.9, 1.0, 1.1, 1.25}) {
    test::HeadRigTakeOptions o;
    o.seed = seed++;
    o.face_scale = face_scale;
    worst = std::max(worst, test::check_head_rig_calibration(rig, test::builtin_marker_layout(), o));
  }
  WARN("built-in face, head rig 40 mm off the skin, ghost slot, faces 0.8-1.25x: worst bound point " << worst
                                                                                                   << " mm from the truth");
}

// Unlike the rig above: markers at different distances off the skin, two on a headband
// above the face, one wobbling on its mount (issue 29: a real rig found by rigidity, not by
// looking like the synthetic one).
TEST_CASE("A head rig of 3 to 6 markers 30 to 50 mm off the skin, on a headband and wobbling, is found and never bound") {
  const Rig& rig = BuiltinFace::instance().rig();
  const std::vector<std::vector<double>> rigs = {{30, 50, 40}, {35, 45, 30, 50}, {30, 38, 46, 50, 42, 34}};
  unsigned seed = 40;
  for (const auto& offsets : rigs) {
    test::HeadRigTakeOptions o;
    o.seed = seed++;
    o.head_markers = int(offsets.size());
    o.head_offsets_mm = offsets;
    o.headband_markers = int(offsets.size()) / 2;
    o.wobble_mm = 0.8;
    INFO(offsets.size() << " head markers");
    test::check_head_rig_calibration(rig, test::builtin_marker_layout(), o);
  }
}

TEST_CASE("Plain ICP converges wrong from 30 to 50 degree turns where hull then surface ICP does not") {
  const Rig& rig = BuiltinFace::instance().rig();
  const auto layout = test::builtin_marker_layout();
  Eigen::Matrix3Xd X(3, Eigen::Index(layout.size()));
  for (std::size_t k = 0; k < layout.size(); ++k) X.col(Eigen::Index(k)) = test::layout_point(layout[k], rig.neutral);
  const auto hp = convex_hull_vertices(X), hv = convex_hull_vertices(rig.neutral);
  Eigen::Matrix3Xd HP(3, Eigen::Index(hp.size())), HV(3, Eigen::Index(hv.size()));
  for (std::size_t i = 0; i < hp.size(); ++i) HP.col(Eigen::Index(i)) = X.col(hp[i]);
  for (std::size_t i = 0; i < hv.size(); ++i) HV.col(Eigen::Index(i)) = rig.neutral.col(hv[i]);
  auto max_error_mm = [&](const Similarity& T) { return (T.apply(X) - X).colwise().norm().maxCoeff() * 10.0; };
  int plain_wrong = 0, hull_right = 0;
  // The markers as captured, turned by a yaw or a pitch; both methods start from the same
  // centred, unrotated guess. (From a single start neither always wins: calibrate() runs
  // the two-step method from 48 starts.)
  const std::array<std::pair<double, Eigen::Vector3d>, 3> turns = {
      std::pair{30.0, Eigen::Vector3d::UnitY()}, std::pair{40.0, Eigen::Vector3d::UnitY()}, std::pair{50.0, Eigen::Vector3d::UnitX()}};
  for (const auto& [degrees, axis] : turns) {
    Similarity start;
    start.rotation = Eigen::AngleAxisd(degrees * std::numbers::pi / 180.0, axis).toRotationMatrix();
    start.translation = HV.rowwise().mean() - start.rotation * HP.rowwise().mean();
    const IcpResult plain = icp_to_surface(X, rig, start, 0.7, 1.4);
    const IcpResult hull = icp_hulls(HP, HV, start, 0.7, 1.4);
    const IcpResult two_step = icp_to_surface(X, rig, hull.transform, 0.7, 1.4);
    INFO(degrees << " degrees: plain ICP " << max_error_mm(plain.transform) << " mm, hull then surface "
                 << max_error_mm(two_step.transform) << " mm");
    CHECK(max_error_mm(plain.transform) > 10.0);
    CHECK(max_error_mm(two_step.transform) < 0.01);
    plain_wrong += max_error_mm(plain.transform) > 10.0;
    hull_right += max_error_mm(two_step.transform) < 0.01;
  }
  CHECK(plain_wrong == 3);
  CHECK(hull_right == 3);
}

TEST_CASE("Calibrated offsets give the rig neutral at rest despite identity mismatch") {
  const BuiltinFace& face = BuiltinFace::instance();
  const Rig& rig = face.rig();
  const auto layout = test::builtin_marker_layout();
  // The actor's face: wider, shorter, with a fuller mid-face than the rig's, in mm.
  auto actor = [](const Eigen::Vector3d& x) -> Eigen::Vector3d {
    return Eigen::Vector3d(1.08 * x.x(), 0.94 * x.y(), x.z() + 0.25 * std::exp(-(x.x() * x.x() + x.y() * x.y()) / 20.0)) * 10.0;
  };
  std::vector<std::string> labels;
  Eigen::Matrix3Xd neutral(3, Eigen::Index(layout.size()));
  for (std::size_t k = 0; k < layout.size(); ++k) {
    labels.push_back(layout[k].label);
    neutral.col(Eigen::Index(k)) = actor(test::layout_point(layout[k], rig.neutral));
  }
  Calibration cal = calibrate(rig, labels, neutral, std::vector<uint8_t>(layout.size(), 1),
                              CalibrationOptions{.take_mm_per_unit = 1.0});
  // Stable: the five markers highest on the face (no jaw or mouth shape reaches them here).
  std::vector<std::size_t> by_height(layout.size());
  std::iota(by_height.begin(), by_height.end(), 0);
  std::sort(by_height.begin(), by_height.end(), [&](std::size_t a, std::size_t b) { return neutral(1, Eigen::Index(a)) > neutral(1, Eigen::Index(b)); });
  for (int i = 0; i < 5; ++i) cal.stable_markers.push_back(labels[by_height[std::size_t(i)]]);
  pipeline::MarkerMapper mapper(cal, labels, "");
  auto model = build_solver_model(rig, cal.bindings());
  for (const SolverMethod method : {SolverMethod::kNonlinear, SolverMethod::kLinear}) {
    auto solver = make_solver(method, model);
    auto result = solver->make_result();
    auto mapped = mapper.make_output();
    // At rest: the targets are the bound points, the face the rig's neutral.
    MarkerFrame frame;
    for (std::size_t k = 0; k < layout.size(); ++k) {
      Marker m;
      m.label.assign(labels[k]);
      m.position = neutral.col(Eigen::Index(k));
      frame.markers.push_back(m);
    }
    mapper.process(frame, mapped);
    for (std::size_t k = 0; k < layout.size(); ++k) CHECK((mapped.targets.col(Eigen::Index(k)) - cal.markers[k].bound_point).norm() < 1e-9);
    solver->solve(mapped.targets, mapped.present, result);
    INFO(solver->name() << " at rest: largest weight " << result.weights.maxCoeff() << ", vertex error "
              << (result.vertices - rig.neutral).colwise().norm().maxCoeff() * 10.0 << " mm");
    CHECK(result.weights.maxCoeff() < 0.02);
    CHECK((result.vertices - rig.neutral).colwise().norm().maxCoeff() * 10.0 < 0.2);
    // The actor opens the jaw: the same motion on their face reads as jawOpen.
    Eigen::VectorXd w = Eigen::VectorXd::Zero(rig.shape_count());
    const auto jaw = *rig.shape_index("jawOpen");
    w[jaw] = 0.6;
    const Eigen::Matrix3Xd pose = face.articulated_pose(w);
    for (std::size_t k = 0; k < layout.size(); ++k)
      frame.markers[k].position = neutral.col(Eigen::Index(k)) +
                                  10.0 * (test::layout_point(layout[k], pose) - test::layout_point(layout[k], rig.neutral));
    solver->reset();
    mapper.process(frame, mapped);
    solver->solve(mapped.targets, mapped.present, result);
    INFO(solver->name() << " jawOpen 0.6 solved as " << result.weights[jaw]);
    CHECK(std::abs(result.weights[jaw] - 0.6) < 0.15);
  }
}

TEST_CASE("Head stabiliser rejects an outlier and holds the pose with too few stable markers") {
  std::mt19937 rng(9);
  std::normal_distribution<double> g;
  Eigen::Matrix3Xd reference(3, 6);
  for (Eigen::Index i = 0; i < reference.size(); ++i) reference.data()[i] = 5.0 * g(rng);
  HeadStabiliser stabiliser({0, 1, 2, 3, 4, 5}, reference, StabiliserParams{.outlier_floor = 0.5});
  Similarity pose;
  pose.rotation = test::random_rotation(rng);
  pose.translation = {10, 20, 30};
  std::vector<Marker> markers(7);  // slot 6 is a face marker the stabiliser ignores
  for (int i = 0; i < 6; ++i) markers[std::size_t(i)].position = pose.apply(Eigen::Vector3d(reference.col(i)));
  markers[6].position = {1e6, 0, 0};
  markers[3].position += Eigen::Vector3d(0, 4.0, 0);  // a bumped marker
  std::vector<uint32_t> flags(7, 0);
  HeadPoseResult out;
  CHECK_FALSE(stabiliser.process(markers, out, flags));
  CHECK(out.inliers == 5);
  CHECK(rotation_angle(out.pose.rotation.transpose() * pose.rotation) < 1e-9);
  CHECK((out.pose.translation - pose.translation).norm() < 1e-9);
  CHECK((flags[3] & kMarkerOutlier) != 0);
  CHECK(std::count_if(flags.begin(), flags.end(), [](uint32_t f) { return f != 0; }) == 1);
  CHECK(std::isnan(stabiliser.residuals()[0]) == false);
  CHECK(stabiliser.residuals()[3] == Approx(4.0).margin(1e-9));
  // Only two stable markers visible: the last pose is held and flagged.
  for (int i = 2; i < 6; ++i) markers[std::size_t(i)].flags = kMarkerMissing;
  markers[0].position += Eigen::Vector3d(3, 0, 0);
  CHECK(stabiliser.process(markers, out));
  CHECK(out.held);
  CHECK((out.pose.translation - pose.translation).norm() < 1e-9);
  // A NaN position counts as missing, never as a point.
  for (int i = 2; i < 6; ++i) markers[std::size_t(i)].flags = 0, markers[std::size_t(i)].position.setConstant(std::nan(""));
  CHECK(stabiliser.process(markers, out));
  CHECK_THROWS_WITH(HeadStabiliser({0, 1}, reference.leftCols(2)), Catch::Contains("at least 3"));
}

TEST_CASE("Stable markers are found as the ones that move rigidly with the head") {
  SyntheticTakeOptions o;
  o.head_sway_deg = 8.0;
  o.noise_mm = 0.1;
  auto take = make_synthetic_take(o);
  // Four head-rig markers fixed to the skull, appended after the face markers.
  std::mt19937 rng(2);
  std::normal_distribution<double> g;
  std::vector<Eigen::Vector3d> rig_points = {{7, 9, 2}, {-7, 9, 2}, {0, 11, 4}, {0, 8, 7}};
  // They follow the same head sway the generator applies to the face.
  const std::size_t K = take.layout.size();
  for (std::size_t f = 0; f < take.frames.size(); ++f) {
    const double a = o.head_sway_deg * std::numbers::pi / 180.0 * std::sin(2.0 * std::numbers::pi * 0.3 * double(f) / o.rate_hz);
    Similarity head;
    head.rotation = Eigen::AngleAxisd(a, Eigen::Vector3d(0.3, 1.0, 0.2).normalized()).toRotationMatrix();
    head.translation = Eigen::Vector3d(0.5 * std::sin(0.05 * double(f)), 0.3 * std::cos(0.04 * double(f)), 0.0);
    for (std::size_t i = 0; i < rig_points.size(); ++i) {
      Marker m;
      m.label.assign(fmt::format("Head{}", i));
      m.position = take.rig_to_take.apply(head.apply(rig_points[i])) + Eigen::Vector3d(g(rng), g(rng), g(rng)) * 0.1;
      take.frames[f].markers.push_back(m);
    }
  }
  // Face markers also slide on the skin by up to 1.5 mm, each at its own phase.
  for (std::size_t f = 0; f < take.frames.size(); ++f)
    for (std::size_t k = 0; k < K; ++k)
      take.frames[f].markers[k].position += 1.5 * std::sin(0.2 * double(f) + double(k)) * Eigen::Vector3d(0.6, 0.8, 0.0);
  double deviation = 0;
  const auto stable = find_stable_markers(take.frames, 4, &deviation);
  CHECK(stable == std::vector<int>({int(K), int(K) + 1, int(K) + 2, int(K) + 3}));
  CHECK(deviation < 0.2);  // take units (mm): the noise's 0.14 mm, not the 1 mm slide
}

TEST_CASE("Assignment solver finds the optimum of small problems") {
  std::mt19937 rng(4);
  std::uniform_real_distribution<double> u(0.0, 10.0);
  AssignmentSolver solver(6, 8);
  for (int trial = 0; trial < 200; ++trial) {
    const int rows = 1 + trial % 6, cols = rows + trial % 3;
    std::vector<double> cost(static_cast<std::size_t>(rows * cols));
    for (auto& c : cost) c = u(rng);
    std::vector<int> assignment(static_cast<std::size_t>(rows));
    const double total = solver.solve(rows, cols, cost, assignment);
    // Brute force over the ways to pick distinct columns.
    std::vector<int> cols_order(static_cast<std::size_t>(cols));
    std::iota(cols_order.begin(), cols_order.end(), 0);
    double best = 1e300;
    do {
      double sum = 0;
      for (int r = 0; r < rows; ++r) sum += cost[std::size_t(r * cols + cols_order[std::size_t(r)])];
      best = std::min(best, sum);
    } while (std::next_permutation(cols_order.begin(), cols_order.end()));
    INFO("trial " << trial);
    CHECK(total == Approx(best).epsilon(1e-12));
    std::vector<int> sorted = assignment;
    std::sort(sorted.begin(), sorted.end());
    CHECK(std::adjacent_find(sorted.begin(), sorted.end()) == sorted.end());
  }
  std::vector<int> out(7);
  CHECK(std::isnan(solver.solve(7, 8, std::vector<double>(56, 1.0), out)));  // larger than allocated
}

TEST_CASE("Labeller recovers shuffled points through ghosts and dropouts and corrects a swap") {
  SyntheticTakeOptions o;
  o.take_mm_per_unit = 1.0;
  o.head_sway_deg = 5.0;
  const auto take = make_synthetic_take(o);
  const std::size_t K = take.labels.size();
  std::vector<uint8_t> present;
  const Eigen::Matrix3Xd reference = positions_of(take.frames[0], present);
  LabellerParams p;
  p.gate = 6.0;  // mm
  p.gate_growth = 1.0;
  p.max_gate = 15.0;
  p.label_margin = 1.0;
  MarkerLabeller labeller(take.labels, reference, p);
  std::mt19937 rng(8);
  std::uniform_real_distribution<double> u(-1.0, 1.0);
  MarkerFrame out;
  int correct = 0, dropout_frames = 0;
  const std::size_t dropped = 7;
  for (std::size_t f = 0; f < take.frames.size(); ++f) {
    std::vector<Eigen::Vector3d> points;
    std::vector<int> truth;
    const bool dropout = f >= 40 && f < 60;
    for (std::size_t k = 0; k < K; ++k) {
      if (dropout && k == dropped) continue;
      points.push_back(take.frames[f].markers[k].position);
      truth.push_back(int(k));
    }
    // Two ghosts: reflections far from any marker.
    const Eigen::Vector3d centre = reference.rowwise().mean();
    points.push_back(centre + Eigen::Vector3d(u(rng), u(rng), u(rng)) * 400.0 + Eigen::Vector3d(300, 0, 0));
    points.push_back(centre + Eigen::Vector3d(u(rng), u(rng), u(rng)) * 400.0 - Eigen::Vector3d(300, 0, 0));
    std::vector<std::size_t> order(points.size());
    std::iota(order.begin(), order.end(), 0);
    std::shuffle(order.begin(), order.end(), rng);
    std::vector<Eigen::Vector3d> shuffled;
    for (auto i : order) shuffled.push_back(points[i]);
    const LabelStats stats = labeller.label(shuffled, out);
    bool ok = true;
    for (std::size_t k = 0; k < K; ++k) {
      if (dropout && k == dropped) ok &= !out.markers[k].present();
      else ok &= out.markers[k].present() && out.markers[k].position == take.frames[f].markers[k].position;
    }
    if (dropout) {
      dropout_frames += ok;
      CHECK(stats.missing == 1);
    }
    CHECK(stats.ghosts == 2);
    correct += ok;
  }
  CHECK(correct == int(take.frames.size()));
  CHECK(dropout_frames == 20);

  // Labelled input with a swapped pair: corrected and flagged.
  MarkerLabeller checker(take.labels, reference, p);
  int fixed = 0;
  for (std::size_t f = 0; f < take.frames.size(); ++f) {
    MarkerFrame frame = take.frames[f];
    const bool swapped = f >= 50 && f < 80;
    if (swapped) std::swap(frame.markers[3].position, frame.markers[4].position);
    const LabelStats stats = checker.check(frame);
    bool ok = true;
    for (std::size_t k = 0; k < K; ++k) ok &= frame.markers[k].position == take.frames[f].markers[k].position;
    if (swapped) {
      ok &= (frame.markers[3].flags & kMarkerRelabelled) && (frame.markers[4].flags & kMarkerRelabelled) && stats.relabelled == 2;
    } else {
      ok &= stats.relabelled == 0;
    }
    fixed += ok;
  }
  CHECK(fixed == int(take.frames.size()));
}

TEST_CASE("A marker lost long enough for its gate to pass a tracked neighbour does not take the neighbour's point") {
  // Five markers on a line 10 mm apart; marker 2 is hidden for 40 frames, long enough for
  // its gate to grow to 20 mm, while the set drifts 0.3 mm a frame. Its neighbours keep
  // their points (before, a lost marker cost its whole wide gate to leave missing, so it
  // took a neighbour 10 mm away and left the neighbour missing).
  Eigen::Matrix3Xd reference(3, 5);
  for (int k = 0; k < 5; ++k) reference.col(k) = Eigen::Vector3d(10.0 * k, 3.0 * (k % 2), 0.0);
  const std::vector<std::string> labels{"a", "b", "c", "d", "e"};
  LabellerParams p;
  p.gate = 6.0;  // mm
  p.gate_growth = 1.0;
  p.max_gate = 20.0;
  p.label_margin = 1.0;
  for (const bool checking : {false, true}) {
    INFO((checking ? "check()" : "label()"));
    MarkerLabeller labeller(labels, reference, p);
    int right = 0, frames = 0;
    for (int f = 0; f < 80; ++f, ++frames) {
      const bool hidden = f >= 20 && f < 60;
      MarkerFrame frame = make_marker_frame(labels);
      std::vector<Eigen::Vector3d> points;
      for (int k = 0; k < 5; ++k) {
        Marker& m = frame.markers[std::size_t(k)];
        // A small expression wobble on top of the drift: the tracked predictions are off by
        // up to about 1 mm.
        m.position = reference.col(k) + Eigen::Vector3d(0.3 * f, 0.8 * std::sin(0.7 * f + k), 0.0);
        if (hidden && k == 2) {
          m.flags = kMarkerMissing;
          m.position.setConstant(std::numeric_limits<double>::quiet_NaN());
        } else {
          m.flags = 0;
          points.push_back(m.position);
        }
      }
      const MarkerFrame truth = frame;
      MarkerFrame out;
      if (checking) {
        out = frame;
        labeller.check(out);
      } else {
        labeller.label(points, out);
      }
      bool ok = true;
      for (std::size_t k = 0; k < 5; ++k)
        ok &= truth.markers[k].present() ? out.markers[k].present() && out.markers[k].position == truth.markers[k].position
                                         : !out.markers[k].present();
      right += ok;
    }
    CHECK(right == frames);
  }
}

TEST_CASE("Auto-neutral picks the rest stretch and refuses a take that never rests") {
  SyntheticTakeOptions o;
  o.rest_frames = 0;
  o.motion_frames = 300;
  auto take = make_synthetic_take(o);
  // Put a rest stretch in the middle: frames 120..179 copy the neutral shape.
  SyntheticTakeOptions rest = o;
  rest.rest_frames = 60;
  rest.motion_frames = 0;
  const auto still = make_synthetic_take(rest);
  for (int f = 0; f < 60; ++f)
    for (std::size_t k = 0; k < take.labels.size(); ++k)
      take.frames[std::size_t(120 + f)].markers[k].position = still.frames[std::size_t(f)].markers[k].position;
  const auto stable = find_stable_markers(take.frames, 6);
  NeutralSearchOptions search;
  search.rate_hz = 60.0;
  search.take_mm_per_unit = 1.0;
  const NeutralFrame n = find_neutral_frame(take.frames, stable, search);
  INFO("picked frame " << n.frame_index << " at " << n.distance_mm << " mm, " << n.speed_mm_s << " mm/s");
  // Every frame of the chosen stretch is at rest: no marker of the noise-free truth is
  // more than 1 mm from neutral (the performance also starts from rest).
  const BuiltinFace& builtin = BuiltinFace::instance();
  for (std::size_t f = n.window_start; f < n.window_start + n.window_frames; ++f) {
    double largest = 0.0;
    if (f < 120 || f >= 180) {
      const Eigen::Matrix3Xd pose = builtin.articulated_pose(take.weights[f]);
      for (const auto& b : take.layout)
        largest = std::max(largest, (test::layout_point(b, pose) - test::layout_point(b, builtin.rig().neutral)).norm() * 10.0);
    }
    INFO("frame " << f << " largest marker motion from rest " << largest << " mm");
    CHECK(largest < 1.0);
  }
  CHECK(n.distance_mm < 1.5);  // the largest marker offset: 0.3 mm noise reaches about 1 mm
  CHECK(n.speed_mm_s < 15.0);

  // A face that never rests: the jaw swings wide open and shut twice a second throughout.
  const BuiltinFace& face = BuiltinFace::instance();
  const Rig& rig = face.rig();
  const auto layout = test::builtin_marker_layout();
  std::vector<MarkerFrame> busy;
  for (int f = 0; f < 240; ++f) {
    Eigen::VectorXd w = Eigen::VectorXd::Zero(rig.shape_count());
    w[*rig.shape_index("jawOpen")] = 0.5 + 0.5 * std::sin(2.0 * std::numbers::pi * 2.0 * f / 60.0);
    w[*rig.shape_index("mouthSmile_L")] = 0.5 + 0.5 * std::cos(2.0 * std::numbers::pi * 1.3 * f / 60.0);
    w[*rig.shape_index("browInnerUp")] = 0.5 + 0.5 * std::sin(2.0 * std::numbers::pi * 1.7 * f / 60.0);
    const Eigen::Matrix3Xd pose = face.articulated_pose(w);
    MarkerFrame frame;
    for (const auto& b : layout) {
      Marker m;
      m.label.assign(b.label);
      m.position = test::layout_point(b, pose) * 10.0;
      frame.markers.push_back(m);
    }
    busy.push_back(frame);
  }
  CHECK_THROWS_WITH(find_neutral_frame(busy, stable, search), Catch::Contains("no neutral-looking stretch"));
  // No frame with every stable marker.
  for (std::size_t f = 0; f < busy.size(); ++f) busy[f].markers[std::size_t(stable[f % stable.size()])].flags = kMarkerMissing;
  CHECK_THROWS_WITH(find_neutral_frame(busy, stable, search), Catch::Contains("no frame has every stable marker"));
}

TEST_CASE("Auto-neutral tolerates dropouts: each marker present in most of the stretch, and names a marker too often missing") {
  SyntheticTakeOptions o;
  o.rest_frames = 0;
  o.motion_frames = 300;
  auto take = make_synthetic_take(o);
  SyntheticTakeOptions rest = o;
  rest.rest_frames = 60;
  rest.motion_frames = 0;
  const auto still = make_synthetic_take(rest);
  for (int f = 0; f < 60; ++f)
    for (std::size_t k = 0; k < take.labels.size(); ++k)
      take.frames[std::size_t(120 + f)].markers[k].position = still.frames[std::size_t(f)].markers[k].position;
  const auto stable = find_stable_markers(take.frames, 6);
  NeutralSearchOptions search;
  search.rate_hz = 60.0;
  search.take_mm_per_unit = 1.0;
  const NeutralFrame clean = find_neutral_frame(take.frames, stable, search);

  // Every marker drops 0.5% of the frames at random and two (not stable ones) 5%: not one
  // 15-frame stretch has every marker in every frame.
  std::vector<int> dropping;
  for (int k = 0; dropping.size() < 2; ++k)
    if (std::find(stable.begin(), stable.end(), k) == stable.end()) dropping.push_back(k);
  std::mt19937 random(11);
  std::uniform_real_distribution<double> u(0.0, 1.0);
  auto dropped = take;
  std::size_t complete_windows = 0;
  for (auto& f : dropped.frames)
    for (std::size_t k = 0; k < f.markers.size(); ++k)
      if (u(random) < (std::find(dropping.begin(), dropping.end(), int(k)) != dropping.end() ? 0.05 : 0.005))
        f.markers[k].flags = kMarkerMissing;
  for (std::size_t start = 0; start + 15 <= dropped.frames.size(); ++start) {
    bool complete = true;
    for (std::size_t f = start; f < start + 15; ++f) complete &= dropped.frames[f].present_count() == dropped.labels.size();
    complete_windows += complete;
  }
  CHECK(complete_windows == 0);
  const NeutralFrame n = find_neutral_frame(dropped.frames, stable, search);
  INFO("clean: frames " << clean.window_start << ".." << clean.window_start + clean.window_frames << "; with dropouts "
                        << n.window_start << ".." << n.window_start + n.window_frames);
  CHECK(n.window_start >= 120);  // the rest stretch, as without dropouts
  CHECK(n.window_start + n.window_frames <= 180);
  CHECK(n.distance_mm < 1.5);
  for (int s : stable) CHECK(dropped.frames[n.frame_index].markers[std::size_t(s)].present());  // the average's anchor
  std::vector<uint8_t> present;
  const Eigen::Matrix3Xd mean = average_positions(dropped.frames, n.window_start, n.window_frames, n.frame_index, stable,
                                                  search.min_presence, present);
  CHECK(std::count(present.begin(), present.end(), 1) == std::ptrdiff_t(dropped.labels.size()));
  CHECK(mean.allFinite());
  {
    // A stable marker lost in the requested anchor frame (a dropout at the moment an
    // operator presses "calibrate neutral"): the head frame comes from its nearest complete
    // neighbour, and the average has the same shape (the head frame it is expressed in may
    // move rigidly) to within the head fit's noise.
    auto holed = dropped.frames;
    holed[n.frame_index].markers[std::size_t(stable[0])].flags = kMarkerMissing;
    std::vector<uint8_t> holed_present;
    const Eigen::Matrix3Xd holed_mean = average_positions(holed, n.window_start, n.window_frames, n.frame_index, stable,
                                                          search.min_presence, holed_present);
    CHECK(holed_present == present);
    double worst_distance_change = 0;
    for (Eigen::Index i = 0; i < mean.cols(); ++i)
      for (Eigen::Index j = i + 1; j < mean.cols(); ++j)
        worst_distance_change = std::max(worst_distance_change, std::abs((holed_mean.col(i) - holed_mean.col(j)).norm() -
                                                                         (mean.col(i) - mean.col(j)).norm()));
    CHECK(worst_distance_change < 0.2);
    // With a stable marker gone from every averaged frame there is no head frame: named.
    for (std::size_t f = n.window_start; f < n.window_start + n.window_frames; ++f)
      holed[f].markers[std::size_t(stable[0])].flags = kMarkerMissing;
    CHECK_THROWS_WITH(average_positions(holed, n.window_start, n.window_frames, n.frame_index, stable, search.min_presence,
                                        holed_present),
                      Catch::Contains("has every stable marker"));
  }

  // One marker missing in 2 of every 5 frames: present in most of the take (so not left
  // out as a ghost slot), but in at most 60% of any stretch: named.
  for (std::size_t f = 0; f < dropped.frames.size(); ++f)
    if (f % 5 < 2) dropped.frames[f].markers[std::size_t(dropping[0])].flags = kMarkerMissing;
  CHECK_THROWS_WITH(find_neutral_frame(dropped.frames, stable, search),
                    Catch::Contains("has each marker present in 80% of its frames; too often missing: " +
                                    dropped.labels[std::size_t(dropping[0])] + " (at best 60%)"));
  search.min_presence = 0.4;  // configurable: then it is accepted
  CHECK_NOTHROW(find_neutral_frame(dropped.frames, stable, search));
}

TEST_CASE("Calibration profile round-trips and is read strictly with line numbers") {
  SyntheticTakeOptions o;
  const auto take = make_synthetic_take(o);
  const Rig& rig = BuiltinFace::instance().rig();
  Calibration cal = calibrate_whole_take(rig, take.labels, take.frames, 60.0, 1.0);
  cal.source_take = "synthetic \"take\".trc";
  cal.source_frame = 12;
  cal.notes.push_back("a note");
  const std::string text = write_calibration_profile(cal);
  const Calibration back = read_calibration_profile(text, "actor.toml");
  CHECK(back.rig_name == cal.rig_name);
  CHECK(back.rig_hash == cal.rig_hash);
  CHECK(back.take_mm_per_unit == cal.take_mm_per_unit);
  CHECK(back.source_take == cal.source_take);
  CHECK(back.source_frame == 12);
  CHECK(back.stable_markers == cal.stable_markers);
  CHECK(back.notes == cal.notes);
  CHECK(back.take_to_rig.scale == cal.take_to_rig.scale);
  CHECK((back.take_to_rig.rotation - cal.take_to_rig.rotation).norm() == 0.0);
  CHECK((back.take_to_rig.translation - cal.take_to_rig.translation).norm() == 0.0);
  REQUIRE(back.markers.size() == cal.markers.size());
  for (std::size_t k = 0; k < cal.markers.size(); ++k) {
    CHECK(back.markers[k].label == cal.markers[k].label);
    CHECK(back.markers[k].binding.vertices == cal.markers[k].binding.vertices);
    CHECK((back.markers[k].binding.barycentric - cal.markers[k].binding.barycentric).norm() == 0.0);
    CHECK((back.markers[k].neutral - cal.markers[k].neutral).norm() == 0.0);
    CHECK(back.markers[k].residual_mm == cal.markers[k].residual_mm);
  }
  CHECK_NOTHROW(check_profile_matches_rig(back, rig, "actor.toml"));
  // The shapes left out of the weight fit, and the threshold they were decided at.
  CHECK(text.find("version = 4\n") != std::string::npos);
  CHECK(back.observability_known);
  CHECK(back.observable_shape_mm == cal.observable_shape_mm);
  REQUIRE(back.unobserved_shapes.size() == cal.unobserved_shapes.size());
  for (std::size_t i = 0; i < cal.unobserved_shapes.size(); ++i) {
    CHECK(back.unobserved_shapes[i].name == cal.unobserved_shapes[i].name);
    CHECK(back.unobserved_shapes[i].max_displacement_mm == cal.unobserved_shapes[i].max_displacement_mm);
  }
  Calibration decided = cal;
  decided.unobserved_shapes = {{rig.shape_names[1], 0.25}};
  const Calibration one = read_calibration_profile(write_calibration_profile(decided), "actor.toml");
  REQUIRE(one.unobserved_shapes.size() == 1);
  CHECK(one.unfitted_shapes() == std::vector<std::string>{rig.shape_names[1]});
  CHECK(one.unobserved_shapes[0].max_displacement_mm == 0.25);
  // A profile from before version 3 has no [observability]: undecided, and read as before.
  // Version 3 has no distinct_mm and no same_as: read as it was decided.
  Calibration v3 = cal;
  v3.distinct_shape_mm = 0.0;
  v3.unobserved_shapes = {{rig.shape_names[1], 0.25}};
  const std::string v3_text = write_calibration_profile(v3);
  CHECK(v3_text.find("\nversion = 3\n") != std::string::npos);
  CHECK(read_calibration_profile(v3_text, "actor.toml").distinct_shape_mm == 0.0);
  Calibration same = cal;
  same.unobserved_shapes = {{rig.shape_names[2], 3.6, rig.shape_names[1], 0.57}};
  const Calibration same_back = read_calibration_profile(write_calibration_profile(same), "actor.toml");
  REQUIRE(same_back.unobserved_shapes.size() == 1);
  CHECK(same_back.unobserved_shapes[0].same_as == rig.shape_names[1]);
  CHECK(same_back.unobserved_shapes[0].distinct_mm == 0.57);
  Calibration undecided = cal;
  undecided.observability_known = false;
  const std::string older = write_calibration_profile(undecided);
  CHECK(older.find("version = 3") == std::string::npos);
  CHECK(older.find("version = 4") == std::string::npos);
  CHECK_FALSE(read_calibration_profile(older, "actor.toml").observability_known);
  decided.unobserved_shapes = {{"noSuchShape", 0.25}};
  CHECK_THROWS_WITH(check_profile_matches_rig(read_calibration_profile(write_calibration_profile(decided), "actor.toml"), rig,
                                              "actor.toml"),
                    Catch::Contains("unobserved shape 'noSuchShape'"));

  auto line_of = [&](const std::string& s, const std::string& needle) {
    return 1 + std::count(s.begin(), s.begin() + std::ptrdiff_t(s.find(needle)), '\n');
  };
  // An edited value breaks the checksum.
  std::string edited = text;
  edited.replace(edited.find("frame = 12"), 10, "frame = 13");
  CHECK_THROWS_WITH(read_calibration_profile(edited, "actor.toml"),
                    Catch::Contains("actor.toml:2:") && Catch::Contains("checksum mismatch"));
  // Without the checksum, hand edits are accepted but still checked.
  std::string unsummed = text.substr(0, text.find("checksum")) + text.substr(text.find('\n', text.find("checksum")) + 1);
  CHECK_NOTHROW(read_calibration_profile(unsummed, "actor.toml"));
  std::string unknown = unsummed;
  unknown.insert(unknown.find("residual_mm"), "residual_cm = 1\n");
  CHECK_THROWS_WITH(read_calibration_profile(unknown, "actor.toml"),
                    Catch::Contains(fmt::format("actor.toml:{}:", line_of(unknown, "residual_cm"))) && Catch::Contains("unknown key 'residual_cm'"));
  std::string newer = unsummed;
  REQUIRE(newer.find("\nversion = 4\n") != std::string::npos);
  newer.replace(newer.find("\nversion = 4\n") + 1, 11, "version = 9");
  CHECK_THROWS_WITH(read_calibration_profile(newer, "actor.toml"), Catch::Contains("version 9"));
  std::string bad_rotation = unsummed;
  bad_rotation.replace(bad_rotation.find("rotation = [["), 13, "rotation = [[2, ");
  CHECK_THROWS_WITH(read_calibration_profile(bad_rotation, "actor.toml"), Catch::Contains("transform.rotation"));
  CHECK_THROWS_WITH(read_calibration_profile("version = 1\n[rig\n", "broken.toml"), Catch::Contains("broken.toml:2"));
  // A vertex index past int was truncated (2^32 bound vertex 0), and a start past int too.
  std::string huge_vertex = unsummed;
  const auto first_vertex = huge_vertex.find("vertices = [") + 12;
  huge_vertex.replace(first_vertex, huge_vertex.find(',', first_vertex) - first_vertex, "4294967296");
  CHECK_THROWS_WITH(read_calibration_profile(huge_vertex, "actor.toml"),
                    Catch::Contains(fmt::format("actor.toml:{}:", line_of(huge_vertex, "vertices = [4294967296"))) &&
                        Catch::Contains("vertex indices"));
  std::string huge_start = unsummed;
  huge_start.replace(huge_start.find("start = "), 8, "start = 4294967296");
  CHECK_THROWS_WITH(read_calibration_profile(huge_start, "actor.toml"), Catch::Contains("fit.start"));
  std::string not_utf8 = unsummed;
  not_utf8.insert(not_utf8.find("a note") + 2, "\xed\xa0\x80");  // a UTF-16 surrogate
  CHECK_THROWS_WITH(read_calibration_profile(not_utf8, "actor.toml"),
                    Catch::Contains(fmt::format("actor.toml:{}:", line_of(not_utf8, "note\""))) && Catch::Contains("not valid UTF-8"));
  // A profile for another rig.
  Calibration other = back;
  other.rig_hash ^= 1;
  CHECK_THROWS_WITH(check_profile_matches_rig(other, rig, "actor.toml"), Catch::Contains("calibrate again"));
}

TEST_CASE("Calibration gives clear errors for too few markers NaN and flat marker sets") {
  const Rig& rig = BuiltinFace::instance().rig();
  const auto take = make_synthetic_take(SyntheticTakeOptions{});
  std::vector<uint8_t> present;
  Eigen::Matrix3Xd P = positions_of(take.frames[0], present);
  // Too few present.
  std::vector<uint8_t> few(present.size(), 0);
  for (int k = 0; k < 5; ++k) few[std::size_t(k)] = 1;
  CHECK_THROWS_WITH(calibrate(rig, take.labels, P, few), Catch::Contains("5 markers present") && Catch::Contains("at least 6"));
  // NaN on a marker flagged present.
  Eigen::Matrix3Xd nan = P;
  nan(1, 4) = std::nan("");
  CHECK_THROWS_WITH(calibrate(rig, take.labels, nan, present), Catch::Contains(take.labels[4]) && Catch::Contains("NaN"));
  // ... and the same marker flagged missing is left out with a note.
  std::vector<uint8_t> without = present;
  without[4] = 0;
  const Calibration c = calibrate(rig, take.labels, nan, without);
  CHECK(c.markers.size() == take.labels.size() - 1);
  CHECK(c.find(take.labels[4]) == -1);
  CHECK(c.notes.size() == 1);
  // All markers on a plane.
  Eigen::Matrix3Xd flat = P;
  flat.row(2).setConstant(5.0);
  CHECK_THROWS_WITH(calibrate(rig, take.labels, flat, present), Catch::Contains("flat or degenerate"));
  // Sizes that disagree.
  CHECK_THROWS_WITH(calibrate(rig, {"a"}, P, present), Catch::Contains("disagree"));
  // Stable-marker search with too little data.
  CHECK_THROWS_WITH(find_stable_markers(std::span<const MarkerFrame>(take.frames.data(), 1), 4), Catch::Contains("at least 2"));
  // Labeller with too few markers.
  CHECK_THROWS_WITH(MarkerLabeller({"a", "b"}, Eigen::Matrix3Xd::Zero(3, 2)), Catch::Contains("at least 3"));
  // Mapper whose stable markers are not in the take: it maps without stabilising.
  Calibration no_stable = c;
  no_stable.stable_markers = {"nope1", "nope2", "nope3"};
  const pipeline::MarkerMapper unstabilised(no_stable, take.labels, "");
  CHECK_FALSE(unstabilised.stabilising());
  CHECK(unstabilised.stable_markers_found() == 0);
  // Mapper with none of the calibration's markers in the frames.
  CHECK_THROWS_WITH(pipeline::MarkerMapper(c, std::vector<std::string>{"x", "y", "z"}, ""),
                    Catch::Contains("only 0 of the calibration's"));
}

TEST_CASE("Per-frame stabilise map and label steps allocate nothing") {
  SyntheticTakeOptions o;
  o.head_sway_deg = 5.0;
  o.motion_frames = 60;
  const auto take = make_synthetic_take(o);
  const Rig& rig = BuiltinFace::instance().rig();
  const Calibration cal = calibrate_whole_take(rig, take.labels, take.frames, 60.0, 1.0);
  pipeline::MarkerMapper mapper(cal, take.labels, "");
  auto mapped = mapper.make_output();
  std::vector<uint8_t> present;
  const Eigen::Matrix3Xd reference = positions_of(take.frames[0], present);
  LabellerParams p;
  p.gate = 6.0;
  p.max_gate = 15.0;
  MarkerLabeller labeller(take.labels, reference, p), checker(take.labels, reference, p);
  MarkerFrame labelled, checked = take.frames[0];
  labelled.markers.reserve(take.labels.size());
  std::vector<uint32_t> flags(take.labels.size(), 0);
  std::vector<Eigen::Vector3d> points;
  points.reserve(take.labels.size() + 2);
  int64_t allocations = 0;
  for (std::size_t f = 0; f < take.frames.size(); ++f) {
    points.clear();
    for (const auto& m : take.frames[f].markers) points.push_back(m.position);
    checked.markers = take.frames[f].markers;  // same size: copies in place
    if (f == 20) checked.markers[2].flags = kMarkerMissing, checked.markers[2].position.setConstant(std::nan(""));
    test::CountAllocations counter;
    mapper.process(take.frames[f], mapped, flags);
    labeller.label(points, labelled);
    checker.check(checked);
    if (f > 0) allocations += counter.count();  // the first frame sizes the labeller's output
  }
  CHECK(allocations == 0);
  CHECK(mapped.head_held == false);
}
