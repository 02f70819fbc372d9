// facecap calibrate, solve and eval, run as processes the way operators run them.
#include <cstdio>
#include <numbers>
#include <fstream>
#include <sstream>

#include <catch2/catch.hpp>
#include <fmt/format.h>
#include <nlohmann/json.hpp>
#include <sys/wait.h>

#include "formats/livelinkface.hpp"
#include "formats/recording.hpp"
#include "formats/take.hpp"
#include "solver/align/profile.hpp"
#include "tests/align_test_support.hpp"
#include "tests/test_support.hpp"

using namespace facecap;

namespace {

using test::Run;
using test::run_facecap;
using test::slurp;


// The synthetic built-in take as a TRC file in mm, in a random pose (Z up or anything).
formats::MarkerTake to_take(const test::SyntheticTake& s, const std::string& units) {
  formats::MarkerTake take;
  take.format = formats::TakeFormat::kTrc;
  take.labels = s.labels;
  take.rate_hz = 60.0;
  take.units = units;
  take.first_frame = 1;
  take.frames = s.frames;
  return take;
}

}  // namespace

TEST_CASE("facecap calibrate then solve to CSV and fcrec then eval on a synthetic take", "[tools]") {
  const auto dir = facecap::test::scratch_dir("align-tools");
  test::SyntheticTakeOptions o;
  o.seed = 21;
  o.take_mm_per_unit = 1.0;
  o.rest_frames = 60;
  o.motion_frames = 120;
  o.head_sway_deg = 4.0;
  const auto synthetic = test::make_synthetic_take(o);
  const auto trc = dir / "take.trc";
  formats::write_take(trc, to_take(synthetic, "mm"));

  Run r = run_facecap(dir, {"calibrate", "--rig", "builtin", "--take", trc.string(), "--auto-neutral", "-o", (dir / "actor.toml").string(), "--json"});
  INFO(r.out << r.err);
  REQUIRE(r.exit_code == 0);
  const auto report = nlohmann::json::parse(r.out);
  CHECK(report["units"] == "mm");
  CHECK(report["units_detected"] == true);
  CHECK(report["residual_mm"]["max"].get<double>() < 1.0);
  CHECK(report["stable_residual_median_mm"].get<double>() < 0.5);
  CHECK(report["markers"].size() == synthetic.labels.size());
  const auto cal = align::load_calibration_profile(dir / "actor.toml");
  CHECK(cal.source_take == "take.trc");
  CHECK(cal.stable_markers.size() == 6);
  // The text report lists every marker's residual.
  r = run_facecap(dir, {"calibrate", "--rig", "builtin", "--take", trc.string(), "--frame", "10", "--average", "9", "-o",
                        (dir / "actor.toml").string(), "--force"});
  REQUIRE(r.exit_code == 0);
  for (const auto& label : synthetic.labels) CHECK(r.out.find(label) != std::string::npos);
  CHECK(r.out.find("residual median") != std::string::npos);
  // --head names markers for the head pose only; a --stable marker that --markers leaves
  // out is one too. Neither is bound; both stabilise.
  const std::string a = synthetic.labels[0], b = synthetic.labels[1], c = synthetic.labels[2];
  std::string some;
  for (std::size_t k = 3; k < synthetic.labels.size(); ++k) some += (some.empty() ? "" : ",") + synthetic.labels[k];
  r = run_facecap(dir, {"calibrate", "--rig", "builtin", "--take", trc.string(), "--markers", some, "--head", a + "," + b,
                        "--stable", b + "," + c + "," + synthetic.labels[3], "-o", (dir / "heads.toml").string(), "--json"});
  INFO(r.out << r.err);
  REQUIRE(r.exit_code == 0);
  const auto heads = nlohmann::json::parse(r.out);
  CHECK(heads["head_markers"] == nlohmann::json({a, b, c}));
  CHECK(heads["markers"].size() == synthetic.labels.size() - 3);
  CHECK(heads["stable_markers"] == nlohmann::json({b, c, synthetic.labels[3]}));
  CHECK(heads["scale_at_band_limit"] == false);
  CHECK(std::abs(heads["face_size_ratio"].get<double>() - 1.0) < 0.02);
  const auto head_profile = align::load_calibration_profile(dir / "heads.toml");
  CHECK(head_profile.find(a) < 0);
  CHECK(head_profile.find_head(a) >= 0);
  // Refuses to overwrite without --force.
  r = run_facecap(dir, {"calibrate", "--rig", "builtin", "--take", trc.string(), "-o", (dir / "actor.toml").string()});
  CHECK(r.exit_code == 1);
  CHECK(r.err.find("--force") != std::string::npos);

  // Solve to a Live Link Face CSV: jawOpen follows the truth.
  r = run_facecap(dir, {"solve", "--rig", "builtin", "--calib", (dir / "actor.toml").string(), "--take", trc.string(), "-o",
                        (dir / "out.csv").string()});
  INFO(r.out << r.err);
  REQUIRE(r.exit_code == 0);
  CHECK(r.err.find("solving take.trc") != std::string::npos);  // the progress bar
  const auto face = formats::read_livelinkface(dir / "out.csv");
  REQUIRE(face.frames.size() == synthetic.frames.size());
  const auto jaw_arkit = *formats::arkit_shape_index("JawOpen");
  const auto jaw_rig = *BuiltinFace::instance().rig().shape_index("jawOpen");
  double worst = 0;
  for (std::size_t f = 0; f < face.frames.size(); ++f)
    worst = std::max(worst, std::abs(double(face.frames[f].weights[jaw_arkit]) - synthetic.weights[f][jaw_rig]));
  INFO("largest jawOpen error " << worst);
  CHECK(worst < 0.15);
  // The head sway shows in the head angles (yaw about the rig's vertical axis).
  double max_yaw = 0;
  for (const auto& f : face.frames) max_yaw = std::max(max_yaw, double(std::abs(f.angles[0])));
  CHECK(max_yaw > 0.02);
  CHECK(max_yaw < 0.2);
  // One Live Link timecode frame per take frame at 60 Hz, each .000 (the take starts at 0).
  const auto frame_number = [](const Timecode& tc) {
    return ((int64_t(tc.hours) * 60 + tc.minutes) * 60 + tc.seconds) * formats::kLiveLinkTimecodeRate + tc.frames;
  };
  int64_t bad_steps = 0;
  for (std::size_t f = 1; f < face.frames.size(); ++f)
    bad_steps += frame_number(face.frames[f].timecode) != frame_number(face.frames[f - 1].timecode) + 1;
  CHECK(bad_steps == 0);
  CHECK(frame_number(face.frames.front().timecode) == 0);
  CHECK(frame_number(face.frames.back().timecode) == int64_t(face.frames.size()) - 1);
  for (const auto& f : face.frames) CHECK(f.timecode.subframe == 0.0f);

  // ... and to a recording with the calibration in its header.
  r = run_facecap(dir, {"solve", "--rig", "builtin", "--calib", (dir / "actor.toml").string(), "--take", trc.string(), "-o",
                        (dir / "out.fcrec").string(), "--solver", "linear", "-q"});
  REQUIRE(r.exit_code == 0);
  CHECK(r.err.empty());
  formats::RecordingReader rec(dir / "out.fcrec");
  CHECK(rec.solved_frame_count() == synthetic.frames.size());
  CHECK(rec.marker_frame_count() == synthetic.frames.size());
  CHECK(rec.header().calibration.find("[[marker]]") != std::string::npos);
  SolvedFrame solved;
  rec.read_solved_frame(100, solved);
  CHECK(solved.weights.size() == BuiltinFace::instance().rig().shape_count());

  // convert writes the recording's solved weights as Live Link Face; our reader reads
  // back every frame's weights (10 decimals) and a timecode per frame.
  r = run_facecap(dir, {"convert", (dir / "out.fcrec").string(), (dir / "converted.csv").string()});
  INFO(r.out << r.err);
  REQUIRE(r.exit_code == 0);
  const auto converted = formats::read_livelinkface(dir / "converted.csv");
  REQUIRE(converted.frames.size() == rec.solved_frame_count());
  CHECK(converted.rate_hz == 60.0);
  double weight_error = 0;
  for (std::size_t f = 0; f < converted.frames.size(); ++f) {
    rec.read_solved_frame(f, solved);
    weight_error = std::max(weight_error, std::abs(double(converted.frames[f].weights[jaw_arkit]) - solved.weights[jaw_rig]));
    CHECK(frame_number(converted.frames[f].timecode) == int64_t(f));
  }
  CHECK(weight_error < 1e-6);
  // solve on the recording, without --calib, uses the calibration and settings it stores:
  // the same weights again.
  r = run_facecap(dir, {"solve", "--rig", "builtin", "--take", (dir / "out.fcrec").string(), "-o",
                        (dir / "again.csv").string(), "-q"});
  INFO(r.out << r.err);
  REQUIRE(r.exit_code == 0);
  const auto again = formats::read_livelinkface(dir / "again.csv");
  REQUIRE(again.frames.size() == converted.frames.size());
  double again_error = 0;
  for (std::size_t f = 0; f < again.frames.size(); ++f)
    for (std::size_t a = 0; a < formats::kArkitShapeCount; ++a)
      again_error = std::max(again_error, std::abs(double(again.frames[f].weights[a] - converted.frames[f].weights[a])));
  CHECK(again_error < 1e-6);
  // inspect summarises the solved weights and the head pose.
  r = run_facecap(dir, {"inspect", (dir / "out.fcrec").string(), "--json"});
  INFO(r.out << r.err);
  REQUIRE(r.exit_code == 0);
  const auto inspected = nlohmann::json::parse(r.out)["solved"];
  CHECK(inspected["frames"] == synthetic.frames.size());
  std::vector<double> jaw;
  for (std::size_t f = 0; f < rec.solved_frame_count(); ++f) {
    rec.read_solved_frame(f, solved);
    jaw.push_back(solved.weights[jaw_rig]);
  }
  std::sort(jaw.begin(), jaw.end());
  const auto& jaw_summary = inspected["shapes"][jaw_rig];
  CHECK(jaw_summary["name"] == "jawOpen");
  CHECK(jaw_summary["min"].get<double>() == Approx(jaw.front()));
  CHECK(jaw_summary["max"].get<double>() == Approx(jaw.back()));
  CHECK(jaw_summary["median"].get<double>() == Approx(jaw[(jaw.size() - 1) / 2]));  // nearest rank
  CHECK(jaw_summary["frames_above_half"] == std::count_if(jaw.begin(), jaw.end(), [](double w) { return w > 0.5; }));
  // The head pose comes from the markers alone: the same yaw as the CSV's.
  const auto yaw = inspected["head"]["yaw_deg"];
  CHECK(std::max(-yaw[0].get<double>(), yaw[1].get<double>()) == Approx(max_yaw * 180.0 / std::numbers::pi).margin(1e-3));
  r = run_facecap(dir, {"inspect", (dir / "out.fcrec").string()});
  CHECK(r.out.find("frames > 0.5") != std::string::npos);

  // eval: held-out error and the rest, per solver, as JSON.
  r = run_facecap(dir, {"eval", "--rig", "builtin", "--take", trc.string(), "--calib", (dir / "actor.toml").string(), "--solver",
                        "nonlinear,linear,dt", "--json", "--every", "20"});
  INFO(r.out << r.err);
  REQUIRE(r.exit_code == 0);
  const auto eval = nlohmann::json::parse(r.out);
  CHECK(eval["sampling"]["sampled_frames"] == 9);
  // The settings as decided for the built-in face, which is hinged.
  CHECK(eval["solver"]["weight_refinements"] == 2);
  CHECK(eval["solver"]["boundary_hold"] == 0.0);
  CHECK(eval["stable_residual_mm"]["median"].get<double>() < 0.5);
  for (const char* name : {"nonlinear", "linear", "dt"}) {
    INFO(name);
    REQUIRE(eval["solvers"].contains(name));
    const auto& s = eval["solvers"][name];
    const double heldout = s["heldout_mm"]["median"].get<double>();
    CHECK(heldout > 0.0);
    CHECK(heldout < 3.0);
    CHECK(s["heldout_mm"]["p95"].get<double>() >= heldout);
    // The same error in the actor's mm: the take is in mm, the built-in rig in its own units.
    const double actor_scale = eval["actor_mm_per_rig_mm"].get<double>();
    const auto used = align::load_calibration_profile(dir / "actor.toml");
    CHECK(actor_scale == Approx(used.take_mm_per_unit / (used.take_to_rig.scale * used.rig_mm_per_unit)));
    CHECK(s["heldout_actor_mm"]["median"].get<double>() == Approx(heldout * actor_scale));
    CHECK(s["heldout_mm"]["samples"].get<int>() == 9 * int(eval["heldout_markers"].size()));
    CHECK(s["jitter_mm"]["mean"].get<double>() >= 0.0);
    CHECK(s.contains("intersections"));
    CHECK(s.contains("flipped"));
  }
}

TEST_CASE("facecap calibrate and solve give clear errors on bad input", "[tools]") {
  const auto dir = facecap::test::scratch_dir("align-tools-bad");
  test::SyntheticTakeOptions o;
  o.rest_frames = 30;
  o.motion_frames = 10;
  auto synthetic = test::make_synthetic_take(o);
  // Four markers only.
  auto few = to_take(synthetic, "mm");
  few.labels.resize(4);
  for (auto& f : few.frames) f.markers.resize(4);
  formats::write_take(dir / "few.trc", few);
  Run r = run_facecap(dir, {"calibrate", "--rig", "builtin", "--take", (dir / "few.trc").string(), "-o", (dir / "a.toml").string()});
  CHECK(r.exit_code == 1);
  CHECK(r.err.find("4 markers; calibration needs at least 6") != std::string::npos);
  // A frame that does not exist.
  formats::write_take(dir / "take.trc", to_take(synthetic, "mm"));
  r = run_facecap(dir, {"calibrate", "--rig", "builtin", "--take", (dir / "take.trc").string(), "--frame", "999", "-o", (dir / "a.toml").string()});
  CHECK(r.exit_code == 1);
  CHECK(r.err.find("no frame number 999") != std::string::npos);
  // A marker missing in every frame is left out (of the neutral search, the stable markers
  // and the fit) with a note; the rest calibrates.
  auto gappy = to_take(synthetic, "mm");
  for (auto& f : gappy.frames) formats::set_missing(f.markers[5]);
  formats::write_take(dir / "gappy.trc", gappy);
  r = run_facecap(dir, {"calibrate", "--rig", "builtin", "--take", (dir / "gappy.trc").string(), "--frame", "5", "-o", (dir / "g.toml").string()});
  INFO(r.out << r.err);
  CHECK(r.exit_code == 0);
  CHECK(r.out.find(fmt::format("'{}' present in fewer than half of the take's frames: left out", gappy.labels[5])) !=
        std::string::npos);
  // A profile made for another rig.
  r = run_facecap(dir, {"calibrate", "--rig", "builtin", "--take", (dir / "take.trc").string(), "--frame", "5", "-o", (dir / "a.toml").string()});
  REQUIRE(r.exit_code == 0);
  std::string text = slurp(dir / "a.toml");
  const auto at = text.find("content_hash = \"");
  text.replace(at + 16, 16, "0123456789abcdef");
  text.erase(text.find("checksum"), text.find('\n', text.find("checksum")) - text.find("checksum") + 1);
  facecap::test::write_text(dir / "other.toml", text);
  r = run_facecap(dir, {"solve", "--rig", "builtin", "--calib", (dir / "other.toml").string(), "--take", (dir / "take.trc").string(), "-o",
                        (dir / "out.csv").string()});
  CHECK(r.exit_code == 1);
  CHECK(r.err.find("calibrate again") != std::string::npos);
  // An unknown solver and an unknown output format.
  r = run_facecap(dir, {"solve", "--rig", "builtin", "--calib", (dir / "a.toml").string(), "--take", (dir / "take.trc").string(), "-o",
                        (dir / "out.csv").string(), "--solver", "magic"});
  CHECK(r.exit_code == 1);
  CHECK(r.err.find("\"magic\" is not allowed (allowed: one of: nonlinear") != std::string::npos);
  r = run_facecap(dir, {"solve", "--rig", "builtin", "--calib", (dir / "a.toml").string(), "--take", (dir / "take.trc").string(), "-o",
                        (dir / "out.txt").string()});
  CHECK(r.exit_code == 1);
  CHECK(r.err.find(".csv") != std::string::npos);
  // A take in mm whose header says cm (the profile was made in mm): refused by solve and
  // eval, naming the units it looks like; told --units mm, it solves.
  formats::write_take(dir / "says_cm.trc", to_take(synthetic, "cm"));
  const std::vector<std::string> solve_says_cm = {"solve", "--rig", "builtin", "--calib", (dir / "a.toml").string(), "--take",
                                                  (dir / "says_cm.trc").string(), "-o", (dir / "units.csv").string(), "-q"};
  r = run_facecap(dir, solve_says_cm);
  CHECK(r.exit_code == 1);
  CHECK_THAT(r.err, Catch::Contains("says_cm.trc: read in cm as it states, its face is 10 times the size of the calibrated "
                                    "one: its values look like mm; pass --units mm if they are"));
  r = run_facecap(dir, {"eval", "--rig", "builtin", "--calib", (dir / "a.toml").string(), "--take", (dir / "says_cm.trc").string()});
  CHECK(r.exit_code == 1);
  CHECK_THAT(r.err, Catch::Contains("look like mm"));
  std::vector<std::string> told = solve_says_cm;
  told.insert(told.end(), {"--units", "mm"});
  r = run_facecap(dir, told);
  INFO(r.out << r.err);
  CHECK(r.exit_code == 0);
}

TEST_CASE("facecap eval on a real AnimFace take reports held-out error for every solver", "[tools][data]") {
  FACECAP_REQUIRE_SHARED_DATA(ict, "ict-face");
  FACECAP_REQUIRE_SHARED_DATA(animface, "markers/animface");
  const auto dir = facecap::test::scratch_dir("align-tools-animface");
  const auto take = (animface / "JawMoCap.trc").string();
  Run r = run_facecap(dir, {"calibrate", "--rig", ict.string(), "--take", take, "-o", (dir / "actor.toml").string()});
  INFO(r.out << r.err);
  REQUIRE(r.exit_code == 0);
  // meshik is left out: holding out each of the ~60 markers in turn costs it about 2 s a
  // marker on a single frame, two minutes of CI (its eval fields are checked against a
  // synthetic take's truth in test_tools).
  r = run_facecap(dir, {"eval", "--rig", ict.string(), "--take", take, "--calib", (dir / "actor.toml").string(), "--solver",
                        "nonlinear,linear,dt", "--json", "--max-frames", "240", "--every", "60"});
  INFO(r.out << r.err);
  REQUIRE(r.exit_code == 0);
  const auto eval = nlohmann::json::parse(r.out);
  CHECK(eval["frames"] == 240);
  // ICT is an artist's linear blend: no refinements, the outer edge held.
  CHECK(eval["solver"]["weight_refinements"] == 0);
  CHECK(eval["solver"]["boundary_hold"] == 0.003);
  CHECK(eval["stable_residual_mm"]["median"].get<double>() < 1.0);
  for (const char* name : {"nonlinear", "linear", "dt"}) {
    INFO(name);
    REQUIRE(eval["solvers"].contains(name));
    const double heldout = eval["solvers"][name]["heldout_mm"]["median"].get<double>();
    CHECK(heldout > 0.1);
    CHECK(heldout < 5.0);
    // Flips and crossings by region, split into the rig's own (its linear blend of the
    // same weights) and the solve's; the parts add up to the totals.
    for (const char* what : {"flipped", "intersections"}) {
      INFO(what);
      const auto& m = eval["solvers"][name][what];
      double in_blend = 0, added = 0;
      for (const char* region : {"lips", "eyelids", "elsewhere"}) {
        in_blend += m["per_checked_frame_by_region"][region]["in_rig_blend"].get<double>();
        added += m["per_checked_frame_by_region"][region]["added_by_solve"].get<double>();
      }
      const double total = m[std::string(what) == "flipped" ? "triangles_per_checked_frame" : "new_pairs_per_checked_frame"];
      CHECK(in_blend + added == Approx(total));
      CHECK(m["added_by_solve_per_checked_frame"].get<double>() == Approx(added));
      // The linear solve is the rig's linear blend: it adds nothing of its own.
      if (std::string(name) == "linear") CHECK(added == 0.0);
    }
  }
  // ICT's lips fold and cross in its own shapes (its neutral has 124 crossing pairs at the
  // lip corners): the lips hold most of what the linear blend shows.
  const auto& lips = eval["solvers"]["linear"]["intersections"]["per_checked_frame_by_region"];
  CHECK(lips["lips"]["in_rig_blend"].get<double>() > lips["elsewhere"]["in_rig_blend"].get<double>());
}

// The take where the mesh's free outer edge showed: with a forehead marker held out, the
// pinned solve carried the brow's motion up to the forehead's edge (p95 7.26 mm against
// linear's 7.13 without solver.boundary_hold). Held, nonlinear is the better of the two.
TEST_CASE("on EyebrowsMoCap, nonlinear's held-out error is below linear's, median and p95, and its folds are undone "
          "at no cost in held-out error", "[tools][data]") {
  FACECAP_REQUIRE_SHARED_DATA(ict, "ict-face");
  FACECAP_REQUIRE_SHARED_DATA(animface, "markers/animface");
  const auto dir = facecap::test::scratch_dir("align-tools-eyebrows");
  const auto take = (animface / "EyebrowsMoCap.trc").string();
  Run r = run_facecap(dir, {"calibrate", "--rig", ict.string(), "--take", take, "-o", (dir / "actor.toml").string()});
  INFO(r.out << r.err);
  REQUIRE(r.exit_code == 0);
  r = run_facecap(dir, {"eval", "--rig", ict.string(), "--take", take, "--calib", (dir / "actor.toml").string(), "--solver",
                        "nonlinear,linear", "--json", "--every", "10"});
  INFO(r.out << r.err);
  REQUIRE(r.exit_code == 0);
  const auto eval = nlohmann::json::parse(r.out);
  const auto& nonlinear = eval["solvers"]["nonlinear"]["heldout_actor_mm"];
  const auto& linear = eval["solvers"]["linear"]["heldout_actor_mm"];
  WARN(fmt::format("EyebrowsMoCap held out, actor mm: nonlinear median {:.3f} p95 {:.2f}, linear median {:.3f} p95 {:.2f}",
                   nonlinear["median"].get<double>(), nonlinear["p95"].get<double>(), linear["median"].get<double>(),
                   linear["p95"].get<double>()));
  CHECK(nonlinear["median"].get<double>() < linear["median"].get<double>());
  CHECK(nonlinear["p95"].get<double>() < linear["p95"].get<double>());
  CHECK(eval["solvers"]["nonlinear"]["folds"]["folded_frames"].get<int>() == 0);

  // The paper's solve (no fold stage) folds the brow on about 120 frames. Undoing those
  // folds costs no held-out error: the fold pins hold the blend's shape where the skin
  // around the fold is. Pinned to the blend where it is, a brow marker's neighbours went
  // 4-5 mm further off when it was held out (Reyebrow_Inside p95 7.6 -> 12.4 mm, the take's
  // p95 +3.1%).
  r = run_facecap(dir, {"eval", "--rig", ict.string(), "--take", take, "--calib", (dir / "actor.toml").string(), "--solver",
                        "nonlinear", "--json", "--every", "10", "--set", "solver.fold_max_pins=0"});
  INFO(r.out << r.err);
  REQUIRE(r.exit_code == 0);
  const auto paper = nlohmann::json::parse(r.out)["solvers"]["nonlinear"];
  CHECK(paper["folds"]["folded_frames"].get<int>() > 50);
  CHECK(nonlinear["median"].get<double>() <= 1.02 * paper["heldout_actor_mm"]["median"].get<double>());
  CHECK(nonlinear["p95"].get<double>() <= 1.02 * paper["heldout_actor_mm"]["p95"].get<double>());
  for (const std::string marker : {"Reyebrow_Inside", "Reyebrow_Outside", "Reyebrow_M", "Leyebrow_Inside"}) {
    INFO(marker);
    CHECK(eval["solvers"]["nonlinear"]["heldout_actor_mm_by_marker"][marker]["p95"].get<double>() <=
          1.1 * paper["heldout_actor_mm_by_marker"][marker]["p95"].get<double>());
  }
}

// Frame 125 of CheeksMoCap: pinning only a folded triangle's corners pushed the fold onto
// the triangle beside it, round after round, and it was still folded after the last
// round (flagged). From the third round the fold stage pins the triangles beside a fold
// too.
TEST_CASE("CheeksMoCap's first 140 frames solve without a folded frame", "[tools][data]") {
  FACECAP_REQUIRE_SHARED_DATA(ict, "ict-face");
  FACECAP_REQUIRE_SHARED_DATA(animface, "markers/animface");
  const auto dir = facecap::test::scratch_dir("align-tools-cheeks");
  const auto take = (animface / "CheeksMoCap.trc").string();
  Run r = run_facecap(dir, {"calibrate", "--rig", ict.string(), "--take", take, "-o", (dir / "actor.toml").string()});
  INFO(r.out << r.err);
  REQUIRE(r.exit_code == 0);
  r = run_facecap(dir, {"eval", "--rig", ict.string(), "--take", take, "--calib", (dir / "actor.toml").string(), "--solver",
                        "nonlinear", "--json", "--every", "10", "--max-frames", "140"});
  INFO(r.out << r.err);
  REQUIRE(r.exit_code == 0);
  const auto folds = nlohmann::json::parse(r.out)["solvers"]["nonlinear"]["folds"];
  INFO(folds.dump());
  CHECK(folds["frames"].get<int>() == 140);
  CHECK(folds["folded_frames"].get<int>() == 0);
  CHECK(folds["flagged_frames"].get<int>() == 0);
}
