// Regression tests for inputs found by fault injection and fuzzing (issue 19): each one
// crashed, overflowed, allocated without bound or was accepted silently before its fix.
// Every reader must meet them with an Error naming where, or a warning naming what.
#include <algorithm>
#include <cstring>

#include <catch2/catch.hpp>
#include <fmt/format.h>

#include "core/error.hpp"
#include "core/io.hpp"
#include "formats/livelinkface.hpp"
#include "formats/recording.hpp"
#include "formats/take.hpp"
#include "formats/trc.hpp"
#include "tests/formats_test_support.hpp"
#include "tests/test_support.hpp"

using namespace facecap;
using namespace facecap::formats;
using Catch::Contains;

namespace {

// A TRC of one marker column per label, every row at `time`.
std::string trc_text(const std::vector<std::string>& labels, int rows, std::string_view time, std::string_view rate) {
  std::string text = "PathFileType\t4\t(X/Y/Z)\tt.trc\nDataRate\tCameraRate\tNumFrames\tNumMarkers\tUnits\n";
  text += fmt::format("{}\t{}\t{}\t{}\tmm\nFrame#\tTime", rate, rate, rows, labels.size());
  for (const auto& label : labels) text += fmt::format("\t{}\t\t", label);
  text += "\n\t";
  for (std::size_t k = 1; k <= labels.size(); ++k) text += fmt::format("\tX{0}\tY{0}\tZ{0}", k);
  text += "\n";
  for (int r = 0; r < rows; ++r) {
    text += fmt::format("{}\t{}", r + 1, time);
    for (std::size_t k = 0; k < labels.size(); ++k) text += fmt::format("\t{}\t{}\t{}", k, r, 1);
    text += "\n";
  }
  return text;
}

bool has_warning(const std::vector<std::string>& warnings, const std::string& needle) {
  return std::any_of(warnings.begin(), warnings.end(), [&](const std::string& w) { return w.find(needle) != std::string::npos; });
}

}  // namespace

TEST_CASE("C3D: a real-typed POINT:USED beyond 65535 is refused at its byte before labels are allocated", "[hostile][c3d]") {
  // 4e9 aborted `facecap inspect` with std::bad_alloc; 5e7 took 5 s and 1.6 GB.
  for (float points : {4e9f, 5e7f, 65536.0f}) {
    const auto file = test::c3d_with_real_point_count(points);
    CHECK_THROWS_WITH(read_take(file, "used.c3d"),
                      Contains("used.c3d @ byte 536") && Contains(fmt::format("POINT:USED is {}", int64_t(points))) &&
                          Contains("more than the 65535 points"));
  }
  const MarkerTake most = read_take(test::c3d_with_real_point_count(65535.0f), "most.c3d");
  CHECK(most.labels.size() == 65535);
  CHECK(most.frames.empty());
}

TEST_CASE("Live Link Face: a timecode wrapping back and forth counts one midnight, not a day per wrap", "[hostile][livelinkface]") {
  // Each apparent wrap added a day: 213,504 alternating rows overflowed int64 nanoseconds.
  std::string text = "Timecode,BlendShapeCount";
  for (const auto& s : kArkitShapes) text += fmt::format(",{}", s.arkit);
  text += "\n";
  constexpr int kRows = 220000;
  for (int r = 0; r < kRows; ++r) text += r % 2 == 0 ? "23:59:59:59.000,0\n" : "00:00:00:00.000,0\n";
  const FaceTake take = read_livelinkface(text, "wraps.csv");
  REQUIRE(take.frames.size() == kRows);
  const int64_t day_ns = 24 * 3600 * kNsPerSecond;
  int64_t earliest = INT64_MAX, latest = INT64_MIN;
  for (const auto& f : take.frames) {
    earliest = std::min(earliest, f.source_time_ns);
    latest = std::max(latest, f.source_time_ns);
  }
  const int64_t last_frame_of_day_ns = day_ns - std::llround(1e9 / 60);  // 23:59:59:59
  CHECK(earliest == last_frame_of_day_ns);                          // line 2
  CHECK(take.frames[1].source_time_ns == day_ns);                   // line 3: past midnight
  CHECK(latest == day_ns + last_frame_of_day_ns);                   // within two days, whatever follows
  CHECK(has_warning(take.warnings, fmt::format("jumps back {} times (first at line 5); line 3 was read as passing midnight",
                                               kRows / 2 - 1)));
}

TEST_CASE("Live Link Face: a repeated column is named with both positions; the first is read", "[hostile][livelinkface]") {
  std::string header = "Timecode,BlendShapeCount";
  std::string row = "00:00:01:00.000,53";
  for (const auto& s : kArkitShapes) {
    header += fmt::format(",{}", s.arkit);
    row += s.arkit == "JawOpen" ? ",0.25" : ",0";
  }
  const FaceTake take = read_livelinkface(header + ",JawOpen\n" + row + ",0.75\n", "repeat.csv");
  CHECK(take.frames.at(0).weights[*arkit_shape_index("JawOpen")] == 0.25f);
  CHECK(has_warning(take.warnings, "column 55 repeats 'JawOpen' of column"));
}

TEST_CASE("Every take reader names a label given to two marker slots, with both slots", "[hostile]") {
  MarkerTake take = test::synthetic_take(4, 4);
  take.labels[2] = take.labels[0];  // "M000" twice
  for (auto& frame : take.frames) frame.markers[2].label.assign(take.labels[0]);
  const auto dir = test::scratch_dir("duplicate-labels");
  for (const char* name : {"dup.c3d", "dup.trc", "dup.fcrec"}) {
    INFO(name);
    write_take(dir / name, take);
    const MarkerTake back = read_take(dir / name);
    CHECK(has_warning(back.warnings, "label 'M000' is given to markers 1 and 3; matching by label uses marker 1"));
  }
}

TEST_CASE("Recordings: a label repeated within a frame names the frame and both markers", "[hostile][recording]") {
  const auto path = test::scratch_dir("repeat-in-frame") / "repeat.fcrec";
  {
    RecordingHeader header;
    header.rate_hz = 60.0;
    RecordingWriter writer(path, header);
    MarkerFrame frame;
    frame.frame_no = 7;
    for (const char* label : {"A", "B", "A"}) {
      Marker& m = frame.markers.emplace_back();
      m.label.assign(label);
    }
    writer.append_marker_frame(frame);
    writer.close();
  }
  const MarkerTake take = read_take(path);
  CHECK(take.labels == std::vector<std::string>{"A", "B"});
  CHECK(has_warning(take.warnings, "1 markers repeat a label within their frame, the first 'A' in frame 7 (markers 1 and 3"));
}

TEST_CASE("Recordings: labels that change every frame are refused before every frame gets a slot per label", "[hostile][recording]") {
  // 3,000 frames of one marker each with a new id: 9 million slots (about 800 MB) from 270 KB.
  const auto path = test::scratch_dir("label-churn") / "churn.fcrec";
  constexpr int kFrames = 3000;
  {
    RecordingWriter writer(path, RecordingHeader{});
    MarkerFrame frame;
    frame.markers.resize(1);
    for (int f = 0; f < kFrames; ++f) {
      frame.frame_no = f;
      frame.markers[0].id = f;  // unlabelled: named id_<id>
      writer.append_marker_frame(frame);
    }
    writer.close();
  }
  const auto bytes = std::filesystem::file_size(path);
  CHECK_THROWS_WITH(read_take(path), Contains("churn.fcrec") && Contains("distinct marker labels by frame") &&
                                         Contains(fmt::format("marker samples a {}-byte file may expand to", bytes)));
}

TEST_CASE("Frames that all carry one timestamp are re-timed at the nominal rate, with a warning", "[hostile]") {
  // They played a whole take in one tick (replay paces by timestamps) with only an info line.
  const MarkerTake trc = read_trc(trc_text({"A", "B"}, 5, "0", "60"), "still.trc");
  REQUIRE(trc.frames.size() == 5);
  CHECK(trc.frames[4].source_time_ns == std::llround(4 * 1e9 / 60));
  CHECK(has_warning(trc.warnings, "all 5 frames carry the same timestamp (0 ns); timed at the nominal 60 Hz instead"));

  const MarkerTake no_rate = read_trc(trc_text({"A"}, 3, "2.5", "0"), "norate.trc");
  CHECK(no_rate.frames[2].source_time_ns == 2'500'000'000);
  CHECK(has_warning(no_rate.warnings, "all 3 frames carry the same timestamp and the take states no frame rate"));

  MarkerTake take = test::synthetic_take(6, 2, 120.0);
  for (auto& frame : take.frames) frame.source_time_ns = 1000;
  const auto path = test::scratch_dir("still-recording") / "still.fcrec";
  write_take(path, take);
  const MarkerTake back = read_take(path);
  CHECK(back.frames[5].source_time_ns == 1000 + std::llround(5 * 1e9 / 120));
  CHECK(has_warning(back.warnings, "all 6 frames carry the same timestamp"));
}

TEST_CASE("A frame rate that cannot time the take is treated as unknown, with a warning", "[hostile]") {
  const MarkerTake take = read_trc(trc_text({"A"}, 3, "0", "1e300"), "fast.trc");
  CHECK(take.rate_hz == 0.0);
  CHECK(has_warning(take.warnings, "frame rate 1e+300 Hz is not usable; treated as unknown"));
}
