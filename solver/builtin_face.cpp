#include "solver/builtin_face.hpp"

#include <algorithm>
#include <array>
#include <cmath>
#include <functional>
#include <string_view>
#include <numbers>

#include <Eigen/Geometry>

namespace facecap {
namespace {

constexpr double kPi = std::numbers::pi;
constexpr double deg(double d) { return d * kPi / 180.0; }

// Face layout (cm). The face is an ellipse in x/y; depth is an ellipsoid with a nose.
constexpr double kHalfWidth = 7.5, kTop = 9.0, kBottom = -11.0;
constexpr int kColumns = 81, kRows = 101;
constexpr double kMouthY = -5.0, kMouthHalfWidth = 2.4;
constexpr double kEyeX = 3.2, kEyeY = 2.0, kEyeHalfWidth = 1.4, kEyeHalfHeight = 0.45;
constexpr double kJawOpenDegrees = 25.0, kBlinkDegrees = 40.0, kWideDegrees = -12.0;

double smoothstep(double edge0, double edge1, double x) {
  const double t = std::clamp((x - edge0) / (edge1 - edge0), 0.0, 1.0);
  return t * t * (3.0 - 2.0 * t);
}
double gauss(double dx, double dy, double sx, double sy) {
  return std::exp(-0.5 * (dx * dx / (sx * sx) + dy * dy / (sy * sy)));
}

bool inside_face(double x, double y) {
  const double cy = 0.5 * (kTop + kBottom), ry = 0.5 * (kTop - kBottom);
  return (x / kHalfWidth) * (x / kHalfWidth) + ((y - cy) / ry) * ((y - cy) / ry) <= 1.0;
}
// The slit between the lips: two quad rows, so the lips rest 4 mm apart.
constexpr double kLipGap = 0.2;  // half the gap
bool in_mouth_slit(double x, double y) { return std::abs(x) < kMouthHalfWidth && std::abs(y - kMouthY) < 0.75 * kLipGap; }
bool in_eye_opening(double x, double y) {
  const double dx = (std::abs(x) - kEyeX) / kEyeHalfWidth, dy = (y - kEyeY) / kEyeHalfHeight;
  return dx * dx + dy * dy < 1.0;
}

double face_depth(double x, double y) {
  const double ex = x / 8.5, ey = (y + 1.0) / 12.5;
  double z = 9.0 * std::sqrt(std::max(0.05, 1.0 - ex * ex - ey * ey)) - 6.0;
  z += 2.3 * gauss(x, y + 0.5, 0.9, 2.2) * smoothstep(-3.5, -1.5, y);  // nose
  z -= 0.6 * gauss(std::abs(x) - kEyeX, y - kEyeY, 1.6, 1.0);          // eye sockets
  z += 0.5 * gauss(x, y - kMouthY, 2.6, 0.9);                          // lips
  z += 0.3 * gauss(std::abs(x) - kEyeX, y - (kEyeY + 1.3), 1.8, 0.35); // brow ridge
  return z;
}

// Fraction of the jaw's rotation each point follows: all of the lower lip and chin,
// none of the upper lip, blending across the cheeks beside the mouth corners.
double jaw_amount(double x, double y) {
  if (std::abs(x) < kMouthHalfWidth) return y < kMouthY ? 1.0 : 0.0;
  const double spread = 0.4 + 0.8 * (std::abs(x) - kMouthHalfWidth);
  return 1.0 - smoothstep(kMouthY - spread, kMouthY + spread, y);
}

// Fraction of the upper lid's rotation: the band above the eye opening.
double lid_amount(double x, double y, double eye_x) {
  if (y < kEyeY) return 0.0;
  const double dx = (x - eye_x) / (kEyeHalfWidth + 0.3), dy = (y - kEyeY) / 1.0;
  return 1.0 - smoothstep(0.7, 1.0, std::sqrt(dx * dx + dy * dy));
}

struct Translation {
  const char* name;
  double cx, cy, sx, sy;  // Gaussian region
  Eigen::Vector3d d;      // displacement at the centre (cm)
  int lip_side;           // 0 both lips, +1 upper only, -1 lower only
  bool follows_jaw;       // weighted by jaw_amount (jaw translations)
};

// Translational shapes; _L is the actor's left (+X). Mirrored pairs are listed once
// with a positive cx and expanded below.
const Translation kTranslations[] = {
    {"browDown", 2.0, 3.6, 1.2, 0.6, {-0.15, -0.35, 0.0}, 0, false},
    {"browInnerUp", 1.2, 3.6, 0.9, 0.7, {0.0, 0.55, 0.05}, 0, false},
    {"browOuterUp", 4.2, 3.4, 1.1, 0.7, {0.05, 0.5, 0.0}, 0, false},
    {"cheekPuff", 4.2, -3.5, 1.4, 1.5, {0.45, 0.0, 0.5}, 0, false},
    {"cheekSquint", 3.8, 0.3, 1.2, 0.7, {0.0, 0.3, 0.1}, 0, false},
    {"eyeSquint", 3.2, 1.3, 1.1, 0.45, {0.0, 0.25, 0.05}, 0, false},
    {"mouthDimple", 2.7, -5.0, 0.7, 0.7, {0.2, 0.0, -0.25}, 0, false},
    {"mouthFrown", 2.4, -5.3, 1.0, 1.0, {0.1, -0.45, 0.0}, 0, false},
    {"mouthLowerDown", 1.1, -5.4, 1.0, 0.5, {0.0, -0.45, 0.1}, -1, false},
    {"mouthPress", 1.2, -5.0, 1.1, 0.5, {0.0, 0.0, -0.2}, 0, false},
    {"mouthSmile", 2.4, -4.9, 1.2, 1.1, {0.5, 0.55, -0.2}, 0, false},
    {"mouthStretch", 2.4, -5.1, 1.2, 1.0, {0.55, -0.25, -0.1}, 0, false},
    {"mouthUpperUp", 1.1, -4.6, 1.0, 0.5, {0.0, 0.4, 0.1}, 1, false},
    {"noseSneer", 0.9, -0.3, 0.6, 0.9, {0.05, 0.35, 0.05}, 0, false},
};
// Symmetric shapes (cx = 0), not mirrored.
const Translation kCentred[] = {
    {"jawForward", 0.0, -8.0, 30.0, 30.0, {0.0, 0.0, 0.6}, 0, true},
    {"jawLeft", 0.0, -8.0, 30.0, 30.0, {0.6, 0.0, 0.0}, 0, true},
    {"jawRight", 0.0, -8.0, 30.0, 30.0, {-0.6, 0.0, 0.0}, 0, true},
    {"mouthClose", 0.0, -5.2, 2.0, 0.5, {0.0, 0.55, 0.05}, -1, false},  // lower lip rises past the upper
    {"mouthFunnel", 0.0, -5.0, 1.8, 0.7, {0.0, 0.0, 0.45}, 0, false},
    {"mouthLeft", 0.0, -5.0, 2.2, 0.9, {0.5, 0.0, 0.0}, 0, false},
    {"mouthPucker", 0.0, -5.0, 1.7, 0.7, {0.0, 0.0, 0.6}, 0, false},
    {"mouthRight", 0.0, -5.0, 2.2, 0.9, {-0.5, 0.0, 0.0}, 0, false},
    {"mouthRollLower", 0.0, -5.2, 1.9, 0.35, {0.0, 0.12, -0.35}, -1, false},
    {"mouthRollUpper", 0.0, -4.8, 1.9, 0.35, {0.0, -0.12, -0.35}, 1, false},
    {"mouthShrugLower", 0.0, -6.0, 1.8, 0.9, {0.0, 0.3, 0.15}, -1, false},
    {"mouthShrugUpper", 0.0, -4.5, 1.8, 0.6, {0.0, 0.2, 0.1}, 1, false},
};

Eigen::Vector3d translation_at(const Translation& t, double cx, double mirror, const Eigen::Vector3d& p,
                               double jaw) {
  const double x = p.x(), y = p.y();
  double amount = gauss(x - cx, y - t.cy, t.sx, t.sy);
  // One lip only: split like the jaw, sharply inside the slit, smoothly past the corners.
  if (t.lip_side > 0) amount *= 1.0 - jaw;
  if (t.lip_side < 0) amount *= jaw;
  if (t.follows_jaw) amount = jaw;
  Eigen::Vector3d d = t.d;
  d.x() *= mirror;
  // Pucker and funnel also pull the lips toward the mouth's centre line.
  if (std::string_view(t.name) == "mouthPucker") d.x() = -0.35 * x / kMouthHalfWidth;
  if (std::string_view(t.name) == "mouthFunnel") d.y() = (y > kMouthY ? 0.25 : -0.25);
  return amount * d;
}

Eigen::Matrix3d rotation_x(double radians) {
  return Eigen::AngleAxisd(radians, Eigen::Vector3d::UnitX()).toRotationMatrix();
}

}  // namespace

const BuiltinFace& BuiltinFace::instance() {
  static const BuiltinFace face;
  return face;
}

double BuiltinFace::jaw_open_radians() const { return deg(kJawOpenDegrees); }

BuiltinFace::BuiltinFace() {
  // Grid vertices; quads kept where the whole quad is on the face and not in an opening.
  auto grid_x = [](int c) { return -kHalfWidth + 2.0 * kHalfWidth * c / (kColumns - 1); };
  auto grid_y = [](int r) { return kBottom + (kTop - kBottom) * r / (kRows - 1); };
  std::vector<int> index(kColumns * kRows, -1);
  std::vector<Eigen::Vector3i> tris;
  auto vertex = [&](int c, int r) -> int& { return index[std::size_t(r * kColumns + c)]; };
  std::vector<std::array<int, 4>> quads;
  for (int r = 0; r + 1 < kRows; ++r)
    for (int c = 0; c + 1 < kColumns; ++c) {
      const double mx = 0.5 * (grid_x(c) + grid_x(c + 1)), my = 0.5 * (grid_y(r) + grid_y(r + 1));
      if (!inside_face(grid_x(c), grid_y(r)) || !inside_face(grid_x(c + 1), grid_y(r)) ||
          !inside_face(grid_x(c), grid_y(r + 1)) || !inside_face(grid_x(c + 1), grid_y(r + 1)))
        continue;
      if (in_mouth_slit(mx, my) || in_eye_opening(mx, my)) continue;
      quads.push_back({c, r, 0, 0});
    }
  std::vector<Eigen::Vector3d> points;
  for (const auto& q : quads)
    for (int dr = 0; dr < 2; ++dr)
      for (int dc = 0; dc < 2; ++dc) {
        int& v = vertex(q[0] + dc, q[1] + dr);
        if (v >= 0) continue;
        v = int(points.size());
        const double x = grid_x(q[0] + dc), y = grid_y(q[1] + dr);
        points.emplace_back(x, y, face_depth(x, y));
      }
  for (const auto& q : quads) {
    const int a = vertex(q[0], q[1]), b = vertex(q[0] + 1, q[1]), c = vertex(q[0] + 1, q[1] + 1),
              d = vertex(q[0], q[1] + 1);
    // Counter-clockwise seen from +Z, so normals face the viewer; alternate diagonals.
    if ((q[0] + q[1]) % 2) { tris.emplace_back(a, b, c); tris.emplace_back(a, c, d); }
    else { tris.emplace_back(a, b, d); tris.emplace_back(b, c, d); }
  }
  const Eigen::Index n = Eigen::Index(points.size());
  rig_.name = "builtin";
  rig_.source = "builtin";
  rig_.hinged = true;  // its jaw and lids turn about hinges (articulated_pose)
  rig_.neutral.resize(3, n);
  for (Eigen::Index v = 0; v < n; ++v) rig_.neutral.col(v) = points[std::size_t(v)];
  rig_.triangles.resize(3, Eigen::Index(tris.size()));
  for (std::size_t t = 0; t < tris.size(); ++t) rig_.triangles.col(Eigen::Index(t)) = tris[t];

  // Per-vertex articulation amounts and landmarks.
  jaw_amount_.resize(n);
  lid_amount_left_.resize(n);
  lid_amount_right_.resize(n);
  double lowest = 1e9;
  for (Eigen::Index v = 0; v < n; ++v) {
    const double x = rig_.neutral(0, v), y = rig_.neutral(1, v);
    jaw_amount_[v] = jaw_amount(x, y);
    lid_amount_left_[v] = lid_amount(x, y, kEyeX);
    lid_amount_right_[v] = lid_amount(x, y, -kEyeX);
    if (std::abs(x) < 1e-9 && y < lowest) { lowest = y; chin_vertex_ = int(v); }
    if (std::abs(x) < kMouthHalfWidth - 1e-9 && std::abs(y - (kMouthY + kLipGap)) < 1e-6) upper_lip_.push_back(int(v));
    if (std::abs(x) < kMouthHalfWidth - 1e-9 && std::abs(y - (kMouthY - kLipGap)) < 1e-6) lower_lip_.push_back(int(v));
  }
  jaw_hinge_point_ = Eigen::Vector3d(0.0, -2.0, -3.0);
  eye_centre_left_ = Eigen::Vector3d(kEyeX, kEyeY, face_depth(kEyeX, kEyeY) - 1.2);
  eye_centre_right_ = Eigen::Vector3d(-kEyeX, kEyeY, face_depth(-kEyeX, kEyeY) - 1.2);

  // Shapes, sorted by name like a directory of OBJ files.
  struct ShapeDef { std::string name; std::function<Eigen::Vector3d(Eigen::Index)> delta; };
  std::vector<ShapeDef> defs;
  auto add_translation = [&](const Translation& t, const std::string& name, double cx, double mirror) {
    defs.push_back({name, [this, t, cx, mirror](Eigen::Index v) {
                      return translation_at(t, cx, mirror, rig_.neutral.col(v), jaw_amount_[v]);
                    }});
  };
  for (const auto& t : kTranslations) {
    add_translation(t, std::string(t.name) + "_L", t.cx, 1.0);
    add_translation(t, std::string(t.name) + "_R", -t.cx, -1.0);
  }
  for (const auto& t : kCentred) add_translation(t, t.name, 0.0, 1.0);
  auto add_rotation = [&](const std::string& name, const Eigen::Vector3d& centre, const Eigen::VectorXd* amount,
                          double degrees) {
    defs.push_back({name, [this, centre, amount, degrees](Eigen::Index v) -> Eigen::Vector3d {
                      const Eigen::Vector3d p = rig_.neutral.col(v);
                      return rotation_x(deg(degrees) * (*amount)[v]) * (p - centre) + centre - p;
                    }});
  };
  add_rotation("jawOpen", jaw_hinge_point_, &jaw_amount_, kJawOpenDegrees);
  add_rotation("eyeBlink_L", eye_centre_left_, &lid_amount_left_, kBlinkDegrees);
  add_rotation("eyeBlink_R", eye_centre_right_, &lid_amount_right_, kBlinkDegrees);
  add_rotation("eyeWide_L", eye_centre_left_, &lid_amount_left_, kWideDegrees);
  add_rotation("eyeWide_R", eye_centre_right_, &lid_amount_right_, kWideDegrees);
  std::sort(defs.begin(), defs.end(), [](const ShapeDef& a, const ShapeDef& b) { return a.name < b.name; });

  rig_.deltas.resize(3 * n, Eigen::Index(defs.size()));
  for (std::size_t s = 0; s < defs.size(); ++s) {
    rig_.shape_names.push_back(defs[s].name);
    for (Eigen::Index v = 0; v < n; ++v) rig_.deltas.col(Eigen::Index(s)).segment<3>(3 * v) = defs[s].delta(v);
  }
  jaw_open_ = int(*rig_.shape_index("jawOpen"));
  blink_left_ = int(*rig_.shape_index("eyeBlink_L"));
  blink_right_ = int(*rig_.shape_index("eyeBlink_R"));
  wide_left_ = int(*rig_.shape_index("eyeWide_L"));
  wide_right_ = int(*rig_.shape_index("eyeWide_R"));
}

Eigen::Matrix3Xd BuiltinFace::articulated_pose(const Eigen::VectorXd& weights) const {
  Eigen::VectorXd translation_weights = weights;
  for (int s : {jaw_open_, blink_left_, blink_right_, wide_left_, wide_right_}) translation_weights[s] = 0.0;
  Eigen::Matrix3Xd pose = rig_.linear_blend(translation_weights);
  const double jaw = deg(kJawOpenDegrees) * weights[jaw_open_];
  const double lid_left = deg(kBlinkDegrees) * weights[blink_left_] + deg(kWideDegrees) * weights[wide_left_];
  const double lid_right = deg(kBlinkDegrees) * weights[blink_right_] + deg(kWideDegrees) * weights[wide_right_];
  for (Eigen::Index v = 0; v < pose.cols(); ++v) {
    auto turn = [&](double radians, const Eigen::Vector3d& centre) {
      if (radians != 0.0) pose.col(v) = rotation_x(radians) * (pose.col(v) - centre) + centre;
    };
    turn(lid_left * lid_amount_left_[v], eye_centre_left_);
    turn(lid_right * lid_amount_right_[v], eye_centre_right_);
    turn(jaw * jaw_amount_[v], jaw_hinge_point_);
  }
  return pose;
}

Eigen::VectorXd BuiltinFace::motion_weights(double t) const {
  Eigen::VectorXd w = Eigen::VectorXd::Zero(rig_.shape_count());
  auto set = [&](const char* name, double value) {
    if (auto i = rig_.shape_index(name)) w[*i] = std::clamp(value, 0.0, 1.0);
  };
  auto wave = [t](double period, double phase) { return 0.5 - 0.5 * std::cos(2.0 * kPi * (t / period + phase)); };
  // Blinks: short closures every 3.7 s.
  const double blink_phase = std::fmod(t, 3.7);
  const double blink = blink_phase < 0.3 ? std::sin(kPi * blink_phase / 0.3) : 0.0;
  set("eyeBlink_L", blink);
  set("eyeBlink_R", blink);
  set("jawOpen", 0.8 * std::pow(wave(2.9, 0.0), 1.5));
  set("mouthSmile_L", 0.7 * wave(6.1, 0.25));
  set("mouthSmile_R", 0.6 * wave(6.1, 0.3));
  set("browInnerUp_L", 0.6 * wave(5.3, 0.5));
  set("browInnerUp_R", 0.6 * wave(5.3, 0.5));
  set("mouthPucker", 0.7 * std::max(0.0, std::sin(2.0 * kPi * t / 7.7)));
  set("mouthFunnel", 0.5 * std::max(0.0, -std::sin(2.0 * kPi * t / 7.7)));
  set("cheekPuff_L", 0.4 * wave(11.0, 0.7));
  set("cheekPuff_R", 0.4 * wave(11.0, 0.7));
  set("browDown_L", 0.5 * wave(8.3, 0.1));
  set("browDown_R", 0.5 * wave(8.3, 0.15));
  set("jawLeft", 0.3 * std::max(0.0, std::sin(2.0 * kPi * t / 9.1)));
  set("jawRight", 0.3 * std::max(0.0, -std::sin(2.0 * kPi * t / 9.1)));
  return w;
}

}  // namespace facecap
