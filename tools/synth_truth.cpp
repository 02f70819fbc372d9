#include "tools/synth_truth.hpp"

#include <cerrno>
#include <cstdlib>
#include <cstring>
#include <sstream>

#include <fmt/format.h>
#include <nlohmann/json.hpp>

#include "core/error.hpp"

namespace facecap::tools {
namespace {

constexpr char kVerticesMagic[8] = {'F', 'C', 'T', 'R', 'U', 'T', 'H', 'V'};
constexpr std::size_t kVerticesHeaderBytes = 32;
constexpr const char* kManifestFormat = "facecap-synth-truth";
constexpr std::size_t kPoseColumns = 8;  // frame, time_s, head_rx..rz, head_tx..tz

std::vector<std::string_view> split_commas(std::string_view line) {
  std::vector<std::string_view> out;
  std::size_t start = 0;
  while (true) {
    const std::size_t comma = line.find(',', start);
    out.push_back(line.substr(start, comma == std::string_view::npos ? std::string_view::npos : comma - start));
    if (comma == std::string_view::npos) break;
    start = comma + 1;
  }
  return out;
}

double parse_number(std::string_view cell, const std::string& file, int64_t line) {
  const std::string text(cell);
  char* end = nullptr;
  errno = 0;
  const double v = std::strtod(text.c_str(), &end);
  if (text.empty() || end != text.c_str() + text.size() || errno == ERANGE)
    throw line_error(file, line, fmt::format("'{}' is not a number", text));
  return v;
}

template <typename T>
T json_field(const nlohmann::json& j, const char* key, const std::string& file) {
  if (!j.contains(key)) throw file_error(file, fmt::format("the truth manifest has no \"{}\"", key));
  try {
    return j.at(key).get<T>();
  } catch (const nlohmann::json::exception& e) {
    throw file_error(file, fmt::format("\"{}\": {}", key, e.what()));
  }
}

void put_u32(char* p, uint32_t v) { std::memcpy(p, &v, 4); }
void put_u64(char* p, uint64_t v) { std::memcpy(p, &v, 8); }
uint32_t get_u32(const char* p) { uint32_t v; std::memcpy(&v, p, 4); return v; }

}  // namespace

void write_synth_truth(const std::filesystem::path& manifest, const SynthTruth& truth) {
  const std::size_t F = truth.frame_count();
  if (truth.head_rotation.size() != F || truth.head_translation.size() != F)
    throw Error("write_synth_truth: head poses and weights differ in frame count");
  nlohmann::json j;
  j["format"] = kManifestFormat;
  j["version"] = kSynthTruthVersion;
  j["rig"] = truth.rig;
  j["rig_name"] = truth.rig_name;
  j["rig_hash"] = truth.rig_hash;
  j["rig_units"] = truth.rig_units;
  j["take"] = truth.take_file;
  j["take_units"] = truth.take_units;
  j["frames"] = F;
  j["rate_hz"] = truth.rate_hz;
  j["seed"] = truth.seed;
  j["noise_mm"] = truth.noise_mm;
  j["dropout"] = truth.dropout;
  j["head_motion"] = truth.head_motion;
  j["weights_source"] = truth.weights_source;
  nlohmann::json markers = nlohmann::json::array();
  for (std::size_t k = 0; k < truth.marker_labels.size(); ++k)
    markers.push_back({{"label", truth.marker_labels[k]}, {"vertex", truth.marker_vertices[k]}});
  j["markers"] = markers;
  j["shapes"] = truth.shape_names;
  j["weights_file"] = truth.weights_file;
  j["vertices_file"] = truth.vertices_file.empty() ? nlohmann::json(nullptr) : nlohmann::json(truth.vertices_file);
  {
    std::ofstream out(manifest, std::ios::binary | std::ios::trunc);
    out << j.dump(2) << '\n';
    if (!out) throw file_error(manifest.string(), "cannot write the truth manifest");
  }
  const std::filesystem::path csv = manifest.parent_path() / truth.weights_file;
  std::ofstream out(csv, std::ios::binary | std::ios::trunc);
  std::string text = "frame,time_s,head_rx,head_ry,head_rz,head_tx,head_ty,head_tz";
  for (const auto& name : truth.shape_names) text += "," + name;
  text += '\n';
  for (std::size_t f = 0; f < F; ++f) {
    const Eigen::Vector3d& r = truth.head_rotation[f];
    const Eigen::Vector3d& t = truth.head_translation[f];
    text += fmt::format("{},{:.9g},{:.9g},{:.9g},{:.9g},{:.9g},{:.9g},{:.9g}", f, double(f) / truth.rate_hz, r.x(), r.y(),
                        r.z(), t.x(), t.y(), t.z());
    for (Eigen::Index s = 0; s < truth.weights[f].size(); ++s) text += fmt::format(",{:.9g}", truth.weights[f][s]);
    text += '\n';
  }
  out << text;
  if (!out) throw file_error(csv.string(), "cannot write the truth weights");
}

SynthTruth read_synth_truth(const std::filesystem::path& manifest) {
  const std::string file = manifest.string();
  std::ifstream in(manifest, std::ios::binary);
  if (!in) throw file_error(file, "cannot open the truth manifest");
  nlohmann::json j;
  try {
    j = nlohmann::json::parse(in);
  } catch (const nlohmann::json::exception& e) {
    throw file_error(file, fmt::format("not JSON: {}", e.what()));
  }
  if (!j.is_object() || j.value("format", "") != kManifestFormat)
    throw file_error(file, fmt::format("not a facecap synth truth manifest (no \"format\": \"{}\")", kManifestFormat));
  const int version = json_field<int>(j, "version", file);
  if (version > kSynthTruthVersion)
    throw file_error(file, fmt::format("truth manifest version {} is newer than this reader ({})", version, kSynthTruthVersion));
  SynthTruth truth;
  truth.rig = json_field<std::string>(j, "rig", file);
  truth.rig_name = json_field<std::string>(j, "rig_name", file);
  truth.rig_hash = json_field<std::string>(j, "rig_hash", file);
  truth.rig_units = json_field<std::string>(j, "rig_units", file);
  truth.take_file = json_field<std::string>(j, "take", file);
  truth.take_units = json_field<std::string>(j, "take_units", file);
  truth.rate_hz = json_field<double>(j, "rate_hz", file);
  truth.seed = json_field<uint64_t>(j, "seed", file);
  truth.noise_mm = json_field<double>(j, "noise_mm", file);
  truth.dropout = json_field<double>(j, "dropout", file);
  truth.head_motion = json_field<bool>(j, "head_motion", file);
  truth.weights_source = json_field<std::string>(j, "weights_source", file);
  truth.shape_names = json_field<std::vector<std::string>>(j, "shapes", file);
  truth.weights_file = json_field<std::string>(j, "weights_file", file);
  if (j.contains("vertices_file") && !j["vertices_file"].is_null())
    truth.vertices_file = json_field<std::string>(j, "vertices_file", file);
  const auto markers = json_field<nlohmann::json>(j, "markers", file);
  if (!markers.is_array()) throw file_error(file, "\"markers\" must be an array");
  for (const auto& m : markers) {
    if (!m.is_object() || !m.contains("label") || !m.contains("vertex") || !m["label"].is_string() ||
        !m["vertex"].is_number_integer())
      throw file_error(file, "every marker needs a \"label\" string and a \"vertex\" integer");
    truth.marker_labels.push_back(m["label"].get<std::string>());
    truth.marker_vertices.push_back(m["vertex"].get<int>());
  }
  const std::size_t frames = json_field<std::size_t>(j, "frames", file);

  const std::filesystem::path csv = manifest.parent_path() / truth.weights_file;
  std::ifstream weights_in(csv, std::ios::binary);
  if (!weights_in) throw file_error(csv.string(), "cannot open the truth weights");
  std::string line;
  int64_t line_no = 1;
  if (!std::getline(weights_in, line)) throw file_error(csv.string(), "empty truth weights file");
  const auto header = split_commas(line);
  const std::size_t M = truth.shape_names.size();
  if (header.size() != kPoseColumns + M) throw line_error(csv.string(), 1, fmt::format("expected {} columns, found {}", kPoseColumns + M, header.size()));
  for (std::size_t s = 0; s < M; ++s)
    if (header[kPoseColumns + s] != truth.shape_names[s])
      throw line_error(csv.string(), 1, fmt::format("column {} is '{}', the manifest says '{}'", kPoseColumns + s + 1,
                                                     header[kPoseColumns + s], truth.shape_names[s]));
  while (std::getline(weights_in, line)) {
    ++line_no;
    if (line.empty()) continue;
    const auto cells = split_commas(line);
    if (cells.size() != kPoseColumns + M)
      throw line_error(csv.string(), line_no, fmt::format("expected {} columns, found {}", kPoseColumns + M, cells.size()));
    Eigen::Vector3d r, t;
    for (int k = 0; k < 3; ++k) {
      r[k] = parse_number(cells[2 + std::size_t(k)], csv.string(), line_no);
      t[k] = parse_number(cells[5 + std::size_t(k)], csv.string(), line_no);
    }
    Eigen::VectorXd w(static_cast<Eigen::Index>(M));
    for (std::size_t s = 0; s < M; ++s) w[Eigen::Index(s)] = parse_number(cells[kPoseColumns + s], csv.string(), line_no);
    truth.head_rotation.push_back(r);
    truth.head_translation.push_back(t);
    truth.weights.push_back(std::move(w));
  }
  if (truth.weights.size() != frames)
    throw file_error(csv.string(), fmt::format("{} frames of weights, the manifest says {}", truth.weights.size(), frames));
  return truth;
}

TruthVerticesWriter::TruthVerticesWriter(const std::filesystem::path& path, int64_t vertex_count, int64_t frame_count)
    : path_(path), out_(path, std::ios::binary | std::ios::trunc), vertex_count_(vertex_count), frame_count_(frame_count),
      buffer_(std::size_t(3 * vertex_count)) {
  if (!out_) throw file_error(path.string(), "cannot create the truth vertices file");
  char header[kVerticesHeaderBytes] = {};
  std::memcpy(header, kVerticesMagic, 8);
  put_u32(header + 8, 1);
  put_u32(header + 12, uint32_t(vertex_count));
  put_u32(header + 16, uint32_t(frame_count));
  put_u32(header + 20, 4);
  put_u64(header + 24, 0);
  out_.write(header, kVerticesHeaderBytes);
}

void TruthVerticesWriter::append(const Eigen::Matrix3Xd& vertices) {
  if (vertices.cols() != vertex_count_) throw Error("TruthVerticesWriter: wrong vertex count");
  if (written_ >= frame_count_) throw file_error(path_.string(), "more frames than announced");
  for (Eigen::Index v = 0; v < vertex_count_; ++v)
    for (int k = 0; k < 3; ++k) buffer_[std::size_t(3 * v + k)] = float(vertices(k, v));
  out_.write(reinterpret_cast<const char*>(buffer_.data()), std::streamsize(buffer_.size() * sizeof(float)));
  ++written_;
}

void TruthVerticesWriter::close() {
  if (written_ != frame_count_)
    throw file_error(path_.string(), fmt::format("{} frames written, {} announced", written_, frame_count_));
  out_.close();
  if (!out_) throw file_error(path_.string(), "cannot write the truth vertices");
}

TruthVerticesReader::TruthVerticesReader(const std::filesystem::path& path) : path_(path), in_(path, std::ios::binary) {
  if (!in_) throw file_error(path.string(), "cannot open the truth vertices file");
  char header[kVerticesHeaderBytes];
  if (!in_.read(header, kVerticesHeaderBytes)) throw offset_error(path.string(), 0, "truncated header");
  if (std::memcmp(header, kVerticesMagic, 8) != 0) throw offset_error(path.string(), 0, "not a facecap truth vertices file (magic)");
  if (get_u32(header + 8) != 1) throw offset_error(path.string(), 8, fmt::format("unsupported version {}", get_u32(header + 8)));
  if (get_u32(header + 20) != 4) throw offset_error(path.string(), 20, "values must be 4-byte floats");
  vertex_count_ = get_u32(header + 12);
  frame_count_ = get_u32(header + 16);
  const auto expected = std::uintmax_t(kVerticesHeaderBytes) + std::uintmax_t(frame_count_ * vertex_count_ * 12);
  const auto size = std::filesystem::file_size(path);
  if (size != expected)
    throw file_error(path.string(), fmt::format("{} bytes, expected {} for {} frames of {} vertices", size, expected,
                                                frame_count_, vertex_count_));
  buffer_.resize(std::size_t(3 * vertex_count_));
}

void TruthVerticesReader::read(int64_t frame, Eigen::Matrix3Xd& out) {
  if (frame < 0 || frame >= frame_count_) throw file_error(path_.string(), fmt::format("no frame {}", frame));
  in_.seekg(std::streamoff(kVerticesHeaderBytes + std::size_t(frame) * buffer_.size() * sizeof(float)));
  if (!in_.read(reinterpret_cast<char*>(buffer_.data()), std::streamsize(buffer_.size() * sizeof(float))))
    throw file_error(path_.string(), fmt::format("cannot read frame {}", frame));
  out.resize(3, vertex_count_);
  for (Eigen::Index v = 0; v < vertex_count_; ++v)
    for (int k = 0; k < 3; ++k) out(k, v) = buffer_[std::size_t(3 * v + k)];
}

}  // namespace facecap::tools
