#include "solver/obj_mesh.hpp"

#include <charconv>
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
        coords.push_back(value);
      }
      mesh.vertex_lines.push_back(line_no);
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
