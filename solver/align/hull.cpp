#include "solver/align/hull.hpp"

#include <algorithm>
#include <cstdio>
#include <cstdlib>
#include <string>

#include <fmt/format.h>

extern "C" {
#include <libqhull_r/qhull_ra.h>
}

#include "core/error.hpp"

namespace facecap::align {

std::vector<int> convex_hull_vertices(const Eigen::Matrix3Xd& points) {
  const Eigen::Index n = points.cols();
  if (n < 4) throw Error(fmt::format("convex hull: {} points, at least 4 needed", n));
  if (!points.allFinite()) throw Error("convex hull: non-finite (NaN or infinite) coordinates");
  // Qhull reads a contiguous array of coordT and may perturb it: work on a copy.
  std::vector<coordT> coords(points.data(), points.data() + 3 * n);
  char* err_text = nullptr;
  std::size_t err_size = 0;
  FILE* err = open_memstream(&err_text, &err_size);
  qhT qh_storage;
  qhT* qh = &qh_storage;
  QHULL_LIB_CHECK
  qh_zero(qh, err);
  char command[] = "qhull Qt";
  const int code = qh_new_qhull(qh, 3, int(n), coords.data(), False, command, nullptr, err);
  std::vector<int> result;
  if (code == 0) {
    vertexT* vertex;
    FORALLvertices { result.push_back(qh_pointid(qh, vertex->point)); }
  }
  qh_freeqhull(qh, !qh_ALL);
  int curlong = 0, totlong = 0;
  qh_memfreeshort(qh, &curlong, &totlong);
  if (err) std::fclose(err);
  std::string message = err_text ? std::string(err_text, err_size) : std::string();
  std::free(err_text);
  if (code != 0) {
    const auto first_line = message.substr(0, message.find('\n'));
    throw Error(fmt::format("convex hull of {} points failed (flat or degenerate set?): {}", n,
                            first_line.empty() ? fmt::format("qhull error {}", code) : first_line));
  }
  std::sort(result.begin(), result.end());
  return result;
}

}  // namespace facecap::align
