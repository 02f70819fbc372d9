#pragma once
// The calibration of the cameras the v4l2 driver triangulates with: per camera the
// intrinsics (camera matrix), OpenCV's distortion coefficients and the extrinsics (world
// to camera), read from an OpenCV-style YAML file by our own reader of the subset OpenCV
// writes (calibration_yaml.hpp; cv::FileStorage's reader can spin forever on hostile
// bytes). Two layouts are accepted (docs/cameras.md):
//
//   - `cameras:` a sequence of maps (name, image_width, image_height, camera_matrix,
//     distortion_coefficients, rotation, translation), any number of cameras, each
//     rotation a 3x3 matrix or a Rodrigues vector, world to camera;
//   - OpenCV's stereo calibration output: M1, D1, M2, D2 (intrinsics) and R, T (camera 2
//     from camera 1), camera 1 being the world.
//
// `units` (mm, cm or m; default mm) is the unit of the translations, and so of the points
// triangulated. It lives with the driver rather than in formats/ because it reads through
// OpenCV, which only this driver links.
#include <filesystem>
#include <string>
#include <string_view>
#include <vector>

#include <Eigen/Core>

namespace facecap::drivers::v4l2 {

struct CameraModel {
  std::string name;                 // for messages ("left", "camera 2")
  int width = 0, height = 0;        // pixels; 0 when the file does not say (the camera's own size is kept)
  Eigen::Matrix3d camera_matrix = Eigen::Matrix3d::Identity();  // fx 0 cx; 0 fy cy; 0 0 1
  std::vector<double> distortion;   // k1 k2 p1 p2 [k3 [k4 k5 k6 [s1 s2 s3 s4 [tx ty]]]]: 0, 4, 5, 8, 12 or 14
  Eigen::Matrix3d rotation = Eigen::Matrix3d::Identity();  // world to camera: x_cam = R x_world + t
  Eigen::Vector3d translation = Eigen::Vector3d::Zero();

  Eigen::Vector3d centre() const { return -rotation.transpose() * translation; }  // in the world
  double focal_px() const { return 0.5 * (camera_matrix(0, 0) + camera_matrix(1, 1)); }
};

struct CameraCalibration {
  std::vector<CameraModel> cameras;  // at least 2
  std::string units = "mm";          // of the translations and of the points triangulated
};

// Throws Error naming the file, the line (for syntax errors) or the key
// ("cameras[1].camera_matrix") and what is wrong. Not RT-safe.
CameraCalibration read_camera_calibration(const std::filesystem::path& path);
CameraCalibration parse_camera_calibration(std::string_view text, const std::string& name);

// Writes the `cameras:` layout (YAML), which read_camera_calibration reads back exactly.
// Throws Error. Not RT-safe.
void write_camera_calibration(const std::filesystem::path& path, const CameraCalibration& calibration);

}  // namespace facecap::drivers::v4l2
