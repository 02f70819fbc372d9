#include "formats/livelinkface.hpp"

#include <algorithm>
#include <cmath>
#include <limits>
#include <numbers>
#include <numeric>

#include <Eigen/Geometry>

#include <fmt/format.h>

#include "core/error.hpp"
#include "core/io.hpp"
#include "formats/text.hpp"

namespace facecap::formats {
namespace {

constexpr int64_t kNsPerDay = 24 * 3600 * kNsPerSecond;

// The app's CSV column order: Live Link order with JawLeft/JawRight and
// MouthLeft/MouthRight swapped. Indices into kArkitShapes.
std::array<std::size_t, kArkitShapeCount> csv_shape_order() {
  std::array<std::size_t, kArkitShapeCount> order{};
  std::iota(order.begin(), order.end(), std::size_t(0));
  auto swap_columns = [&order](std::string_view a, std::string_view b) {
    std::swap(order[*arkit_shape_index(a)], order[*arkit_shape_index(b)]);
  };
  swap_columns("JawLeft", "JawRight");
  swap_columns("MouthLeft", "MouthRight");
  return order;
}

// Where each CSV column goes.
struct Column {
  enum Kind : uint8_t { kIgnored, kWeight, kAngle } kind = kIgnored;
  std::size_t index = 0;
};

double estimate_rate(const std::vector<FaceFrame>& frames) {
  std::vector<int64_t> steps;
  for (std::size_t i = 1; i < frames.size(); ++i) {
    const int64_t step = frames[i].source_time_ns - frames[i - 1].source_time_ns;
    if (step > 0) steps.push_back(step);
  }
  if (steps.empty()) return 0.0;
  std::nth_element(steps.begin(), steps.begin() + std::ptrdiff_t(steps.size() / 2), steps.end());
  const double rate = 1e9 / double(steps[steps.size() / 2]);
  const double nearest = std::round(rate);
  return std::abs(rate - nearest) < 0.01 * nearest ? nearest : rate;
}

}  // namespace

std::size_t FaceTake::lost_frames() const noexcept {
  return std::size_t(std::count_if(frames.begin(), frames.end(), [](const FaceFrame& f) { return !f.tracked; }));
}

std::optional<Timecode> parse_livelink_timecode(std::string_view text) noexcept {
  text = trim_spaces(text);
  Timecode tc;
  int parts[4] = {0, 0, 0, 0};
  std::size_t at = 0;
  for (int i = 0; i < 4; ++i) {
    std::size_t end = at;
    while (end < text.size() && text[end] >= '0' && text[end] <= '9') ++end;
    if (end == at || end - at > 2) return std::nullopt;
    for (std::size_t d = at; d < end; ++d) parts[i] = parts[i] * 10 + (text[d] - '0');
    at = end;
    if (i < 3) {
      if (at >= text.size() || text[at] != ':') return std::nullopt;
      ++at;
    }
  }
  float fraction = 0.0f;
  if (at < text.size()) {
    if (text[at] != '.' || at + 1 >= text.size() || text.size() - at > 10) return std::nullopt;
    const auto value = parse_double(text.substr(at));
    if (!value || text.substr(at + 1).find_first_not_of("0123456789") != std::string_view::npos) return std::nullopt;
    fraction = float(*value);
  }
  if (parts[0] > 23 || parts[1] > 59 || parts[2] > 59 || parts[3] >= kLiveLinkTimecodeRate) return std::nullopt;
  tc.hours = uint8_t(parts[0]);
  tc.minutes = uint8_t(parts[1]);
  tc.seconds = uint8_t(parts[2]);
  tc.frames = uint8_t(parts[3]);
  tc.subframe = fraction;
  tc.rate_hz = kLiveLinkTimecodeRate;
  return tc;
}

std::string format_livelink_timecode(const Timecode& tc) {
  const int thousandths = std::clamp(int(std::lround(double(tc.subframe) * 1000.0)), 0, 999);
  return fmt::format("{:02}:{:02}:{:02}:{:02}.{:03}", tc.hours, tc.minutes, tc.seconds, tc.frames, thousandths);
}

int64_t timecode_time_ns(const Timecode& tc) noexcept {
  const int64_t seconds = int64_t(tc.hours) * 3600 + int64_t(tc.minutes) * 60 + tc.seconds;
  const double frames = double(tc.frames) + double(tc.subframe);
  return seconds * kNsPerSecond + (tc.rate_hz == 0 ? 0 : std::llround(frames * 1e9 / tc.rate_hz));
}

Timecode livelink_timecode_at(int64_t time_of_day_ns) noexcept {
  const int64_t day_ns = ((time_of_day_ns % kNsPerDay) + kNsPerDay) % kNsPerDay;
  // Thousandths of a frame: ns * 60 / 1e6, rounded (no overflow: a day is 5.2e12 of them).
  const int64_t thousandths = (day_ns * kLiveLinkTimecodeRate + 500'000) / 1'000'000;
  const int64_t whole = thousandths / 1000;
  const int64_t seconds = whole / kLiveLinkTimecodeRate;
  Timecode tc;
  tc.rate_hz = kLiveLinkTimecodeRate;
  tc.frames = uint8_t(whole % kLiveLinkTimecodeRate);
  tc.seconds = uint8_t(seconds % 60);
  tc.minutes = uint8_t((seconds / 60) % 60);
  tc.hours = uint8_t((seconds / 3600) % 24);
  tc.subframe = float(double(thousandths % 1000) / 1000.0);
  return tc;
}

FaceFrame face_frame_from_solved(const SolvedFrame& solved, const ArkitWeights& arkit) {
  FaceFrame out;
  out.source_time_ns = solved.timecode.valid() ? timecode_time_ns(solved.timecode) : solved.source_time_ns;
  out.timecode = livelink_timecode_at(out.source_time_ns);
  arkit.map(std::span<const float>(solved.weights.data(), std::size_t(solved.weights.size())), out.weights);
  out.angles = {};
  const std::array<float, 3> head = head_yaw_pitch_roll(solved.head_rotation);
  std::copy(head.begin(), head.end(), out.angles.begin());
  return out;
}

FaceTake read_livelinkface(std::string_view text, const std::string& name) {
  FaceTake take;
  LineCursor lines(text);
  std::string_view line;
  std::vector<std::string_view> fields;
  auto fail = [&](std::string_view field, const std::string& what) -> Error {
    return text_error(name, lines.line_number(), int64_t(field.data() - line.data()) + 1, what);
  };

  if (!lines.next(line)) throw line_error(name, 1, "empty file: expected the Live Link Face header line");
  split_fields(line, ',', fields);
  if (fields.size() < 2 || !equals_ignore_case(trim_spaces(fields[0]), "Timecode") ||
      !equals_ignore_case(trim_spaces(fields[1]), "BlendShapeCount")) {
    throw line_error(name, 1, "not a Live Link Face CSV: the header does not start with Timecode,BlendShapeCount");
  }
  const std::size_t column_count = fields.size();
  std::vector<Column> columns(column_count);
  std::vector<std::string> column_names(fields.begin(), fields.end());
  // The column each weight and angle is read from (0: none yet; data columns start at 2).
  std::array<std::size_t, kArkitShapeCount> weight_column{};
  std::array<std::size_t, kLiveLinkAngleCount> angle_column{};
  std::vector<std::string> ignored;
  std::size_t repeated = 0;
  for (std::size_t c = 2; c < column_count; ++c) {
    const std::string_view column_name = trim_spaces(fields[c]);
    std::size_t* first = nullptr;
    Column column;
    if (auto s = arkit_shape_index(column_name)) {
      first = &weight_column[*s];
      column = {Column::kWeight, *s};
    } else if (const auto angle = std::find_if(kLiveLinkAngleNames.begin(), kLiveLinkAngleNames.end(),
                                               [&](std::string_view a) { return equals_ignore_case(a, column_name); });
               angle != kLiveLinkAngleNames.end()) {
      column = {Column::kAngle, std::size_t(angle - kLiveLinkAngleNames.begin())};
      first = &angle_column[column.index];
    }
    if (first && *first == 0) {
      *first = c;
      columns[c] = column;
    } else if (first) {
      if (repeated++ == 0)  // the first is read, as everywhere a name is repeated
        take.warnings.push_back(fmt::format("{}: column {} repeats '{}' of column {}; the first is read", name, c + 1,
                                            column_name, *first + 1));
    } else if (!(column_name.empty() && c + 1 == column_count)) {  // not a trailing comma
      ignored.emplace_back(column_name);
    }
  }
  if (repeated > 1) take.warnings.push_back(fmt::format("{}: {} columns repeat an earlier name", name, repeated));
  for (std::size_t s = 0; s < kArkitShapeCount; ++s) {
    if (weight_column[s] == 0) throw line_error(name, 1, fmt::format("header lacks the {} column", kArkitShapes[s].arkit));
  }
  if (!ignored.empty()) {
    take.warnings.push_back(
        fmt::format("{}: {} unknown columns ignored (first: '{}')", name, ignored.size(), ignored.front()));
  }
  if (std::count(angle_column.begin(), angle_column.end(), std::size_t(0)) > 0) {
    take.warnings.push_back(fmt::format("{}: some head/eye angle columns are missing; read as 0", name));
  }

  const float nan = std::numeric_limits<float>::quiet_NaN();
  // A take may run past one midnight (timecode jumping back by more than half a day); a
  // second such jump cannot be another midnight (that would be a take of over a day) and
  // counts as a jump back, so times stay within two days whatever the rows say.
  int64_t day_offset_ns = 0;
  int64_t midnight_line = 0;
  std::size_t jumps_back = 0;
  int64_t first_jump_back_line = 0;
  std::size_t count_mismatches = 0;
  while (lines.next(line)) {
    if (trim_spaces(line).empty()) continue;
    split_fields(line, ',', fields);
    if (fields.size() < 2) throw fail(line, "row has no BlendShapeCount field");
    const auto timecode = parse_livelink_timecode(fields[0]);
    if (!timecode)
      throw fail(fields[0], fmt::format("timecode '{}' is not HH:MM:SS:FF.fff at 60 fps", trim_spaces(fields[0])));
    const auto count = parse_int(fields[1]);
    if (!count || *count < 0) throw fail(fields[1], fmt::format("BlendShapeCount '{}' is not a count", fields[1]));

    FaceFrame& frame = take.frames.emplace_back();
    frame.timecode = *timecode;
    frame.source_time_ns = timecode_time_ns(*timecode) + day_offset_ns;
    if (take.frames.size() > 1) {
      const int64_t previous_ns = take.frames[take.frames.size() - 2].source_time_ns;
      if (midnight_line == 0 && frame.source_time_ns < previous_ns - kNsPerDay / 2) {
        midnight_line = lines.line_number();  // the take ran past midnight
        day_offset_ns = kNsPerDay;
        frame.source_time_ns += kNsPerDay;
      } else if (frame.source_time_ns < previous_ns) {
        if (jumps_back++ == 0) first_jump_back_line = lines.line_number();
      }
    }
    if (*count == 0 && (fields.size() == 2 ||
                        std::all_of(fields.begin() + 2, fields.end(), [](auto f) { return trim_spaces(f).empty(); }))) {
      frame.tracked = false;
      frame.weights.fill(nan);
      frame.angles.fill(nan);
      continue;
    }
    if (fields.size() != column_count) {
      throw fail(fields.back(), fmt::format("row has {} fields, the header {}", fields.size(), column_count));
    }
    if (std::size_t(*count) != column_count - 2) ++count_mismatches;
    for (std::size_t c = 2; c < column_count; ++c) {
      if (columns[c].kind == Column::kIgnored) continue;
      const auto value = parse_double(fields[c]);
      if (!value || !std::isfinite(*value))
        throw fail(fields[c], fmt::format("{} value '{}' is not a number", column_names[c], fields[c]));
      if (columns[c].kind == Column::kWeight) {
        frame.weights[columns[c].index] = float(*value);
      } else {
        frame.angles[columns[c].index] = float(*value);
      }
    }
  }
  if (jumps_back > 0) {
    take.warnings.push_back(fmt::format("{}: the timecode jumps back {} times (first at line {}){}", name, jumps_back,
                                        first_jump_back_line,
                                        midnight_line ? fmt::format("; line {} was read as passing midnight", midnight_line)
                                                      : std::string()));
  }
  if (count_mismatches > 0) {
    take.warnings.push_back(fmt::format("{}: {} rows give a BlendShapeCount other than the {} value columns", name,
                                        count_mismatches, column_count - 2));
  }
  take.rate_hz = estimate_rate(take.frames);
  return take;
}

FaceTake read_livelinkface(const std::filesystem::path& path) {
  const auto bytes = read_file_bytes(path);
  return read_livelinkface(std::string_view(bytes.data(), bytes.size()), path.string());
}

std::string write_livelinkface(const FaceTake& take) {
  const auto order = csv_shape_order();
  std::string out = "Timecode,BlendShapeCount";
  for (std::size_t shape : order) out += fmt::format(",{}", kArkitShapes[shape].arkit);
  for (auto column : kLiveLinkAngleNames) out += fmt::format(",{}", column);
  out += '\n';
  for (const FaceFrame& frame : take.frames) {
    out += format_livelink_timecode(frame.timecode);
    if (!frame.tracked) {
      out += ",0\n";
      continue;
    }
    out += fmt::format(",{}", kArkitShapeCount + kLiveLinkAngleCount);
    for (std::size_t shape : order) out += fmt::format(",{:.10f}", frame.weights[shape]);
    for (float angle : frame.angles) out += fmt::format(",{:.10f}", angle);
    out += '\n';
  }
  return out;
}

}  // namespace facecap::formats
