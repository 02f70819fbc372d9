#include "tests/marker_drawing.hpp"

#include <algorithm>
#include <cmath>

namespace facecap::test {
namespace {

// Adds one spot to `image`, out to 4 sigma.
void add_spot(const Spot& s, int width, int height, float* image) {
  const int reach = int(std::ceil(4 * std::max(s.sigma_x, s.sigma_y)));
  const double c = std::cos(s.angle), n = std::sin(s.angle);
  for (int y = int(std::floor(s.v)) - reach; y <= int(std::ceil(s.v)) + reach; ++y) {
    if (y < 0 || y >= height) continue;
    float* row = image + std::ptrdiff_t(y) * width;
    for (int x = int(std::floor(s.u)) - reach; x <= int(std::ceil(s.u)) + reach; ++x) {
      if (x < 0 || x >= width) continue;
      const double a = c * (x - s.u) + n * (y - s.v), b = -n * (x - s.u) + c * (y - s.v);
      row[x] += float(s.peak * std::exp(-0.5 * (a * a / (s.sigma_x * s.sigma_x) + b * b / (s.sigma_y * s.sigma_y))));
    }
  }
}

}  // namespace

void draw_spots(std::span<const Spot> spots, float background, int width, int height, float* image) {
  std::fill_n(image, std::ptrdiff_t(width) * height, background);
  for (const Spot& s : spots) add_spot(s, width, height, image);
}

void to_grey(const float* image, std::span<const float> noise, int width, int height, uint8_t* grey, int stride) {
  for (int y = 0; y < height; ++y) {
    const std::ptrdiff_t at = std::ptrdiff_t(y) * width;
    for (int x = 0; x < width; ++x) {
      const float value = noise.empty() ? image[at + x] : image[at + x] + noise[std::size_t(at + x)];
      grey[std::ptrdiff_t(y) * stride + x] = uint8_t(std::clamp<long>(std::lrint(value), 0, 255));
    }
  }
}

}  // namespace facecap::test
