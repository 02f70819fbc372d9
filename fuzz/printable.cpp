// libFuzzer target: core/printable.hpp, which every log line and the NatNet source's shown
// text pass through. Its output must hold no control byte, be valid UTF-8 (checked here
// with iconv, independently of its own decoder) and come back unchanged from a second pass.
#include <cstdint>
#include <cstdlib>
#include <string>

#include <iconv.h>

#include "core/printable.hpp"
#include "fuzz/fuzz_support.hpp"

namespace {

bool valid_utf8(const std::string& text) {
  static const iconv_t check = iconv_open("UTF-8", "UTF-8");
  iconv(check, nullptr, nullptr, nullptr, nullptr);
  std::string in = text, out(text.size() * 4 + 4, '\0');
  char* from = in.data();
  char* to = out.data();
  std::size_t from_left = in.size(), to_left = out.size();
  return iconv(check, &from, &from_left, &to, &to_left) != std::size_t(-1) && from_left == 0;
}

}  // namespace

extern "C" int LLVMFuzzerTestOneInput(const uint8_t* data, std::size_t size) {
  const std::string shown = facecap::printable(facecap::fuzz::text_of(data, size));
  for (const char c : shown)
    if (uint8_t(c) < 0x20 || uint8_t(c) == 0x7f) std::abort();
  if (!valid_utf8(shown)) std::abort();
  if (facecap::printable(shown) != shown) std::abort();
  return 0;
}
