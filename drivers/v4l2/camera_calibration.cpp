#include "drivers/v4l2/camera_calibration.hpp"

#include <cmath>

#include <Eigen/Geometry>
#include <fmt/format.h>
#include <opencv2/core.hpp>
#include <opencv2/core/eigen.hpp>

#include "core/error.hpp"
#include "core/io.hpp"
#include "drivers/v4l2/calibration_yaml.hpp"

namespace facecap::drivers::v4l2 {
namespace {

constexpr int kMaxMatrixSide = 16;  // checked before anything is allocated for a matrix

struct Reader {
  const std::string& name;

  [[noreturn]] void fail(const std::string& key, std::string what) const {
    throw Error(std::move(what), {.file = name, .key = key});
  }

  // A matrix as OpenCV writes it (!!opencv-matrix: rows, cols, dt, data) or a plain list;
  // returned row-major with its shape. Sizes are checked before OpenCV reads the data.
  std::vector<double> matrix(const YamlNode& node, const std::string& key, int& rows, int& cols) const {
    if (node.is_sequence()) {
      if (node.items().size() > std::size_t(kMaxMatrixSide * kMaxMatrixSide))
        fail(key, fmt::format("{} numbers are too many", node.items().size()));
      rows = 1;
      cols = int(node.items().size());
    } else if (node.is_mapping()) {
      const auto r = node["rows"].integer(), c = node["cols"].integer();
      const YamlNode& data = node["data"];
      if (!r || !c || !data.is_sequence()) fail(key, "a matrix needs integer rows and cols and a data list");
      if (*r < 1 || *c < 1 || *r > kMaxMatrixSide || *c > kMaxMatrixSide)
        fail(key, fmt::format("a {}x{} matrix is outside 1x1 to {}x{}", *r, *c, kMaxMatrixSide, kMaxMatrixSide));
      rows = int(*r);
      cols = int(*c);
      if (data.items().size() != std::size_t(rows * cols))
        fail(key, fmt::format("a {}x{} matrix needs {} numbers, the data has {}", rows, cols, rows * cols,
                              data.items().size()));
      return numbers(data, key);
    } else {
      fail(key, node.is_none() ? "is missing" : "must be a matrix (!!opencv-matrix) or a list of numbers");
    }
    return numbers(node, key);
  }

  std::vector<double> numbers(const YamlNode& list, const std::string& key) const {
    std::vector<double> out;
    for (const YamlNode& item : list.items()) {
      const auto value = item.real();
      if (!value) fail(key, fmt::format("element {} is not a number", out.size()));
      if (!std::isfinite(*value)) fail(key, fmt::format("element {} is not finite", out.size()));
      out.push_back(*value);
    }
    return out;
  }

  Eigen::Matrix3d matrix3(const YamlNode& node, const std::string& key) const {
    int rows = 0, cols = 0;
    const std::vector<double> v = matrix(node, key, rows, cols);
    if (v.size() != 9) fail(key, fmt::format("must be 3x3, not {}x{}", rows, cols));
    return Eigen::Map<const Eigen::Matrix<double, 3, 3, Eigen::RowMajor>>(v.data());
  }

  Eigen::Vector3d vector3(const YamlNode& node, const std::string& key) const {
    int rows = 0, cols = 0;
    const std::vector<double> v = matrix(node, key, rows, cols);
    if (v.size() != 3 || (rows != 1 && cols != 1)) fail(key, fmt::format("must be 3x1, not {}x{}", rows, cols));
    return Eigen::Vector3d(v[0], v[1], v[2]);
  }

  Eigen::Matrix3d camera_matrix(const YamlNode& node, const std::string& key) const {
    const Eigen::Matrix3d k = matrix3(node, key);
    if (!(k(0, 0) > 0 && k(1, 1) > 0)) fail(key, fmt::format("fx and fy must be positive (got {} and {})", k(0, 0), k(1, 1)));
    if (k(1, 0) != 0 || k(2, 0) != 0 || k(2, 1) != 0 || k(2, 2) != 1)
      fail(key, "must be [fx s cx; 0 fy cy; 0 0 1]");
    return k;
  }

  std::vector<double> distortion(const YamlNode& node, const std::string& key) const {
    if (node.is_none()) return {};
    int rows = 0, cols = 0;
    std::vector<double> d = matrix(node, key, rows, cols);
    if (rows != 1 && cols != 1) fail(key, fmt::format("must be a row or a column, not {}x{}", rows, cols));
    if (d.size() != 4 && d.size() != 5 && d.size() != 8 && d.size() != 12 && d.size() != 14)
      fail(key, fmt::format("OpenCV's distortion models have 4, 5, 8, 12 or 14 coefficients, not {}", d.size()));
    return d;
  }

  // A 3x3 rotation (orthonormal, determinant 1) or a Rodrigues vector.
  Eigen::Matrix3d rotation(const YamlNode& node, const std::string& key) const {
    int rows = 0, cols = 0;
    const std::vector<double> v = matrix(node, key, rows, cols);
    if (v.size() == 3 && (rows == 1 || cols == 1)) {
      const Eigen::Vector3d r(v[0], v[1], v[2]);
      return r.norm() > 0 ? Eigen::AngleAxisd(r.norm(), r.normalized()).toRotationMatrix() : Eigen::Matrix3d::Identity();
    }
    if (v.size() != 9) fail(key, fmt::format("must be a 3x3 rotation or a 3x1 Rodrigues vector, not {}x{}", rows, cols));
    const Eigen::Matrix3d r = Eigen::Map<const Eigen::Matrix<double, 3, 3, Eigen::RowMajor>>(v.data());
    if ((r.transpose() * r - Eigen::Matrix3d::Identity()).cwiseAbs().maxCoeff() > 1e-5 || r.determinant() < 0)
      fail(key, "is not a rotation (R^T R must be the identity, det R = 1, to 1e-5)");
    return r;
  }

  int size(const YamlNode& node, const std::string& key) const {
    if (node.is_none()) return 0;
    const auto pixels = node.integer();
    if (!pixels || *pixels < 1 || *pixels > 65535) fail(key, "must be a whole number of pixels, 1 to 65535");
    return int(*pixels);
  }
};

CameraCalibration parse(const YamlNode& fs, const std::string& name) {
  const Reader read{name};
  CameraCalibration out;
  if (!fs.is_mapping()) read.fail("cameras", "the calibration must be a mapping (units, cameras, ...)");
  if (const YamlNode& units = fs["units"]; !units.is_none()) {
    if (units.text() != "mm" && units.text() != "cm" && units.text() != "m")
      read.fail("units", "must be \"mm\", \"cm\" or \"m\"");
    out.units = units.text();
  }
  if (const YamlNode& cameras = fs["cameras"]; !cameras.is_none()) {
    if (!cameras.is_sequence()) read.fail("cameras", "must be a sequence of cameras");
    for (const YamlNode& node : cameras.items()) {
      const std::string key = fmt::format("cameras[{}]", out.cameras.size());
      if (!node.is_mapping())
        read.fail(key, "must be a map (name, camera_matrix, distortion_coefficients, rotation, translation)");
      CameraModel& c = out.cameras.emplace_back();
      c.name = node["name"].is_string() && !node["name"].text().empty() ? node["name"].text()
                                                                          : fmt::format("camera {}", out.cameras.size());
      c.width = read.size(node["image_width"], key + ".image_width");
      c.height = read.size(node["image_height"], key + ".image_height");
      c.camera_matrix = read.camera_matrix(node["camera_matrix"], key + ".camera_matrix");
      c.distortion = read.distortion(node["distortion_coefficients"], key + ".distortion_coefficients");
      c.rotation = read.rotation(node["rotation"], key + ".rotation");
      c.translation = read.vector3(node["translation"], key + ".translation");
    }
  } else if (!fs["M1"].is_none()) {  // OpenCV's stereo calibration: camera 1 is the world
    const int width = read.size(fs["image_width"], "image_width"), height = read.size(fs["image_height"], "image_height");
    for (int i = 1; i <= 2; ++i) {
      CameraModel& c = out.cameras.emplace_back();
      c.name = fmt::format("camera {}", i);
      c.width = width;
      c.height = height;
      c.camera_matrix = read.camera_matrix(fs[fmt::format("M{}", i)], fmt::format("M{}", i));
      c.distortion = read.distortion(fs[fmt::format("D{}", i)], fmt::format("D{}", i));
    }
    out.cameras[1].rotation = read.rotation(fs["R"], "R");
    out.cameras[1].translation = read.vector3(fs["T"], "T");
  } else {
    read.fail("cameras", "no cameras: give a `cameras` sequence, or M1, D1, M2, D2, R and T as OpenCV's stereo "
                         "calibration writes them");
  }
  if (out.cameras.size() < 2)
    read.fail("cameras", fmt::format("{} camera: triangulation needs at least 2", out.cameras.size()));
  for (std::size_t i = 0; i < out.cameras.size(); ++i)
    for (std::size_t j = 0; j < i; ++j)
      if ((out.cameras[i].centre() - out.cameras[j].centre()).norm() == 0)
        read.fail(fmt::format("cameras[{}].translation", i),
                  fmt::format("{} sits where {} does: a baseline is needed", out.cameras[i].name, out.cameras[j].name));
  return out;
}

}  // namespace

CameraCalibration parse_camera_calibration(std::string_view text, const std::string& name) {
  if (text.find_first_not_of(" \t\r\n") == std::string_view::npos) throw file_error(name, "the calibration is empty");
  // Our own reader of the YAML subset the format uses: OpenCV's (4.6) can spin forever on
  // a few hostile bytes, and startup must stay stoppable.
  return parse(parse_calibration_yaml(text, name), name);
}

CameraCalibration read_camera_calibration(const std::filesystem::path& path) {
  const std::vector<char> bytes = read_file_bytes(path);
  return parse_camera_calibration(std::string_view(bytes.data(), bytes.size()), path.string());
}

void write_camera_calibration(const std::filesystem::path& path, const CameraCalibration& calibration) {
  try {
    cv::FileStorage fs(path.string(), cv::FileStorage::WRITE | cv::FileStorage::FORMAT_YAML);
    if (!fs.isOpened()) throw file_error(path.string(), "cannot be written");
    fs << "units" << calibration.units << "cameras" << "[";
    for (const CameraModel& c : calibration.cameras) {
      cv::Mat k, r, t;
      cv::eigen2cv(c.camera_matrix, k);
      cv::eigen2cv(c.rotation, r);
      cv::eigen2cv(c.translation, t);
      fs << "{" << "name" << c.name;
      if (c.width > 0) fs << "image_width" << c.width << "image_height" << c.height;
      fs << "camera_matrix" << k;
      if (!c.distortion.empty()) fs << "distortion_coefficients" << cv::Mat(c.distortion, true).reshape(1, 1);
      fs << "rotation" << r << "translation" << t << "}";
    }
    fs << "]";
  } catch (const cv::Exception& e) {
    throw file_error(path.string(), e.err.empty() ? e.what() : e.err);
  }
}

}  // namespace facecap::drivers::v4l2
