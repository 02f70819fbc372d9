#include "solver/obj_mesh.hpp"

#include <charconv>
#include <cmath>
#include <limits>
#include <vector>

#include <fmt/format.h>

#include "core/error.hpp"
#include "core/io.hpp"

namespace facecap {
namespace {

bool is_space(char c) { return c == ' ' || c == '\t' || c == '\r' || c == '\f' || c == '\v'; }

struct LineCursor {
  std::string_view line;
  std::size_t pos = 0;
  void skip_space() { while (pos < line.size() && is_space(line[pos])) ++pos; }
  std::string_view next_token() {
    skip_space();
    const std::size_t start = pos;
    while (pos < line.size() && !is_space(line[pos])) ++pos;
    return line.substr(start, pos - start);
  }
};

}  // namespace

ObjMesh parse_obj(std::string_view text, const std::string& file) {
  std::vector<double> coords;
  std::vector<int> tris;
  int polygons = 0;
  coords.reserve(text.size() / 12);
  tris.reserve(text.size() / 12);
  std::vector<int> polygon;
  ObjMesh mesh;
  int64_t line_no = 0;
  std::size_t start = 0;
  while (start < text.size()) {
    std::size_t end = text.find('\n', start);
    if (end == std::string_view::npos) end = text.size();
    ++line_no;
    LineCursor cur{text.substr(start, end - start)};
    start = end + 1;
    const std::string_view keyword = cur.next_token();
    if (keyword == "v") {
      for (int k = 0; k < 3; ++k) {
        const std::string_view tok = cur.next_token();
        if (tok.empty())
          throw line_error(file, line_no, fmt::format("vertex has {} coordinates, expected 3 (truncated file?)", k));
        double value = 0;
        const auto [ptr, ec] = std::from_chars(tok.data(), tok.data() + tok.size(), value);
        if (ec != std::errc{} || ptr != tok.data() + tok.size())
          throw line_error(file, line_no, fmt::format("vertex coordinate '{}' is not a number", tok));
        if (!std::isfinite(value))
          throw line_error(file, line_no, fmt::format("vertex coordinate '{}' is not a finite number", tok));
        coords.push_back(value);
      }
      mesh.vertex_lines.push_back(line_no);
      if (mesh.vertex_lines.size() > std::size_t(std::numeric_limits<int>::max()))
        throw line_error(file, line_no, "more vertices than a face index can address");
      // A fourth (w) or colour values may follow; they are ignored.
    } else if (keyword == "f") {
      polygon.clear();
      const int vertex_count = static_cast<int>(coords.size() / 3);
      for (std::string_view tok = cur.next_token(); !tok.empty(); tok = cur.next_token()) {
        const std::string_view index_text = tok.substr(0, tok.find('/'));
        int index = 0;
        const auto [ptr, ec] = std::from_chars(index_text.data(), index_text.data() + index_text.size(), index);
        if (ec != std::errc{} || ptr != index_text.data() + index_text.size() || index == 0)
          throw line_error(file, line_no, fmt::format("face index '{}' is not a valid index", tok));
        const int resolved = index > 0 ? index - 1 : vertex_count + index;
        if (resolved < 0 || resolved >= vertex_count)
          throw line_error(file, line_no,
                           fmt::format("face index {} out of range (the file has {} vertices so far)", index, vertex_count));
        polygon.push_back(resolved);
      }
      if (polygon.size() < 3)
        throw line_error(file, line_no, fmt::format("face has {} vertices, needs at least 3 (truncated file?)", polygon.size()));
      if (tris.size() / 3 + polygon.size() > std::size_t(std::numeric_limits<int>::max()))
        throw line_error(file, line_no, "more triangles than a mesh can index");
      for (std::size_t i = 1; i + 1 < polygon.size(); ++i) {
        tris.push_back(polygon[0]);
        tris.push_back(polygon[i]);
        tris.push_back(polygon[i + 1]);
        mesh.triangle_lines.push_back(line_no);
      }
      ++polygons;
    }
    // vt, vn, o, g, s, usemtl, mtllib, comments, blank lines: not geometry we need.
  }
  mesh.line_count = line_no;
  mesh.vertices = Eigen::Map<const Eigen::Matrix3Xd>(coords.data(), 3, Eigen::Index(coords.size() / 3));
  mesh.triangles = Eigen::Map<const Eigen::Matrix3Xi>(tris.data(), 3, Eigen::Index(tris.size() / 3));
  mesh.polygons = polygons;
  return mesh;
}

ObjMesh read_obj(const std::string& path) {
  const std::vector<char> bytes = read_file_bytes(path);
  return parse_obj(std::string_view(bytes.data(), bytes.size()), path);
}

void check_shape_matches_neutral(const ObjMesh& shape, const std::string& shape_file, const ObjMesh& neutral,
                                 const std::string& neutral_name) {
  const Eigen::Index n = neutral.vertices.cols();
  if (shape.vertices.cols() > n)
    throw line_error(shape_file, shape.vertex_lines[std::size_t(n)],
                     fmt::format("vertex {} is one more than the neutral {} has ({}): all shapes must share its vertices",
                                 n + 1, neutral_name, n));
  if (shape.vertices.cols() < n)
    throw line_error(shape_file, shape.line_count,
                     fmt::format("file ends after {} vertices, the neutral {} has {} (truncated file?)",
                                 shape.vertices.cols(), neutral_name, n));
  const Eigen::Index shape_faces = shape.triangles.cols(), neutral_faces = neutral.triangles.cols();
  if (shape_faces == 0) return;  // a shape may leave the faces to the neutral
  Eigen::Index t = 0;
  while (t < std::min(shape_faces, neutral_faces) && shape.triangles.col(t) == neutral.triangles.col(t)) ++t;
  if (t == shape_faces && t == neutral_faces) return;
  if (t == shape_faces)
    throw line_error(shape_file, shape.line_count,
                     fmt::format("file ends after {} triangles, the neutral {} has {}: all shapes must share its topology",
                                 shape_faces, neutral_name, neutral_faces));
  throw line_error(shape_file, shape.triangle_lines[std::size_t(t)],
                   t == neutral_faces
                       ? fmt::format("triangle {} is one more than the neutral {} has ({}): all shapes must share its topology",
                                     t + 1, neutral_name, neutral_faces)
                       : fmt::format("face list differs from the neutral {} here: all shapes must share its topology",
                                     neutral_name));
}

std::string format_obj(const Eigen::Matrix3Xd& vertices, const Eigen::Matrix3Xi& triangles) {
  std::string out;
  out.reserve(std::size_t(vertices.cols()) * 40 + std::size_t(triangles.cols()) * 24);
  for (Eigen::Index v = 0; v < vertices.cols(); ++v)
    out += fmt::format("v {:.9g} {:.9g} {:.9g}\n", vertices(0, v), vertices(1, v), vertices(2, v));
  for (Eigen::Index t = 0; t < triangles.cols(); ++t)
    out += fmt::format("f {} {} {}\n", triangles(0, t) + 1, triangles(1, t) + 1, triangles(2, t) + 1);
  return out;
}

}  // namespace facecap
