#pragma once
// A minimal, strict Wavefront OBJ reader for blendshape meshes. Strict on purpose:
// a rig file with a bad number must fail with its line, not load as zeros.
#include <cstdint>
#include <string>
#include <vector>
#include <string_view>

#include <Eigen/Core>

namespace facecap {

struct ObjMesh {
  Eigen::Matrix3Xd vertices;   // 3 x N
  Eigen::Matrix3Xi triangles;  // 3 x T, polygons fan-triangulated
  int polygons = 0;            // faces as written (a quad counts once)
  std::vector<int64_t> vertex_lines;    // N: the line each vertex was read from
  std::vector<int64_t> triangle_lines;  // T: the line of the face each triangle came from
  int64_t line_count = 0;
};

// Parses OBJ text; `file` names it in errors ("path:line: what").
// Reads v and f (v, v/vt, v//vn, v/vt/vn, negative indices); ignores vt, vn, groups,
// materials and smoothing. Coordinates must be finite (nan and inf are refused). Throws
// Error.
ObjMesh parse_obj(std::string_view text, const std::string& file);
ObjMesh read_obj(const std::string& path);

// Throws Error at the shape's file:line unless `shape` can be a blendshape of `neutral`:
// the same number of vertices and, when it has faces at all, the same faces in order.
void check_shape_matches_neutral(const ObjMesh& shape, const std::string& shape_file, const ObjMesh& neutral,
                                 const std::string& neutral_name);

// Writes vertices and triangles (for tests and exports).
std::string format_obj(const Eigen::Matrix3Xd& vertices, const Eigen::Matrix3Xi& triangles);

}  // namespace facecap
