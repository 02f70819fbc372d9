#pragma once
// Helpers shared by the solver tests: marker positions of a pose, error measures.
#include <cstdint>
#include <vector>

#include <Eigen/Core>

#include "solver/face_solver.hpp"

namespace facecap::test {

inline std::vector<uint8_t> all_present(Eigen::Index k) { return std::vector<uint8_t>(std::size_t(k), 1); }

// Marker positions (3 x K) on a pose (3 x N) for a layout.
inline Eigen::Matrix3Xd markers_of(const Eigen::Matrix3Xd& pose, const std::vector<MarkerBinding>& layout) {
  Eigen::Matrix3Xd out(3, Eigen::Index(layout.size()));
  for (std::size_t k = 0; k < layout.size(); ++k) {
    out.col(Eigen::Index(k)).setZero();
    for (int a = 0; a < 3; ++a) out.col(Eigen::Index(k)) += layout[k].barycentric[a] * pose.col(layout[k].vertices[a]);
  }
  return out;
}

inline double max_error(const Eigen::Matrix3Xd& a, const Eigen::Matrix3Xd& b) { return (a - b).colwise().norm().maxCoeff(); }
inline double mean_error(const Eigen::Matrix3Xd& a, const Eigen::Matrix3Xd& b) { return (a - b).colwise().norm().mean(); }

}  // namespace facecap::test
