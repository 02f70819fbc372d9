// Fake V4L2 cameras inside a process that knows nothing of them: fake_v4l2.cpp built as a
// module that facecapd is started with (LD_PRELOAD), its devices registered when the module
// loads from the scene file FACECAP_FAKE_V4L2_SCENE names (fake_camera_scene.hpp), each
// frame drawn from its spots at VIDIOC_DQBUF (marker_drawing.hpp). Frame `sequence` of a
// camera is the scene's frame `sequence` modulo the scene's length. With
// FACECAP_FAKE_V4L2_LOG, one line per frame handed out, "<camera> <sequence>
// <timestamp_ns>", so that the test maps the frames the process saw to the scene's. Links
// the C++ library and libjpeg (MJPEG) only: no OpenCV, no facecap library. A scene that
// does not read ends the process at load, saying why.
#include <algorithm>
#include <cstdio>
#include <cstdlib>
#include <exception>
#include <random>
#include <string>
#include <vector>

#include <fcntl.h>
#include <linux/videodev2.h>
#include <unistd.h>

#include "tests/fake_camera_scene.hpp"
#include "tests/fake_v4l2.hpp"
#include "tests/marker_drawing.hpp"

namespace facecap::test {
namespace {

// The sensor noise: one table of normal deviates, each image taking it from an offset
// chosen by its noise seed (drawing 300,000 deviates per image would cost more than the rest).
constexpr std::size_t kNoiseOffsets = 1 << 16;

struct Preloaded {
  CameraScene scene;
  std::vector<float> noise;
  std::vector<std::vector<float>> canvas;  // per camera, its float image
  int log_fd = -1;
};

Preloaded& preloaded() {
  static Preloaded instance;
  return instance;
}

uint32_t fourcc_of(const std::string& format) {
  if (format == "YUYV") return V4L2_PIX_FMT_YUYV;
  if (format == "MJPG") return V4L2_PIX_FMT_MJPEG;
  return V4L2_PIX_FMT_GREY;
}

// Draws camera `camera`'s image of frame `sequence`. Called by the fake under its lock.
void draw(std::size_t camera, int64_t sequence, uint8_t* grey, int stride) {
  Preloaded& p = preloaded();
  const SceneDevice& device = p.scene.devices[camera];
  const SceneImage& image = p.scene.frames[std::size_t(sequence) % p.scene.frames.size()][camera];
  std::vector<float>& canvas = p.canvas[camera];
  draw_spots(image.spots, p.scene.background, device.width, device.height, canvas.data());
  const std::size_t offset = std::size_t((image.noise_seed * 0x9E3779B97F4A7C15ull) >> 48) % kNoiseOffsets;
  to_grey(canvas.data(), std::span<const float>(p.noise).subspan(offset, canvas.size()), device.width, device.height,
          grey, stride);
}

void log_frame(std::size_t camera, int64_t sequence, int64_t timestamp_ns) {
  const int fd = preloaded().log_fd;
  if (fd < 0) return;
  char line[80];
  const int n = std::snprintf(line, sizeof line, "%zu %lld %lld\n", camera, static_cast<long long>(sequence),
                              static_cast<long long>(timestamp_ns));
  if (::write(fd, line, std::size_t(n)) != n) std::perror("facecap fake v4l2: writing the frame log");
}

__attribute__((constructor)) void register_scene_devices() {
  const char* scene_file = std::getenv("FACECAP_FAKE_V4L2_SCENE");
  if (!scene_file) return;
  Preloaded& p = preloaded();
  try {
    p.scene = read_camera_scene(scene_file);
  } catch (const std::exception& e) {
    std::fprintf(stderr, "facecap fake v4l2: %s\n", e.what());
    std::_Exit(3);
  }
  if (const char* log = std::getenv("FACECAP_FAKE_V4L2_LOG")) {
    p.log_fd = ::open(log, O_WRONLY | O_CREAT | O_TRUNC | O_APPEND | O_CLOEXEC, 0644);
    if (p.log_fd < 0) {
      std::fprintf(stderr, "facecap fake v4l2: cannot write the frame log %s\n", log);
      std::_Exit(3);
    }
  }
  std::size_t largest = 0;
  for (const SceneDevice& d : p.scene.devices) {
    p.canvas.emplace_back(std::size_t(d.width) * std::size_t(d.height));
    largest = std::max(largest, p.canvas.back().size());
  }
  p.noise.assign(largest + kNoiseOffsets, 0.0f);
  if (p.scene.noise > 0) {
    std::mt19937 rng(1);
    std::normal_distribution<float> deviate(0.0f, p.scene.noise);
    for (float& n : p.noise) n = deviate(rng);
  }
  for (std::size_t k = 0; k < p.scene.devices.size(); ++k) {
    const SceneDevice& d = p.scene.devices[k];
    fake_v4l2::add({.path = d.path,
                    .fourcc = fourcc_of(d.format),
                    .width = d.width,
                    .height = d.height,
                    .period_ns = d.period_ns,
                    .offset_ns = d.offset_ns,
                    .render = [k](int64_t sequence, uint8_t* grey, int stride) { draw(k, sequence, grey, stride); },
                    .dequeued = [k](int64_t sequence, int64_t timestamp_ns) { log_frame(k, sequence, timestamp_ns); }});
  }
}

}  // namespace
}  // namespace facecap::test
