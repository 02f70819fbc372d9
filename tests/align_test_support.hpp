#pragma once
// Synthetic marker takes of the built-in face for the alignment tests: markers bound to
// the rig, moved by its articulated ground truth, then put through a rigid transform and
// a unit change into "capture" coordinates with Gaussian noise.
#include <cmath>
#include <numbers>
#include <random>
#include <string>
#include <vector>

#include <Eigen/Core>
#include <Eigen/Geometry>

#include "core/frame.hpp"
#include "solver/align/geometry.hpp"
#include "solver/builtin_face.hpp"
#include "solver/face_solver.hpp"
#include "solver/marker_layout.hpp"

namespace facecap::test {

inline Eigen::Matrix3d random_rotation(std::mt19937& rng) {
  std::normal_distribution<double> g;
  Eigen::Quaterniond q(g(rng), g(rng), g(rng), g(rng));
  q.normalize();
  return q.toRotationMatrix();
}

// 40 spread markers plus the nose tip, the nose bridge and the chin, as a real layout has.
inline std::vector<MarkerBinding> builtin_marker_layout() {
  const Rig& rig = BuiltinFace::instance().rig();
  auto layout = spread_marker_layout(rig, 40);
  Eigen::Index tip = 0;
  rig.neutral.row(2).maxCoeff(&tip);
  int bridge = -1;
  double best = -1e9;
  for (Eigen::Index v = 0; v < rig.vertex_count(); ++v)
    if (rig.neutral(1, v) > rig.neutral(1, tip) + 2.0 && std::abs(rig.neutral(0, v)) < 0.3 && rig.neutral(2, v) > best)
      best = rig.neutral(2, v), bridge = int(v);
  layout.push_back(MarkerBinding::at_vertex("NoseTip", int(tip)));
  layout.push_back(MarkerBinding::at_vertex("NoseBridge", bridge));
  layout.push_back(MarkerBinding::at_vertex("Chin", BuiltinFace::instance().chin_vertex()));
  return layout;
}

inline Eigen::Vector3d layout_point(const MarkerBinding& b, const Eigen::Matrix3Xd& pose) {
  return b.barycentric[0] * pose.col(b.vertices[0]) + b.barycentric[1] * pose.col(b.vertices[1]) +
         b.barycentric[2] * pose.col(b.vertices[2]);
}

struct SyntheticTake {
  std::vector<MarkerBinding> layout;
  std::vector<std::string> labels;
  std::vector<MarkerFrame> frames;
  std::vector<Eigen::VectorXd> weights;  // per frame, the truth
  align::Similarity rig_to_take;         // take = s R rig + t (s = rig mm / take mm)
  double take_mm_per_unit = 10.0;
};

struct SyntheticTakeOptions {
  unsigned seed = 1;
  double take_mm_per_unit = 1.0;   // the take's units
  double noise_mm = 0.3;
  int rest_frames = 30;            // neutral frames first ...
  int motion_frames = 120;         // ... then the built-in performance
  double rate_hz = 60.0;
  double head_sway_deg = 0.0;      // per-frame head rotation amplitude (0: still head)
};

inline SyntheticTake make_synthetic_take(const SyntheticTakeOptions& o) {
  const BuiltinFace& face = BuiltinFace::instance();
  const Rig& rig = face.rig();
  std::mt19937 rng(o.seed);
  std::normal_distribution<double> g;
  SyntheticTake t;
  t.layout = builtin_marker_layout();
  for (const auto& b : t.layout) t.labels.push_back(b.label);
  t.take_mm_per_unit = o.take_mm_per_unit;
  t.rig_to_take.rotation = random_rotation(rng);
  t.rig_to_take.scale = 10.0 / o.take_mm_per_unit;  // the built-in face is in cm
  t.rig_to_take.translation = Eigen::Vector3d(g(rng), g(rng), g(rng)) * (300.0 / o.take_mm_per_unit);
  const int F = o.rest_frames + o.motion_frames;
  for (int f = 0; f < F; ++f) {
    const Eigen::VectorXd w = f < o.rest_frames ? Eigen::VectorXd::Zero(rig.shape_count())
                                                : face.motion_weights(double(f - o.rest_frames) / o.rate_hz);
    const Eigen::Matrix3Xd pose = face.articulated_pose(w);
    // Head sway about the face's centre, in rig space.
    align::Similarity head;
    if (o.head_sway_deg > 0) {
      const double a = o.head_sway_deg * std::numbers::pi / 180.0 * std::sin(2.0 * std::numbers::pi * 0.3 * f / o.rate_hz);
      head.rotation = Eigen::AngleAxisd(a, Eigen::Vector3d(0.3, 1.0, 0.2).normalized()).toRotationMatrix();
      head.translation = Eigen::Vector3d(0.5 * std::sin(0.05 * f), 0.3 * std::cos(0.04 * f), 0.0);
    }
    MarkerFrame frame;
    frame.frame_no = f + 1;
    frame.source_time_ns = int64_t(double(f) / o.rate_hz * 1e9);
    for (std::size_t k = 0; k < t.layout.size(); ++k) {
      Marker m;
      m.id = int32_t(k);
      m.label.assign(t.labels[k]);
      const Eigen::Vector3d x = head.apply(layout_point(t.layout[k], pose));
      m.position = t.rig_to_take.apply(x) + Eigen::Vector3d(g(rng), g(rng), g(rng)) * (o.noise_mm / o.take_mm_per_unit);
      frame.markers.push_back(m);
    }
    t.frames.push_back(std::move(frame));
    t.weights.push_back(w);
  }
  return t;
}

}  // namespace facecap::test
