#include "tests/fake_camera_scene.hpp"

#include <fstream>
#include <iomanip>
#include <sstream>
#include <stdexcept>

namespace facecap::test {
namespace {

constexpr const char* kMagic = "facecap fake v4l2 scene 1";
constexpr std::size_t kMaxDevices = 8;
constexpr int kMaxSide = 4096;
constexpr std::size_t kMaxSpots = 4096;  // per image

}  // namespace

void write_camera_scene(const std::filesystem::path& file, const CameraScene& scene) {
  std::ofstream out(file);
  out << std::setprecision(17) << kMagic << "\nbackground " << scene.background << " noise " << scene.noise << "\n";
  for (const SceneDevice& d : scene.devices)
    out << "device " << d.path << ' ' << d.format << ' ' << d.width << ' ' << d.height << ' ' << d.period_ns << ' '
        << d.offset_ns << "\n";
  for (std::size_t f = 0; f < scene.frames.size(); ++f)
    for (std::size_t c = 0; c < scene.frames[f].size(); ++c) {
      const SceneImage& image = scene.frames[f][c];
      out << "image " << f << ' ' << c << ' ' << image.noise_seed << ' ' << image.spots.size() << "\n";
      for (const Spot& s : image.spots)
        out << s.u << ' ' << s.v << ' ' << s.sigma_x << ' ' << s.sigma_y << ' ' << s.angle << ' ' << s.peak << "\n";
    }
  if (!out.flush()) throw std::runtime_error(file.string() + ": cannot write the camera scene");
}

CameraScene read_camera_scene(const std::filesystem::path& file) {
  std::ifstream in(file);
  if (!in) throw std::runtime_error(file.string() + ": cannot open the camera scene");
  CameraScene scene;
  std::string line;
  int line_no = 0;
  auto fail = [&](const std::string& what) -> void {
    throw std::runtime_error(file.string() + ":" + std::to_string(line_no) + ": " + what);
  };
  auto next_line = [&](const char* wanted) -> std::istringstream {
    if (!std::getline(in, line)) fail(std::string("ends where ") + wanted + " should follow");
    ++line_no;
    return std::istringstream(line);
  };
  if (next_line("the magic line").str() != kMagic) fail(std::string("is not a camera scene (no \"") + kMagic + "\")");
  std::string word1, word2;
  if (!(next_line("the background") >> word1 >> scene.background >> word2 >> scene.noise) || word1 != "background" ||
      word2 != "noise")
    fail("wants \"background <grey> noise <grey>\"");
  if (!(scene.noise >= 0)) fail("noise below 0");
  std::size_t frame = 0, camera = 0;
  while (std::getline(in, line)) {
    ++line_no;
    std::istringstream fields(line);
    std::string kind;
    fields >> kind;
    if (kind == "device") {
      if (!scene.frames.empty()) fail("a device after the images");
      if (scene.devices.size() == kMaxDevices) fail("more than 8 devices");
      SceneDevice& d = scene.devices.emplace_back();
      if (!(fields >> d.path >> d.format >> d.width >> d.height >> d.period_ns >> d.offset_ns))
        fail("wants \"device <path> <format> <width> <height> <period_ns> <offset_ns>\"");
      if (d.format != "GREY" && d.format != "YUYV" && d.format != "MJPG") fail("format " + d.format + " is not GREY, YUYV or MJPG");
      if (d.width < 1 || d.width > kMaxSide || d.height < 1 || d.height > kMaxSide)
        fail("size outside 1x1 to 4096x4096");
      if (d.period_ns <= 0 || d.offset_ns < 0) fail("wants a period > 0 and an offset >= 0");
    } else if (kind == "image") {
      std::size_t f = 0, c = 0, spots = 0;
      uint64_t seed = 0;
      if (!(fields >> f >> c >> seed >> spots)) fail("wants \"image <frame> <camera> <noise_seed> <spots>\"");
      if (scene.devices.empty()) fail("an image before any device");
      if (f != frame || c != camera) fail("images out of order: frame " + std::to_string(frame) + " camera " + std::to_string(camera) + " is next");
      if (spots > kMaxSpots) fail(std::to_string(spots) + " spots: at most 4096 an image");
      if (c == 0) scene.frames.emplace_back();
      SceneImage& image = scene.frames.back().emplace_back();
      image.noise_seed = seed;
      for (std::size_t k = 0; k < spots; ++k) {
        Spot& s = image.spots.emplace_back();
        if (!(next_line("a spot") >> s.u >> s.v >> s.sigma_x >> s.sigma_y >> s.angle >> s.peak))
          fail("wants \"<u> <v> <sigma_x> <sigma_y> <angle> <peak>\"");
        if (!(s.sigma_x > 0 && s.sigma_x < 100 && s.sigma_y > 0 && s.sigma_y < 100)) fail("sigma outside (0, 100) px");
      }
      if (++camera == scene.devices.size()) {
        camera = 0;
        ++frame;
      }
    } else if (!kind.empty()) {
      fail("unknown line \"" + kind + "\"");
    }
  }
  if (scene.frames.empty() || camera != 0) fail("wants every camera's image of at least one frame");
  return scene;
}

}  // namespace facecap::test
