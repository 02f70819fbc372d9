#pragma once
// Helpers shared by the solver tests: marker positions of a pose, error measures.
#include <cstdint>
#include <vector>

#include <Eigen/Core>

#include "solver/face_solver.hpp"
#include "solver/kernels/kernels.hpp"

namespace facecap::test {

// The kernel paths this CPU runs (solver/kernels/kernels.hpp), portable first.
inline std::vector<KernelPath> runnable_kernel_paths() {
  std::vector<KernelPath> paths;
  for (const KernelPath p : {KernelPath::kPortable, KernelPath::kAvx2, KernelPath::kAvx512})
    if (kernels::cpu_runs(p)) paths.push_back(p);
  return paths;
}

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
