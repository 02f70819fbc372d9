#include "core/printable.hpp"

#include <cstdint>

namespace facecap {
namespace {

// The length of the valid UTF-8 sequence at text[i] (RFC 3629: no overlongs, surrogates
// or code points above U+10FFFF), 0 when there is none.
std::size_t utf8_length(std::string_view text, std::size_t i) {
  const auto byte = [&](std::size_t k) { return uint8_t(text[i + k]); };
  const auto continuation = [&](std::size_t k) { return i + k < text.size() && (byte(k) & 0xc0) == 0x80; };
  const uint8_t b = byte(0);
  if (b < 0x80) return 1;
  if (b >= 0xc2 && b <= 0xdf) return continuation(1) ? 2 : 0;
  if (b >= 0xe0 && b <= 0xef) {
    if (!continuation(1) || !continuation(2)) return 0;
    if ((b == 0xe0 && byte(1) < 0xa0) || (b == 0xed && byte(1) > 0x9f)) return 0;  // overlong, surrogate
    return 3;
  }
  if (b >= 0xf0 && b <= 0xf4) {
    if (!continuation(1) || !continuation(2) || !continuation(3)) return 0;
    if ((b == 0xf0 && byte(1) < 0x90) || (b == 0xf4 && byte(1) > 0x8f)) return 0;  // overlong, > U+10FFFF
    return 4;
  }
  return 0;
}

void append_escaped(uint8_t b, std::string& out) {
  constexpr char kHex[] = "0123456789abcdef";
  out += "\\x";
  out += kHex[b >> 4];
  out += kHex[b & 0xf];
}

}  // namespace

void append_printable(std::string_view text, std::string& out) {
  for (std::size_t i = 0; i < text.size();) {
    const uint8_t b = uint8_t(text[i]);
    const std::size_t n = utf8_length(text, i);
    // C1 controls are U+0080..U+009F: 0xc2 0x80..0x9f (some terminals take U+009B as CSI).
    const bool control = n == 1 ? (b < 0x20 || b == 0x7f) : n == 2 && b == 0xc2 && uint8_t(text[i + 1]) < 0xa0;
    if (n == 0 || control) {
      for (std::size_t k = 0; k < (n == 0 ? 1 : n); ++k) append_escaped(uint8_t(text[i + k]), out);
      i += n == 0 ? 1 : n;
    } else {
      out.append(text.substr(i, n));
      i += n;
    }
  }
}

std::string printable(std::string_view text) {
  std::string out;
  out.reserve(text.size());
  append_printable(text, out);
  return out;
}

}  // namespace facecap
