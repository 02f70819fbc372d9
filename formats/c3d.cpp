#include "formats/c3d.hpp"

#include <algorithm>
#include <cctype>
#include <cmath>
#include <limits>
#include <optional>

#include <fmt/format.h>

#include "core/error.hpp"
#include "formats/byte_io.hpp"
#include "formats/text.hpp"

namespace facecap::formats {
namespace {

constexpr std::size_t kBlockBytes = 512;
constexpr uint8_t kHeaderKey = 0x50;    // second byte of every C3D file
constexpr uint8_t kProcessorBase = 83;  // processor byte = 83 + type
enum class Processor : uint8_t { kIntel = 1, kDec = 2, kMips = 3 };
constexpr std::size_t kMaxLabelsPerParameter = 255;  // a dimension is one byte
constexpr std::size_t kMaxPoints = 65535;            // POINT:USED is a 16-bit word

std::string_view processor_name(Processor p) {
  switch (p) {
    case Processor::kIntel: return "intel";
    case Processor::kDec: return "dec";
    case Processor::kMips: return "mips";
  }
  return "?";
}

// C3D pads text with spaces, some writers with NULs.
std::string_view trim(std::string_view s) {
  while (!s.empty() && (s.back() == ' ' || s.back() == '\0' || s.back() == '\t')) s.remove_suffix(1);
  while (!s.empty() && (s.front() == ' ' || s.front() == '\0' || s.front() == '\t')) s.remove_prefix(1);
  return s;
}

// One parameter as found in the parameter section; its data stays in the file buffer.
struct Parameter {
  int group_id = 0;
  std::string group;
  std::string name;
  int8_t type = 0;  // -1 char, 1 byte, 2 int16, 4 real
  std::vector<std::size_t> dims;
  std::size_t data_offset = 0;
  std::size_t element_count = 1;
};

class Parameters {
 public:
  const Parameter* find(std::string_view group, std::string_view name) const {
    for (const auto& p : list) {
      if (equals_ignore_case(p.group, group) && equals_ignore_case(p.name, name)) return &p;
    }
    return nullptr;
  }
  std::vector<Parameter> list;
};

// Values of a parameter, decoded with the file's encoding. The reader is positioned
// freely; the parameter's extent was checked when it was parsed.
class ParameterValues {
 public:
  explicit ParameterValues(ByteReader& reader) : reader_(reader) {}

  // The first element as a number, for integer and real parameters alike.
  std::optional<double> number(const Parameter* p) const {
    if (!p || p->element_count == 0) return std::nullopt;
    reader_.seek(p->data_offset);
    switch (p->type) {
      case 1: return double(reader_.u8());
      case 2: return double(reader_.i16());
      case 4: return double(reader_.f32());
      default: return std::nullopt;
    }
  }
  // A count stored in a signed 16-bit word: values above 32767 wrap negative in files.
  std::optional<int64_t> count(const Parameter* p) const {
    if (!p || p->element_count == 0) return std::nullopt;
    reader_.seek(p->data_offset);
    if (p->type == 2) return int64_t(reader_.u16());
    if (p->type == 1) return int64_t(reader_.u8());
    if (p->type == 4) {
      const double v = reader_.f32();
      if (!std::isfinite(v) || v < 0 || v > 4.0e9) return std::nullopt;
      return int64_t(std::llround(v));
    }
    return std::nullopt;
  }
  // A 32-bit frame number stored as two unsigned 16-bit words (low, high).
  std::optional<int64_t> long_field(const Parameter* p) const {
    if (!p || p->type != 2 || p->element_count < 2) return std::nullopt;
    reader_.seek(p->data_offset);
    const int64_t low = reader_.u16();
    const int64_t high = reader_.u16();
    return low | (high << 16);
  }
  // A character matrix: dims[0] is the string length, the rest the count.
  std::vector<std::string> strings(const Parameter* p) const {
    std::vector<std::string> out;
    if (!p || p->type != -1) return out;
    if (p->dims.empty()) {
      reader_.seek(p->data_offset);
      out.emplace_back(trim(reader_.bytes(p->element_count)));
      return out;
    }
    const std::size_t length = p->dims[0];
    const std::size_t count = length == 0 ? 0 : p->element_count / length;
    reader_.seek(p->data_offset);
    out.reserve(count);
    for (std::size_t i = 0; i < count; ++i) out.emplace_back(trim(reader_.bytes(length)));
    return out;
  }

 private:
  ByteReader& reader_;
};

bool valid_name_char(char c) { return c > ' ' && c < 0x7f; }

// Walks the linked list of groups and parameters. Damage (a bad name, type, dimension
// or link) ends the walk with a warning: everything before it is kept, because the
// entries readers need usually come first and the data section is intact.
Parameters parse_parameters(ByteReader& reader, std::size_t begin, std::size_t end,
                            std::vector<std::string>& warnings) {
  Parameters params;
  std::vector<std::pair<int, std::string>> groups;
  std::size_t at = begin;
  auto damaged = [&](std::size_t offset, const std::string& what) {
    warnings.push_back(fmt::format("{} @ byte {}: parameter section damaged ({}); ignored from there on", reader.name(),
                                   offset, what));
  };
  while (at + 2 <= end) {
    reader.seek(at);
    const int8_t name_length_signed = reader.i8();
    const int8_t id = reader.i8();
    if (name_length_signed == 0) break;  // end marker used by many writers
    const std::size_t name_length = std::size_t(std::abs(int(name_length_signed)));
    if (id == 0) {
      damaged(at, "entry with group id 0");
      break;
    }
    // name, 2-byte link, and for parameters at least type and dimension count
    if (at + 2 + name_length + 2 > end) {
      damaged(at, "entry runs past the parameter section");
      break;
    }
    std::string name(reader.bytes(name_length));
    if (!std::all_of(name.begin(), name.end(), valid_name_char)) {
      damaged(at, fmt::format("name of {} bytes is not printable text", name_length));
      break;
    }
    const std::size_t link_at = reader.offset();
    const int16_t link = reader.i16();
    const std::size_t next = link == 0 ? end : link_at + std::size_t(uint16_t(link));
    if (link < 0 || next <= link_at) {
      damaged(link_at, fmt::format("link {} to the next entry points backwards", link));
      break;
    }

    if (id < 0) {
      groups.emplace_back(-int(id), std::move(name));
    } else {
      Parameter p;
      p.group_id = id;
      p.name = std::move(name);
      if (!reader.has(2)) {
        damaged(reader.offset(), "truncated parameter");
        break;
      }
      p.type = reader.i8();
      if (p.type != -1 && p.type != 1 && p.type != 2 && p.type != 4) {
        damaged(reader.offset() - 1,
                fmt::format("parameter {} has data type {}, expected -1, 1, 2 or 4", p.name, int(p.type)));
        break;
      }
      const uint8_t dim_count = reader.u8();
      if (dim_count > 7 || !reader.has(dim_count)) {
        damaged(reader.offset() - 1, fmt::format("parameter {} has {} dimensions", p.name, dim_count));
        break;
      }
      for (uint8_t d = 0; d < dim_count; ++d) {
        p.dims.push_back(reader.u8());
        p.element_count *= p.dims.back();
      }
      p.data_offset = reader.offset();
      const std::size_t data_bytes = p.element_count * std::size_t(std::abs(int(p.type)));
      if (data_bytes > end - std::min(end, p.data_offset)) {
        damaged(p.data_offset,
                fmt::format("data of parameter {} ({} bytes) runs past the section", p.name, data_bytes));
        break;
      }
      params.list.push_back(std::move(p));
    }
    if (link == 0) break;
    at = next;
  }
  for (auto& p : params.list) {
    for (const auto& [id, name] : groups) {
      if (id == p.group_id) p.group = name;
    }
  }
  return params;
}

std::string generated_label(std::size_t index) { return fmt::format("point_{}", index + 1); }

}  // namespace

MarkerTake read_c3d(std::span<const char> bytes, const std::string& name) {
  ByteReader reader(bytes, name);
  MarkerTake take;
  take.format = TakeFormat::kC3d;
  if (bytes.size() < kBlockBytes) {
    reader.fail_at(0, fmt::format("not a C3D file: {} bytes, shorter than the 512-byte header", bytes.size()));
  }
  const uint8_t parameter_block = reader.u8();
  const uint8_t key = reader.u8();
  if (key != kHeaderKey) {
    reader.fail_at(1, fmt::format("not a C3D file: byte 1 is 0x{:02x}, expected 0x50", key));
  }
  if (parameter_block == 0) reader.fail_at(0, "header points to parameter block 0 (blocks count from 1)");
  const std::size_t parameter_start = (std::size_t(parameter_block) - 1) * kBlockBytes;
  if (parameter_start + 4 > bytes.size()) {
    reader.fail_at(
        0, fmt::format("parameter block {} lies past the end of the file ({} bytes)", parameter_block, bytes.size()));
  }
  reader.seek(parameter_start + 2);
  const uint8_t parameter_blocks = reader.u8();
  const uint8_t processor_byte = reader.u8();
  if (processor_byte < kProcessorBase + 1 || processor_byte > kProcessorBase + 3) {
    reader.fail_at(
        parameter_start + 3,
        fmt::format("processor type byte is {}, expected 84 (Intel), 85 (DEC) or 86 (MIPS)", processor_byte));
  }
  const auto processor = Processor(processor_byte - kProcessorBase);
  reader.set_encoding(processor == Processor::kMips ? ByteOrder::kBig : ByteOrder::kLittle,
                      processor == Processor::kDec ? RealFormat::kVax : RealFormat::kIeee);

  // Header words (1-based word numbers as in the C3D manual).
  reader.seek(2);
  const int64_t header_points = reader.u16("header point count");             // word 2
  const int64_t header_analog_per_frame = reader.u16("header analog count");  // word 3
  const int64_t header_first = reader.u16("header first frame");              // word 4
  const int64_t header_last = reader.u16("header last frame");                // word 5
  reader.skip(2);                                                             // word 6: max gap
  const float header_scale = reader.f32("header scale");                      // words 7-8
  const int64_t header_data_start = reader.u16("header data start");          // word 9
  reader.skip(2);                                                             // word 10
  const float header_rate = reader.f32("header frame rate");                  // words 11-12

  // The section's block count is not a reliable bound (s13_Dance understates it): the
  // walk ends at the list's terminator, and damage detection stops it in foreign data.
  Parameters params = parse_parameters(reader, parameter_start + 4, bytes.size(), take.warnings);
  if (params.list.empty()) {
    take.warnings.push_back(fmt::format(
        "{}: no parameters (the section declares {} blocks); layout taken from the header", name, parameter_blocks));
  }
  ParameterValues values(reader);

  const int64_t points = values.count(params.find("POINT", "USED")).value_or(header_points);
  // One label per point is allocated even for a take of no frames: the count must be one
  // a 16-bit word can hold, as the format defines it (a real-typed parameter can claim more).
  if (points > int64_t(kMaxPoints)) {
    reader.fail_at(params.find("POINT", "USED")->data_offset,
                   fmt::format("POINT:USED is {}, more than the {} points a C3D file can hold", points, kMaxPoints));
  }
  double scale = values.number(params.find("POINT", "SCALE")).value_or(header_scale);
  if (!std::isfinite(scale) || scale == 0.0) {
    if (std::isfinite(header_scale) && header_scale != 0.0f) {
      scale = header_scale;
    } else {
      reader.fail_at(12, fmt::format("point scale is {}, cannot tell integer from float storage", scale));
    }
  }
  const bool float_storage = scale < 0;
  double rate = values.number(params.find("POINT", "RATE")).value_or(header_rate);
  if (!std::isfinite(rate) || rate < 0) rate = std::isfinite(header_rate) && header_rate > 0 ? header_rate : 0.0;

  // DATA_START: the parameter wins, the header fills in when it is 0 or absent.
  const std::size_t block_count = (bytes.size() + kBlockBytes - 1) / kBlockBytes;
  // The data may start at the very end of the file (a take of 0 frames).
  auto usable_block = [&](int64_t block) { return block >= 2 && std::size_t(block) <= block_count + 1; };
  int64_t data_start = values.count(params.find("POINT", "DATA_START")).value_or(0);
  if (!usable_block(data_start)) {
    if (data_start != 0) {
      take.warnings.push_back(fmt::format("{}: POINT:DATA_START {} lies outside the file; using the header's {}", name,
                                          data_start, header_data_start));
    }
    data_start = header_data_start;
  }
  if (!usable_block(data_start)) {
    reader.fail_at(
        16, fmt::format("data section start block {} lies outside the file ({} blocks)", data_start, block_count));
  }

  // Analog words per frame: the header's count, or the parameters' when it is 0.
  int64_t analog_per_frame = header_analog_per_frame;
  if (analog_per_frame == 0) {
    const auto used = values.count(params.find("ANALOG", "USED"));
    const auto analog_rate = values.number(params.find("ANALOG", "RATE"));
    if (used && *used > 0 && analog_rate && rate > 0 && std::isfinite(*analog_rate)) {
      const double ratio = *analog_rate / rate;
      if (ratio >= 1 && ratio < 65536) analog_per_frame = *used * std::llround(ratio);
    }
  }

  int64_t first_frame = header_first;
  int64_t last_frame = header_last;
  if (auto start = values.long_field(params.find("TRIAL", "ACTUAL_START_FIELD"))) first_frame = *start;
  if (auto stop = values.long_field(params.find("TRIAL", "ACTUAL_END_FIELD"))) last_frame = *stop;
  int64_t frame_count = last_frame >= first_frame ? last_frame - first_frame + 1 : 0;
  if (last_frame < first_frame) {
    // The 16-bit header overflowed and no TRIAL fields exist: use POINT:FRAMES / LONG_FRAMES.
    frame_count = values.count(params.find("POINT", "LONG_FRAMES"))
                      .value_or(values.count(params.find("POINT", "FRAMES")).value_or(0));
  }

  const std::size_t word_bytes = float_storage ? 4 : 2;
  const uint64_t frame_bytes = (uint64_t(points) * 4 + uint64_t(analog_per_frame)) * word_bytes;
  const std::size_t data_offset = (std::size_t(data_start) - 1) * kBlockBytes;
  const uint64_t available = bytes.size() - std::min(bytes.size(), data_offset);
  // Frames of no points and no analog samples take no bytes in the file but memory in the
  // take: a 4 KiB header could otherwise claim millions of them.
  if (frame_count > 0 && frame_bytes == 0) {
    reader.fail_at(data_offset, fmt::format("the file declares {} frames of 0 points and 0 analog words: frames "
                                            "that hold nothing",
                                            frame_count));
  }
  if (frame_count > 0 && uint64_t(frame_count) > available / frame_bytes) {
    reader.fail_at(
        data_offset,
        fmt::format("data section holds {} complete frames, but the file declares {} ({} points, "
                    "{} analog words, {} bytes per frame)",
                    frame_bytes ? available / frame_bytes : 0, frame_count, points, analog_per_frame, frame_bytes));
  }

  // Labels: POINT:LABELS then LABELS2, LABELS3, ... until every point has one.
  std::vector<std::string> labels;
  for (int part = 1; labels.size() < std::size_t(points); ++part) {
    const auto* p = params.find("POINT", part == 1 ? std::string("LABELS") : fmt::format("LABELS{}", part));
    if (!p) break;
    for (auto& label : values.strings(p)) {
      if (labels.size() < std::size_t(points)) labels.push_back(std::move(label));
    }
  }
  const std::size_t labelled = labels.size();
  labels.resize(std::size_t(points));
  for (std::size_t i = 0; i < labels.size(); ++i) {
    if (labels[i].empty()) labels[i] = generated_label(i);
  }
  if (labelled < std::size_t(points)) {
    take.warnings.push_back(fmt::format("{}: {} of {} points have no POINT:LABELS entry; named point_N", name,
                                        std::size_t(points) - labelled, points));
  }
  const auto units = values.strings(params.find("POINT", "UNITS"));
  take.units = units.empty() || units[0].empty() ? "mm" : units[0];
  if (units.empty()) take.warnings.push_back(fmt::format("{}: no POINT:UNITS; assuming mm", name));

  take.labels = std::move(labels);
  take.rate_hz = rate;
  take.first_frame = first_frame;
  take.metadata = {
      {"processor", std::string(processor_name(processor))},
      {"storage", float_storage ? "float" : "integer"},
      {"scale", fmt::format("{}", scale)},
      {"parameter_block", fmt::format("{}", parameter_block)},
      {"data_start_block", fmt::format("{}", data_start)},
      {"analog_words_per_frame", fmt::format("{}", analog_per_frame)},
  };

  // Data section.
  const double point_scale = float_storage ? 1.0 : scale;
  const bool timed = usable_frame_rate(rate, std::size_t(frame_count));  // finish_take says why not
  const double nan = std::numeric_limits<double>::quiet_NaN();
  take.frames.resize(std::size_t(frame_count));
  reader.seek(data_offset, "data section");
  for (int64_t f = 0; f < frame_count; ++f) {
    MarkerFrame& frame = take.frames[std::size_t(f)];
    frame.frame_no = first_frame + f;
    frame.source_time_ns = timed ? std::llround(double(f) * 1e9 / rate) : 0;
    frame.markers.resize(std::size_t(points));
    for (int64_t p = 0; p < points; ++p) {
      Marker& m = frame.markers[std::size_t(p)];
      m.id = int32_t(p);
      m.label.assign(take.labels[std::size_t(p)]);
      double xyz[3];
      double residual_word;
      if (float_storage) {
        for (double& v : xyz) v = reader.f32("point coordinate");
        residual_word = reader.f32("point residual");
      } else {
        for (double& v : xyz) v = reader.i16("point coordinate") * point_scale;
        residual_word = reader.i16("point residual");
      }
      const bool finite = std::isfinite(xyz[0]) && std::isfinite(xyz[1]) && std::isfinite(xyz[2]);
      if (residual_word < 0 || !finite || std::isnan(residual_word)) {
        m.flags = kMarkerMissing;
        m.position = Eigen::Vector3d(nan, nan, nan);
      } else {
        m.position = Eigen::Vector3d(xyz[0], xyz[1], xyz[2]);
      }
    }
    reader.skip(std::size_t(analog_per_frame) * word_bytes, "analog samples");
  }
  finish_take(take, name);
  return take;
}

namespace {

// Builds the parameter section: groups and parameters in a linked list.
class ParameterSectionWriter {
 public:
  explicit ParameterSectionWriter(std::vector<char>& out) : out_(out), w_(out) {}

  void group(int8_t id, std::string_view name, std::string_view description) {
    begin_entry(int8_t(-id), name);
    w_.u8(uint8_t(description.size()));
    w_.bytes(description);
  }
  void int16s(int8_t group, std::string_view name, std::span<const int16_t> values, bool scalar = false) {
    begin_parameter(group, name, 2, scalar ? std::vector<std::size_t>{} : std::vector<std::size_t>{values.size()});
    for (int16_t v : values) w_.i16(v);
    end_parameter();
  }
  void real(int8_t group, std::string_view name, float value) {
    begin_parameter(group, name, 4, {});
    w_.f32(value);
    end_parameter();
  }
  void text(int8_t group, std::string_view name, std::string_view value) {
    begin_parameter(group, name, -1, {std::max<std::size_t>(value.size(), 1)});
    w_.bytes(value);
    if (value.empty()) w_.u8(' ');
    end_parameter();
  }
  // Fixed-width strings, padded with spaces: dims [width, count].
  void texts(int8_t group, std::string_view name, std::span<const std::string> values) {
    std::size_t width = 1;
    for (const auto& v : values) width = std::max(width, std::min<std::size_t>(v.size(), 255));
    begin_parameter(group, name, -1, {width, values.size()});
    for (const auto& v : values) {
      const std::string_view s = std::string_view(v).substr(0, width);
      w_.bytes(s);
      for (std::size_t i = s.size(); i < width; ++i) w_.u8(' ');
    }
    end_parameter();
  }
  // Terminates the list: the last entry links to nothing.
  void finish() {
    if (link_at_) w_.patch<int16_t>(*link_at_, 0);
  }

 private:
  void begin_entry(int8_t id, std::string_view name) {
    const std::size_t entry_at = out_.size();
    if (link_at_) w_.patch<int16_t>(*link_at_, int16_t(entry_at - *link_at_));
    w_.i8(int8_t(name.size()));
    w_.i8(id);
    w_.bytes(name);
    link_at_ = out_.size();
    w_.i16(0);
  }
  void begin_parameter(int8_t group, std::string_view name, int8_t type, const std::vector<std::size_t>& dims) {
    begin_entry(group, name);
    w_.i8(type);
    w_.u8(uint8_t(dims.size()));
    for (auto d : dims) w_.u8(uint8_t(d));
  }
  void end_parameter() { w_.u8(0); }  // no description

  std::vector<char>& out_;
  ByteWriter w_;
  std::optional<std::size_t> link_at_;
};

void pad_to_block(std::vector<char>& out) {
  out.resize((out.size() + kBlockBytes - 1) / kBlockBytes * kBlockBytes, '\0');
}

int16_t word_bits(int64_t unsigned_value) { return int16_t(uint16_t(std::clamp<int64_t>(unsigned_value, 0, 65535))); }

}  // namespace

std::vector<char> write_c3d(const MarkerTake& take, const ProgressFn& progress) {
  check_take_shape(take, "C3D writer");
  const std::size_t points = take.marker_count();
  if (points > kMaxPoints)
    throw Error(fmt::format("C3D holds at most {} points per frame, the take has {}", kMaxPoints, points));
  const int64_t frames = int64_t(take.frames.size());
  const int64_t first = std::max<int64_t>(1, take.first_frame);
  const int64_t last = first + frames - 1;  // first - 1 for an empty take
  const float scale = -1.0f;                // float storage; residuals are written as 0 (present) or -1 (missing)
  const float rate = float(take.rate_hz);

  // Parameters first (their size sets the data start block).
  std::vector<char> params;
  ParameterSectionWriter pw(params);
  constexpr int8_t kPoint = 1, kAnalog = 2, kTrial = 3, kManufacturer = 4;
  pw.group(kPoint, "POINT", "3-D point parameters");
  const int16_t used = word_bits(int64_t(points));
  pw.int16s(kPoint, "USED", std::span(&used, 1), true);
  pw.real(kPoint, "SCALE", scale);
  pw.real(kPoint, "RATE", rate);
  const std::size_t data_start_param_at = params.size();
  const int16_t placeholder = 0;
  pw.int16s(kPoint, "DATA_START", std::span(&placeholder, 1), true);
  const int16_t frames_word = word_bits(frames);
  pw.int16s(kPoint, "FRAMES", std::span(&frames_word, 1), true);
  pw.real(kPoint, "LONG_FRAMES", float(frames));
  pw.text(kPoint, "UNITS", take.units.empty() ? "mm" : take.units);
  for (std::size_t part = 1;; ++part) {
    const std::size_t begin = (part - 1) * kMaxLabelsPerParameter;
    const std::size_t end = std::min(points, begin + kMaxLabelsPerParameter);
    const std::vector<std::string> chunk(take.labels.begin() + std::ptrdiff_t(begin),
                                         take.labels.begin() + std::ptrdiff_t(end));
    pw.texts(kPoint, part == 1 ? std::string("LABELS") : fmt::format("LABELS{}", part), chunk);
    if (end >= points) break;
  }
  pw.group(kAnalog, "ANALOG", "Analog data parameters");
  const int16_t zero = 0;
  pw.int16s(kAnalog, "USED", std::span(&zero, 1), true);
  pw.real(kAnalog, "RATE", rate);
  pw.group(kTrial, "TRIAL", "Trial parameters");
  const int16_t start_field[2] = {int16_t(uint16_t(first & 0xffff)), int16_t(uint16_t((first >> 16) & 0xffff))};
  const int16_t end_field[2] = {int16_t(uint16_t(last & 0xffff)), int16_t(uint16_t((last >> 16) & 0xffff))};
  pw.int16s(kTrial, "ACTUAL_START_FIELD", start_field);
  pw.int16s(kTrial, "ACTUAL_END_FIELD", end_field);
  pw.group(kManufacturer, "MANUFACTURER", "Software that wrote the file");
  pw.text(kManufacturer, "SOFTWARE", "facecap");
  pw.finish();

  const std::size_t parameter_bytes = 4 + params.size() + 1;  // 4-byte section header, end byte
  const std::size_t parameter_blocks = (parameter_bytes + kBlockBytes - 1) / kBlockBytes;
  if (parameter_blocks > 255)
    throw Error(fmt::format("C3D parameter section would need {} blocks (at most 255)", parameter_blocks));
  const std::size_t data_start = 2 + parameter_blocks;
  // Patch DATA_START's value: after the entry's name length, id, name, link, type, dims.
  {
    const std::size_t value_at = data_start_param_at + 2 + std::string_view("DATA_START").size() + 2 + 2;
    ByteWriter(params).patch<int16_t>(value_at, word_bits(int64_t(data_start)));
  }

  std::vector<char> out;
  out.reserve(data_start * kBlockBytes + std::size_t(frames) * points * 16);
  ByteWriter w(out);
  // Header block.
  w.u8(2);  // parameter block
  w.u8(kHeaderKey);
  w.u16(uint16_t(used));
  w.u16(0);  // analog words per frame
  w.u16(uint16_t(std::min<int64_t>(first, 65535)));
  w.u16(uint16_t(std::clamp<int64_t>(last, 0, 65535)));
  w.u16(0);  // max interpolation gap
  w.f32(scale);
  w.u16(uint16_t(data_start));
  w.u16(0);  // analog samples per frame
  w.f32(rate);
  w.zeros(298 - out.size());
  w.u16(12345);  // word 150: 4-character event labels supported
  pad_to_block(out);
  // Parameter section.
  w.u8(1);
  w.u8(kHeaderKey);
  w.u8(uint8_t(parameter_blocks));
  w.u8(kProcessorBase + uint8_t(Processor::kIntel));
  w.bytes(std::string_view(params.data(), params.size()));
  w.u8(0);
  pad_to_block(out);
  // Data section.
  for (std::size_t f = 0; f < take.frames.size(); ++f) {
    for (const Marker& m : take.frames[f].markers) {
      if (m.present()) {
        w.f32(float(m.position.x()));
        w.f32(float(m.position.y()));
        w.f32(float(m.position.z()));
        w.f32(0.0f);
      } else {
        w.f32(0.0f);
        w.f32(0.0f);
        w.f32(0.0f);
        w.f32(-1.0f);
      }
    }
    report_progress(progress, f + 1, take.frames.size());
  }
  pad_to_block(out);
  return out;
}

}  // namespace facecap::formats
