#pragma once
// Calibration (paper Algorithm 1, extended to start from any capture frame): from one
// neutral frame of markers in the take's own coordinates (mm, cm or m; Y-up or Z-up; any
// position and heading) to a similarity transform into rig space and a binding of every
// marker to the rig's surface.
//
//   1. Convex hulls (Qhull) of the markers and of the mesh vertices.
//   2. ICP with a similarity transform (rotation, uniform scale, translation) from the
//      marker hull points to the mesh hull points, from many starts: the hulls' principal
//      axes matched in each of the 24 axis permutations with sign flips, and the 24
//      axis-aligned rotations themselves.
//   3. From each hull result, ICP of all markers against the mesh surface (k-d tree over
//      the vertices, exact closest point on the triangles around them), trimmed so that
//      markers where the actor's face departs from the rig's do not pull the fit.
//   4. The start with the lowest trimmed residual wins; each marker is bound to its
//      closest surface point (triangle + barycentric).
//
// The scale is kept within a plausible band around the unit ratio (faces differ in size,
// by well under 2x), which rules out ICP's degenerate shrinking. Units are given, or
// detected from the hulls' sizes (mm, cm and m are a factor of 10 apart).
// Everything here is offline (not real-time).
#include <cstdint>
#include <optional>
#include <string>
#include <vector>

#include <Eigen/Core>

#include "solver/align/geometry.hpp"
#include "solver/face_solver.hpp"
#include "solver/rig.hpp"

namespace facecap::align {

struct CalibrationOptions {
  std::optional<double> take_mm_per_unit;  // nullopt: detect from the hulls' sizes
  double rig_mm_per_unit = 10.0;           // the rig's units (ICT FaceKit and the built-in face: cm)
  double scale_band = 1.6;                 // actor / rig face size allowed in [1/band, band]
  double trim_fraction = 0.2;              // the worst markers left out of each surface ICP step ...
  double trim_floor_mm = 0.5;              // ... unless this close to the surface
  int hull_iterations = 40;
  int surface_iterations = 60;
  int minimum_markers = 6;
};

struct MarkerCalibration {
  std::string label;
  MarkerBinding binding;                                   // the surface point it sits on
  Eigen::Vector3d neutral = Eigen::Vector3d::Zero();       // take units, at the calibration frame
  Eigen::Vector3d bound_point = Eigen::Vector3d::Zero();   // rig space: the binding's position on the neutral mesh
  double residual_mm = 0.0;  // |transform(neutral) - bound_point| in rig millimetres
};

struct Calibration {
  std::string rig_name;
  uint64_t rig_hash = 0;
  double rig_mm_per_unit = 10.0;
  double take_mm_per_unit = 10.0;
  bool units_detected = false;  // take units were detected, not given
  Similarity take_to_rig;       // rig = s R take + t at the calibration frame
  std::vector<MarkerCalibration> markers;
  std::vector<std::string> stable_markers;  // labels used for head stabilisation
  std::string source_take;
  int64_t source_frame = -1;
  double hull_rms_mm = 0.0;     // rig mm, the winning start's hull ICP residual
  double trimmed_rms_mm = 0.0;  // rig mm, surface ICP residual over the kept markers
  int start_index = -1;         // which start won (diagnostics)
  std::vector<std::string> notes;  // what the operator should know (excluded markers, ...)

  // Index of a label in markers, or -1.
  int find(const std::string& label) const;
};

// ICP of points (3 x K) onto a mesh surface from a start transform, keeping the scale in
// [scale_min, scale_max]. Exposed so tests can compare plain ICP with the hull start.
struct IcpResult {
  Similarity transform;
  double trimmed_rms = 0.0;  // rig units
  int iterations = 0;
};
IcpResult icp_to_surface(const Eigen::Matrix3Xd& points, const Rig& rig, const Similarity& start, double scale_min,
                         double scale_max, double trim_fraction = 0.2, int iterations = 60);
// ICP of hull points onto the mesh's hull points, same conventions.
IcpResult icp_hulls(const Eigen::Matrix3Xd& marker_hull, const Eigen::Matrix3Xd& mesh_hull, const Similarity& start,
                    double scale_min, double scale_max, int iterations = 40);

// Calibrates from one frame. labels: K; neutral: 3 x K in take units; present: K flags
// (missing markers are left out and noted). Throws Error on unusable input (fewer than
// minimum_markers present, NaN coordinates on present markers, a flat marker set, an
// empty rig).
Calibration calibrate(const Rig& rig, const std::vector<std::string>& labels, const Eigen::Matrix3Xd& neutral,
                      const std::vector<uint8_t>& present, const CalibrationOptions& options = {});

// Bindings in solver order (the calibration's marker order).
std::vector<MarkerBinding> calibration_bindings(const Calibration& calibration);

}  // namespace facecap::align
