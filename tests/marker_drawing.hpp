#pragma once
// Synthetic IR images drawn from a list of Gaussian spots (markers' glows, a reflection's
// streak), with the C++ library only: shared by the in-process renderer
// (synthetic_cameras.cpp, which projects the markers with OpenCV) and the preloaded fake
// V4L2 cameras (fake_v4l2_preload.cpp, which must not link OpenCV), so that both draw
// the same images the same way.
#include <cstdint>
#include <span>

namespace facecap::test {

// A Gaussian of `peak` grey levels at (u, v) px; sigma_x and sigma_y along `angle`
// (radians) for a streak, equal for a round marker.
struct Spot {
  double u = 0, v = 0;
  double sigma_x = 1, sigma_y = 1, angle = 0;
  double peak = 0;
};

// `image` (width x height floats, row after row) set to `background` plus every spot.
void draw_spots(std::span<const Spot> spots, float background, int width, int height, float* image);

// `image` plus `noise` (one value per pixel, or empty for none) to 8-bit grey, `stride`
// bytes a row: rounded to nearest (ties to even) and saturated, as OpenCV's convertTo does.
void to_grey(const float* image, std::span<const float> noise, int width, int height, uint8_t* grey, int stride);

}  // namespace facecap::test
