#include "drivers/v4l2/camera_calibration.hpp"

#include <cmath>
#include <regex>

#include <Eigen/Geometry>
#include <fmt/format.h>
#include <opencv2/core.hpp>
#include <opencv2/core/eigen.hpp>

#include "core/error.hpp"
#include "core/io.hpp"

namespace facecap::drivers::v4l2 {
namespace {

// OpenCV reads YAML from memory only after its "%YAML:1.0" line; a file without one gets
// it, and line numbers in messages are moved back.
constexpr std::string_view kYamlHeader = "%YAML:1.0\n---\n";
constexpr int kYamlHeaderLines = 2;
constexpr int kMaxMatrixSide = 16;  // checked before OpenCV allocates anything for a matrix

// "OpenCV(4.6.0) .../persistence_yml.cpp:764: error: (-212:Parsing error) parseValue in
// function '(4): Incorrect indentation'" -> "name:2: Incorrect indentation".
Error opencv_error(const std::string& name, const cv::Exception& e, int line_shift) {
  static const std::regex at_line(R"(\((\d+)\): (.*)')");
  std::smatch m;
  const std::string what = e.what();
  if (std::regex_search(what, m, at_line)) return line_error(name, std::stoll(m[1]) - line_shift, m[2]);
  return file_error(name, e.err.empty() ? what : e.err);
}

struct Reader {
  const std::string& name;

  [[noreturn]] void fail(const std::string& key, std::string what) const {
    throw Error(std::move(what), {.file = name, .key = key});
  }

  // A matrix as OpenCV writes it (!!opencv-matrix: rows, cols, dt, data) or a plain list;
  // returned row-major with its shape. Sizes are checked before OpenCV reads the data.
  std::vector<double> matrix(const cv::FileNode& node, const std::string& key, int& rows, int& cols) const {
    if (node.isSeq()) {
      if (node.size() > std::size_t(kMaxMatrixSide * kMaxMatrixSide)) fail(key, fmt::format("{} numbers are too many", node.size()));
      rows = 1;
      cols = int(node.size());
    } else if (node.isMap()) {
      const cv::FileNode r = node["rows"], c = node["cols"], data = node["data"];
      if (!r.isInt() || !c.isInt() || !data.isSeq()) fail(key, "a matrix needs integer rows and cols and a data list");
      rows = int(r);
      cols = int(c);
      if (rows < 1 || cols < 1 || rows > kMaxMatrixSide || cols > kMaxMatrixSide)
        fail(key, fmt::format("a {}x{} matrix is outside 1x1 to {}x{}", rows, cols, kMaxMatrixSide, kMaxMatrixSide));
      if (data.size() != std::size_t(rows * cols))
        fail(key, fmt::format("a {}x{} matrix needs {} numbers, the data has {}", rows, cols, rows * cols, data.size()));
      return numbers(data, key);
    } else {
      fail(key, node.isNone() ? "is missing" : "must be a matrix (!!opencv-matrix) or a list of numbers");
    }
    return numbers(node, key);
  }

  std::vector<double> numbers(const cv::FileNode& list, const std::string& key) const {
    std::vector<double> out;
    for (const cv::FileNode& item : list) {
      if (!item.isReal() && !item.isInt()) fail(key, fmt::format("element {} is not a number", out.size()));
      out.push_back(double(item));
      if (!std::isfinite(out.back())) fail(key, fmt::format("element {} is not finite", out.size() - 1));
    }
    return out;
  }

  Eigen::Matrix3d matrix3(const cv::FileNode& node, const std::string& key) const {
    int rows = 0, cols = 0;
    const std::vector<double> v = matrix(node, key, rows, cols);
    if (v.size() != 9) fail(key, fmt::format("must be 3x3, not {}x{}", rows, cols));
    return Eigen::Map<const Eigen::Matrix<double, 3, 3, Eigen::RowMajor>>(v.data());
  }

  Eigen::Vector3d vector3(const cv::FileNode& node, const std::string& key) const {
    int rows = 0, cols = 0;
    const std::vector<double> v = matrix(node, key, rows, cols);
    if (v.size() != 3 || (rows != 1 && cols != 1)) fail(key, fmt::format("must be 3x1, not {}x{}", rows, cols));
    return Eigen::Vector3d(v[0], v[1], v[2]);
  }

  Eigen::Matrix3d camera_matrix(const cv::FileNode& node, const std::string& key) const {
    const Eigen::Matrix3d k = matrix3(node, key);
    if (!(k(0, 0) > 0 && k(1, 1) > 0)) fail(key, fmt::format("fx and fy must be positive (got {} and {})", k(0, 0), k(1, 1)));
    if (k(1, 0) != 0 || k(2, 0) != 0 || k(2, 1) != 0 || k(2, 2) != 1)
      fail(key, "must be [fx s cx; 0 fy cy; 0 0 1]");
    return k;
  }

  std::vector<double> distortion(const cv::FileNode& node, const std::string& key) const {
    if (node.isNone()) return {};
    int rows = 0, cols = 0;
    std::vector<double> d = matrix(node, key, rows, cols);
    if (rows != 1 && cols != 1) fail(key, fmt::format("must be a row or a column, not {}x{}", rows, cols));
    if (d.size() != 4 && d.size() != 5 && d.size() != 8 && d.size() != 12 && d.size() != 14)
      fail(key, fmt::format("OpenCV's distortion models have 4, 5, 8, 12 or 14 coefficients, not {}", d.size()));
    return d;
  }

  // A 3x3 rotation (orthonormal, determinant 1) or a Rodrigues vector.
  Eigen::Matrix3d rotation(const cv::FileNode& node, const std::string& key) const {
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

  int size(const cv::FileNode& node, const std::string& key) const {
    if (node.isNone()) return 0;
    if (!node.isInt() || int(node) < 1 || int(node) > 65535) fail(key, "must be a whole number of pixels, 1 to 65535");
    return int(node);
  }
};

CameraCalibration parse(const cv::FileStorage& fs, const std::string& name) {
  const Reader read{name};
  CameraCalibration out;
  if (const cv::FileNode units = fs["units"]; !units.isNone()) {
    if (!units.isString() || (std::string(units) != "mm" && std::string(units) != "cm" && std::string(units) != "m"))
      read.fail("units", "must be \"mm\", \"cm\" or \"m\"");
    out.units = std::string(units);
  }
  if (const cv::FileNode cameras = fs["cameras"]; !cameras.isNone()) {
    if (!cameras.isSeq()) read.fail("cameras", "must be a sequence of cameras");
    for (const cv::FileNode& node : cameras) {
      const std::string key = fmt::format("cameras[{}]", out.cameras.size());
      if (!node.isMap()) read.fail(key, "must be a map (name, camera_matrix, distortion_coefficients, rotation, translation)");
      CameraModel& c = out.cameras.emplace_back();
      c.name = node["name"].isString() ? std::string(node["name"]) : fmt::format("camera {}", out.cameras.size());
      c.width = read.size(node["image_width"], key + ".image_width");
      c.height = read.size(node["image_height"], key + ".image_height");
      c.camera_matrix = read.camera_matrix(node["camera_matrix"], key + ".camera_matrix");
      c.distortion = read.distortion(node["distortion_coefficients"], key + ".distortion_coefficients");
      c.rotation = read.rotation(node["rotation"], key + ".rotation");
      c.translation = read.vector3(node["translation"], key + ".translation");
    }
  } else if (!fs["M1"].isNone()) {  // OpenCV's stereo calibration: camera 1 is the world
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
  const bool headed = text.starts_with("%YAML") || text.starts_with("<") || text.starts_with("{");
  std::string storage = headed ? std::string(text) : std::string(kYamlHeader) + std::string(text);
  try {
    const cv::FileStorage fs(storage, cv::FileStorage::READ | cv::FileStorage::MEMORY);
    if (!fs.isOpened()) throw file_error(name, "OpenCV cannot read it as YAML, XML or JSON");
    return parse(fs, name);
  } catch (const cv::Exception& e) {
    throw opencv_error(name, e, headed ? 0 : kYamlHeaderLines);
  } catch (const std::exception& e) {
    // OpenCV 4.6's YAML reader throws std::length_error on a key with no name ("    :"),
    // found by fuzz/camera_calibration.cpp.
    throw file_error(name, fmt::format("OpenCV cannot read it as YAML, XML or JSON ({})", e.what()));
  }
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
    throw opencv_error(path.string(), e, 0);
  }
}

}  // namespace facecap::drivers::v4l2
