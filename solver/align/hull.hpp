#pragma once
// 3D convex hull (Qhull, reentrant C API): the first step of calibration (paper
// Algorithm 1) matches the hull of the markers to the hull of the mesh, which both
// describe the face's outer shape whatever the marker count or mesh density.
#include <vector>

#include <Eigen/Core>

namespace facecap::align {

// Indices of the columns of points (3 x K) that are vertices of their convex hull,
// ascending. Throws Error for fewer than 4 points, non-finite coordinates or a flat
// (coplanar) set. Not real-time.
std::vector<int> convex_hull_vertices(const Eigen::Matrix3Xd& points);

}  // namespace facecap::align
