// The low-rank update of Eq. 5 (solver/pin_update.hpp) against a dense oracle: the
// corrected solve must equal a direct solve of the modified system.
#include <random>
#include <vector>

#include <catch2/catch.hpp>
#include <Eigen/Dense>

#include "solver/pin_update.hpp"
#include "tests/alloc_counter.hpp"

using namespace facecap;

namespace {

// A marker: beta c c^T in A0 with c = sum_a weights_a e_{vertices_a}.
struct TestMarker {
  std::array<int, 3> vertices;
  Eigen::Vector3d weights;
};

Eigen::VectorXd unit_sum(Eigen::Index n, const std::array<int, 3>& vertices, const Eigen::Vector3d& weights) {
  Eigen::VectorXd u = Eigen::VectorXd::Zero(n);
  for (int a = 0; a < 3; ++a) u[vertices[std::size_t(a)]] += weights[a];
  return u;
}

// A0 = the Laplacian of a random connected graph (a path plus random edges) + 0.1 I +
// beta sum_k c_k c_k^T: symmetric positive definite, like G^T W G + beta C^T C, and
// still so with every marker removed.
struct System {
  Eigen::Index n = 0;
  double beta = 100.0;
  Eigen::MatrixXd A0;
  std::vector<TestMarker> markers;
};

System make_system(Eigen::Index n, int marker_count, unsigned seed) {
  System s;
  s.n = n;
  std::mt19937 rng(seed);
  std::uniform_int_distribution<int> vertex(0, int(n) - 1);
  std::uniform_real_distribution<double> unit(0.0, 1.0);
  s.A0 = 0.1 * Eigen::MatrixXd::Identity(n, n);
  auto edge = [&](int i, int j, double w) {
    if (i == j) return;
    s.A0(i, i) += w, s.A0(j, j) += w, s.A0(i, j) -= w, s.A0(j, i) -= w;
  };
  for (int i = 0; i + 1 < int(n); ++i) edge(i, i + 1, 1.0 + unit(rng));
  for (int e = 0; e < 2 * int(n); ++e) edge(vertex(rng), vertex(rng), unit(rng));
  for (int k = 0; k < marker_count; ++k) {
    Eigen::Vector3d w(unit(rng) + 0.1, unit(rng) + 0.1, unit(rng) + 0.1);
    w /= w.sum();
    TestMarker m{{vertex(rng), vertex(rng), vertex(rng)}, w};
    const Eigen::VectorXd c = unit_sum(n, m.vertices, m.weights);
    s.A0 += s.beta * c * c.transpose();
    s.markers.push_back(m);
  }
  return s;
}

double relative_error(const Eigen::Matrix3Xd& x, const Eigen::Matrix3Xd& expected) {
  return (x - expected).norm() / expected.norm();
}

}  // namespace

TEST_CASE("markers removed and pins added by the low-rank update equal a direct solve of the modified system") {
  const System s = make_system(80, 12, 3);
  const Eigen::LDLT<Eigen::MatrixXd> A0(s.A0);
  std::mt19937 rng(5);
  std::uniform_real_distribution<double> coordinate(-1.0, 1.0);
  Eigen::Matrix3Xd r(3, s.n);
  for (Eigen::Index i = 0; i < r.size(); ++i) r.data()[i] = coordinate(rng);
  const Eigen::Matrix3Xd y = A0.solve(r.transpose()).transpose();

  const std::vector<int> removed = {1, 4, 5, 9};
  const std::vector<int> pinned = {0, 7, 13, 30, 31, 55, 70, 79, 42};
  std::vector<Eigen::VectorXd> columns;  // A0^-1 u, alive while the update is
  for (int k : removed) columns.push_back(A0.solve(unit_sum(s.n, s.markers[std::size_t(k)].vertices, s.markers[std::size_t(k)].weights)));
  for (int v : pinned) columns.push_back(A0.solve(unit_sum(s.n, {v, v, v}, {1.0, 0.0, 0.0})));
  Eigen::Matrix3Xd pin_targets(3, Eigen::Index(pinned.size()));
  for (Eigen::Index i = 0; i < pin_targets.size(); ++i) pin_targets.data()[i] = coordinate(rng);

  // The oracle: A = A0 - beta sum_removed c_k c_k^T + beta sum_pins e_v e_v^T, with
  // right-hand side r + beta sum_pins e_v t_v^T, solved directly.
  Eigen::MatrixXd A = s.A0;
  Eigen::Matrix3Xd rhs = r;
  for (int k : removed) {
    const Eigen::VectorXd c = unit_sum(s.n, s.markers[std::size_t(k)].vertices, s.markers[std::size_t(k)].weights);
    A -= s.beta * c * c.transpose();
  }
  for (std::size_t i = 0; i < pinned.size(); ++i) {
    A(pinned[i], pinned[i]) += s.beta;
    rhs.col(pinned[i]) += s.beta * pin_targets.col(Eigen::Index(i));
  }
  const Eigen::Matrix3Xd expected = A.ldlt().solve(rhs.transpose()).transpose();

  PinUpdate update(s.n, Eigen::Index(removed.size() + pinned.size()));
  Eigen::Matrix3Xd x(3, s.n);
  SECTION("double columns") {
    for (std::size_t i = 0; i < removed.size(); ++i) {
      const TestMarker& m = s.markers[std::size_t(removed[i])];
      REQUIRE(update.add(m.vertices, m.weights, columns[i].data(), -s.beta));
    }
    for (std::size_t i = 0; i < pinned.size(); ++i) {
      const int v = pinned[i];
      REQUIRE(update.add({v, v, v}, {1.0, 0.0, 0.0}, columns[removed.size() + i].data(), s.beta, pin_targets.col(Eigen::Index(i))));
    }
    int64_t allocations = 0;
    bool corrected = false;
    {
      test::CountAllocations counter;
      corrected = update.apply(y, x);
      allocations = counter.count();
    }
    CHECK(corrected);
    CHECK(allocations == 0);
    INFO("relative error " << relative_error(x, expected));
    CHECK(relative_error(x, expected) < 1e-9);
    // Without any change it is the plain solve.
    update.clear();
    CHECK(update.apply(y, x));
    CHECK(x == y);
  }
  SECTION("16-bit pin columns, added before the markers' double columns") {
    PinColumns stored;
    stored.resize(s.n, Eigen::Index(pinned.size()));
    for (std::size_t i = 0; i < pinned.size(); ++i) {
      stored.set_column(Eigen::Index(i), columns[removed.size() + i]);
      const int v = pinned[i];
      REQUIRE(update.add(v, stored.column(Eigen::Index(i)), stored.scale[i], s.beta, pin_targets.col(Eigen::Index(i))));
    }
    for (std::size_t i = 0; i < removed.size(); ++i) {
      const TestMarker& m = s.markers[std::size_t(removed[i])];
      REQUIRE(update.add(m.vertices, m.weights, columns[i].data(), -s.beta));
    }
    CHECK(update.apply(y, x));
    // 16-bit columns round A0^-1 e_v by 1/65534 of its largest entry; the correction
    // x - y, built from them, carries that rounding and nothing more.
    const double error = (x - expected).norm() / (expected - y).norm();
    INFO("error relative to the correction " << error << "; relative to x " << relative_error(x, expected));
    CHECK(error < 1e-3);
    CHECK(error > 1e-12);  // it is the 16-bit path
  }
}

TEST_CASE("a change beyond the update's capacity is refused") {
  const System s = make_system(10, 2, 7);
  const Eigen::VectorXd column = Eigen::LDLT<Eigen::MatrixXd>(s.A0).solve(unit_sum(s.n, {3, 3, 3}, {1.0, 0.0, 0.0}));
  PinUpdate update(s.n, 2);
  CHECK(update.capacity() == 2);
  CHECK(update.add({3, 3, 3}, {1.0, 0.0, 0.0}, column.data(), s.beta, {1.0, 2.0, 3.0}));
  CHECK(update.add({3, 3, 3}, {1.0, 0.0, 0.0}, column.data(), s.beta, {1.0, 2.0, 3.0}));
  CHECK_FALSE(update.add({3, 3, 3}, {1.0, 0.0, 0.0}, column.data(), s.beta, {1.0, 2.0, 3.0}));
  CHECK(update.size() == 2);
}

// A vertex held by nothing but its marker (A0's row there is beta c c^T alone): with the
// marker gone the modified matrix is singular, and so is the small system. The update
// says so and leaves the uncorrected solve.
TEST_CASE("a singular correction is detected and the uncorrected solve kept") {
  System s = make_system(20, 3, 11);
  const Eigen::Index n = s.n + 1, lone = s.n;  // one more vertex, on no edge
  Eigen::MatrixXd A0 = Eigen::MatrixXd::Zero(n, n);
  A0.topLeftCorner(s.n, s.n) = s.A0;
  A0(lone, lone) = 4.0;  // beta e e^T with beta = 4: its inverse, 1/4, is exact
  const double beta = 4.0;
  const Eigen::LDLT<Eigen::MatrixXd> factor(A0);
  const Eigen::VectorXd column = factor.solve(Eigen::VectorXd::Unit(n, lone));
  REQUIRE(column[lone] == 0.25);
  Eigen::Matrix3Xd y = Eigen::Matrix3Xd::Random(3, n);
  Eigen::Matrix3Xd x(3, n);
  PinUpdate update(n, 2);
  const int v = int(lone);
  REQUIRE(update.add({v, v, v}, {1.0, 0.0, 0.0}, column.data(), -beta));
  CHECK_FALSE(update.apply(y, x));
  CHECK(x == y);
}
