#include "solver/stress_corpus.hpp"

#include <random>

#include <fmt/format.h>

#include "solver/collide/folds.hpp"
#include "solver/marker_layout.hpp"
#include "solver/rig.hpp"

namespace facecap {
namespace {

// Per shape: the region of the vertex it moves most (a triangle's region holding it).
std::vector<uint8_t> shape_regions(const Rig& rig) {
  const std::vector<uint8_t> triangle_region = triangle_regions(rig);
  std::vector<uint8_t> vertex_region(std::size_t(rig.vertex_count()), kRegionElsewhere);
  for (Eigen::Index t = 0; t < rig.triangle_count(); ++t)
    for (int j = 0; j < 3; ++j) {
      auto& r = vertex_region[std::size_t(rig.triangles(j, t))];
      r = std::min(r, triangle_region[std::size_t(t)]);
    }
  std::vector<uint8_t> out(std::size_t(rig.shape_count()));
  for (Eigen::Index s = 0; s < rig.shape_count(); ++s) {
    const Eigen::Map<const Eigen::Matrix3Xd> d(rig.deltas.col(s).data(), 3, rig.vertex_count());
    Eigen::Index v = 0;
    d.colwise().squaredNorm().maxCoeff(&v);
    out[std::size_t(s)] = vertex_region[std::size_t(v)];
  }
  return out;
}

}  // namespace

std::vector<StressPose> stress_corpus(const Rig& rig, const std::vector<MarkerBinding>& markers,
                                      const StressCorpusOptions& options) {
  const Eigen::Index M = rig.shape_count(), K = Eigen::Index(markers.size());
  std::vector<StressPose> corpus;
  auto add = [&](std::string name, std::string kind, Eigen::VectorXd w) {
    StressPose pose{std::move(name), std::move(kind), std::move(w), Eigen::Matrix3Xd(3, K)};
    const Eigen::Matrix3Xd blend = rig.linear_blend(pose.weights);
    for (Eigen::Index k = 0; k < K; ++k) pose.targets.col(k) = binding_point(markers[std::size_t(k)], blend);
    corpus.push_back(std::move(pose));
  };

  const std::vector<std::vector<std::string>> combinations = {
      {"eyeBlink", "browDown"}, {"eyeBlink", "eyeWide"}, {"eyeSquint", "mouthSmile"}};
  for (const auto& combination : combinations)
    for (const char* side : {"_L", "_R", ""}) {
      Eigen::VectorXd w = Eigen::VectorXd::Zero(M);
      std::string name;
      bool all = true;
      for (const auto& shape : combination) {
        const auto s = rig.shape_index(shape + side);
        if (!s) { all = false; break; }
        w[*s] = 1.0;
        name += (name.empty() ? "" : "+") + shape + side;
      }
      if (all) add(name, "combination", w);
    }
  {
    Eigen::VectorXd w = Eigen::VectorXd::Zero(M);
    std::string name;
    for (const char* shape : {"jawOpen", "mouthPucker", "mouthFunnel"})
      if (const auto s = rig.shape_index(shape)) {
        w[*s] = 1.0;
        name += (name.empty() ? "" : "+") + std::string(shape);
      }
    if (w.sum() == 3.0) add(name, "combination", w);
  }

  const std::vector<uint8_t> region = shape_regions(rig);
  std::vector<std::vector<Eigen::Index>> by_region(kFaceRegionCount);
  for (Eigen::Index s = 0; s < M; ++s)
    if (rig.deltas.col(s).squaredNorm() > 0.0) by_region[region[std::size_t(s)]].push_back(s);
  for (int r = 0; r < kFaceRegionCount; ++r) {
    const auto& shapes = by_region[std::size_t(r)];
    for (std::size_t a = 0; a < shapes.size(); ++a)
      for (std::size_t b = a + 1; b < shapes.size(); ++b) {
        Eigen::VectorXd w = Eigen::VectorXd::Zero(M);
        w[shapes[a]] = w[shapes[b]] = 1.0;
        add(rig.shape_names[std::size_t(shapes[a])] + "+" + rig.shape_names[std::size_t(shapes[b])], "pair", w);
      }
  }

  std::mt19937 random(options.seed);
  auto uniform = [&](double lo, double hi) { return lo + (hi - lo) * double(random() - random.min()) / double(random.max() - random.min()); };
  auto pick = [&](std::size_t n) { return std::size_t(uniform(0.0, double(n) - 1e-9)); };
  auto draw = [&](const std::vector<Eigen::Index>& shapes) {
    Eigen::VectorXd w = Eigen::VectorXd::Zero(M);
    const int count = 2 + int(pick(3));
    for (int i = 0; i < count; ++i) w[shapes[pick(shapes.size())]] = uniform(0.3, 1.0);
    return w;
  };
  for (int r = 0; r < kFaceRegionCount; ++r) {
    if (by_region[std::size_t(r)].size() < 2) continue;
    for (int i = 0; i < options.random_per_region; ++i)
      add(fmt::format("random {} {}", kFaceRegionNames[r], i), "random", draw(by_region[std::size_t(r)]));
  }
  const double far = options.far_pin_mm * rig_units_per_mm(rig);
  std::vector<int> drawable;  // regions with two shapes or more
  for (int r = 0; r < kFaceRegionCount; ++r)
    if (by_region[std::size_t(r)].size() >= 2) drawable.push_back(r);
  for (int i = 0; i < options.far_pin_poses && K > 0 && !drawable.empty(); ++i) {
    add(fmt::format("far pins {}", i), "far_pins", draw(by_region[std::size_t(drawable[pick(drawable.size())])]));
    const int dragged = 1 + int(pick(3));
    for (int d = 0; d < dragged; ++d) {
      const Eigen::Vector3d direction = Eigen::Vector3d(uniform(-1, 1), uniform(-1, 1), uniform(-1, 1)).normalized();
      corpus.back().targets.col(Eigen::Index(pick(std::size_t(K)))) += far * direction;
    }
  }
  return corpus;
}

}  // namespace facecap
