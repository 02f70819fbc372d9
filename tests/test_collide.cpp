#include <algorithm>
#include <atomic>
#include <cstdlib>
#include <new>
#include <random>
#include <sstream>

#include <catch2/catch.hpp>
#include <Eigen/Geometry>

#include "core/error.hpp"
#include "solver/builtin_face.hpp"
#include "solver/collide/collider.hpp"
#include "solver/collide/geometry.hpp"
#include "solver/collide/lip_region.hpp"
#include "solver/collide/metrics.hpp"
#include "solver/collide/pair_batch.hpp"
#include "solver/rig.hpp"
#include "tests/solver_test_support.hpp"
#include "tests/test_support.hpp"

// ---- Allocation counting: every operator new in this executable goes through here ----

namespace {
thread_local bool t_counting = false;
thread_local long t_allocations = 0;

void* counted_alloc(std::size_t size, std::size_t alignment = 0) {
  if (t_counting) ++t_allocations;
  if (size == 0) size = 1;
  void* p = nullptr;
  if (alignment > alignof(std::max_align_t)) {
    p = std::aligned_alloc(alignment, (size + alignment - 1) / alignment * alignment);
  } else {
    p = std::malloc(size);
  }
  return p;
}

// Out of line, so the compiler does not pair std::free with an inlined operator new.
[[gnu::noinline]] void release(void* p) noexcept { std::free(p); }
}  // namespace

void* operator new(std::size_t size) {
  if (void* p = counted_alloc(size)) return p;
  throw std::bad_alloc();
}
void* operator new[](std::size_t size) {
  if (void* p = counted_alloc(size)) return p;
  throw std::bad_alloc();
}
void* operator new(std::size_t size, std::align_val_t al) {
  if (void* p = counted_alloc(size, std::size_t(al))) return p;
  throw std::bad_alloc();
}
void* operator new[](std::size_t size, std::align_val_t al) {
  if (void* p = counted_alloc(size, std::size_t(al))) return p;
  throw std::bad_alloc();
}
void* operator new(std::size_t size, const std::nothrow_t&) noexcept { return counted_alloc(size); }
void* operator new[](std::size_t size, const std::nothrow_t&) noexcept { return counted_alloc(size); }
void operator delete(void* p) noexcept { release(p); }
void operator delete[](void* p) noexcept { release(p); }
void operator delete(void* p, std::size_t) noexcept { release(p); }
void operator delete[](void* p, std::size_t) noexcept { release(p); }
void operator delete(void* p, std::align_val_t) noexcept { release(p); }
void operator delete[](void* p, std::align_val_t) noexcept { release(p); }
void operator delete(void* p, std::size_t, std::align_val_t) noexcept { release(p); }
void operator delete[](void* p, std::size_t, std::align_val_t) noexcept { release(p); }

using namespace facecap;
using Vec3 = Eigen::Vector3d;

namespace Catch {
template <>
struct StringMaker<TrianglePair> {
  static std::string convert(const TrianglePair& p) {
    std::ostringstream out;
    out << '(' << p.first << ' ' << p.second << ')';
    return out.str();
  }
};
}  // namespace Catch

namespace {

// Counts operator new calls made by this thread while alive.
class AllocationCounter {
 public:
  AllocationCounter() {
    t_allocations = 0;
    t_counting = true;
  }
  ~AllocationCounter() { t_counting = false; }
  long count() const { return t_allocations; }
};

double tri_distance(const std::array<Vec3, 3>& a, const std::array<Vec3, 3>& b) {
  return triangle_distance(a[0], a[1], a[2], b[0], b[1], b[2]);
}

// Distance by brute force: the closest pair among points sampled on both triangles
// on a barycentric grid with n steps per edge. Never below the true distance; above it
// by at most the grid spacing of both triangles.
double sampled_distance(const std::array<Vec3, 3>& a, const std::array<Vec3, 3>& b, int n) {
  auto samples = [n](const std::array<Vec3, 3>& t) {
    std::vector<Vec3> points;
    for (int i = 0; i <= n; ++i)
      for (int j = 0; i + j <= n; ++j) {
        const double u = double(i) / n, v = double(j) / n;
        points.push_back(t[0] + u * (t[1] - t[0]) + v * (t[2] - t[0]));
      }
    return points;
  };
  const auto pa = samples(a), pb = samples(b);
  double best = std::numeric_limits<double>::infinity();
  for (const Vec3& p : pa)
    for (const Vec3& q : pb) best = std::min(best, (p - q).squaredNorm());
  return std::sqrt(best);
}

double longest_edge(const std::array<Vec3, 3>& t) {
  return std::max({(t[1] - t[0]).norm(), (t[2] - t[1]).norm(), (t[0] - t[2]).norm()});
}

std::array<Vec3, 3> corners(const Eigen::Matrix3Xi& triangles, const Eigen::Matrix3Xd& x, int t) {
  return {x.col(triangles(0, t)), x.col(triangles(1, t)), x.col(triangles(2, t))};
}

bool share_vertex(const Eigen::Matrix3Xi& triangles, int s, int t) {
  for (int i = 0; i < 3; ++i)
    for (int j = 0; j < 3; ++j)
      if (triangles(i, s) == triangles(j, t)) return true;
  return false;
}

// Every candidate pair closer than epsilon, sharing no vertex: O(T^2) with only a
// per-axis gap test in front of the exact distance.
std::vector<TrianglePair> brute_force_pairs(const Eigen::Matrix3Xi& triangles, const Eigen::Matrix3Xd& x,
                                            std::vector<int> candidates, double epsilon) {
  std::sort(candidates.begin(), candidates.end());
  std::vector<Vec3> lo, hi;
  for (int t : candidates) {
    const auto c = corners(triangles, x, t);
    lo.push_back(c[0].cwiseMin(c[1]).cwiseMin(c[2]));
    hi.push_back(c[0].cwiseMax(c[1]).cwiseMax(c[2]));
  }
  std::vector<TrianglePair> pairs;
  for (std::size_t i = 0; i < candidates.size(); ++i)
    for (std::size_t j = i + 1; j < candidates.size(); ++j) {
      const Vec3 gap = (lo[j] - hi[i]).cwiseMax(lo[i] - hi[j]);
      if (gap.maxCoeff() >= epsilon) continue;
      const int s = candidates[i], t = candidates[j];
      if (share_vertex(triangles, s, t)) continue;
      if (tri_distance(corners(triangles, x, s), corners(triangles, x, t)) < epsilon) pairs.push_back({s, t});
    }
  std::sort(pairs.begin(), pairs.end());
  return pairs;
}

std::vector<TrianglePair> collider_pairs(const CollisionResult& r) {
  return {r.valid_pairs().begin(), r.valid_pairs().end()};
}

std::vector<int32_t> union_of_vertices(const Eigen::Matrix3Xi& triangles, std::span<const TrianglePair> pairs) {
  std::vector<int32_t> v;
  for (const auto& p : pairs)
    for (int k = 0; k < 3; ++k) {
      v.push_back(triangles(k, p.first));
      v.push_back(triangles(k, p.second));
    }
  std::sort(v.begin(), v.end());
  v.erase(std::unique(v.begin(), v.end()), v.end());
  return v;
}

const BuiltinFace& face() { return BuiltinFace::instance(); }

std::vector<int> builtin_lip_hint() {
  std::vector<int> lips = face().upper_lip_vertices();
  lips.insert(lips.end(), face().lower_lip_vertices().begin(), face().lower_lip_vertices().end());
  return lips;
}

Eigen::Matrix3Xd pose(const Rig& rig, std::initializer_list<std::pair<const char*, double>> weights) {
  Eigen::VectorXd w = Eigen::VectorXd::Zero(rig.shape_count());
  for (const auto& [name, value] : weights) {
    const auto index = rig.shape_index(name);
    REQUIRE(index.has_value());
    w[*index] = value;
  }
  return rig.linear_blend(w);
}

// Candidate triangles' vertices moved by up to `amplitude` in each coordinate.
Eigen::Matrix3Xd perturbed(const Eigen::Matrix3Xd& x, const Eigen::Matrix3Xi& triangles,
                           const std::vector<int>& candidates, double amplitude, uint32_t seed) {
  std::mt19937 rng(seed);
  std::uniform_real_distribution<double> noise(-amplitude, amplitude);
  Eigen::Matrix3Xd out = x;
  std::vector<int> vertices;
  for (int t : candidates)
    for (int k = 0; k < 3; ++k) vertices.push_back(triangles(k, t));
  std::sort(vertices.begin(), vertices.end());
  vertices.erase(std::unique(vertices.begin(), vertices.end()), vertices.end());
  for (int v : vertices)
    for (int k = 0; k < 3; ++k) out(k, v) += noise(rng);
  return out;
}

}  // namespace

// ---- Triangle-triangle distance ----------------------------------------------------

TEST_CASE("parallel offset triangles are exactly their offset apart") {
  const std::array<Vec3, 3> a{Vec3(0, 0, 0), Vec3(2, 0, 0), Vec3(0, 2, 0)};
  for (double d : {1.0, 0.01, 1e-6}) {
    const std::array<Vec3, 3> b{Vec3(0.2, 0.2, d), Vec3(1.0, 0.2, d), Vec3(0.2, 1.0, d)};
    CHECK(tri_distance(a, b) == Approx(d).epsilon(1e-12));
    CHECK(tri_distance(b, a) == Approx(d).epsilon(1e-12));
    CHECK_FALSE(triangles_intersect(a[0], a[1], a[2], b[0], b[1], b[2]));
    CHECK(triangles_closer_than(a[0], a[1], a[2], b[0], b[1], b[2], 1.001 * d));
    CHECK_FALSE(triangles_closer_than(a[0], a[1], a[2], b[0], b[1], b[2], 0.999 * d));
  }
}

TEST_CASE("crossing triangles are at distance zero") {
  const std::array<Vec3, 3> a{Vec3(-1, -1, 0), Vec3(2, -1, 0), Vec3(-1, 2, 0)};
  SECTION("one pierces the other's interior") {
    const std::array<Vec3, 3> b{Vec3(0.2, 0.2, -1), Vec3(0.3, 0.2, 1), Vec3(0.2, 0.4, 1)};
    CHECK(tri_distance(a, b) == 0.0);
    CHECK(tri_distance(b, a) == 0.0);
    CHECK(triangles_intersect(a[0], a[1], a[2], b[0], b[1], b[2]));
    CHECK(triangles_intersect(b[0], b[1], b[2], a[0], a[1], a[2]));
    CHECK(triangles_closer_than(a[0], a[1], a[2], b[0], b[1], b[2], 1e-9));
  }
  SECTION("a chain link: each pierces the other, no vertex near the other") {
    const std::array<Vec3, 3> b{Vec3(0, 0, -1), Vec3(0, 0, 1), Vec3(0, 5, 0)};
    const std::array<Vec3, 3> c{Vec3(-3, 1, 0), Vec3(3, 1, 0), Vec3(0, -3, 0)};
    CHECK(tri_distance(b, c) == 0.0);
    CHECK(triangles_intersect(c[0], c[1], c[2], b[0], b[1], b[2]));
  }
  SECTION("coplanar overlapping triangles") {
    const std::array<Vec3, 3> b{Vec3(0, 0, 0), Vec3(1, 0.5, 0), Vec3(0.5, 1, 0)};
    CHECK(tri_distance(a, b) == 0.0);
    CHECK(triangles_intersect(b[0], b[1], b[2], a[0], a[1], a[2]));
    const std::array<Vec3, 3> far{Vec3(5, 5, 0), Vec3(6, 5, 0), Vec3(5, 6, 0)};
    CHECK_FALSE(triangles_intersect(far[0], far[1], far[2], a[0], a[1], a[2]));
    CHECK(tri_distance(a, far) == Approx(std::sqrt(2.0) * 4.5).epsilon(1e-12));
  }
}

TEST_CASE("the closest points can lie inside an edge of each triangle") {
  // a's edge along x at y = z = 0; b lies in the plane x = 0 with an edge along z at y = d.
  const double d = 0.3;
  const std::array<Vec3, 3> a{Vec3(-1, 0, 0), Vec3(1, 0, 0), Vec3(0, -1, 0)};
  const std::array<Vec3, 3> b{Vec3(0, d, -1), Vec3(0, d, 1), Vec3(0, d + 1, 0)};
  CHECK(tri_distance(a, b) == Approx(d).epsilon(1e-12));
  CHECK(tri_distance(b, a) == Approx(d).epsilon(1e-12));
  // Every vertex is farther than the edges: this is an edge-edge case.
  for (const Vec3& p : a) CHECK((p - Vec3(0, d, 0)).norm() > d + 0.5);
}

TEST_CASE("the closest point can be a vertex over the other face's interior") {
  const double d = 0.05;
  const std::array<Vec3, 3> a{Vec3(-1, -1, 0), Vec3(2, -1, 0), Vec3(-1, 2, 0)};
  const std::array<Vec3, 3> b{Vec3(0.1, 0.1, d), Vec3(1, 0, d + 1), Vec3(0, 1, d + 1)};
  CHECK(tri_distance(a, b) == Approx(d).epsilon(1e-12));
  CHECK(tri_distance(b, a) == Approx(d).epsilon(1e-12));
}

TEST_CASE("triangle distance matches brute-force sampling and is symmetric") {
  std::mt19937 rng(7);
  std::uniform_real_distribution<double> coord(-1.0, 1.0);
  const int steps = 60;
  int intersecting = 0;
  for (int trial = 0; trial < 40; ++trial) {
    std::array<Vec3, 3> a, b;
    const Vec3 offset(coord(rng), coord(rng), coord(rng));
    for (auto& p : a) p = Vec3(coord(rng), coord(rng), coord(rng));
    for (auto& p : b) p = Vec3(coord(rng), coord(rng), coord(rng)) + 0.8 * offset;
    const double exact = tri_distance(a, b);
    const double sampled = sampled_distance(a, b, steps);
    INFO("trial " << trial << ": exact " << exact << " sampled " << sampled);
    // No sampled pair is closer than the exact distance...
    CHECK(exact <= sampled + 1e-12);
    // ...and the grid gets within its spacing of it.
    CHECK(sampled - exact <= (longest_edge(a) + longest_edge(b)) / steps);
    // The same for any order of the triangles and of their vertices.
    CHECK(tri_distance(b, a) == Approx(exact).margin(1e-14));
    CHECK(tri_distance({a[2], a[0], a[1]}, {b[1], b[0], b[2]}) == Approx(exact).margin(1e-14));
    CHECK(triangles_closer_than(a[0], a[1], a[2], b[0], b[1], b[2], exact + 1e-9));
    CHECK_FALSE(triangles_closer_than(a[0], a[1], a[2], b[0], b[1], b[2], exact - 1e-9));
    if (exact == 0.0) ++intersecting;
  }
  CHECK(intersecting > 0);  // the trials include crossing pairs
  CHECK(intersecting < 40);
}

// The batched test must agree with the single one pair for pair, also where the
// distance is within a hair of epsilon, for crossing, touching, sliver and zero-area
// triangles, and far from the origin (its float pass works relative to a corner).
TEST_CASE("the batched closeness test agrees with the single-pair test at the threshold") {
  std::mt19937 rng(11);
  std::uniform_real_distribution<double> coord(-1.0, 1.0), near(0.998, 1.002);
  std::vector<TrianglePairCorners> pairs;
  std::vector<double> epsilons;
  auto add = [&](const std::array<Vec3, 3>& a, const std::array<Vec3, 3>& b, double epsilon) {
    pairs.push_back({{a[0], a[1], a[2]}, {b[0], b[1], b[2]}});
    epsilons.push_back(epsilon);
  };
  for (int trial = 0; trial < 400; ++trial) {
    const Vec3 origin = trial % 4 == 3 ? Vec3(1e3, -2e3, 5e2) : Vec3::Zero();
    const double size = trial % 5 == 0 ? 1e-3 : 0.3;  // lip-sized and tiny triangles
    std::array<Vec3, 3> a, b;
    const Vec3 offset(coord(rng), coord(rng), coord(rng));
    for (auto& p : a) p = origin + size * Vec3(coord(rng), coord(rng), coord(rng));
    for (auto& p : b) p = origin + size * (Vec3(coord(rng), coord(rng), coord(rng)) + 0.8 * offset);
    if (trial % 7 == 0) b[2] = b[0] + 1e-9 * (b[1] - b[0]);  // a sliver
    if (trial % 11 == 0) b[2] = b[1];                        // zero area
    const double distance = tri_distance(a, b);
    add(a, b, distance > 0.0 ? distance * near(rng) : 1e-3 * size);  // epsilon within 0.2% of the distance
    add(a, b, 0.01);                                                 // the solver's default
  }
  std::size_t closer = 0;
  for (const KernelPath path : facecap::test::runnable_kernel_paths())
  for (std::size_t first = 0; first < pairs.size(); first += kCloserBatch) {
    INFO("kernels " << kKernelPaths.name(path));
    const kernels::KernelTable& table = kernels::table(path);
    const std::size_t count = std::min<std::size_t>(kCloserBatch, pairs.size() - first);
    // One epsilon per batch call: run each pair's epsilon through its own batch of one
    // and the whole batch at the default.
    for (std::size_t k = 0; k < count; ++k) {
      const auto& p = pairs[first + k];
      const bool single = triangles_closer_than(p.a[0], p.a[1], p.a[2], p.b[0], p.b[1], p.b[2], epsilons[first + k]);
      const uint32_t batched = triangles_closer_than(table, std::span(&p, 1), epsilons[first + k]);
      INFO("pair " << first + k << " epsilon " << epsilons[first + k]);
      CHECK(batched == (single ? 1u : 0u));
      closer += single;
    }
    const uint32_t bits = triangles_closer_than(table, std::span(pairs.data() + first, count), 0.01);
    for (std::size_t k = 0; k < count; ++k) {
      const auto& p = pairs[first + k];
      CHECK(((bits >> k) & 1u) == (triangles_closer_than(p.a[0], p.a[1], p.a[2], p.b[0], p.b[1], p.b[2], 0.01) ? 1u : 0u));
    }
  }
  const std::size_t tested = pairs.size() * facecap::test::runnable_kernel_paths().size();
  CHECK(closer > tested / 10);  // both outcomes are exercised
  CHECK(closer < tested * 9 / 10);
}

TEST_CASE("degenerate triangles are measured as segments") {
  const std::array<Vec3, 3> a{Vec3(-1, -1, 0), Vec3(2, -1, 0), Vec3(-1, 2, 0)};
  // A zero-area "triangle" (a segment) hanging above a, and one crossing it.
  const std::array<Vec3, 3> above{Vec3(0, 0, 0.5), Vec3(0, 0, 1.5), Vec3(0, 0, 1.0)};
  const std::array<Vec3, 3> through{Vec3(0, 0, -0.5), Vec3(0, 0, 0.5), Vec3(0, 0, 0.5)};
  CHECK(tri_distance(a, above) == Approx(0.5).epsilon(1e-12));
  CHECK(tri_distance(above, a) == Approx(0.5).epsilon(1e-12));
  CHECK(tri_distance(a, through) == 0.0);
  CHECK(tri_distance(through, a) == 0.0);
}

// ---- The collider on the built-in face ------------------------------------------------

TEST_CASE("the built-in face: neutral intersects nowhere and mouthClose brings the lips within 1 mm") {
  const Rig& rig = face().rig();
  CHECK(count_intersecting_pairs(rig.triangles, rig.neutral) == 0);
  CHECK(count_flipped_triangles(rig.triangles, rig.neutral, rig.neutral) == 0);

  // mouthClose = 1 slides the lower lip up behind the upper one: the lips come within
  // a millimetre but do not cross (the linear blend stays intersection-free).
  const Eigen::Matrix3Xd closed = rig.shape_positions(*rig.shape_index("mouthClose"));
  CHECK(count_intersecting_pairs(rig.triangles, closed) == 0);
  const std::vector<int> lips = lip_region_triangles(rig);
  double closest = std::numeric_limits<double>::infinity();
  for (const auto& p : brute_force_pairs(rig.triangles, closed, lips, 0.2))
    closest = std::min(closest, tri_distance(corners(rig.triangles, closed, p.first), corners(rig.triangles, closed, p.second)));
  CHECK(closest > 0.0);
  CHECK(closest < 0.1);
  TriangleCollider collider;
  ColliderConfig config;
  config.epsilon = closest + 0.01;
  collider.configure(rig.triangles, rig.neutral, lips, config);
  CollisionResult result = collider.make_result();
  REQUIRE(collider.detect(rig.neutral, result));
  CHECK(result.pairs_found == 0);
  REQUIRE(collider.detect(closed, result));
  CHECK(result.pairs_found > 0);
  CHECK_FALSE(result.overflowed());
  for (const auto& p : result.valid_pairs()) {
    const double d = tri_distance(corners(rig.triangles, closed, p.first), corners(rig.triangles, closed, p.second));
    CHECK(d >= closest);
    CHECK(d < config.epsilon);
  }

  // Pushed further, or with the lower lip shrugged up too, the lips cross.
  const Eigen::Matrix3Xd overclosed = pose(rig, {{"mouthClose", 2.0}});
  const Eigen::Matrix3Xd shrugged = pose(rig, {{"mouthClose", 1.0}, {"mouthShrugLower", 1.0}});
  const auto crossing = intersecting_pairs(rig.triangles, shrugged);
  CHECK(count_intersecting_pairs(rig.triangles, overclosed) > 0);
  CHECK(crossing.size() > 0);
  CHECK(count_new_intersecting_pairs(rig.triangles, rig.neutral, shrugged) == int64_t(crossing.size()));
  // The lip region holds every crossing pair, and the collider reports all of them.
  REQUIRE(collider.detect(shrugged, result));
  const auto found = collider_pairs(result);
  CHECK(std::includes(found.begin(), found.end(), crossing.begin(), crossing.end()));
}

TEST_CASE("the collider finds exactly the brute-force pairs on perturbed built-in faces") {
  const Rig& rig = face().rig();
  const std::vector<int> lips = lip_region_triangles(rig);
  REQUIRE(lips.size() > 300);
  struct Case {
    const char* name;
    Eigen::Matrix3Xd positions;
    double epsilon;
  };
  std::vector<Case> cases;
  cases.push_back({"mouthClose", rig.shape_positions(*rig.shape_index("mouthClose")), 0.1});
  cases.push_back({"mouthClose+mouthShrugLower", pose(rig, {{"mouthClose", 1.0}, {"mouthShrugLower", 1.0}}), 0.02});
  for (uint32_t seed = 1; seed <= 4; ++seed) {
    const double amplitude = 0.04 * seed;
    cases.push_back({"perturbed neutral", perturbed(rig.neutral, rig.triangles, lips, amplitude, seed), 0.1});
    cases.push_back({"perturbed mouthClose", perturbed(cases[0].positions, rig.triangles, lips, amplitude, 100 + seed), 0.02});
  }
  std::size_t cases_with_pairs = 0, cases_with_crossings = 0;
  for (const Case& c : cases) {
    TriangleCollider collider;
    ColliderConfig config;
    config.epsilon = c.epsilon;
    config.max_pairs = 100000;
    collider.configure(rig.triangles, rig.neutral, lips, config);
    CollisionResult result = collider.make_result();
    REQUIRE(collider.detect(c.positions, result));
    const auto expected = brute_force_pairs(rig.triangles, c.positions, lips, c.epsilon);
    INFO(c.name << ": " << expected.size() << " pairs expected, " << result.pairs_found << " found");
    CHECK(collider_pairs(result) == expected);
    CHECK_FALSE(result.overflowed());
    // Vertices: exactly the union of the pairs' vertices, ascending.
    const auto vertices = std::vector<int32_t>(result.valid_vertices().begin(), result.valid_vertices().end());
    CHECK(vertices == union_of_vertices(rig.triangles, expected));
    for (const auto& p : result.valid_pairs()) CHECK_FALSE(share_vertex(rig.triangles, p.first, p.second));
    if (!expected.empty()) ++cases_with_pairs;
    if (count_intersecting_pairs(rig.triangles, c.positions) > 0) ++cases_with_crossings;
  }
  // The cases are not vacuous: they find pairs, and several have crossing triangles.
  CHECK(cases_with_pairs == cases.size());
  CHECK(cases_with_crossings >= 3);
}

TEST_CASE("the collider over the whole face equals brute force") {
  const Rig& rig = face().rig();
  const std::vector<int> every = all_triangles(rig.triangle_count());
  const Eigen::Matrix3Xd x = perturbed(pose(rig, {{"mouthClose", 1.0}, {"mouthShrugLower", 1.0}, {"eyeBlink_L", 1.0}}),
                                       rig.triangles, lip_region_triangles(rig), 0.05, 9);
  TriangleCollider collider;
  ColliderConfig config;
  config.epsilon = 0.02;
  config.max_pairs = 100000;
  collider.configure(rig.triangles, rig.neutral, every, config);
  CollisionResult result = collider.make_result();
  REQUIRE(collider.detect(x, result));
  const auto expected = brute_force_pairs(rig.triangles, x, every, config.epsilon);
  CHECK(expected.size() > 100);
  CHECK(collider_pairs(result) == expected);
  // The whole-mesh intersection metric agrees with brute force at epsilon -> 0.
  std::vector<TrianglePair> crossing;
  for (const auto& p : expected)
    if (tri_distance(corners(rig.triangles, x, p.first), corners(rig.triangles, x, p.second)) == 0.0) crossing.push_back(p);
  CHECK(intersecting_pairs(rig.triangles, x) == crossing);
}

// Mesh-edge distance between the nearest vertices of two triangles (0: shared vertex).
int edge_distance(const Eigen::Matrix3Xi& triangles, Eigen::Index vertex_count, int32_t a, int32_t b, int limit) {
  auto adjacent = std::vector<std::vector<int>>(std::size_t(vertex_count));
  for (Eigen::Index t = 0; t < triangles.cols(); ++t)
    for (int k = 0; k < 3; ++k) {
      adjacent[std::size_t(triangles(k, t))].push_back(triangles((k + 1) % 3, t));
      adjacent[std::size_t(triangles((k + 1) % 3, t))].push_back(triangles(k, t));
    }
  auto distance = std::vector<int>(std::size_t(vertex_count), -1);
  std::vector<int> frontier;
  for (int k = 0; k < 3; ++k) { distance[std::size_t(triangles(k, a))] = 0; frontier.push_back(triangles(k, a)); }
  for (int d = 0; d <= limit; ++d) {
    for (int k = 0; k < 3; ++k)
      if (distance[std::size_t(triangles(k, b))] == d) return d;
    std::vector<int> next;
    for (int v : frontier)
      for (int u : adjacent[std::size_t(v)])
        if (distance[std::size_t(u)] < 0) { distance[std::size_t(u)] = d + 1; next.push_back(u); }
    frontier = std::move(next);
  }
  return limit + 1;
}

TEST_CASE("neighbour_edges leaves out exactly the pairs that near on the mesh") {
  const Rig& rig = face().rig();
  const std::vector<int> lips = lip_region_triangles(rig);
  const Eigen::Matrix3Xd x = perturbed(rig.shape_positions(*rig.shape_index("mouthClose")), rig.triangles, lips, 0.08, 5);
  constexpr double kEpsilon = 0.3;  // wide, so that near neighbours on the mesh count too
  const auto all = brute_force_pairs(rig.triangles, x, lips, kEpsilon);
  for (const int edges : {1, 2}) {
    TriangleCollider collider;
    ColliderConfig config;
    config.epsilon = kEpsilon;
    config.max_pairs = 100000;
    config.neighbour_edges = edges;
    collider.configure(rig.triangles, rig.neutral, lips, config);
    CollisionResult result = collider.make_result();
    REQUIRE(collider.detect(x, result));
    std::vector<TrianglePair> expected;
    for (const auto& p : all)
      if (edge_distance(rig.triangles, rig.vertex_count(), p.first, p.second, edges) > edges) expected.push_back(p);
    INFO(edges << " edges: " << all.size() << " pairs in all, " << expected.size() << " farther apart on the mesh");
    CHECK(expected.size() < all.size());  // some pairs are mesh neighbours ...
    CHECK_FALSE(expected.empty());        // ... and some are not
    CHECK(collider_pairs(result) == expected);
  }
}

TEST_CASE("pairs sharing a vertex are never reported") {
  const Rig& rig = face().rig();
  TriangleCollider collider;
  ColliderConfig config;
  config.epsilon = 0.5;  // larger than an edge: every neighbour would be "close"
  config.max_pairs = 1000000;
  const std::vector<int> lips = lip_region_triangles(rig);
  collider.configure(rig.triangles, rig.neutral, lips, config);
  CollisionResult result = collider.make_result();
  REQUIRE(collider.detect(rig.neutral, result));
  CHECK(result.pairs_found > 1000);
  for (const auto& p : result.valid_pairs()) REQUIRE_FALSE(share_vertex(rig.triangles, p.first, p.second));
  CHECK(collider_pairs(result) == brute_force_pairs(rig.triangles, rig.neutral, lips, config.epsilon));
}

TEST_CASE("overflow is counted and flagged, and the vertex set stays complete") {
  const Rig& rig = face().rig();
  const std::vector<int> lips = lip_region_triangles(rig);
  const Eigen::Matrix3Xd closed = rig.shape_positions(*rig.shape_index("mouthClose"));
  ColliderConfig config;
  config.epsilon = 0.1;
  TriangleCollider full;
  full.configure(rig.triangles, rig.neutral, lips, config);
  CollisionResult all = full.make_result();
  REQUIRE(full.detect(closed, all));
  REQUIRE(all.pairs_found > 10);

  config.max_pairs = 5;
  TriangleCollider small;
  small.configure(rig.triangles, rig.neutral, lips, config);
  CollisionResult some = small.make_result();
  CHECK(some.pairs.size() == 5);
  REQUIRE(small.detect(closed, some));
  CHECK(some.overflowed());
  CHECK(some.pair_count == 5);
  CHECK(some.pairs_found == all.pairs_found);
  CHECK(std::vector<int32_t>(some.valid_vertices().begin(), some.valid_vertices().end()) ==
        std::vector<int32_t>(all.valid_vertices().begin(), all.valid_vertices().end()));

  config.max_pairs = 4096;
  config.max_vertices = 3;
  TriangleCollider few_vertices;
  few_vertices.configure(rig.triangles, rig.neutral, lips, config);
  CollisionResult r = few_vertices.make_result();
  REQUIRE(few_vertices.detect(closed, r));
  CHECK(r.overflowed());
  CHECK(r.vertex_count == 3);
  CHECK(r.vertices_found == all.vertex_count);
}

TEST_CASE("the tree and the results are deterministic") {
  const Rig& rig = face().rig();
  std::vector<int> lips = lip_region_triangles(rig);
  const Eigen::Matrix3Xd x = perturbed(rig.neutral, rig.triangles, lips, 0.1, 3);
  ColliderConfig config;
  config.epsilon = 0.05;
  TriangleCollider first, second;
  first.configure(rig.triangles, rig.neutral, lips, config);
  std::mt19937 rng(5);
  std::shuffle(lips.begin(), lips.end(), rng);
  lips.push_back(lips.front());  // a duplicate is ignored
  second.configure(rig.triangles, rig.neutral, lips, config);
  CHECK(first.tree_depth() == second.tree_depth());
  CHECK(std::equal(first.candidate_triangles().begin(), first.candidate_triangles().end(),
                   second.candidate_triangles().begin(), second.candidate_triangles().end()));
  CollisionResult a = first.make_result(), b = second.make_result();
  REQUIRE(first.detect(x, a));
  REQUIRE(second.detect(x, b));
  CHECK(a.pairs_found > 0);
  CHECK(collider_pairs(a) == collider_pairs(b));
  // Running again on the same positions gives the same frame.
  REQUIRE(first.detect(x, b));
  CHECK(collider_pairs(a) == collider_pairs(b));
}

TEST_CASE("rest contacts can be left out") {
  const Rig& rig = face().rig();
  const std::vector<int> lips = lip_region_triangles(rig);
  const Eigen::Matrix3Xd closed = rig.shape_positions(*rig.shape_index("mouthClose"));
  ColliderConfig config;
  config.epsilon = 0.3;  // wider than the 0.137 cm between the lips at rest
  config.max_pairs = 100000;
  TriangleCollider all, fresh;
  all.configure(rig.triangles, rig.neutral, lips, config);
  config.ignore_rest_contacts = true;
  fresh.configure(rig.triangles, rig.neutral, lips, config);
  REQUIRE(fresh.rest_contacts().size() > 0);
  CollisionResult a = all.make_result(), f = fresh.make_result();
  REQUIRE(fresh.detect(rig.neutral, f));
  CHECK(f.pairs_found == 0);
  REQUIRE(all.detect(closed, a));
  REQUIRE(fresh.detect(closed, f));
  REQUIRE_FALSE(a.overflowed());
  std::vector<TrianglePair> expected;
  const auto every = collider_pairs(a);
  std::set_difference(every.begin(), every.end(), fresh.rest_contacts().begin(), fresh.rest_contacts().end(),
                      std::back_inserter(expected));
  CHECK(f.pairs_found > 0);
  CHECK(collider_pairs(f) == expected);
}

TEST_CASE("per-frame detection allocates nothing") {
  const Rig& rig = face().rig();
  const std::vector<int> lips = lip_region_triangles(rig);
  const Eigen::Matrix3Xd closed = rig.shape_positions(*rig.shape_index("mouthClose"));
  const Eigen::Matrix3Xd crossing = pose(rig, {{"mouthClose", 1.0}, {"mouthShrugLower", 1.0}});
  const Eigen::Matrix3Xd noisy = perturbed(closed, rig.triangles, lips, 0.1, 11);
  ColliderConfig config;
  config.epsilon = 0.05;
  config.max_pairs = 16;  // small enough to overflow on the noisy frame
  config.ignore_rest_contacts = true;
  TriangleCollider lip_collider, face_collider;
  lip_collider.configure(rig.triangles, rig.neutral, lips, config);
  face_collider.configure(rig.triangles, rig.neutral, all_triangles(rig.triangle_count()), config);
  CollisionResult lip_result = lip_collider.make_result(), face_result = face_collider.make_result();
  const Eigen::Map<const Eigen::Matrix3Xd> mapped(noisy.data(), 3, noisy.cols());

  long allocations = 0;
  int32_t pairs = 0;
  bool overflowed = false;
  {
    AllocationCounter counter;
    for (int frame = 0; frame < 20; ++frame) {
      for (const Eigen::Matrix3Xd* x : {&rig.neutral, &closed, &crossing, &noisy}) {
        lip_collider.detect(*x, lip_result);
        pairs += lip_result.pairs_found;
        overflowed = overflowed || lip_result.overflowed();
        face_collider.detect(*x, face_result);
      }
      lip_collider.detect(mapped, lip_result);
    }
    allocations = counter.count();
  }
  CHECK(allocations == 0);
  CHECK(pairs > 0);
  CHECK(overflowed);
  // The counter does count: configuring allocates.
  AllocationCounter counter;
  TriangleCollider another;
  another.configure(rig.triangles, rig.neutral, lips, config);
  CHECK(counter.count() > 0);
}

TEST_CASE("configuration errors throw and detection refuses mismatched input") {
  const Rig& rig = face().rig();
  TriangleCollider collider;
  CollisionResult result;
  CHECK_FALSE(collider.detect(rig.neutral, result));  // not configured
  ColliderConfig config;
  const std::vector<int> bad{0, int(rig.triangle_count())};
  CHECK_THROWS_AS(collider.configure(rig.triangles, rig.neutral, bad, config), Error);
  config.epsilon = -1.0;
  CHECK_THROWS_AS(collider.configure(rig.triangles, rig.neutral, all_triangles(10), config), Error);
  config.epsilon = 0.01;
  config.max_pairs = -1;
  CHECK_THROWS_AS(collider.configure(rig.triangles, rig.neutral, all_triangles(10), config), Error);
  config.max_pairs = 10;
  collider.configure(rig.triangles, rig.neutral, all_triangles(10), config);
  result = collider.make_result();
  const Eigen::Matrix3Xd too_few = rig.neutral.leftCols(10);
  CHECK_FALSE(collider.detect(too_few, result));
  CHECK(result.pair_count == 0);
  CHECK(collider.detect(rig.neutral, result));
  Eigen::Matrix3Xd broken = rig.neutral;
  broken(1, rig.triangles(0, 3)) = std::numeric_limits<double>::quiet_NaN();
  CHECK_FALSE(collider.detect(broken, result));
  const auto used = collider.candidate_vertices();
  int outside = 0;
  while (std::binary_search(used.begin(), used.end(), outside)) ++outside;
  broken = rig.neutral;
  broken(1, outside) = std::numeric_limits<double>::quiet_NaN();
  CHECK(collider.detect(broken, result));  // not a candidate vertex: ignored
}

TEST_CASE("an empty candidate set finds nothing") {
  const Rig& rig = face().rig();
  TriangleCollider collider;
  collider.configure(rig.triangles, rig.neutral, {}, ColliderConfig{});
  CollisionResult result = collider.make_result();
  CHECK(collider.detect(rig.neutral, result));
  CHECK(result.pairs_found == 0);
  CHECK(result.vertex_count == 0);
}

// ---- Regions and metrics ----------------------------------------------------------------

TEST_CASE("the lip region is found from the shapes alone") {
  const Rig& rig = face().rig();
  const std::vector<int> lips = find_lip_vertices(rig);
  // Every vertex of both inner lip rows, plus the mouth corners, nothing elsewhere.
  for (int v : builtin_lip_hint()) CHECK(std::binary_search(lips.begin(), lips.end(), v));
  for (int v : lips) {
    CHECK(std::abs(rig.neutral(1, v) + 5.0) < 0.25);  // the mouth line is y = -5 cm
    CHECK(std::abs(rig.neutral(0, v)) < 3.0);
  }
  LipRegionOptions from_hint;
  from_hint.lip_vertices = builtin_lip_hint();
  const auto hinted = lip_region_triangles(rig, from_hint);
  const auto automatic = lip_region_triangles(rig);
  CHECK(std::includes(automatic.begin(), automatic.end(), hinted.begin(), hinted.end()));
  CHECK(automatic.size() < std::size_t(rig.triangle_count()) / 10);
  // A mask computed by the caller works too.
  const auto mask = mouth_moving_vertices(rig, 0.1);
  const auto moving = masked_triangles(rig.triangles, mask);
  CHECK(moving.size() > automatic.size());
  CHECK(std::includes(moving.begin(), moving.end(), hinted.begin(), hinted.end()));
}

TEST_CASE("flipped triangles are counted against the rest normals") {
  // A unit square as two triangles; moving a corner across the diagonal turns one over.
  Eigen::Matrix3Xd square(3, 4);
  square << 0, 1, 1, 0,  //
      0, 0, 1, 1,        //
      0, 0, 0, 0;
  Eigen::Matrix3Xi two(3, 2);
  two << 0, 0,  //
      1, 2,     //
      2, 3;
  CHECK(count_flipped_triangles(two, square, square) == 0);
  Eigen::Matrix3Xd moved = square;
  moved.col(1) = Vec3(0.0, 1.5, 0.2);
  CHECK(count_flipped_triangles(two, square, moved) == 1);
  moved.col(1) = Vec3(0.5, 0.5, 0.0);  // onto the diagonal: zero area, not counted
  CHECK(count_flipped_triangles(two, square, moved) == 0);

  // The built-in face mirrored in x: a triangle with rest normal n gets (n_x, -n_y,
  // -n_z), so it counts as flipped exactly when n_x^2 < n_y^2 + n_z^2.
  const Rig& rig = face().rig();
  CHECK(count_flipped_triangles(rig.triangles, rig.neutral, rig.neutral) == 0);
  Eigen::Matrix3Xd mirrored = rig.neutral;
  mirrored.row(0) *= -1.0;
  int64_t expected = 0;
  for (Eigen::Index t = 0; t < rig.triangle_count(); ++t) {
    const auto c = corners(rig.triangles, rig.neutral, int(t));
    const Vec3 n = (c[1] - c[0]).cross(c[2] - c[0]);
    if (n.x() * n.x() < n.y() * n.y() + n.z() * n.z()) ++expected;
  }
  CHECK(expected > rig.triangle_count() / 2);
  CHECK(count_flipped_triangles(rig.triangles, rig.neutral, mirrored) == expected);
}

TEST_CASE("the intersection counter is reusable frame after frame") {
  const Rig& rig = face().rig();
  IntersectionCounter counter;
  counter.configure(rig.triangles, rig.neutral);
  const Eigen::Matrix3Xd shrugged = pose(rig, {{"mouthClose", 1.0}, {"mouthShrugLower", 1.0}});
  const Eigen::Matrix3Xd overclosed = pose(rig, {{"mouthClose", 2.0}});
  const auto expected = intersecting_pairs(rig.triangles, shrugged);  // a tree built on that pose
  CHECK(expected.size() == 78);
  CHECK(counter.pairs(shrugged) == expected);
  CHECK(counter.count(overclosed) == count_intersecting_pairs(rig.triangles, overclosed));
  long allocations = 0;
  int64_t total = 0;
  {
    AllocationCounter allocation_counter;
    for (const Eigen::Matrix3Xd* x : {&rig.neutral, &shrugged, &overclosed}) total += counter.count(*x);
    allocations = allocation_counter.count();
  }
  CHECK(allocations == 0);
  CHECK(total == int64_t(expected.size()) + count_intersecting_pairs(rig.triangles, overclosed));
  IntersectionCounter unconfigured;
  CHECK_THROWS_AS(unconfigured.count(rig.neutral), Error);
  const Eigen::Matrix3Xd too_few = rig.neutral.leftCols(3);
  CHECK_THROWS_AS(counter.count(too_few), Error);
}

// ---- ICT FaceKit, when ../shared/data is present ------------------------------------------

TEST_CASE("ICT FaceKit: intersecting lip pairs of the linear blend, and the lip collider") {
  FACECAP_REQUIRE_SHARED_DATA(dir, "ict-face");
  const Rig rig = load_rig(dir.string());
  const auto rest = intersecting_pairs(rig.triangles, rig.neutral);
  // The neutral's mouth corners already interpenetrate.
  CHECK(rest.size() == 124);
  const std::vector<int> lips = lip_region_triangles(rig);
  ColliderConfig config;
  config.epsilon = 0.01;
  config.max_pairs = 100000;
  TriangleCollider collider;
  collider.configure(rig.triangles, rig.neutral, lips, config);
  CollisionResult result = collider.make_result();

  struct Pose {
    std::string name;
    std::vector<std::pair<const char*, double>> weights;
  };
  const std::vector<Pose> poses{
      {"mouthClose=1", {{"mouthClose", 1.0}}},
      {"mouthRollLower=1", {{"mouthRollLower", 1.0}}},
      {"mouthRollUpper=1", {{"mouthRollUpper", 1.0}}},
      {"mouthRollLower=1 mouthRollUpper=1", {{"mouthRollLower", 1.0}, {"mouthRollUpper", 1.0}}},
      {"jawOpen=0.2 mouthClose=0.2", {{"jawOpen", 0.2}, {"mouthClose", 0.2}}},
      {"jawOpen=0.3 mouthClose=0.3", {{"jawOpen", 0.3}, {"mouthClose", 0.3}}},
      {"jawOpen=0.5 mouthClose=0.5", {{"jawOpen", 0.5}, {"mouthClose", 0.5}}},
      {"jawOpen=0.6 mouthClose=0.5", {{"jawOpen", 0.6}, {"mouthClose", 0.5}}},
      {"jawOpen=1 mouthClose=1", {{"jawOpen", 1.0}, {"mouthClose", 1.0}}},
      {"jawOpen=0.6 mouthClose=0.2", {{"jawOpen", 0.6}, {"mouthClose", 0.2}}},
  };
  std::ostringstream table;
  table << "ICT linear blend, intersecting triangle pairs (neutral: " << rest.size()
        << "), lip region " << lips.size() << " triangles, collider epsilon " << config.epsilon << ":\n";
  for (const Pose& p : poses) {
    Eigen::VectorXd w = Eigen::VectorXd::Zero(rig.shape_count());
    for (const auto& [name, value] : p.weights) w[*rig.shape_index(name)] = value;
    const Eigen::Matrix3Xd x = rig.linear_blend(w);
    const auto now = intersecting_pairs(rig.triangles, x);
    std::vector<TrianglePair> fresh, in_region;
    std::set_difference(now.begin(), now.end(), rest.begin(), rest.end(), std::back_inserter(fresh));
    for (const auto& q : fresh)
      if (std::binary_search(lips.begin(), lips.end(), q.first) && std::binary_search(lips.begin(), lips.end(), q.second))
        in_region.push_back(q);
    REQUIRE(collider.detect(x, result));
    const auto found = collider_pairs(result);
    table << "  " << p.name << ": " << now.size() << " intersecting, " << fresh.size() << " new, " << in_region.size()
          << " of them in the lip region; collider " << result.pairs_found << " pairs, " << result.vertex_count
          << " vertices\n";
    // The collider reports every crossing pair inside its region.
    CHECK(std::includes(found.begin(), found.end(), in_region.begin(), in_region.end()));
    // Apart from mouthClose alone (which pushes the lips into the nose), every new
    // crossing is at the lips.
    if (p.name != "mouthClose=1") CHECK(in_region.size() == fresh.size());
  }
  WARN(table.str());
}

// The collider's kept pairs (ColliderConfig::skin): frame after frame, small steps reuse
// the last traversal's pairs and large ones traverse again, and every frame finds exactly
// the pairs a collider without a skin finds, which the brute-force oracle confirms.
TEST_CASE("a collider with a skin finds the same pairs as one without, frame after frame") {
  const Rig& rig = BuiltinFace::instance().rig();
  const std::vector<int> lips = lip_region_triangles(rig);
  const Eigen::Matrix3Xd closed = rig.shape_positions(*rig.shape_index("mouthClose"));
  ColliderConfig config;
  config.epsilon = 0.15;  // the closed lips come within 0.1 (the test above)
  TriangleCollider plain, skinned;
  plain.configure(rig.triangles, rig.neutral, lips, config);
  config.skin = 0.02;
  skinned.configure(rig.triangles, rig.neutral, lips, config);
  CollisionResult plain_result = plain.make_result(), skinned_result = skinned.make_result();
  int traversals = 0, reuses = 0, frames_with_pairs = 0;
  for (int frame = 0; frame <= 120; ++frame) {
    // Closing the mouth in steps of 1/60 (small: reused) with a jump every 40 frames.
    const double t = std::min(1.0, frame / 60.0 + (frame % 40 == 39 ? 0.3 : 0.0));
    const Eigen::Matrix3Xd positions = rig.neutral + t * (closed - rig.neutral);
    REQUIRE(plain.detect(positions, plain_result));
    REQUIRE(skinned.detect(positions, skinned_result));
    INFO("frame " << frame);
    REQUIRE(skinned_result.pairs_found == plain_result.pairs_found);
    CHECK(std::equal(plain_result.valid_pairs().begin(), plain_result.valid_pairs().end(),
                     skinned_result.valid_pairs().begin(), skinned_result.valid_pairs().end()));
    CHECK(plain_result.traversed);
    (skinned_result.traversed ? traversals : reuses) += 1;
    if (plain_result.pairs_found > 0) {
      ++frames_with_pairs;
      CHECK(std::size_t(plain_result.pairs_found) == brute_force_pairs(rig.triangles, positions, lips, config.epsilon).size());
    }
  }
  CHECK(frames_with_pairs > 20);
  CHECK(reuses > 60);      // small steps keep the pairs
  CHECK(traversals >= 4);  // the jumps and the first frame traverse
}
