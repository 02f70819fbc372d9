// Golden replays: a live solve in facecapd and an offline `facecap solve` of the same take
// with the same calibration profile and [solver] section are the same solve, to the last
// bit; and a recording solved again from what it stores reproduces itself.
// (gpsd's regress-driver is the model; `facecap diff` is the comparison.)
#include <catch2/catch.hpp>
#include <fmt/format.h>
#include <nlohmann/json.hpp>
#include <unistd.h>

#include "formats/recording.hpp"
#include "formats/take.hpp"
#include "tests/test_support.hpp"

using namespace facecap;
namespace fs = std::filesystem;

namespace {

// The golden tolerances: weights to 1e-9, vertices to 1e-9 cm.
const std::vector<std::string> kGolden = {"--tolerance-weight", "1e-9", "--tolerance-mm", "1e-8", "--json"};

nlohmann::json diff(const fs::path& dir, const fs::path& a, const fs::path& b, int expected_exit) {
  std::vector<std::string> args = {"diff", a.string(), b.string()};
  args.insert(args.end(), kGolden.begin(), kGolden.end());
  const test::Run r = test::run_facecap(dir, args);
  INFO(r.err);
  REQUIRE(r.exit_code == expected_exit);
  return nlohmann::json::parse(r.out);
}

}  // namespace

TEST_CASE("facecapd in lockstep and facecap solve give the same frames of a real take, and a recording re-solves to itself",
          "[data][golden]") {
  FACECAP_REQUIRE_SHARED_DATA(ict, "ict-face");
  FACECAP_REQUIRE_SHARED_DATA(jaw, "markers/animface/JawMoCap.trc");
  const fs::path dir = test::scratch_dir("golden");
  // The calibration, as an operator makes it, from the whole take.
  test::Run r = test::run_facecap(dir, {"calibrate", "--rig", ict.string(), "--take", jaw.string(), "--auto-neutral",
                                        "-o", (dir / "actor.toml").string()});
  INFO(r.out << r.err);
  REQUIRE(r.exit_code == 0);
  // The first 600 frames (10 s at 60 Hz): enough of the jaw's range, recordings of 50 MB.
  formats::MarkerTake take = formats::read_take(jaw);
  take.frames.resize(600);
  const fs::path trc = dir / "jaw.trc";
  formats::write_take(trc, take);
  // Non-default solver settings, so that a solve with the defaults would differ; the
  // temporal filter on in both (by default facecapd filters and facecap solve does not).
  test::write_text(dir / "facecapd.toml", fmt::format(R"(version = 1
[source]
driver = "replay"
[source.replay]
file = "{}"
[rig]
path = "{}"
[calibration]
file = "{}"
[solver]
alpha = 0.2
weight_refinements = 1
[filter]
mode = "on"
[loop]
mode = "lockstep"
realtime = false
[outputs.shm]
name = "facecap-test-{}-golden"
[outputs.recording]
enabled = true
directory = "{}"
vertices = true
)", trc.string(), ict.string(), (dir / "actor.toml").string(), ::getpid(), (dir / "rec").string()));

  std::vector<std::string> facecapd_args = {"--config", (dir / "facecapd.toml").string()};
  r = test::run_built("daemon/facecapd", dir, facecapd_args);
  INFO(r.out << r.err);
  REQUIRE(r.exit_code == 0);
  REQUIRE(fs::is_directory(dir / "rec"));
  const fs::path live = fs::directory_iterator(dir / "rec")->path();
  {
    const formats::RecordingReader reader(live);
    CHECK(reader.solved_frame_count() == 600);
    CHECK(reader.header().rate_hz == take.rate_hz);
    CHECK(reader.header().rig_units == "cm");
    CHECK_THAT(reader.header().solver_settings, Catch::Contains("alpha = 0.2\n") && Catch::Contains("stabilise_head = true") &&
                                                   Catch::Contains("[filter]\nmode = \"on\"\n"));
  }

  // The same take offline, with the same profile and the daemon's own configuration file.
  const fs::path offline = dir / "offline.fcrec";
  r = test::run_facecap(dir, {"solve", "--rig", ict.string(), "--calib", (dir / "actor.toml").string(), "--take",
                              trc.string(), "-o", offline.string(), "--vertices", "--config",
                              (dir / "facecapd.toml").string(), "-q"});
  INFO(r.out << r.err);
  REQUIRE(r.exit_code == 0);
  nlohmann::json same = diff(dir, live, offline, 0);
  INFO(same.dump(2));
  CHECK(same["frames"]["compared"] == 600);
  CHECK(same["vertices_mm"]["frames"] == 600);
  CHECK(same["weights"]["max"].get<double>() <= 1e-9);
  CHECK(same["vertices_mm"]["max"].get<double>() <= 1e-8);
  CHECK(same["head_rotation_degrees"]["max"].get<double>() <= 1e-9);
  CHECK(same["flags"]["frames_differ"] == 0);
  CHECK(same["solver_settings"]["differ"] == false);
  WARN("facecapd vs facecap solve: largest weight difference " << same["weights"]["max"] << ", largest vertex "
       "difference " << same["vertices_mm"]["max"] << " mm over " << same["frames"]["compared"] << " frames");

  // The live recording solved again from what it stores: its calibration and settings.
  const fs::path again = dir / "again.fcrec";
  r = test::run_facecap(dir, {"solve", "--rig", ict.string(), "--take", live.string(), "-o", again.string(),
                              "--vertices", "-q"});
  INFO(r.out << r.err);
  REQUIRE(r.exit_code == 0);
  CHECK_THAT(r.out, Catch::Contains("the recording's stored settings"));
  same = diff(dir, live, again, 0);
  CHECK(same["frames"]["compared"] == 600);
  CHECK(same["vertices_mm"]["max"].get<double>() <= 1e-8);

  // Told otherwise (the default alpha), the same recording solves differently: the
  // comparison above can fail.
  r = test::run_facecap(dir, {"solve", "--rig", ict.string(), "--take", live.string(), "-o", (dir / "other.fcrec").string(),
                              "--set", "solver.alpha=0.1", "-q"});
  REQUIRE(r.exit_code == 0);
  const nlohmann::json differs = diff(dir, live, dir / "other.fcrec", 1);
  CHECK(differs["weights"]["max"].get<double>() > 1e-4);
  CHECK(differs["solver_settings"]["differ"] == true);
}
