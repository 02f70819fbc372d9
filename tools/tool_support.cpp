#include "tools/tool_support.hpp"

#include <algorithm>
#include <cmath>

#include <fmt/format.h>

#include "core/error.hpp"
#include "core/io.hpp"
#include "core/units.hpp"
#include "formats/arkit.hpp"
#include "formats/livelinkface.hpp"
#include "solver/builtin_face.hpp"

namespace facecap::tools {
namespace {

// Linear resampling of per-frame weights from source_rate to rate.
std::vector<Eigen::VectorXd> resample(const std::vector<Eigen::VectorXd>& source, double source_rate, double rate,
                                      long max_frames) {
  std::vector<Eigen::VectorXd> out;
  if (source.empty()) return out;
  const double duration = double(source.size() - 1) / source_rate;
  const long available = long(std::floor(duration * rate + 1e-9)) + 1;
  const long count = max_frames < 0 ? available : std::min(available, max_frames);
  out.reserve(std::size_t(count));
  for (long f = 0; f < count; ++f) {
    const double s = double(f) * source_rate / rate;
    const std::size_t i = std::min(std::size_t(std::floor(s + 1e-9)), source.size() - 1);
    const double frac = std::clamp(s - double(i), 0.0, 1.0);
    if (i + 1 >= source.size() || frac < 1e-9) out.push_back(source[i]);
    else out.push_back((1.0 - frac) * source[i] + frac * source[i + 1]);
  }
  return out;
}

}  // namespace

WeightCurves livelinkface_curves(const std::filesystem::path& csv, const Rig& rig, double rate_hz, long max_frames) {
  const formats::FaceTake take = formats::read_livelinkface(csv);
  if (take.frames.empty()) throw file_error(csv.string(), "the Live Link Face CSV has no frames");
  const auto matches = formats::match_arkit_to_rig(rig.shape_names);
  WeightCurves curves;
  curves.source = csv.string();
  std::vector<uint8_t> driven(std::size_t(rig.shape_count()), 0);
  for (std::size_t a = 0; a < formats::kArkitShapeCount; ++a) {
    if (matches[a].empty()) curves.unmatched.emplace_back(formats::kArkitShapes[a].arkit);
    for (std::size_t s : matches[a]) driven[s] = 1;
  }
  for (Eigen::Index s = 0; s < rig.shape_count(); ++s)
    if (driven[std::size_t(s)]) curves.driven_shapes.push_back(rig.shape_names[std::size_t(s)]);
  if (curves.driven_shapes.empty())
    throw file_error(csv.string(), fmt::format("no ARKit shape matches a shape of rig '{}'", rig.name));

  std::vector<Eigen::VectorXd> source;
  source.reserve(take.frames.size());
  Eigen::VectorXd last = Eigen::VectorXd::Zero(rig.shape_count());
  for (const auto& frame : take.frames) {
    if (!frame.tracked) {
      ++curves.held_frames;
      source.push_back(last);
      continue;
    }
    Eigen::VectorXd w = Eigen::VectorXd::Zero(rig.shape_count());
    for (std::size_t a = 0; a < formats::kArkitShapeCount; ++a) {
      const double value = std::isfinite(frame.weights[a]) ? std::clamp(double(frame.weights[a]), 0.0, 1.0) : 0.0;
      for (std::size_t s : matches[a]) w[Eigen::Index(s)] = value;
    }
    source.push_back(w);
    last = w;
  }
  const double source_rate = take.rate_hz > 0 ? take.rate_hz : double(formats::kLiveLinkTimecodeRate);
  curves.rate_hz = rate_hz > 0 ? rate_hz : source_rate;
  curves.frames = resample(source, source_rate, curves.rate_hz, max_frames);
  return curves;
}

WeightCurves builtin_motion_curves(const Rig& rig, double rate_hz, long max_frames) {
  if (!(rate_hz > 0)) throw Error(fmt::format("the frame rate must be > 0 (got {})", rate_hz));
  if (max_frames < 0) throw Error("the built-in motion needs a frame count");
  const BuiltinFace& face = BuiltinFace::instance();
  const auto& names = face.rig().shape_names;
  std::vector<std::pair<Eigen::Index, Eigen::Index>> map;  // builtin shape -> rig shape
  WeightCurves curves;
  curves.source = "builtin motion";
  curves.rate_hz = rate_hz;
  for (std::size_t b = 0; b < names.size(); ++b) {
    if (auto s = rig.shape_index(names[b])) map.emplace_back(Eigen::Index(b), *s);
    else curves.unmatched.push_back(names[b]);
  }
  if (map.empty()) throw Error(fmt::format("rig '{}' has none of the built-in face's shape names", rig.name));
  for (const auto& [b, s] : map) curves.driven_shapes.push_back(rig.shape_names[std::size_t(s)]);
  curves.frames.reserve(std::size_t(max_frames));
  for (long f = 0; f < max_frames; ++f) {
    const Eigen::VectorXd motion = face.motion_weights(double(f) / rate_hz);
    Eigen::VectorXd w = Eigen::VectorXd::Zero(rig.shape_count());
    for (const auto& [b, s] : map) w[s] = motion[b];
    curves.frames.push_back(std::move(w));
  }
  return curves;
}

std::string rig_units(const Rig& rig, const std::string& override_units) {
  const std::string units = override_units.empty() ? guess_face_units(bounding_box(rig.neutral)) : override_units;
  if (!millimetres_per_unit(units))
    throw Error(fmt::format("cannot tell rig '{}''s units (got '{}'): pass --rig-units mm, cm or m", rig.name, units));
  return units;
}

bool is_builtin_face(const Rig& rig) {
  const Rig& builtin = BuiltinFace::instance().rig();
  return rig.vertex_count() == builtin.vertex_count() && rig.shape_count() == builtin.shape_count() &&
         rig.content_hash() == builtin.content_hash();
}

Eigen::Matrix3Xd truth_pose(const Rig& rig, bool builtin, const Eigen::VectorXd& weights) {
  if (builtin) return BuiltinFace::instance().articulated_pose(weights);
  return rig.linear_blend(weights);
}

Eigen::Matrix3Xd marker_positions(const Eigen::Matrix3Xd& pose, const std::vector<MarkerBinding>& markers) {
  Eigen::Matrix3Xd out = Eigen::Matrix3Xd::Zero(3, Eigen::Index(markers.size()));
  for (std::size_t k = 0; k < markers.size(); ++k)
    for (int a = 0; a < 3; ++a) out.col(Eigen::Index(k)) += markers[k].barycentric[a] * pose.col(markers[k].vertices[a]);
  return out;
}

std::vector<SolverMethod> select_solvers(const std::string& option) {
  std::vector<SolverMethod> out;
  if (option == "all") {
    for (const auto& entry : kSolverMethods.entries()) out.push_back(entry.value);
    return out;
  }
  std::size_t start = 0;
  while (start <= option.size()) {
    const std::size_t comma = std::min(option.find(',', start), option.size());
    const std::string name = option.substr(start, comma - start);
    const auto method = kSolverMethods.parse(name);
    if (!method)
      throw Error(fmt::format("unknown solver '{}': choose all or from {}", name, fmt::join(kSolverMethods.names(), ", ")));
    if (std::find(out.begin(), out.end(), *method) == out.end()) out.push_back(*method);
    start = comma + 1;
  }
  return out;
}

double percentile(std::vector<double>& values, double p) {
  if (values.empty()) return 0.0;
  const double rank = std::ceil(std::clamp(p, 0.0, 100.0) / 100.0 * double(values.size()));
  const std::size_t index = std::size_t(std::max(rank, 1.0)) - 1;
  std::nth_element(values.begin(), values.begin() + std::ptrdiff_t(index), values.end());
  return values[index];
}

void read_solved_frame_checked(const formats::RecordingReader& reader, std::size_t i, SolvedFrame& out) {
  reader.read_solved_frame(i, out);
  const std::size_t shapes = reader.header().shape_names.size();
  if (std::size_t(out.weights.size()) != shapes)
    throw file_error(reader.name(), fmt::format("solved frame {} has {} weights for the header's {} shapes", i,
                                                out.weights.size(), shapes));
}

void write_live_link_csv(const std::filesystem::path& path, const formats::FaceTake& face) {
  if (face.rate_hz > formats::kLiveLinkTimecodeRate + 0.5)
    fmt::print(stderr, "facecap: warning: {}: {:g} Hz is above the Live Link Face timecode's {} fps: consecutive rows share "
               "a timecode frame and differ in its fraction\n", path.string(), face.rate_hz, formats::kLiveLinkTimecodeRate);
  const std::string text = formats::write_livelinkface(face);
  write_file_atomically(path, std::span<const char>(text.data(), text.size()));
}

}  // namespace facecap::tools
