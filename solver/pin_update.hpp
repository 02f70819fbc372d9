#pragma once
// Eq. 5 after low-rank changes of its factored matrix, without refactoring (Woodbury).
// The matrix A0 = G^T W G + beta C^T C is factored once with every marker present; per
// frame a marker dropping out removes beta c_k c_k^T, and a collision pin adds
// beta e_v e_v^T to the matrix and beta e_v t_v^T (its target) to the right-hand side.
// With U the changes' vectors (N x s), D their scales and T their targets (s x 3), from
// y = A0^-1 r and the columns Z = A0^-1 U:
//
//   x = (A0 + U D U^T)^-1 (r + U D T) = y + Z (D T - (D^-1 + U^T Z)^-1 U^T (y + Z D T)),
//
// where U^T (y + Z D T) needs Z only at the changed vertices, so the whole mesh is
// touched once, by the last sum. Lifecycle: construct (allocates) -> per frame clear(),
// add() each change, apply() (real-time safe).
#include <array>
#include <cstdint>
#include <vector>

#include <Eigen/Core>

#include "core/huge_pages.hpp"

namespace facecap {

// Columns of an N-row matrix as 16-bit fixed point, scale * q with one scale per column
// spanning its largest magnitude: rounding is at most 1/65534 of that, and a quarter of
// double's bytes stream through the per-frame sum. The model's precomputed A0^-1 e_v of
// the collision region: they multiply pin forces beta (t_v - x_v), small next to
// positions, so 16 bits are enough.
struct PinColumns {
  Eigen::Index rows = 0;
  HugePageVector<int16_t> values;  // column-major
  std::vector<float> scale;        // per column

  Eigen::Index cols() const noexcept { return Eigen::Index(scale.size()); }
  void resize(Eigen::Index row_count, Eigen::Index col_count) {
    rows = row_count;
    values.assign(std::size_t(row_count * col_count), 0);
    scale.assign(std::size_t(col_count), 0.0f);
  }
  const int16_t* column(Eigen::Index c) const noexcept { return values.data() + std::size_t(c * rows); }
  void set_column(Eigen::Index c, const Eigen::Ref<const Eigen::VectorXd>& column);
};

class PinUpdate {
 public:
  // Room for `capacity` changes of a system of vertex_count vertices. Allocates; not
  // real-time.
  PinUpdate(Eigen::Index vertex_count, Eigen::Index capacity);

  // Forgets every change. Real-time safe.
  void clear() noexcept { count_ = 0; }

  // Adds scale u u^T to A0 and scale u target^T to the right-hand side, with
  // u = sum_a weights_a e_{vertices_a} (a marker: its barycentric corners; a pin: one
  // vertex, weights (1, 0, 0)) and column = A0^-1 u (N doubles, alive until apply()).
  // Returns false, adding nothing, when capacity is reached. Real-time safe.
  bool add(const std::array<int, 3>& vertices, const Eigen::Vector3d& weights, const double* column, double scale,
           const Eigen::Vector3d& target = Eigen::Vector3d::Zero()) noexcept;
  // The same for u = e_vertex with A0^-1 e_vertex stored as column_scale * column (a
  // column of PinColumns). Real-time safe.
  bool add(int vertex, const int16_t* column, float column_scale, double scale, const Eigen::Vector3d& target) noexcept;

  // Gives change `index` (0 .. size() - 1, in the order added) another target. Real-time safe.
  void retarget(Eigen::Index index, const Eigen::Vector3d& target) noexcept { changes_[std::size_t(index)].target = target; }

  Eigen::Index size() const noexcept { return count_; }
  Eigen::Index capacity() const noexcept { return Eigen::Index(changes_.size()); }

  // x = (A0 + U D U^T)^-1 (r + U D T) from y = A0^-1 r; y, x: 3 x N, not aliased.
  // Returns false, leaving x = y, when D^-1 + U^T Z is singular (the changes leave A
  // singular: a vertex held by nothing but a marker that dropped out). Real-time safe.
  [[nodiscard]] bool apply(const Eigen::Matrix3Xd& y, Eigen::Matrix3Xd& x) noexcept;

 private:
  // One change: A0^-1 u is `column`, or column_scale * pin_column.
  struct Change {
    std::array<int, 3> vertices;
    Eigen::Vector3d weights;
    const double* column;
    const int16_t* pin_column;  // with column_scale
    float column_scale;
    double scale;
    Eigen::Vector3d target = Eigen::Vector3d::Zero();
    double column_at(int v) const noexcept { return column ? column[v] : double(column_scale) * double(pin_column[v]); }
  };

  // x += Z C for the solved coefficients C (rows of small_rhs_). Real-time safe.
  void add_columns(Eigen::Matrix3Xd& x) noexcept;

  Eigen::Index vertex_count_;
  std::vector<Change> changes_;  // capacity
  Eigen::Index count_ = 0;
  std::vector<Eigen::Index> pin_changes_;  // capacity; in add_columns(): the changes with 16-bit columns, in order
  Eigen::Matrix<double, Eigen::Dynamic, Eigen::Dynamic, Eigen::RowMajor> small_;  // D^-1 + U^T Z, row operations
  Eigen::Matrix<double, Eigen::Dynamic, 3> small_rhs_;
  Eigen::Matrix<double, Eigen::Dynamic, 3> correction_;  // N x 3: Z C, coordinate by coordinate
};

}  // namespace facecap
