#include "formats/trc.hpp"

#include <cmath>
#include <limits>

#include <fmt/format.h>

#include "core/error.hpp"
#include "formats/text.hpp"

namespace facecap::formats {
namespace {

// TRC rows are tab-separated (empty cells meaningful) or, in some exports, separated by
// runs of spaces.
void split_row(std::string_view line, std::vector<std::string_view>& out) {
  if (line.find('\t') != std::string_view::npos) {
    split_fields(line, '\t', out);
    for (auto& f : out) f = trim_spaces(f);
  } else {
    split_whitespace(line, out);
  }
}

bool blank(std::string_view line) { return trim_spaces(line).empty(); }

}  // namespace

MarkerTake read_trc(std::string_view text, const std::string& name) {
  MarkerTake take;
  take.format = TakeFormat::kTrc;
  LineCursor lines(text);
  std::string_view line;
  std::vector<std::string_view> fields;
  auto column_of = [&](std::string_view field) { return int64_t(field.data() - line.data()) + 1; };
  auto fail = [&](std::string_view field, const std::string& what) -> Error {
    return text_error(name, lines.line_number(), column_of(field), what);
  };
  auto next_header_line = [&](std::string_view what) {
    if (!lines.next(line))
      throw line_error(name, lines.line_number() + 1, fmt::format("file ends before the {} line", what));
    split_row(line, fields);
  };

  next_header_line("PathFileType");
  if (fields.size() < 2 || !equals_ignore_case(fields[0], "PathFileType")) {
    throw line_error(name, 1, "not a TRC file: the first line does not start with PathFileType");
  }
  const auto path_file_type = parse_int(fields[1]);
  if (!path_file_type || (*path_file_type != 3 && *path_file_type != 4)) {
    throw fail(fields[1], fmt::format("PathFileType '{}' is not supported (3 or 4)", fields[1]));
  }
  take.metadata.emplace_back("PathFileType", std::string(fields[1]));
  if (fields.size() > 2) take.metadata.emplace_back("coordinates", std::string(fields[2]));
  if (fields.size() > 3) take.metadata.emplace_back("source_path", std::string(fields[3]));

  next_header_line("header keys");
  const std::vector<std::string_view> keys = fields;
  const int64_t keys_line = lines.line_number();
  next_header_line("header values");
  std::optional<int64_t> marker_count, declared_frames;
  std::optional<double> data_rate, camera_rate;
  std::string_view units;
  for (std::size_t i = 0; i < keys.size(); ++i) {
    if (keys[i].empty()) continue;
    const std::string_view value = i < fields.size() ? fields[i] : std::string_view{};
    take.metadata.emplace_back(std::string(keys[i]), std::string(value));
    auto number = [&]() {
      auto v = parse_double(value);
      if (!v || !std::isfinite(*v))
        throw fail(value.empty() ? line.substr(line.size()) : value,
                   fmt::format("{} '{}' is not a number", keys[i], value));
      return *v;
    };
    auto count = [&]() {
      auto v = parse_int(value);
      if (!v || *v < 0)
        throw fail(value.empty() ? line.substr(line.size()) : value,
                   fmt::format("{} '{}' is not a count", keys[i], value));
      return *v;
    };
    if (equals_ignore_case(keys[i], "NumMarkers"))
      marker_count = count();
    else if (equals_ignore_case(keys[i], "NumFrames"))
      declared_frames = count();
    else if (equals_ignore_case(keys[i], "DataRate"))
      data_rate = number();
    else if (equals_ignore_case(keys[i], "CameraRate"))
      camera_rate = number();
    else if (equals_ignore_case(keys[i], "Units"))
      units = value;
  }
  if (!marker_count) throw line_error(name, keys_line, "header has no NumMarkers");
  take.rate_hz = data_rate.value_or(camera_rate.value_or(0.0));
  if (take.rate_hz < 0) throw line_error(name, lines.line_number(), fmt::format("negative DataRate {}", take.rate_hz));
  take.units = units.empty() ? "mm" : std::string(units);
  if (units.empty()) take.warnings.push_back(fmt::format("{}: no Units in the header; assuming mm", name));

  next_header_line("marker labels");
  if (fields.empty() || !equals_ignore_case(fields[0], "Frame#")) {
    throw fail(fields.empty() ? line : fields[0], "expected the label line to start with Frame#");
  }
  std::vector<std::string> labels;
  for (std::size_t i = 2; i < fields.size(); ++i) {
    if (!fields[i].empty()) labels.emplace_back(fields[i]);
  }
  next_header_line("coordinate names (X1 Y1 Z1 ...)");
  std::size_t coordinate_names = 0;
  for (auto f : fields) coordinate_names += f.empty() ? 0 : 1;
  const std::size_t named_markers = std::max(labels.size(), coordinate_names / 3);
  if (std::size_t(*marker_count) > named_markers) {
    throw line_error(
        name, lines.line_number(),
        fmt::format("NumMarkers is {} but the header names only {} markers", *marker_count, named_markers));
  }
  const std::size_t markers = std::size_t(*marker_count);
  if (labels.size() != markers) {
    take.warnings.push_back(
        fmt::format("{}: NumMarkers is {} but the label line names {} markers", name, markers, labels.size()));
  }
  labels.resize(markers);
  for (std::size_t k = 0; k < markers; ++k) {
    if (labels[k].empty()) labels[k] = fmt::format("marker_{}", k + 1);
  }
  take.labels = std::move(labels);

  const double nan = std::numeric_limits<double>::quiet_NaN();
  // A hostile header can claim thousands of markers over millions of short rows.
  const std::size_t limit = max_take_samples(text.size());
  std::size_t rows_with_extra_columns = 0;
  std::size_t partial_cells = 0;
  while (lines.next(line)) {
    if (blank(line)) continue;
    split_row(line, fields);
    if (fields.size() < 2) throw fail(fields[0], "data row has no Time column");
    if ((take.frames.size() + 1) * std::max<std::size_t>(markers, 1) > limit) {
      throw line_error(name, lines.line_number(),
                       fmt::format("{} markers per frame over this many rows is more than a file "
                                   "of {} bytes can hold",
                                   markers, text.size()));
    }
    const auto frame_no = parse_int(fields[0]);
    if (!frame_no) throw fail(fields[0], fmt::format("frame number '{}' is not an integer", fields[0]));
    const auto time = parse_double(fields[1]);
    if (!time || !std::isfinite(*time) || std::abs(*time) > 9.2e9)
      throw fail(fields[1], fmt::format("time '{}' is not a number", fields[1]));
    MarkerFrame& frame = take.frames.emplace_back();
    frame.frame_no = *frame_no;
    frame.source_time_ns = std::llround(*time * 1e9);
    frame.markers.resize(markers);
    for (std::size_t k = 0; k < markers; ++k) {
      Marker& m = frame.markers[k];
      m.id = int32_t(k);
      m.label.assign(take.labels[k]);
      const std::size_t base = 2 + 3 * k;
      double xyz[3] = {0, 0, 0};
      int empty = 0;
      bool not_a_number = false;
      for (int axis = 0; axis < 3; ++axis) {
        const std::size_t at = base + std::size_t(axis);
        if (at >= fields.size() || fields[at].empty()) {
          ++empty;
          continue;
        }
        const auto v = parse_double(fields[at]);
        if (!v) {
          throw fail(fields[at],
                     fmt::format("{} of marker {} is '{}', not a number", "XYZ"[axis], take.labels[k], fields[at]));
        }
        xyz[axis] = *v;
        not_a_number |= !std::isfinite(*v);
      }
      if (empty == 0 && !not_a_number) {
        m.position = Eigen::Vector3d(xyz[0], xyz[1], xyz[2]);
      } else {
        partial_cells += (empty > 0 && empty < 3) ? 1 : 0;
        m.flags = kMarkerMissing;
        m.position = Eigen::Vector3d(nan, nan, nan);
      }
    }
    for (std::size_t at = 2 + 3 * markers; at < fields.size(); ++at) {
      if (!fields[at].empty()) {
        ++rows_with_extra_columns;
        break;
      }
    }
  }
  take.first_frame = take.frames.empty() ? 1 : take.frames.front().frame_no;
  if (declared_frames && std::size_t(*declared_frames) != take.frames.size()) {
    take.warnings.push_back(
        fmt::format("{}: NumFrames is {} but {} data rows were read", name, *declared_frames, take.frames.size()));
  }
  if (rows_with_extra_columns > 0) {
    take.warnings.push_back(fmt::format("{}: {} rows carry values past the {} declared markers (ignored)", name,
                                        rows_with_extra_columns, markers));
  }
  if (partial_cells > 0) {
    take.warnings.push_back(
        fmt::format("{}: {} markers had only some coordinates and were read as missing", name, partial_cells));
  }
  finish_take(take, name);
  return take;
}

std::string write_trc(const MarkerTake& take, std::string_view file_name, const ProgressFn& progress) {
  check_take_shape(take, "TRC writer");
  const std::size_t markers = take.marker_count();
  const std::string rate = format_shortest(take.rate_hz);
  std::string out;
  out.reserve(256 + markers * 24 + take.frames.size() * (16 + markers * 30));
  out += fmt::format("PathFileType\t4\t(X/Y/Z)\t{}\n", file_name);
  out += "DataRate\tCameraRate\tNumFrames\tNumMarkers\tUnits\tOrigDataRate\tOrigDataStartFrame\tOrigNumFrames\n";
  out += fmt::format("{}\t{}\t{}\t{}\t{}\t{}\t{}\t{}\n", rate, rate, take.frames.size(), markers,
                     take.units.empty() ? "mm" : take.units, rate, take.first_frame, take.frames.size());
  out += "Frame#\tTime";
  for (const auto& label : take.labels) {
    out += '\t';
    for (char c : label) out += (c == '\t' || c == '\n' || c == '\r') ? '_' : c;  // keep the row layout intact
    out += "\t\t";
  }
  out += "\n\t";
  for (std::size_t k = 1; k <= markers; ++k) out += fmt::format("\tX{0}\tY{0}\tZ{0}", k);
  out += "\n\n";
  for (std::size_t f = 0; f < take.frames.size(); ++f) {
    const MarkerFrame& frame = take.frames[f];
    out += fmt::format("{}\t{}", frame.frame_no, format_shortest(double(frame.source_time_ns) / 1e9));
    for (const Marker& m : frame.markers) {
      if (m.present()) {
        for (int axis = 0; axis < 3; ++axis) {
          out += '\t';
          out += format_shortest(float(m.position[axis]));
        }
      } else {
        out += "\t\t\t";
      }
    }
    out += '\n';
    report_progress(progress, f + 1, take.frames.size());
  }
  return out;
}

}  // namespace facecap::formats
