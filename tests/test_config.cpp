// facecapd.toml: the schema, the shipped file, and the messages for bad configurations.
#include <cstdio>
#include <fstream>
#include <set>
#include <sstream>

#include <catch2/catch.hpp>

#include "config/config_file.hpp"
#include "config/schema.hpp"
#include "tests/test_support.hpp"

using namespace facecap;
using namespace facecap::config;
using Catch::Contains;
namespace fs = std::filesystem;

namespace {

fs::path write_config(const std::string& name, const std::string& text) {
  static const fs::path dir = test::scratch_dir("config");
  const fs::path path = dir / name;
  test::write_text(path, text);
  return path;
}

// The one problem of a configuration that must have exactly one.
Error only_problem(const fs::path& path, const std::vector<std::string>& overrides = {}) {
  try {
    load_config(path.string(), overrides);
  } catch (const ConfigError& e) {
    INFO(e.what());
    REQUIRE(e.problems().size() == 1);
    return e.problems().front();
  }
  FAIL("the configuration was accepted");
  return Error("unreachable");
}

std::string read_text(const fs::path& path) {
  std::ifstream in(path);
  std::stringstream s;
  s << in.rdbuf();
  return s.str();
}

using test::run_and_capture;

}  // namespace

TEST_CASE("every schema key has a default of its own type and sections are contiguous") {
  std::set<std::string_view> paths, finished_sections;
  std::string_view section = "\x01";
  for (const KeySpec& key : config_schema()) {
    INFO(key.path);
    CHECK(paths.insert(key.path).second);
    // A choice's value is its name; every other key's value has its type's alternative.
    if (key.type() == ValueType::kChoice) CHECK(std::holds_alternative<std::string>(key.default_value));
    else CHECK(key.default_value.index() == std::size_t(key.type()));
    CHECK_FALSE(key.description.empty());
    if (key.section() != section) {
      CHECK(finished_sections.insert(section).second);
      section = key.section();
      CHECK_FALSE(finished_sections.count(section));
    }
    if (key.type() == ValueType::kFloat || key.type() == ValueType::kInt) {
      const double d = key.type() == ValueType::kFloat ? std::get<double>(key.default_value)
                                                       : double(std::get<int64_t>(key.default_value));
      CHECK(d >= key.min);
      CHECK(d <= key.max);
    }
    if (key.type() == ValueType::kChoice) {
      const auto choices = key.choices();
      CHECK(std::count_if(choices.begin(), choices.end(),
                          [&](const Choice& c) { return c.name == std::get<std::string>(key.default_value); }) == 1);
    }
  }
  CHECK(paths.count("loop.rate_hz"));
  CHECK(default_config().loop.rate_hz == 120.0);
  CHECK(default_config().source.driver == drivers::DriverId::kSim);
}

TEST_CASE("the [solver] defaults are the solver's own, and its choices its tables'") {
  const SolverSection s = default_config().solver;
  const SolverParams p;
  CHECK(s.method == SolverMethod::kNonlinear);
  CHECK(s.alpha == p.alpha);
  CHECK(s.mu == p.mu);
  CHECK(s.beta == p.beta);
  CHECK(s.weight_refinements == p.weight_refinements);
  CHECK(s.collision_region == p.collision_region);
  CHECK(s.collision_epsilon == p.collision_epsilon);
  CHECK(s.collision_max_pins == p.collision_max_pins);
  CHECK(s.active_weight == p.active_weight);
  REQUIRE(find_key("solver.collisions")->choices().size() == kCollisionRegions.size());
  CHECK(find_key("solver.method")->choices()[3].name == "meshik");
  const LoadedConfig c = load_config("", {"solver.collisions=face", "solver.collision_max_pins=128", "solver.method=dt"});
  CHECK(c.values.solver.collision_region == CollisionRegion::kFace);
  CHECK(c.values.solver.collision_max_pins == 128);
  CHECK(c.values.solver.method == SolverMethod::kDt);
}

TEST_CASE("the shipped config/facecapd.toml is exactly what the schema generates") {
  const fs::path shipped = fs::path(FACECAP_SOURCE_DIR) / "config" / "facecapd.toml";
  INFO("regenerate with: build/daemon/facecapd --print-default-config > config/facecapd.toml");
  CHECK(read_text(shipped) == render_documented_defaults());
  // And it loads to the defaults, every key coming from the file.
  const LoadedConfig loaded = load_config(shipped.string());
  CHECK(changed_keys(loaded.values, default_config()).empty());
  for (const KeySpec& key : config_schema()) {
    INFO(key.path);
    CHECK(loaded.origin_of(key.path).origin == Origin::kFile);
  }
}

TEST_CASE("an unknown key names its file position and suggests the key meant") {
  const auto path = write_config("unknown.toml", "version = 1\n\n[loop]\nrate_hz = 240\nrte_hz = 500\n");
  const Error e = only_problem(path);
  CHECK(e.where().line == 5);
  CHECK(e.where().column == 10);
  CHECK(e.where().key == "loop.rte_hz");
  CHECK_THAT(e.what(), Contains(path.string() + ":5:10 [loop.rte_hz]: unknown key 'rte_hz' in [loop]; did you mean 'rate_hz'?"));
}

TEST_CASE("an unknown section is an error with a suggestion") {
  const auto path = write_config("section.toml", "version = 1\n[outptus.shm]\nname = \"x\"\n");
  CHECK_THAT(only_problem(path).what(), Contains("[outptus]: unknown key 'outptus' at the top level; did you mean 'outputs'?"));
}

TEST_CASE("a value of the wrong type says what was expected and what was found") {
  const auto path = write_config("type.toml", "version = 1\n[loop]\nrate_hz = \"fast\"\n");
  const Error e = only_problem(path);
  CHECK(e.where().line == 3);
  CHECK_THAT(e.what(), Contains(":3:11 [loop.rate_hz]: expected a number, got string \"fast\""));
  const auto ints = write_config("int.toml", "version = 1\n[outputs.shm]\nslots = 2.5\n");
  CHECK_THAT(only_problem(ints).what(), Contains("[outputs.shm.slots]: expected an integer, got number 2.5"));
}

TEST_CASE("an out-of-range value shows the bad value and the allowed range with its unit") {
  const auto path = write_config("range.toml", "version = 1\n[loop]\nrate_hz = 5000\n");
  CHECK_THAT(only_problem(path).what(),
             Contains(":3:11 [loop.rate_hz]: 5000.0 is out of range (allowed: 1 to 2000 Hz)"));
  const auto version = write_config("version.toml", "version = 2\n");
  CHECK_THAT(only_problem(version).what(), Contains("[version]: 2 is out of range (allowed: exactly 1)"));
}

TEST_CASE("a value outside its choices lists them and suggests the nearest") {
  const auto path = write_config("choice.toml", "version = 1\n[source]\ndriver = \"simm\"\n");
  CHECK_THAT(only_problem(path).what(),
             Contains("[source.driver]: \"simm\" is not allowed (allowed: one of: sim, replay); did you mean \"sim\"?"));
}

TEST_CASE("a rig file that does not exist is reported at its key") {
  const auto path = write_config("rig.toml", "version = 1\n[rig]\npath = \"faces/missing\"\n");
  const Error e = only_problem(path);
  CHECK(e.where().key == "rig.path");
  CHECK(e.where().line == 3);
  // Relative input paths are relative to the configuration file.
  CHECK_THAT(e.what(), Contains((path.parent_path() / "faces/missing").string() + "\" does not exist"));
}

TEST_CASE("every problem of a file is reported at once in file order") {
  const auto path = write_config("many.toml",
                                 "version = 1\n[loop]\nrte_hz = 5\nrate_hz = \"fast\"\n[rig]\npath = \"/nope/face\"\n"
                                 "[outputs.shm]\nslots = 5000\n");
  try {
    load_config(path.string());
    FAIL("accepted");
  } catch (const ConfigError& e) {
    REQUIRE(e.problems().size() == 4);
    CHECK(e.problems()[0].where().key == "loop.rte_hz");
    CHECK(e.problems()[1].where().key == "loop.rate_hz");
    CHECK(e.problems()[2].where().key == "rig.path");
    CHECK(e.problems()[3].where().key == "outputs.shm.slots");
  }
}

TEST_CASE("rules across keys point at the key to change") {
  const auto replay = write_config("replay.toml", "version = 1\n[source]\ndriver = \"replay\"\n");
  CHECK_THAT(only_problem(replay).what(), Contains("[source.replay.file]: source.driver is \"replay\" but no file is given"));
  const auto lockstep = write_config("lockstep.toml", "version = 1\n[loop]\nmode = \"lockstep\"\n");
  CHECK_THAT(only_problem(lockstep).what(), Contains(":3:8 [loop.mode]: lockstep needs a source that can hand every frame"));
  const auto heads = write_config("heads.toml", "version = 1\n[calibration]\nhead_markers = 2\n");
  CHECK_THAT(only_problem(heads).what(), Contains("[calibration.head_markers]: 2 head markers cannot fix a rigid pose"));
}

TEST_CASE("a TOML syntax error gives its line and column") {
  const auto path = write_config("syntax.toml", "version = 1\n[loop\nrate_hz = 1\n");
  const Error e = only_problem(path);
  CHECK(e.where().line == 2);
  CHECK(e.where().file == path.string());
}

TEST_CASE("overrides apply after the file and are reported as such") {
  const auto path = write_config("base.toml", "version = 1\n[loop]\nrate_hz = 240\n");
  const LoadedConfig c = load_config(path.string(), {"loop.rate_hz=500", "outputs.shm.name=abc", "source.sim.seed = 7"});
  CHECK(c.values.loop.rate_hz == 500.0);
  CHECK(c.values.outputs.shm.name == "abc");  // unquoted string accepted
  CHECK(c.values.source.sim.seed == 7);
  CHECK(c.origin_of("loop.rate_hz").origin == Origin::kCommandLine);
  CHECK(c.origin_of("loop.mode").origin == Origin::kDefault);
  const std::string printed = render_effective_config(c);
  CHECK_THAT(printed, Contains("rate_hz = 500.0") && Contains("# --set"));
  CHECK_THAT(printed, Contains("mode = \"fixed\"") && Contains("# default"));
  CHECK_THAT(only_problem(path, {"loop.rate_hz=0"}).what(), Contains("--set [loop.rate_hz]: 0.0 is out of range"));
}

TEST_CASE("the old [recording] section is read as [outputs.recording] with a warning naming where") {
  const auto path = write_config("old.toml", "version = 1\n[recording]\nenabled = true\ndirectory = \"takes\"\n");
  const LoadedConfig c = load_config(path.string(), {"recording.queue_frames=64"});
  CHECK(c.values.outputs.recording.enabled);
  CHECK(c.values.outputs.recording.directory == "takes");  // relative to the working directory, as documented
  CHECK(c.values.outputs.recording.queue_frames == 64);
  REQUIRE(c.warnings.size() == 2);
  CHECK_THAT(c.warnings[0], Contains(path.string() + ":2") && Contains("[recording] is now [outputs.recording]"));
  CHECK_THAT(only_problem(path, {"recording.queue_frame=64"}).what(), Contains("unknown key 'queue_frame'"));
}

TEST_CASE("a choice key is stored as its enum and written back as its name") {
  const LoadedConfig c = load_config("", {"source.driver=replay", "source.replay.file=" + std::string(FACECAP_SOURCE_DIR) +
                                                                      "/README.md", "loop.mode=lockstep"});
  CHECK(c.values.source.driver == drivers::DriverId::kReplay);
  CHECK(c.values.loop.mode == LoopMode::kLockstep);
  CHECK(format_value(get_value(*find_key("loop.mode"), c.values)) == "\"lockstep\"");
  CHECK_THAT(render_documented_defaults(), Contains("#   lockstep: solve every frame of the source in order"));
  CHECK_THAT(only_problem(write_config("meshik.toml", "version = 1\n[solver]\nmethod = \"meshik\"\n")).what(),
             Contains("meshik.toml:3:10 [solver.method]: meshik is an offline baseline that takes seconds a frame"));
  CHECK_THAT(only_problem(write_config("lock.toml", "version = 1\n[loop]\nmode = \"lockstep\"\n")).what(),
             Contains("[loop.mode]: lockstep needs a source that can hand every frame on request; the sim driver"));
}

TEST_CASE("changed_keys lists exactly the keys that differ") {
  DaemonConfig a = default_config(), b = default_config();
  b.solver.alpha = 0.5;
  b.logging.level = LogLevel::kDebug;
  const auto changed = changed_keys(a, b);
  REQUIRE(changed.size() == 2);
  CHECK(changed[0]->path == "solver.alpha");
  CHECK(changed[0]->reload == Reload::kRebuild);
  CHECK(changed[1]->path == "logging.level");
  CHECK(changed[1]->reload == Reload::kLive);
}

TEST_CASE("did-you-mean only suggests near misses") {
  CHECK(closest_match("rte_hz", {"rate_hz", "mode"}) == "rate_hz");
  CHECK(closest_match("colour", {"rate_hz", "mode"}).empty());
}

TEST_CASE("facecapd --check-config exits 0 for a valid file and 1 with the problems") {
  const std::string facecapd = std::string(FACECAP_BINARY_DIR) + "/daemon/facecapd";
  const auto good = write_config("good.toml", "version = 1\n[loop]\nrate_hz = 240\n");
  const auto bad = write_config("bad.toml", "version = 1\n[loop]\nrte_hz = 240\n");
  int status = 0;
  std::string out = run_and_capture(facecapd + " --check-config " + good.string() + " 2>&1", &status);
  CHECK(WEXITSTATUS(status) == 0);
  CHECK_THAT(out, Contains("valid"));
  out = run_and_capture(facecapd + " --check-config " + bad.string() + " 2>&1", &status);
  CHECK(WEXITSTATUS(status) == 1);
  CHECK_THAT(out, Contains("did you mean 'rate_hz'?"));
  // Running with a bad file starts nothing and says so.
  out = run_and_capture(facecapd + " --config " + bad.string() + " 2>&1", &status);
  CHECK(WEXITSTATUS(status) == 1);
  CHECK_THAT(out, Contains("invalid configuration, nothing started"));
}

TEST_CASE("the key reference in docs/config.md is what the schema generates") {
  const std::string doc = read_text(fs::path(FACECAP_SOURCE_DIR) / "docs" / "config.md");
  INFO("regenerate the part of docs/config.md between the markers with: build/daemon/facecapd --print-config-reference");
  const std::string begin = "<!-- key reference: generated by `facecapd --print-config-reference`; a test checks it -->\n";
  const std::string end = "<!-- end of key reference -->";
  const auto a = doc.find(begin), b = doc.find(end);
  REQUIRE(a != std::string::npos);
  REQUIRE(b != std::string::npos);
  CHECK(doc.substr(a + begin.size(), b - a - begin.size()) == render_markdown_reference());
}

TEST_CASE("a configuration that is not UTF-8 is refused at the first bad byte") {
  const auto path = write_config("latin1.toml", "version = 1\n[outputs.shm]\nname = \"caf\xe9\"\n");
  const Error e = only_problem(path);
  CHECK(e.where().file == path.string());
  CHECK(e.where().line == 3);
  CHECK(e.where().column == 12);
  CHECK_THAT(e.message(), Contains("0xe9") && Contains("not valid UTF-8"));
}