// Live Link Face CSV reader/writer and the ARKit <-> rig name map.
#include <cmath>
#include <set>

#include <catch2/catch.hpp>
#include <fmt/format.h>

#include "core/error.hpp"
#include "core/io.hpp"
#include "formats/arkit.hpp"
#include "formats/livelinkface.hpp"
#include "tests/test_support.hpp"

using namespace facecap;
using namespace facecap::formats;

namespace {

std::size_t shape(std::string_view arkit) { return *arkit_shape_index(arkit); }

std::string replace_first(std::string s, std::string_view from, std::string_view to) {
  const auto at = s.find(from);
  REQUIRE(at != std::string::npos);
  return s.replace(at, from.size(), to);
}

FaceTake small_take() {
  FaceTake take;
  for (int i = 0; i < 4; ++i) {
    FaceFrame& f = take.frames.emplace_back();
    f.timecode = *parse_livelink_timecode(fmt::format("10:00:00:{:02}.250", 2 * i));
    f.tracked = i != 2;
    for (std::size_t s = 0; s < kArkitShapeCount; ++s)
      f.weights[s] = f.tracked ? float(s) / 52.0f + 0.01f * float(i) : NAN;
    for (std::size_t a = 0; a < kLiveLinkAngleCount; ++a) f.angles[a] = f.tracked ? -0.5f + 0.1f * float(a) : NAN;
  }
  take.frames[1].weights[shape("JawOpen")] = 1.0125f;  // the app writes slightly more than 1
  return take;
}

}  // namespace

TEST_CASE("ARKit names map to rig names and back, all 52", "[arkit]") {
  CHECK(kArkitShapes.size() == 52);
  CHECK(arkit_to_rig_name("JawOpen") == "jawOpen");
  CHECK(arkit_to_rig_name("EyeBlinkLeft") == "eyeBlink_L");
  CHECK(arkit_to_rig_name("eyeBlinkLeft") == "eyeBlink_L");  // Apple's camelCase
  CHECK(arkit_to_rig_name("MouthSmileRight") == "mouthSmile_R");
  CHECK(arkit_to_rig_name("HeadYaw") == std::nullopt);
  CHECK(rig_to_arkit_name("eyeBlink_L") == "EyeBlinkLeft");
  CHECK(rig_to_arkit_name("jawOpen") == "JawOpen");
  CHECK(rig_to_arkit_name("cheekRaiser_L") == std::nullopt);
  std::set<std::string_view> arkit, rig;
  for (const auto& s : kArkitShapes) {
    INFO(s.arkit);
    arkit.insert(s.arkit);
    rig.insert(s.rig);
    // The rule behind the table: lower-case first letter, a side suffix Left/Right ->
    // _L/_R; jawLeft, mouthRight, ... name directions, not sides, and keep the word.
    std::string expected(s.arkit);
    expected[0] = char(std::tolower(expected[0]));
    const bool direction =
        expected == "jawLeft" || expected == "jawRight" || expected == "mouthLeft" || expected == "mouthRight";
    if (!direction && expected.ends_with("Left")) expected.replace(expected.size() - 4, 4, "_L");
    if (!direction && expected.ends_with("Right")) expected.replace(expected.size() - 5, 5, "_R");
    CHECK(s.rig == expected);
    CHECK(rig_to_arkit_name(s.rig) == s.arkit);
  }
  CHECK(arkit.size() == 52);
  CHECK(rig.size() == 52);
}

TEST_CASE("ARKit shapes bind to the ICT face's shapes", "[arkit][shared]") {
  FACECAP_REQUIRE_SHARED_DATA(dir, "ict-face");
  std::vector<std::string> rig_shapes;
  for (const auto& entry : std::filesystem::directory_iterator(dir)) {
    if (entry.path().extension() == ".obj" && entry.path().stem() != "generic_neutral_mesh")
      rig_shapes.push_back(entry.path().stem().string());
  }
  std::sort(rig_shapes.begin(), rig_shapes.end());
  REQUIRE(rig_shapes.size() == 57);
  const auto binding = match_arkit_to_rig(rig_shapes);
  std::size_t single = 0;
  for (std::size_t s = 0; s < kArkitShapeCount; ++s) {
    INFO(kArkitShapes[s].arkit);
    const std::string_view arkit = kArkitShapes[s].arkit;
    if (arkit == "TongueOut") {
      CHECK(binding[s].empty());  // ICT has no tongue
    } else if (arkit == "BrowInnerUp" || arkit == "CheekPuff") {
      REQUIRE(binding[s].size() == 2);  // split into _L and _R
      CHECK(rig_shapes[binding[s][0]] == std::string(kArkitShapes[s].rig) + "_L");
      CHECK(rig_shapes[binding[s][1]] == std::string(kArkitShapes[s].rig) + "_R");
    } else {
      REQUIRE(binding[s].size() == 1);
      CHECK(rig_shapes[binding[s][0]] == kArkitShapes[s].rig);
      ++single;
    }
  }
  CHECK(single == 49);
}

TEST_CASE("Live Link timecodes are HH:MM:SS:FF.fff on a 60 fps base", "[livelinkface]") {
  const auto tc = parse_livelink_timecode("12:27:47:47.169");
  REQUIRE(tc);
  CHECK(tc->hours == 12);
  CHECK(tc->minutes == 27);
  CHECK(tc->seconds == 47);
  CHECK(tc->frames == 47);
  CHECK(tc->subframe == Approx(0.169f));
  CHECK(tc->rate_hz == 60);
  CHECK(format_livelink_timecode(*tc) == "12:27:47:47.169");
  CHECK(parse_livelink_timecode("00:32:09:07") != std::nullopt);
  for (const char* bad :
       {"12:27:47:60.000", "12:61:00:00.0", "12:27:47", "1a:00:00:00.0", "12:27:47:47.", "12:27:47:47.1x"}) {
    INFO(bad);
    CHECK(parse_livelink_timecode(bad) == std::nullopt);
  }
}

TEST_CASE("Live Link timecodes of solved frames: one HH:MM:SS:FF per frame, rounded to a thousandth", "[livelinkface]") {
  // A 60 Hz take's frame times in whole ns fall a hair before the frame boundary: they
  // were written 00, 01, 01.999, 03; now each frame is its own, at .000.
  for (int64_t f = 0; f < 600; ++f) {
    const Timecode tc = livelink_timecode_at(f * 1'000'000'000 / 60);
    INFO(f);
    CHECK(int64_t(tc.seconds) * 60 + tc.frames == f);
    CHECK(format_livelink_timecode(tc).ends_with(".000"));
  }
  // 30 Hz steps by two frames, as the app's own 30 Hz files do.
  CHECK(format_livelink_timecode(livelink_timecode_at(3 * 33'333'333)) == "00:00:00:06.000");
  // The fraction is the phase within the frame, as real files have it (S07-001: .169).
  const int64_t start = timecode_time_ns(*parse_livelink_timecode("12:27:47:47.169"));
  CHECK(format_livelink_timecode(livelink_timecode_at(start)) == "12:27:47:47.169");
  CHECK(format_livelink_timecode(livelink_timecode_at(start + 33'333'333)) == "12:27:47:49.169");
  CHECK(format_livelink_timecode(livelink_timecode_at(33'323'333)) == "00:00:00:01.999");  // 1.9994 frames
  // A day wraps; a timecode at another rate is re-based (25 fps frame 5 = 0.2 s = 60 fps frame 12).
  CHECK(format_livelink_timecode(livelink_timecode_at(24 * 3600 * kNsPerSecond + kNsPerSecond)) == "00:00:01:00.000");
  Timecode pal;
  pal.rate_hz = 25;
  pal.frames = 5;
  CHECK(format_livelink_timecode(livelink_timecode_at(timecode_time_ns(pal))) == "00:00:00:12.000");
}

TEST_CASE("Live Link Face writer output reads back; BlendShapeCount in either case", "[livelinkface]") {
  const FaceTake take = small_take();
  const std::string text = write_livelinkface(take);
  CHECK(text.find("10:00:00:04.250,0\n") != std::string::npos);                    // the lost row
  CHECK(text.find(",JawForward,JawRight,JawLeft,JawOpen,") != std::string::npos);  // the app's order
  for (const std::string& variant : {text, replace_first(text, "BlendShapeCount", "blendShapeCount")}) {
    const FaceTake back = read_livelinkface(variant, "written.csv");
    REQUIRE(back.frames.size() == 4);
    CHECK(back.lost_frames() == 1);
    CHECK(back.rate_hz == 30.0);
    CHECK(back.warnings.empty());
    for (std::size_t i = 0; i < 4; ++i) {
      INFO("frame " << i);
      CHECK(back.frames[i].timecode == take.frames[i].timecode);
      CHECK(back.frames[i].tracked == take.frames[i].tracked);
      for (std::size_t s = 0; s < kArkitShapeCount; ++s) {
        if (take.frames[i].tracked) {
          CHECK(back.frames[i].weights[s] == Approx(take.frames[i].weights[s]).margin(1e-9));
        } else {
          CHECK(std::isnan(back.frames[i].weights[s]));
        }
      }
    }
    CHECK(back.frames[1].weights[shape("JawOpen")] == Approx(1.0125f));
    CHECK(back.frames[3].angles[8] == Approx(0.3f));
  }
}

TEST_CASE("Live Link Face errors name line, column and cause", "[livelinkface]") {
  const std::string text = write_livelinkface(small_take());
  auto expect_error = [](const std::string& csv, std::string_view location, std::string_view what) {
    try {
      read_livelinkface(csv, "bad.csv");
      FAIL("no error");
    } catch (const Error& e) {
      INFO(e.what());
      CHECK(std::string(e.what()).find(location) == 0);
      CHECK(std::string(e.what()).find(what) != std::string::npos);
    }
  };
  expect_error(replace_first(text, "10:00:00:02.250", "10:00:00:72.250"), "bad.csv:3:1", "timecode '10:00:00:72.250'");
  expect_error(replace_first(text, ",JawOpen,", ",JawOpened,"), "bad.csv:1", "lacks the JawOpen column");
  expect_error(replace_first(text, "Timecode,", "Time,"), "bad.csv:1", "not a Live Link Face CSV");
  expect_error(replace_first(text, ",61,0.0000000000,", ",61,0.0x,"), "bad.csv:2:20",
               "EyeBlinkLeft value '0.0x' is not a number");
  expect_error(text.substr(0, text.size() - 30), "bad.csv:5:", "row has");
}

TEST_CASE("Live Link Face: every CSV in ../shared/data/livelinkface reads with its gaps counted",
          "[livelinkface][shared]") {
  struct Expected {
    const char* file;
    std::size_t frames, lost;
    double rate_hz;
  };
  for (const Expected& e :
       {Expected{"alexdjulin_S07-001.csv", 2028, 0, 30}, Expected{"alexdjulin_S88-001.csv", 1939, 277, 30},
        Expected{"alexdjulin_alex_rom_3.csv", 4030, 0, 30},
        Expected{"jmtechart_MySlate_3_Jason_Millers_iPhone.csv", 328, 0, 60}}) {
    INFO(e.file);
    FACECAP_REQUIRE_SHARED_DATA(path, std::string("livelinkface/") + e.file);
    const FaceTake take = read_livelinkface(path);
    CHECK(take.frames.size() == e.frames);
    CHECK(take.lost_frames() == e.lost);
    CHECK(take.rate_hz == e.rate_hz);
    CHECK(take.warnings.empty());
  }

  FACECAP_REQUIRE_SHARED_DATA(s07, "livelinkface/alexdjulin_S07-001.csv");
  const FaceTake first = read_livelinkface(s07);
  const FaceFrame& f = first.frames.front();
  CHECK(format_livelink_timecode(f.timecode) == "12:27:47:47.169");
  CHECK(f.weights[shape("EyeLookOutLeft")] == Approx(0.1421131641));
  // The CSV has JawRight before JawLeft: columns are read by name.
  CHECK(f.weights[shape("JawRight")] == Approx(0.0018999915));
  CHECK(f.weights[shape("JawLeft")] == 0.0f);
  CHECK(f.weights[shape("MouthRight")] == Approx(0.0070533231));
  CHECK(f.weights[shape("MouthLeft")] == 0.0f);
  CHECK(f.angles[8] == Approx(0.0176418666));  // RightEyeRoll
  CHECK(f.angles[0] == 0.0f);                  // head angles are all 0 in these exports

  FACECAP_REQUIRE_SHARED_DATA(s88, "livelinkface/alexdjulin_S88-001.csv");
  const FaceTake lost = read_livelinkface(s88);
  CHECK(lost.frames[381].tracked);        // CSV line 383
  CHECK_FALSE(lost.frames[382].tracked);  // line 384: "16:48:52:29.134,0"
  CHECK(std::isnan(lost.frames[382].weights[0]));
  CHECK(lost.frames[382].source_time_ns - lost.frames[381].source_time_ns == Approx(2e9 / 60.0).margin(1e5));

  FACECAP_REQUIRE_SHARED_DATA(rom, "livelinkface/alexdjulin_alex_rom_3.csv");
  const FaceTake rom_take = read_livelinkface(rom);
  CHECK(rom_take.frames[543].weights[shape("EyeLookInRight")] == Approx(1.0033375025));  // > 1 accepted

  // The writer's header is the app's, column for column.
  const auto s07_bytes = read_file_bytes(s07);
  const std::string_view s07_text(s07_bytes.data(), s07_bytes.size());
  const std::string written = write_livelinkface(first);
  CHECK(written.substr(0, written.find('\n')) == s07_text.substr(0, s07_text.find('\n')));

  // And the writer reproduces what it read.
  const FaceTake again = read_livelinkface(write_livelinkface(lost), "rewritten.csv");
  REQUIRE(again.frames.size() == lost.frames.size());
  CHECK(again.lost_frames() == 277);
  for (std::size_t i = 0; i < lost.frames.size(); i += 97) {
    CHECK(again.frames[i].timecode == lost.frames[i].timecode);
    if (lost.frames[i].tracked) CHECK(again.frames[i].weights == lost.frames[i].weights);
  }
}
