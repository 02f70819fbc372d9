#include "tools/label_swap.hpp"

#include <algorithm>
#include <charconv>

#include <fmt/format.h>

#include "core/error.hpp"

namespace facecap::tools {

LabelSwap parse_label_swap(const std::string& spec) {
  std::vector<std::string> parts;
  std::size_t begin = 0;
  for (std::size_t colon; (colon = spec.find(':', begin)) != std::string::npos; begin = colon + 1)
    parts.push_back(spec.substr(begin, colon - begin));
  parts.push_back(spec.substr(begin));
  if (parts.size() < 4 || parts.size() > 5 || parts[0].empty() || parts[1].empty())
    throw Error(fmt::format("label swap '{}': expected FIRST:SECOND:START:FRAMES[:GLIDE]", spec));
  auto number = [&](const std::string& s, const char* what) {
    std::size_t value = 0;
    const auto [end, ec] = std::from_chars(s.data(), s.data() + s.size(), value);
    if (ec != std::errc() || end != s.data() + s.size()) throw Error(fmt::format("label swap '{}': {} '{}' is not a count", spec, what, s));
    return value;
  };
  LabelSwap swap{parts[0], parts[1], number(parts[2], "START"), number(parts[3], "FRAMES"),
                 parts.size() == 5 ? number(parts[4], "GLIDE") : 0};
  if (swap.frames == 0 || 2 * swap.glide > swap.frames)
    throw Error(fmt::format("label swap '{}': FRAMES must be at least 1 and at least twice GLIDE", spec));
  return swap;
}

void inject_label_swap(formats::MarkerTake& take, const LabelSwap& swap) {
  auto slot = [&](const std::string& label) {
    const auto it = std::find(take.labels.begin(), take.labels.end(), label);
    if (it == take.labels.end()) throw Error(fmt::format("label swap: the take has no marker '{}'", label));
    return std::size_t(it - take.labels.begin());
  };
  const std::size_t a = slot(swap.first), b = slot(swap.second);
  if (swap.start + swap.frames > take.frames.size())
    throw Error(fmt::format("label swap {}:{}: frames {} to {} outside the take's {}", swap.first, swap.second, swap.start,
                            swap.start + swap.frames - 1, take.frames.size()));
  for (std::size_t i = 0; i < swap.frames; ++i) {
    auto& markers = take.frames[swap.start + i].markers;
    if (a >= markers.size() || b >= markers.size() || !markers[a].present() || !markers[b].present()) continue;
    // How far each has gone towards the other's place: 0 -> 1 over the first glide, back at the end.
    const std::size_t from_end = swap.frames - 1 - i;
    const double t = swap.glide == 0 ? 1.0 : std::min(1.0, double(std::min(i, from_end) + 1) / double(swap.glide + 1));
    const Eigen::Vector3d pa = markers[a].position, pb = markers[b].position;
    markers[a].position = (1.0 - t) * pa + t * pb;
    markers[b].position = (1.0 - t) * pb + t * pa;
  }
}

}  // namespace facecap::tools
