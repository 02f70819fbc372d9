// libFuzzer target: camera calibration files as the v4l2 driver reads them
// (drivers/v4l2/camera_calibration.hpp: OpenCV-style YAML read by our own parser of the
// subset, calibration_yaml.hpp). Bad input must give facecap::Error and nothing else; a
// calibration that parses must be written (by cv::FileStorage) and read back to the same
// cameras.
#include <cstdlib>
#include <filesystem>

#include <unistd.h>

#include "drivers/v4l2/camera_calibration.hpp"
#include "fuzz/fuzz_support.hpp"

extern "C" int LLVMFuzzerTestOneInput(const uint8_t* data, size_t size) {
  using namespace facecap::drivers::v4l2;
  return facecap::fuzz::parse_refusing_errors([&] {
    const CameraCalibration calibration = parse_camera_calibration(facecap::fuzz::text_of(data, size), "fuzz.yaml");
    static const std::filesystem::path scratch =
        std::filesystem::temp_directory_path() / ("fuzz-camera-calibration-" + std::to_string(getpid()) + ".yaml");
    write_camera_calibration(scratch, calibration);
    const CameraCalibration back = read_camera_calibration(scratch);
    if (back.cameras.size() != calibration.cameras.size() || back.units != calibration.units) std::abort();
    for (std::size_t c = 0; c < back.cameras.size(); ++c)
      if (back.cameras[c].distortion != calibration.cameras[c].distortion ||
          !back.cameras[c].camera_matrix.isApprox(calibration.cameras[c].camera_matrix, 1e-12))
        std::abort();
  });
}
