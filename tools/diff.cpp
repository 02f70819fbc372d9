// facecap diff: compares the solved frames of two recordings frame by frame (weights, head
// pose, vertices, status flags) and says where they differ most. Exit 0 within the
// tolerances, 1 beyond them, 2 when the recordings cannot be compared (as diff(1)). It is
// the regression tool for golden replays (after gpsd's regress-driver) and lets an artist
// compare two solves. Nothing here is real-time.
#include <algorithm>
#include <array>
#include <cmath>
#include <cstdio>
#include <filesystem>
#include <limits>
#include <numbers>
#include <optional>
#include <sstream>
#include <string>
#include <utility>
#include <vector>

#include <fmt/format.h>
#include <dtl/dtl.hpp>
#include <nlohmann/json.hpp>

#include "core/error.hpp"
#include "core/frame.hpp"
#include "core/units.hpp"
#include "formats/recording.hpp"
#include "tools/commands.hpp"
#include "tools/progress.hpp"
#include "tools/tool_support.hpp"

namespace facecap::tools {
namespace {

// Comparisons this long get a progress bar on a terminal without asking.
constexpr std::size_t kLongComparisonFrames = 1000;
// Frames present in one file only: how many numbers are listed.
constexpr std::size_t kListedMissingFrames = 10;
// The exit status for input that cannot be compared, and for usage errors.
constexpr int kExitTrouble = 2;

struct DiffOptions {
  std::string file_a, file_b;
  double tolerance_weight = 1e-6;
  double tolerance_mm = 1e-3;
  double tolerance_degrees = 1e-6;
  std::string rig_units;  // for a recording whose HEAD has none
  std::size_t top = 5;
  bool allow_missing = false;
  bool json = false;
  bool progress = false;
};

// |a - b|, except that two NaNs are the same value and one NaN differs infinitely, so a
// value that went missing on one side is always beyond any tolerance.
double scalar_difference(double a, double b) noexcept {
  const bool nan_a = std::isnan(a), nan_b = std::isnan(b);
  if (nan_a || nan_b) return nan_a == nan_b ? 0.0 : std::numeric_limits<double>::infinity();
  return std::abs(a - b);
}

// Euclidean distance between a and b, each component by scalar_difference.
double distance(const Eigen::Vector3d& a, const Eigen::Vector3d& b) noexcept {
  double sum = 0.0;
  for (int k = 0; k < 3; ++k) sum += std::pow(scalar_difference(a[k], b[k]), 2);
  return std::sqrt(sum);
}

// The angle of the rotation taking a to b, in degrees: 4 atan2(|a - b|, |a + b|) of the
// unit quaternions on one side (q and -q are one rotation). Exactly 0 for equal poses and
// accurate at small angles, where acos (and Eigen's angularDistance with FMA) are not.
double rotation_degrees(const Eigen::Quaterniond& a, const Eigen::Quaterniond& b) noexcept {
  const Eigen::Vector4d qa = a.coeffs().normalized();
  Eigen::Vector4d qb = b.coeffs().normalized();
  if (qa.dot(qb) < 0.0) qb = -qb;
  const double degrees = 4.0 * std::atan2((qa - qb).norm(), (qa + qb).norm()) * 180.0 / std::numbers::pi;
  if (!std::isnan(degrees)) return degrees;
  double coefficient_difference = 0.0;
  for (int k = 0; k < 4; ++k) coefficient_difference += scalar_difference(a.coeffs()[k], b.coeffs()[k]);
  return coefficient_difference == 0.0 ? 0.0 : std::numeric_limits<double>::infinity();
}

// One difference and where it is. element is the shape or vertex index, -1 for a channel
// with one value per frame; a and b are the two values (weights only).
struct Place {
  int64_t frame_no = 0;
  int64_t element = -1;
  double difference = 0.0;
  double a = 0.0, b = 0.0;
};

// The differences of one compared quantity over the common frames: the largest and where,
// mean and RMS, how many values and frames are beyond the tolerance, and the worst frames
// (each with its own largest difference), largest first.
class Channel {
 public:
  // element names a frame's values ("shape", "vertex"), nullptr when a frame has one value;
  // shape_names (weights) names each shape, and its places keep both values.
  Channel(double tolerance, std::size_t top, const char* element = nullptr,
          const std::vector<std::string>* shape_names = nullptr)
      : tolerance_(tolerance), top_(top), element_(element), shape_names_(shape_names) {}

  void add(int64_t element, double difference, double a = 0.0, double b = 0.0) {
    ++values_;
    sum_ += difference;
    sum_squares_ += difference * difference;
    if (difference > tolerance_) ++values_beyond_;
    if (difference > frame_worst_.difference) frame_worst_ = {0, element, difference, a, b};
  }
  // Closes the frame whose values add() received.
  void end_frame(int64_t frame_no) {
    ++frames_;
    Place worst = std::exchange(frame_worst_, Place{});
    worst.frame_no = frame_no;
    if (worst.difference > tolerance_) ++frames_beyond_;
    if (worst.difference <= 0.0) return;
    if (!largest_ || worst.difference > largest_->difference) largest_ = worst;
    if (top_ == 0 || (worst_frames_.size() == top_ && worst.difference <= worst_frames_.back().difference)) return;
    const auto at = std::upper_bound(worst_frames_.begin(), worst_frames_.end(), worst.difference,
                                     [](double d, const Place& p) { return d > p.difference; });
    worst_frames_.insert(at, worst);
    if (worst_frames_.size() > top_) worst_frames_.pop_back();
  }

  double tolerance() const noexcept { return tolerance_; }
  const char* element() const noexcept { return element_; }
  const std::vector<std::string>* shape_names() const noexcept { return shape_names_; }
  std::size_t frames() const noexcept { return frames_; }
  std::size_t frames_beyond() const noexcept { return frames_beyond_; }
  std::size_t values_beyond() const noexcept { return values_beyond_; }
  const std::optional<Place>& largest() const noexcept { return largest_; }  // none when all equal
  const std::vector<Place>& worst_frames() const noexcept { return worst_frames_; }
  double max() const noexcept { return largest_ ? largest_->difference : 0.0; }
  double mean() const noexcept { return values_ ? sum_ / double(values_) : 0.0; }
  double rms() const noexcept { return values_ ? std::sqrt(sum_squares_ / double(values_)) : 0.0; }

 private:
  double tolerance_;
  std::size_t top_;
  const char* element_;
  const std::vector<std::string>* shape_names_;
  std::size_t values_ = 0, values_beyond_ = 0, frames_ = 0, frames_beyond_ = 0;
  double sum_ = 0.0, sum_squares_ = 0.0;
  Place frame_worst_;  // of the frame add() is receiving
  std::optional<Place> largest_;
  std::vector<Place> worst_frames_;
};

// "qp_iteration_cap" for a known SolvedFlags bit, "bit 7" beyond them.
std::string flag_name(std::size_t bit) {
  return bit < kSolvedFlagCount ? std::string(solved_flag_name(bit)) : fmt::format("bit {}", bit);
}

std::vector<std::string> flag_names(uint32_t bits) {
  std::vector<std::string> names;
  for (std::size_t bit = 0; bit < 32; ++bit)
    if (bits & (1u << bit)) names.push_back(flag_name(bit));
  return names;
}

// Frames whose status flags differ: per bit how often only A or only B has it, and the
// first frames that differ.
struct FlagDifferences {
  struct Frame {
    int64_t frame_no;
    uint32_t a, b;
  };
  std::size_t frames_differ = 0;
  std::array<std::size_t, 32> a_only{}, b_only{};
  std::vector<Frame> first;

  void add(int64_t frame_no, uint32_t a, uint32_t b, std::size_t listed) {
    if (a == b) return;
    ++frames_differ;
    for (std::size_t bit = 0; bit < 32; ++bit) {
      a_only[bit] += (a & ~b) >> bit & 1u;
      b_only[bit] += (b & ~a) >> bit & 1u;
    }
    if (first.size() < listed) first.push_back({frame_no, a, b});
  }
};

// Frames present in one recording only: how many, and the first numbers.
struct MissingFrames {
  std::size_t count = 0;
  std::vector<int64_t> first;
  void add(int64_t frame_no) {
    ++count;
    if (first.size() < kListedMissingFrames) first.push_back(frame_no);
  }
};

// How one text field of the two HEADs differs: not at all, or as a unified diff of lines.
struct TextDifference {
  bool differ = false;
  std::string unified;
};

std::vector<std::string> split_lines(const std::string& text) {
  std::vector<std::string> lines;
  std::istringstream in(text);
  for (std::string line; std::getline(in, line);) lines.push_back(line);
  return lines;
}

TextDifference text_difference(const std::string& a, const std::string& b) {
  if (a == b) return {};
  dtl::Diff<std::string> diff(split_lines(a), split_lines(b));
  diff.compose();
  diff.composeUnifiedHunks();
  std::ostringstream unified;
  diff.printUnifiedFormat(unified);
  return {true, unified.str()};
}

using FrameNumbers = std::vector<std::pair<int64_t, std::size_t>>;

// A recording opened for comparison: its millimetres per rig unit and its solved frames
// as (frame number, solved-frame index), sorted by number.
struct Side {
  std::string file;
  formats::RecordingReader reader;
  std::string rig_units;
  bool rig_units_from_option = false;
  double mm_per_unit = 1.0;
  FrameNumbers frames;

  Side(const std::string& path, const std::string& option_units) : file(path), reader(std::filesystem::path(path)) {
    const formats::RecordingHeader& h = reader.header();
    if (reader.solved_frame_count() == 0)
      throw file_error(file, "has no solved frames (a marker-only recording?): nothing to compare");
    rig_units = h.rig_units;
    if (rig_units.empty()) {
      if (option_units.empty()) {
        throw file_error(file, fmt::format("HEAD names no rig_units (format version {}): pass --rig-units mm|cm|m "
                                           "for its vertices and head translation",
                                           h.format_version));
      }
      rig_units = option_units;
      rig_units_from_option = true;
    }
    const auto mm = millimetres_per_unit(rig_units);
    if (!mm) throw file_error(file, fmt::format("rig units '{}' are not mm, cm or m", rig_units));
    mm_per_unit = *mm;

    frames.reserve(reader.solved_frame_count());
    for (const formats::RecordingIndexEntry& e : reader.index())
      if (e.kind == formats::ChunkKind::kSolvedFrame) frames.emplace_back(e.frame_no, frames.size());
    std::stable_sort(frames.begin(), frames.end());
    const auto repeat = std::adjacent_find(frames.begin(), frames.end(),
                                           [](const auto& x, const auto& y) { return x.first == y.first; });
    if (repeat != frames.end()) {
      throw file_error(file, fmt::format("frame number {} repeats (solved frames #{} and #{}, counting from 0): "
                                         "diff matches frames by number",
                                         repeat->first, repeat->second, std::next(repeat)->second));
    }
  }
};

std::string hex_hash(uint64_t hash) { return fmt::format("{:#018x}", hash); }

// Refuses recordings whose frames do not describe the same thing.
void check_comparable(const Side& a, const Side& b) {
  const formats::RecordingHeader& ha = a.reader.header();
  const formats::RecordingHeader& hb = b.reader.header();
  if (ha.rig_hash != hb.rig_hash) {
    throw Error(fmt::format("{} and {} are solves of different rigs: '{}' (rig hash {}) and '{}' (rig hash {})", a.file,
                            b.file, ha.rig_name, hex_hash(ha.rig_hash), hb.rig_name, hex_hash(hb.rig_hash)));
  }
  if (ha.shape_names != hb.shape_names) {
    const auto [at_a, at_b] =
        std::mismatch(ha.shape_names.begin(), ha.shape_names.end(), hb.shape_names.begin(), hb.shape_names.end());
    const auto shape = at_a - ha.shape_names.begin();
    throw Error(fmt::format("{} and {} list different shapes ({} and {}): shape {} is '{}' and '{}'", a.file, b.file,
                            ha.shape_names.size(), hb.shape_names.size(), shape,
                            at_a == ha.shape_names.end() ? "(none)" : *at_a,
                            at_b == hb.shape_names.end() ? "(none)" : *at_b));
  }
}

struct Comparison {
  std::size_t frames_compared = 0;
  MissingFrames only_a, only_b;
  Channel weights, head_rotation, head_translation, vertices;
  std::size_t vertex_frames_only_a = 0, vertex_frames_only_b = 0;  // frames where one side has no vertices
  FlagDifferences flags;
  TextDifference solver_settings, calibration;
  std::vector<std::string> beyond;  // what breaks the tolerances, in table order

  Comparison(const DiffOptions& o, const std::vector<std::string>& shape_names)
      : weights(o.tolerance_weight, o.top, "shape", &shape_names),
        head_rotation(o.tolerance_degrees, o.top),
        head_translation(o.tolerance_mm, o.top),
        vertices(o.tolerance_mm, o.top, "vertex") {}
};

void compare_frame(const Side& a, const SolvedFrame& fa, const Side& b, const SolvedFrame& fb, const DiffOptions& o,
                   Comparison& c) {
  const auto shapes = Eigen::Index(a.reader.header().shape_names.size());
  for (const auto& [side, frame] : {std::pair{&a, &fa}, std::pair{&b, &fb}}) {
    if (frame->weights.size() != shapes) {
      throw file_error(side->file, fmt::format("solved frame {} has {} weights, HEAD names {} shapes", frame->frame_no,
                                               frame->weights.size(), shapes));
    }
  }
  const int64_t frame_no = fa.frame_no;
  for (Eigen::Index s = 0; s < shapes; ++s)
    c.weights.add(s, scalar_difference(fa.weights[s], fb.weights[s]), fa.weights[s], fb.weights[s]);
  c.weights.end_frame(frame_no);
  c.head_rotation.add(-1, rotation_degrees(fa.head_rotation, fb.head_rotation));
  c.head_rotation.end_frame(frame_no);
  c.head_translation.add(-1, distance(fa.head_translation * a.mm_per_unit, fb.head_translation * b.mm_per_unit));
  c.head_translation.end_frame(frame_no);

  const Eigen::Index na = fa.vertices.cols(), nb = fb.vertices.cols();
  if (na > 0 && nb > 0) {
    if (na != nb) throw Error(fmt::format("frame {}: {} has {} vertices, {} has {}", frame_no, a.file, na, b.file, nb));
    for (Eigen::Index v = 0; v < na; ++v) {
      c.vertices.add(v, distance(fa.vertices.col(v).cast<double>() * a.mm_per_unit,
                                 fb.vertices.col(v).cast<double>() * b.mm_per_unit));
    }
    c.vertices.end_frame(frame_no);
  } else {
    c.vertex_frames_only_a += na > 0;
    c.vertex_frames_only_b += nb > 0;
  }
  c.flags.add(frame_no, fa.flags, fb.flags, o.top);
}

std::size_t count_common(const FrameNumbers& a, const FrameNumbers& b) {
  std::size_t common = 0;
  for (auto ia = a.begin(), ib = b.begin(); ia != a.end() && ib != b.end();) {
    if (ia->first < ib->first) {
      ++ia;
    } else if (ib->first < ia->first) {
      ++ib;
    } else {
      ++common, ++ia, ++ib;
    }
  }
  return common;
}

Comparison compare(const Side& a, const Side& b, const DiffOptions& o) {
  check_comparable(a, b);
  Comparison c(o, a.reader.header().shape_names);
  const std::size_t common = count_common(a.frames, b.frames);
  if (common == 0) {
    throw Error(fmt::format("{} and {} have no frame number in common ({}..{} and {}..{})", a.file, b.file,
                            a.frames.front().first, a.frames.back().first, b.frames.front().first,
                            b.frames.back().first));
  }
  const bool show = o.progress || (stderr_is_terminal() && common >= kLongComparisonFrames);
  ProgressBar bar(fmt::format("comparing {} with {}", std::filesystem::path(a.file).filename().string(),
                              std::filesystem::path(b.file).filename().string()),
                  show);
  SolvedFrame fa, fb;  // storage reused frame to frame: one frame of each file in memory at a time
  auto ia = a.frames.begin(), ib = b.frames.begin();
  while (ia != a.frames.end() || ib != b.frames.end()) {
    if (ib == b.frames.end() || (ia != a.frames.end() && ia->first < ib->first)) {
      c.only_a.add((ia++)->first);
    } else if (ia == a.frames.end() || ib->first < ia->first) {
      c.only_b.add((ib++)->first);
    } else {
      a.reader.read_solved_frame(ia->second, fa);
      b.reader.read_solved_frame(ib->second, fb);
      compare_frame(a, fa, b, fb, o, c);
      ++c.frames_compared;
      bar.update(c.frames_compared, common);
      ++ia, ++ib;
    }
  }
  bar.finish();
  c.solver_settings = text_difference(a.reader.header().solver_settings, b.reader.header().solver_settings);
  c.calibration = text_difference(a.reader.header().calibration, b.reader.header().calibration);

  if (c.weights.frames_beyond()) c.beyond.push_back("weights");
  if (c.head_rotation.frames_beyond()) c.beyond.push_back("head_rotation");
  if (c.head_translation.frames_beyond()) c.beyond.push_back("head_translation");
  if (c.vertices.frames_beyond()) c.beyond.push_back("vertices");
  if (c.flags.frames_differ) c.beyond.push_back("flags");
  if (!o.allow_missing && c.only_a.count + c.only_b.count > 0) c.beyond.push_back("missing_frames");
  return c;
}

nlohmann::json side_json(const Side& s) {
  const formats::RecordingHeader& h = s.reader.header();
  return {{"file", s.file},
          {"rig_name", h.rig_name},
          {"rig_hash", hex_hash(h.rig_hash)},
          {"format_version", h.format_version},
          {"rig_units", s.rig_units},
          {"rig_units_from_option", s.rig_units_from_option},
          {"solved_frames", s.reader.solved_frame_count()},
          {"truncated", s.reader.truncated()}};
}

nlohmann::json place_json(const Channel& c, const Place& p) {
  nlohmann::json j = {{"frame", p.frame_no}};
  if (c.element()) j[c.element()] = p.element;
  if (c.shape_names()) {
    j["shape_name"] = (*c.shape_names())[std::size_t(p.element)];
    j["a"] = p.a;
    j["b"] = p.b;
  }
  j["difference"] = p.difference;
  return j;
}

nlohmann::json channel_json(const Channel& c) {
  nlohmann::json worst = nlohmann::json::array();
  for (const Place& p : c.worst_frames()) worst.push_back(place_json(c, p));
  nlohmann::json j = {{"tolerance", c.tolerance()},
                      {"frames", c.frames()},
                      {"max", c.max()},
                      {"largest", c.largest() ? place_json(c, *c.largest()) : nullptr},
                      {"mean", c.mean()},
                      {"rms", c.rms()},
                      {"frames_beyond", c.frames_beyond()}};
  if (c.element()) j["values_beyond"] = c.values_beyond();
  j["worst"] = worst;
  return j;
}

nlohmann::json missing_json(const MissingFrames& m) { return {{"count", m.count}, {"first", m.first}}; }

nlohmann::json flags_json(const FlagDifferences& f) {
  nlohmann::json bits = nlohmann::json::object();
  for (std::size_t bit = 0; bit < 32; ++bit) {
    if (f.a_only[bit] + f.b_only[bit] > 0)
      bits[flag_name(bit)] = {{"a_only", f.a_only[bit]}, {"b_only", f.b_only[bit]}};
  }
  nlohmann::json first = nlohmann::json::array();
  for (const auto& d : f.first) {
    first.push_back({{"frame", d.frame_no},
                     {"a", d.a},
                     {"b", d.b},
                     {"a_only", flag_names(d.a & ~d.b)},
                     {"b_only", flag_names(d.b & ~d.a)}});
  }
  return {{"frames_differ", f.frames_differ}, {"bits", bits}, {"first", first}};
}

nlohmann::json text_json(const TextDifference& t) { return {{"differ", t.differ}, {"diff", t.unified}}; }

nlohmann::json comparison_json(const Side& a, const Side& b, const Comparison& c) {
  nlohmann::json vertices = channel_json(c.vertices);
  vertices["frames_with_vertices_only_in_a"] = c.vertex_frames_only_a;
  vertices["frames_with_vertices_only_in_b"] = c.vertex_frames_only_b;
  return {
      {"a", side_json(a)},
      {"b", side_json(b)},
      {"frames",
       {{"compared", c.frames_compared}, {"only_in_a", missing_json(c.only_a)}, {"only_in_b", missing_json(c.only_b)}}},
      {"weights", channel_json(c.weights)},
      {"head_rotation_degrees", channel_json(c.head_rotation)},
      {"head_translation_mm", channel_json(c.head_translation)},
      {"vertices_mm", vertices},
      {"flags", flags_json(c.flags)},
      {"solver_settings", text_json(c.solver_settings)},
      {"calibration", text_json(c.calibration)},
      {"beyond", c.beyond},
      {"exit_status", c.beyond.empty() ? 0 : 1}};
}

std::string frame_list(const MissingFrames& m) {
  if (m.count == 0) return "0";
  return fmt::format("{} ({}{})", m.count, fmt::join(m.first, ", "), m.count > m.first.size() ? ", ..." : "");
}

std::string joined_flag_names(uint32_t bits) {
  return bits ? fmt::format("{}", fmt::join(flag_names(bits), ",")) : std::string("-");
}

void print_side(const char* letter, const Side& s) {
  const formats::RecordingHeader& h = s.reader.header();
  fmt::print("{}  {}: rig '{}' {}, {} solved frames, rig units {}{}, format {}\n", letter, s.file, h.rig_name,
             hex_hash(h.rig_hash), s.reader.solved_frame_count(), s.rig_units,
             s.rig_units_from_option ? " (--rig-units)" : "", h.format_version);
}

constexpr const char* kRowFormat = "{:<23}{:<14}{:<36}{:<11}{:<11}{:<15}{}\n";

// "frame 7, shape 3 browInnerUp_L", "frame 3, vertex 17", "frame 12".
std::string where(const Channel& c, const Place& p) {
  std::string text = fmt::format("frame {}", p.frame_no);
  if (c.shape_names())
    return text + fmt::format(", shape {} {}", p.element, (*c.shape_names())[std::size_t(p.element)]);
  if (c.element()) return text + fmt::format(", {} {}", c.element(), p.element);
  return text;
}

void print_row(const char* name, const Channel& c) {
  fmt::print(kRowFormat, name, fmt::format("{:.6g}", c.max()), c.largest() ? where(c, *c.largest()) : "-",
             fmt::format("{:.3g}", c.mean()), fmt::format("{:.3g}", c.rms()), c.frames_beyond(),
             fmt::format("{:g}", c.tolerance()));
}

void print_worst(const char* title, const Channel& c) {
  if (c.worst_frames().empty()) return;
  fmt::print("\nworst {}:\n", title);
  for (const Place& p : c.worst_frames()) {
    const std::string difference = fmt::format("{:.6g}", p.difference);
    if (c.shape_names()) {
      fmt::print("  {:<40} {:<12} A {:.9g}, B {:.9g}\n", where(c, p), difference, p.a, p.b);
    } else {
      fmt::print("  {:<40} {}\n", where(c, p), difference);
    }
  }
}

void print_text_difference(const char* name, const TextDifference& t) {
  fmt::print("{:<23}{}\n", name, t.differ ? "differ:" : "same");
  for (const std::string& line : split_lines(t.unified)) fmt::print("  {}\n", line);
}

void print_comparison(const Side& a, const Side& b, const Comparison& c) {
  print_side("A", a);
  print_side("B", b);
  fmt::print("frames: {} compared, only in A: {}, only in B: {}\n\n", c.frames_compared, frame_list(c.only_a),
             frame_list(c.only_b));
  fmt::print(kRowFormat, "channel", "largest", "where", "mean", "rms", "frames beyond", "tolerance");
  print_row("weights", c.weights);
  print_row("head rotation (deg)", c.head_rotation);
  print_row("head translation (mm)", c.head_translation);
  if (c.vertices.frames() > 0) {
    print_row("vertices (mm)", c.vertices);
  } else {
    fmt::print("{:<23}not compared: not in both files\n", "vertices (mm)");
  }
  if (c.vertex_frames_only_a + c.vertex_frames_only_b > 0) {
    fmt::print("{:<23}frames with vertices in one file only: A {}, B {}\n", "", c.vertex_frames_only_a,
               c.vertex_frames_only_b);
  }
  fmt::print("{:<23}{}\n", "flags",
             c.flags.frames_differ ? fmt::format("{} frames differ", c.flags.frames_differ) : std::string("same"));

  print_worst("weights", c.weights);
  print_worst("head rotations (deg)", c.head_rotation);
  print_worst("head translations (mm)", c.head_translation);
  print_worst("vertices (mm)", c.vertices);
  if (!c.flags.first.empty()) {
    fmt::print("\nfirst frames whose flags differ:\n");
    for (const auto& d : c.flags.first) {
      fmt::print("  frame {:<10} A only: {:<28} B only: {}\n", d.frame_no, joined_flag_names(d.a & ~d.b),
                 joined_flag_names(d.b & ~d.a));
    }
  }
  fmt::print("\n");
  print_text_difference("solver settings", c.solver_settings);
  print_text_difference("calibration", c.calibration);
  if (c.beyond.empty()) {
    fmt::print("\nwithin tolerance\n");
  } else {
    std::vector<std::string> names = c.beyond;
    for (std::string& n : names) std::replace(n.begin(), n.end(), '_', ' ');
    fmt::print("\nbeyond tolerance: {}\n", fmt::join(names, ", "));
  }
}

void warn_about(const Side& s, const DiffOptions& o) {
  if (const std::string damage = s.reader.damage_summary(); !damage.empty())
    fmt::print(stderr, "facecap: warning: {}: damaged: {}; comparing the frames read\n", s.file, damage);
  if (!o.rig_units.empty() && !s.rig_units_from_option && s.rig_units != o.rig_units) {
    fmt::print(stderr,
               "facecap: warning: {}: its HEAD names rig units '{}'; --rig-units {} is for a recording "
               "without them\n",
               s.file, s.rig_units, o.rig_units);
  }
}

}  // namespace

void add_diff_command(CLI::App& app, int& exit_code) {
  auto o = std::make_shared<DiffOptions>();
  auto* cmd = app.add_subcommand(
      "diff", "Compare the solved frames of two recordings: exit 0 within tolerances, 1 beyond, 2 not comparable");
  cmd->add_option("a", o->file_a, "The reference recording (.fcrec), e.g. the golden one")->required();
  cmd->add_option("b", o->file_b, "The recording compared with it")->required();
  cmd->add_option("--tolerance-weight", o->tolerance_weight, "Largest |weight difference| within tolerance")
      ->check(CLI::NonNegativeNumber)
      ->capture_default_str();
  cmd->add_option("--tolerance-mm", o->tolerance_mm,
                  "Largest head translation and vertex distance within tolerance, mm")
      ->check(CLI::NonNegativeNumber)
      ->capture_default_str();
  cmd->add_option("--tolerance-degrees", o->tolerance_degrees, "Largest head rotation angle within tolerance, degrees")
      ->check(CLI::NonNegativeNumber)
      ->capture_default_str();
  cmd->add_option("--rig-units", o->rig_units, "Rig units (mm, cm, m) of a recording whose HEAD names none (version 1)")
      ->check(CLI::IsMember({"mm", "cm", "m"}));
  cmd->add_option("--top", o->top, "Worst frames listed per channel")
      ->check(CLI::Range(0, 1000))
      ->capture_default_str();
  cmd->add_flag("--allow-missing", o->allow_missing, "Frames present in one file only do not make the exit status 1");
  cmd->add_flag("--json", o->json, "Print the comparison as JSON (docs/tools.md)");
  cmd->add_flag("--progress", o->progress, "Show progress on stderr (default: on a terminal, for long recordings)");
  cmd->callback([o, &exit_code] {
    try {
      const Side a(o->file_a, o->rig_units), b(o->file_b, o->rig_units);
      warn_about(a, *o);
      warn_about(b, *o);
      const Comparison c = compare(a, b, *o);
      if (o->json) {
        // Infinities (a NaN on one side only) have no JSON form and print as null; names
        // read from the files may hold invalid UTF-8.
        std::puts(comparison_json(a, b, c).dump(2, ' ', false, nlohmann::json::error_handler_t::replace).c_str());
      } else {
        print_comparison(a, b, c);
      }
      exit_code = c.beyond.empty() ? 0 : 1;
    } catch (const Error& e) {
      fmt::print(stderr, "facecap: error: {}\n", e.what());
      exit_code = kExitTrouble;
    }
  });
}

}  // namespace facecap::tools
