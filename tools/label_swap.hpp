#pragma once
// Label swaps injected into a labelled take, for measuring what a swap does to a solve
// (facecap eval --inject-swap, the tests): two markers trade labels over a span of
// frames, gliding from their own places to each other's over `glide` frames at each end
// (0: a jump), as a slow swap by a labelling system glides.
#include <string>

#include "formats/take.hpp"

namespace facecap::tools {

struct LabelSwap {
  std::string first, second;  // labels
  std::size_t start = 0;      // first frame swapped
  std::size_t frames = 0;     // frames swapped (the glides included)
  std::size_t glide = 0;      // frames of gliding at each end
};

// "A:B:START:FRAMES[:GLIDE]". Throws Error naming what is wrong.
LabelSwap parse_label_swap(const std::string& spec);

// Applies the swap to take (a marker missing in a frame stays missing). Throws Error for
// a label the take lacks or a span outside it.
void inject_label_swap(formats::MarkerTake& take, const LabelSwap& swap);

}  // namespace facecap::tools
