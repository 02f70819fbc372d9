#pragma once
// The built-in synthetic face: a procedurally generated face-like surface (cm, Y up,
// looking +Z, like ICT FaceKit) with a mouth slit between the lips, eye openings with
// upper lids, brows, cheeks and a nose, and ARKit/ICT-named shapes. It needs no files:
// it is the embedded default of the daemon, the demo and the self-contained tests.
//
// Most shapes are smooth translations. jawOpen, eyeBlink_* and eyeWide_* are rotations
// (the jaw about a hinge, the upper lids about the eyes' horizontal axes). articulated_pose()
// gives the pose a real hinge produces for any weights (half the angle at weight 0.5),
// which linear blending cannot reproduce: it is the ground truth for solver tests.
#include <string>
#include <vector>

#include <Eigen/Core>

#include "solver/rig.hpp"

namespace facecap {

class BuiltinFace {
 public:
  // Built once, deterministically; thread-safe.
  static const BuiltinFace& instance();

  const Rig& rig() const { return rig_; }

  // The articulated ground truth: translations, then the lids' and the jaw's rotations
  // by weight-proportional angles. weights: M (rig shape order). Returns 3 x N.
  Eigen::Matrix3Xd articulated_pose(const Eigen::VectorXd& weights) const;

  // Jaw hinge: a line through jaw_hinge_point along +X; jawOpen = 1 turns it this far.
  Eigen::Vector3d jaw_hinge_point() const { return jaw_hinge_point_; }
  double jaw_open_radians() const;
  int chin_vertex() const { return chin_vertex_; }

  // Vertex indices of the lips' inner rows (upper, lower): where the lips meet.
  const std::vector<int>& upper_lip_vertices() const { return upper_lip_; }
  const std::vector<int>& lower_lip_vertices() const { return lower_lip_; }

  // A built-in performance: smooth, deterministic weight curves exercising jaw, blinks,
  // smiles, brows and lip shapes. Returns M weights at time t (seconds).
  Eigen::VectorXd motion_weights(double t_seconds) const;

 private:
  BuiltinFace();
  Rig rig_;
  Eigen::VectorXd jaw_amount_;           // N: fraction of the jaw rotation each vertex follows
  Eigen::VectorXd lid_amount_left_, lid_amount_right_;  // N
  Eigen::Vector3d jaw_hinge_point_;
  Eigen::Vector3d eye_centre_left_, eye_centre_right_;
  int chin_vertex_ = -1;
  std::vector<int> upper_lip_, lower_lip_;
  int jaw_open_ = -1, blink_left_ = -1, blink_right_ = -1, wide_left_ = -1, wide_right_ = -1;
};

}  // namespace facecap
