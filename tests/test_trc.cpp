// TRC reader and writer: real exports (varied headers, line endings, gaps) and synthetic edge cases.
#include <catch2/catch.hpp>

#include "core/error.hpp"
#include "core/io.hpp"
#include "formats/c3d.hpp"
#include "formats/trc.hpp"
#include "tests/formats_test_support.hpp"
#include "tests/test_support.hpp"

using namespace facecap;
using namespace facecap::formats;

namespace {

MarkerTake read_shared_trc(const std::filesystem::path& path) {
  const auto bytes = read_file_bytes(path);
  return read_trc(std::string_view(bytes.data(), bytes.size()), path.string());
}

const char* const kSmallTrc =
    "PathFileType\t4\t(X/Y/Z)\tsmall.trc\n"
    "DataRate\tCameraRate\tNumFrames\tNumMarkers\tUnits\tOrigDataRate\tOrigDataStartFrame\tOrigNumFrames\n"
    "100\t100\t3\t2\tm\t100\t1\t3\n"
    "Frame#\tTime\tNose\t\t\tChin\t\t\n"
    "\t\tX1\tY1\tZ1\tX2\tY2\tZ2\n"
    "\n"
    "1\t0.00\t1.5\t2.5\t3.5\t4\t5\t6\n"
    "2\t0.01\t\t\t\t4.25\t5.25\t6.25\n"
    "3\t0.02\t1.75\t2.75\t3.75\n";

std::string replace_all(std::string s, std::string_view from, std::string_view to) {
  for (std::size_t at = s.find(from); at != std::string::npos; at = s.find(from, at + to.size()))
    s.replace(at, from.size(), to);
  return s;
}

void check_small_take(const MarkerTake& take) {
  REQUIRE(take.marker_count() == 2);
  CHECK(take.labels == std::vector<std::string>{"Nose", "Chin"});
  CHECK(take.units == "m");
  CHECK(take.rate_hz == 100.0);
  REQUIRE(take.frames.size() == 3);
  CHECK(take.frames[0].markers[0].position == Eigen::Vector3d(1.5, 2.5, 3.5));
  CHECK(take.frames[0].markers[1].position == Eigen::Vector3d(4, 5, 6));
  CHECK_FALSE(take.frames[1].markers[0].present());  // empty cells
  CHECK(take.frames[1].markers[1].position == Eigen::Vector3d(4.25, 5.25, 6.25));
  CHECK(take.frames[2].markers[0].position == Eigen::Vector3d(1.75, 2.75, 3.75));
  CHECK_FALSE(take.frames[2].markers[1].present());  // short row
  CHECK(take.frames[2].source_time_ns == 20'000'000);
  CHECK(count_gaps(take).missing_samples == 2);
}

}  // namespace

TEST_CASE("TRC: tabs, empty cells and short rows", "[trc]") { check_small_take(read_trc(kSmallTrc, "small.trc")); }

TEST_CASE("TRC: CRLF, CR CR LF and bare CR line endings read the same", "[trc]") {
  for (const char* ending : {"\r\n", "\r\r\n", "\r"}) {
    INFO("ending " << (std::string(ending) == "\r" ? "CR" : std::string(ending) == "\r\n" ? "CRLF" : "CRCRLF"));
    check_small_take(read_trc(replace_all(kSmallTrc, "\n", ending), "endings.trc"));
  }
}

TEST_CASE("TRC: space-separated files read by whitespace runs", "[trc]") {
  const std::string text =
      "PathFileType 3 (X/Y/Z) spaces.trc\n"
      "DataRate CameraRate NumFrames NumMarkers Units\n"
      "30 30 2 2 cm\n"
      "Frame# Time A B\n"
      "  X1 Y1 Z1 X2 Y2 Z2\n"
      "1   0.0   1 2 3   4 5 6\n"
      "2   0.033 7 8 9\n";
  const MarkerTake take = read_trc(text, "spaces.trc");
  CHECK(take.labels == std::vector<std::string>{"A", "B"});
  CHECK(take.units == "cm");
  REQUIRE(take.frames.size() == 2);
  CHECK(take.frames[0].markers[1].position == Eigen::Vector3d(4, 5, 6));
  CHECK(take.frames[1].markers[0].position == Eigen::Vector3d(7, 8, 9));
  CHECK_FALSE(take.frames[1].markers[1].present());
}

TEST_CASE("TRC: errors name the line, column and what was wrong", "[trc]") {
  auto expect_error = [](const std::string& text, std::string_view location, std::string_view what) {
    try {
      read_trc(text, "bad.trc");
      FAIL("no error");
    } catch (const Error& e) {
      INFO(e.what());
      CHECK(std::string(e.what()).find(location) == 0);
      CHECK(std::string(e.what()).find(what) != std::string::npos);
    }
  };
  expect_error(replace_all(kSmallTrc, "4.25", "4.2x5"), "bad.trc:8:11", "X of marker Chin is '4.2x5', not a number");
  expect_error(replace_all(kSmallTrc, "PathFileType\t4", "PathFileType\t5"),
               "bad.trc:1:", "PathFileType '5' is not supported");
  expect_error(replace_all(kSmallTrc, "\t3\t2\tm", "\t3\t900000000\tm"), "bad.trc:5", "NumMarkers is 900000000");
  expect_error("Frame#\tTime\n", "bad.trc:1", "not a TRC file");
  expect_error(std::string(kSmallTrc).substr(0, 174), "bad.trc:5", "file ends before the coordinate names");
  expect_error(replace_all(kSmallTrc, "3\t0.02", "x\t0.02"), "bad.trc:9:1", "frame number 'x'");
}

TEST_CASE("TRC: every file in ../shared/data/trc reads", "[trc][shared]") {
  FACECAP_REQUIRE_SHARED_DATA(one_path, "trc/test_file_01.trc");
  const MarkerTake one = read_shared_trc(one_path);
  CHECK(one.frames.size() == 4);
  CHECK(one.labels == std::vector<std::string>{"HeadTop", "ForeHead"});
  CHECK(one.warnings.empty());
  CHECK(one.frames[3].markers[1].position == Eigen::Vector3d(-2830.76855, 1535.33289, -3161.00732));
  CHECK(one.frames[3].source_time_ns == 50'000'000);

  FACECAP_REQUIRE_SHARED_DATA(three_path, "trc/test_file_03.trc");
  const MarkerTake three = read_shared_trc(three_path);
  CHECK(three.frames.size() == 466);
  CHECK(three.marker_count() == 46);
  CHECK(three.frames[0].present_count() == 0);  // row "1\t0.000": nothing tracked yet
  CHECK(count_gaps(three).missing_samples == 740);
  REQUIRE(three.warnings.size() == 1);  // unlabelled columns past the 46 markers
  CHECK(three.warnings[0].find("41 rows carry values past the 46 declared markers") != std::string::npos);

  FACECAP_REQUIRE_SHARED_DATA(four_path, "trc/test_file_04.trc");  // PathFileType 3, CR CR LF
  const MarkerTake four = read_shared_trc(four_path);
  CHECK(four.metadata_value("PathFileType") == "3");
  CHECK(four.frames.size() == 2);
  CHECK(four.marker_count() == 37);
  CHECK(four.rate_hz == 200.0);
  CHECK(four.labels.front() == "LASI");
  CHECK(four.labels.back() == "LACR1");
  CHECK(four.frames[0].source_time_ns == -5'000'000);
  CHECK(four.frames[0].markers[0].position == Eigen::Vector3d(324.95004, 944.87946, -740.72955));
}

TEST_CASE("TRC: every AnimFace take in ../shared/data/markers reads", "[trc][shared]") {
  const std::pair<const char*, std::size_t> takes[] = {
      {"CheeksMoCap.trc", 1499}, {"EyebrowsMoCap.trc", 902}, {"JawMoCap.trc", 1590}, {"NoseMoCap.trc", 962}};
  for (const auto& [file, frames] : takes) {
    INFO(file);
    FACECAP_REQUIRE_SHARED_DATA(path, std::string("markers/animface/") + file);
    const MarkerTake take = read_shared_trc(path);
    CHECK(take.frames.size() == frames);
    CHECK(take.marker_count() == 41);
    CHECK(take.units == "cm");
    CHECK(take.rate_hz == 60.0);
    CHECK(take.warnings.empty());
    CHECK(count_gaps(take).missing_samples == 0);
    for (const char* label : {"ForeHead_M", "Leyebrow_Inside", "NoseTop", "Mouth_Lend", "Chin_L1"}) {
      CHECK(std::find(take.labels.begin(), take.labels.end(), label) != take.labels.end());
    }
    CHECK(take.frames.back().frame_no == int64_t(frames));
  }
  FACECAP_REQUIRE_SHARED_DATA(cheeks, "markers/animface/CheeksMoCap.trc");
  const MarkerTake take = read_shared_trc(cheeks);
  CHECK(take.frames[0].markers[0].position == Eigen::Vector3d(13.70183, 84.08521, 3.54293));
  CHECK(take.frames.back().source_time_ns == 24'966'670'000);
}

TEST_CASE("TRC writer: synthetic take round-trips at float precision", "[trc]") {
  const MarkerTake take = facecap::test::synthetic_take(50, 5);
  const std::string text = write_trc(take, "synthetic.trc");
  const MarkerTake back = read_trc(text, "synthetic.trc");
  CHECK(back.warnings.empty());
  CHECK(back.rate_hz == take.rate_hz);
  CHECK(back.units == take.units);
  CHECK(back.frames[10].source_time_ns == take.frames[10].source_time_ns);
  facecap::test::require_same_points(take, back, 1e-4);
}

TEST_CASE("C3D -> TRC -> C3D keeps positions at float precision and missing markers exactly", "[trc][c3d][shared]") {
  for (const char* file : {"c3d/Eb015pr.c3d", "c3d/pc_int.c3d", "c3d/c3dorg_s20_phasespace_sample.c3d"}) {
    INFO(file);
    FACECAP_REQUIRE_SHARED_DATA(path, file);
    const auto bytes = read_file_bytes(path);
    const MarkerTake original = read_c3d(bytes, path.string());
    const MarkerTake via_trc = read_trc(write_trc(original, "via.trc"), "via.trc");
    const MarkerTake back = read_c3d(write_c3d(via_trc), "back.c3d");
    CHECK(back.first_frame == original.first_frame);
    CHECK(back.rate_hz == original.rate_hz);
    CHECK(back.units == original.units);
    // Both steps store float32, so the result is float32 of the original, exactly.
    for (std::size_t f = 0; f < original.frames.size(); ++f) {
      for (std::size_t k = 0; k < original.marker_count(); ++k) {
        const Marker& a = original.frames[f].markers[k];
        const Marker& b = back.frames[f].markers[k];
        REQUIRE(a.present() == b.present());
        if (a.present()) REQUIRE(facecap::test::same_float32(a.position, b.position));
      }
    }
    facecap::test::require_same_points(original, back, 1e-3);
  }
}
