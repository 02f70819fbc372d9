#pragma once
// What fake V4L2 cameras preloaded into another process (fake_v4l2_preload.cpp) stream:
// their devices and, per frame and camera, the spots to draw (marker_drawing.hpp). The
// test process projects the markers and writes the scene; the preload reads it at load
// time. C++ library only, as the preload links nothing else. A text file:
//
//   facecap fake v4l2 scene 1
//   background <grey> noise <standard deviation, grey levels>
//   device <path> <GREY|YUYV|MJPG> <width> <height> <period_ns> <offset_ns>    (one per camera)
//   image <frame> <camera> <noise_seed> <spot count>                         (frames 0, 1, ... in order)
//   <u> <v> <sigma_x> <sigma_y> <angle> <peak>                               (that many spot lines)
#include <cstdint>
#include <filesystem>
#include <string>
#include <vector>

#include "tests/marker_drawing.hpp"

namespace facecap::test {

struct SceneDevice {
  std::string path;
  std::string format = "GREY";  // GREY, YUYV or MJPG
  int width = 640, height = 480;
  int64_t period_ns = 0;
  int64_t offset_ns = 0;        // after the grid of frame times (fake_v4l2::Device::offset_ns)
};

struct SceneImage {
  uint64_t noise_seed = 0;      // which noise this image gets
  std::vector<Spot> spots;
};

struct CameraScene {
  float background = 12;
  float noise = 2;
  std::vector<SceneDevice> devices;
  std::vector<std::vector<SceneImage>> frames;  // [frame][camera]
};

// Writes spots exactly (17 significant digits), so that the reader draws what was meant.
void write_camera_scene(const std::filesystem::path& file, const CameraScene& scene);
// Throws std::runtime_error naming the file and line of what is wrong.
CameraScene read_camera_scene(const std::filesystem::path& file);

}  // namespace facecap::test
