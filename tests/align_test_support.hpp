#pragma once
// Synthetic marker takes of the built-in face for the alignment tests: markers bound to
// the rig, moved by its articulated ground truth, then put through a rigid transform and
// a unit change into "capture" coordinates with Gaussian noise.
#include <algorithm>
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

// A take as an optical facial set records it: face markers on an actor whose face is the
// rig's scaled by face_scale, a head rig (headband markers head_rig_mm off the skin,
// rigid with the head), and an "Unlabeled" ghost slot present in ghost_fraction of the
// frames; any rotation and position, mm. The face rests for rest_frames, then blends
// six of the rig's shapes smoothly (linear blend), with a few degrees of head sway.
struct HeadRigTakeOptions {
  unsigned seed = 1;
  double face_scale = 1.0;
  double head_rig_mm = 40.0;
  int head_markers = 4;
  // Per head marker, its distance off the skin (empty: head_rig_mm for every one).
  std::vector<double> head_offsets_mm;
  // The last this many head markers sit on a headband above the face's top edge instead
  // of over the forehead (head_offsets_mm still says how far forward of the skin).
  int headband_markers = 0;
  // The first head marker wobbles on its mount by this much (mm, a slow sway in the head's
  // frame): rigid with the rest but not exactly.
  double wobble_mm = 0.0;
  double ghost_fraction = 0.01;
  double noise_mm = 0.2;
  int rest_frames = 60;
  int motion_frames = 120;
  double rate_hz = 60.0;
  double rig_mm_per_unit = 10.0;
};

struct HeadRigTake {
  SyntheticTake take;              // labels: the layout's, then H0.., then "Unlabeled"
  std::size_t face_markers = 0;
  std::vector<std::string> head_labels;
};

inline HeadRigTake make_head_rig_take(const Rig& rig, std::vector<MarkerBinding> layout, const HeadRigTakeOptions& o) {
  std::mt19937 rng(o.seed);
  std::normal_distribution<double> g;
  std::uniform_real_distribution<double> u(0.0, 1.0);
  HeadRigTake out;
  SyntheticTake& t = out.take;
  t.layout = std::move(layout);
  out.face_markers = t.layout.size();
  for (const auto& b : t.layout) t.labels.push_back(b.label);
  // Head rig: forehead vertices across the top of the face's front, pushed head_rig_mm
  // out along their normals.
  const Eigen::Index V = rig.vertex_count();
  Eigen::Matrix3Xd normal = Eigen::Matrix3Xd::Zero(3, V);
  for (Eigen::Index tri = 0; tri < rig.triangle_count(); ++tri) {
    const Eigen::Vector3d a = rig.neutral.col(rig.triangles(0, tri)), b = rig.neutral.col(rig.triangles(1, tri)),
                          c = rig.neutral.col(rig.triangles(2, tri));
    const Eigen::Vector3d n = (b - a).cross(c - a);
    for (int j = 0; j < 3; ++j) normal.col(rig.triangles(j, tri)) += n;
  }
  const BoundingBox box = bounding_box(rig.neutral);
  std::vector<int> head_vertices;
  for (int h = 0; h < o.head_markers; ++h) {
    const double x = box.min.x() + box.size().x() * (0.25 + 0.5 * h / std::max(1, o.head_markers - 1));
    const double y = box.max.y() - box.size().y() * (h % 2 == 0 ? 0.12 : 0.2);
    int best = -1;
    double best_d = 1e300;
    for (Eigen::Index v = 0; v < V; ++v) {
      if (normal.col(v).normalized().z() < 0.5) continue;  // facing forwards
      const double d = std::hypot(rig.neutral(0, v) - x, rig.neutral(1, v) - y) - 1e-3 * rig.neutral(2, v);
      if (d < best_d) best_d = d, best = int(v);
    }
    head_vertices.push_back(best);
    out.head_labels.push_back("H" + std::to_string(h));
    t.labels.push_back(out.head_labels.back());
  }
  t.labels.push_back("Unlabeled");
  t.take_mm_per_unit = 1.0;
  t.rig_to_take.rotation = random_rotation(rng);
  t.rig_to_take.scale = o.rig_mm_per_unit;
  t.rig_to_take.translation = Eigen::Vector3d(g(rng), g(rng), g(rng)) * 300.0;
  // The actor's face: the rig's scaled about its centre.
  const Eigen::Vector3d centre = rig.neutral.rowwise().mean();
  std::vector<Eigen::Index> shapes;
  for (int i = 0; i < 6; ++i) shapes.push_back(Eigen::Index(u(rng) * double(rig.shape_count() - 1)));
  const int F = o.rest_frames + o.motion_frames;
  for (int f = 0; f < F; ++f) {
    Eigen::VectorXd w = Eigen::VectorXd::Zero(rig.shape_count());
    if (f >= o.rest_frames)
      for (std::size_t i = 0; i < shapes.size(); ++i)
        w[shapes[i]] = 0.4 * (1.0 - std::cos(2.0 * std::numbers::pi * (0.5 + 0.2 * double(i)) * (f - o.rest_frames) / o.rate_hz));
    Eigen::Matrix3Xd pose = rig.neutral;
    for (Eigen::Index s = 0; s < rig.shape_count(); ++s)
      if (w[s] != 0.0) pose += w[s] * Eigen::Map<const Eigen::Matrix3Xd>(rig.deltas.col(s).data(), 3, V);
    pose = ((pose.colwise() - centre) * o.face_scale).colwise() + centre;
    const double a = 3.0 * std::numbers::pi / 180.0 * std::sin(2.0 * std::numbers::pi * 0.3 * f / o.rate_hz);
    align::Similarity head;
    head.rotation = Eigen::AngleAxisd(a, Eigen::Vector3d(0.3, 1.0, 0.2).normalized()).toRotationMatrix();
    head.translation = Eigen::Vector3d(0.5 * std::sin(0.05 * f), 0.3 * std::cos(0.04 * f), 0.0);
    MarkerFrame frame;
    frame.frame_no = f + 1;
    frame.source_time_ns = int64_t(double(f) / o.rate_hz * 1e9);
    auto add = [&](const Eigen::Vector3d& rig_point, bool present) {
      Marker m;
      m.id = int32_t(frame.markers.size());
      m.label.assign(t.labels[frame.markers.size()]);
      m.position = t.rig_to_take.apply(head.apply(rig_point)) + Eigen::Vector3d(g(rng), g(rng), g(rng)) * o.noise_mm;
      if (!present) m.flags |= kMarkerMissing;
      frame.markers.push_back(m);
    };
    for (const auto& b : t.layout) add(layout_point(b, pose), true);
    for (std::size_t h = 0; h < head_vertices.size(); ++h) {
      const int v = head_vertices[h];
      Eigen::Vector3d skin = ((rig.neutral.col(v) - centre) * o.face_scale) + centre;
      if (int(h) >= o.head_markers - o.headband_markers)  // on the band: above the face's top edge
        skin.y() = centre.y() + (box.max.y() - centre.y()) * o.face_scale + 25.0 / o.rig_mm_per_unit;
      const double offset_mm = o.head_offsets_mm.empty() ? o.head_rig_mm : o.head_offsets_mm[h];
      Eigen::Vector3d point = skin + normal.col(v).normalized() * (offset_mm / o.rig_mm_per_unit);
      if (h == 0 && o.wobble_mm > 0.0)
        point += Eigen::Vector3d(std::sin(2.0 * std::numbers::pi * 0.7 * f / o.rate_hz), std::cos(2.0 * std::numbers::pi * 0.4 * f / o.rate_hz), 0.0) *
                 (o.wobble_mm / o.rig_mm_per_unit);
      add(point, true);
    }
    add(centre + Eigen::Vector3d(g(rng), g(rng), g(rng)) * (30.0 / o.rig_mm_per_unit), u(rng) < o.ghost_fraction);
    t.frames.push_back(std::move(frame));
    t.weights.push_back(w);
  }
  return out;
}

}  // namespace facecap::test
