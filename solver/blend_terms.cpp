#include "solver/blend_terms.hpp"

#include <algorithm>
#include <cmath>
#include <iterator>
#include <limits>

namespace facecap {

BlendTerms::Located BlendTerms::locate(int32_t entry) const noexcept {
  Located l;
  l.position = std::size_t(position_of_entry[std::size_t(entry)]);
  const auto run = std::prev(std::upper_bound(blocks.begin(), blocks.end(), int32_t(l.position),
                                              [](int32_t p, const BlockRun& r) { return p < r.first; }));
  const std::size_t entry_values = std::size_t(components) * ShapeBlocks::kBlock;
  l.values = run->values;
  int32_t k = int32_t(l.position) - run->first;
  for (; l.width + 1 < kWidths && k >= run->count[l.width]; ++l.width) {
    l.values += std::size_t(run->count[l.width]) * entry_values * std::size_t(kBytesPerValue[l.width]);
    k -= run->count[l.width];
  }
  l.values += std::size_t(k) * entry_values * std::size_t(kBytesPerValue[l.width]);
  return l;
}

double BlendTerms::stored(const Located& l, int component, int slot) const noexcept {
  const std::size_t at = l.values + (std::size_t(component) * ShapeBlocks::kBlock + std::size_t(slot)) *
                                        std::size_t(kBytesPerValue[l.width]);
  double q = 0.0;
  if (l.width == 0) {
    q = double(int8_t(values[at]));
  } else if (l.width == 1) {
    int16_t v;
    std::memcpy(&v, values.data() + at, sizeof v);
    q = double(v);
  } else {
    float v;
    std::memcpy(&v, values.data() + at, sizeof v);
    q = double(v);
  }
  const std::size_t at_component = l.position * std::size_t(components) + std::size_t(component);
  return double(offsets[at_component]) + double(half_to_float(scales[at_component]) * kScaleUnit) * q;
}

double BlendTerms::at(int32_t entry, int component, int slot) const noexcept {
  return stored(locate(entry), component, slot);
}

void BlendTerms::decode(int32_t entry, std::span<double> out) const noexcept {
  const Located l = locate(entry);
  for (int c = 0; c < components; ++c)
    for (int i = 0; i < ShapeBlocks::kBlock; ++i) out[std::size_t(c * ShapeBlocks::kBlock + i)] = stored(l, c, i);
}

float half_to_float(uint16_t h) noexcept {
  const int exponent = (h >> 10) & 0x1f, mantissa = h & 0x3ff;
  const float magnitude = exponent == 0    ? std::ldexp(float(mantissa), -24)
                          : exponent == 31 ? (mantissa ? std::numeric_limits<float>::quiet_NaN() : std::numeric_limits<float>::infinity())
                                           : std::ldexp(float(1024 + mantissa), exponent - 25);
  return (h & 0x8000) ? -magnitude : magnitude;
}

uint16_t half_at_least(float x) noexcept {
  // Positive halves grow with their bit patterns: the first one not below x.
  uint16_t low = 0, high = 0x7bff;  // 0x7bff: 65504, the largest finite half
  while (low < high) {
    const auto middle = uint16_t(low + (high - low) / 2);
    if (half_to_float(middle) < x) low = uint16_t(middle + 1);
    else high = middle;
  }
  return low;
}

int32_t ShapeBlocks::find_entry(Eigen::Index shape, int block) const noexcept {
  for (int32_t e = block_begin[std::size_t(block)]; e < block_begin[std::size_t(block) + 1]; ++e)
    if (entries[std::size_t(e)].shape == shape) return e;
  return -1;
}

void active_weights(const Eigen::VectorXd& w, double active_weight, const Eigen::VectorXd& reach, double negligible,
                    std::vector<float>& out) noexcept {
  for (Eigen::Index i = 0; i < w.size(); ++i)
    out[std::size_t(i)] = w[i] > active_weight && w[i] * reach[i] > negligible ? float(w[i]) : 0.0f;
}

}  // namespace facecap
