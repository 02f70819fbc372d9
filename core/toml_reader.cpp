#include "core/toml_reader.hpp"

#include <cstdint>

#include <fmt/format.h>

#include "core/error.hpp"
#include "core/io.hpp"

namespace facecap {
namespace {

// Length of the well-formed UTF-8 sequence starting at text[at], 0 when it is not one
// (Unicode 15, table 3-7).
std::size_t utf8_sequence_length(std::string_view text, std::size_t at) noexcept {
  const auto byte = [&](std::size_t i) { return at + i < text.size() ? uint8_t(text[at + i]) : uint8_t(0); };
  const auto in = [](uint8_t b, uint8_t lo, uint8_t hi) { return b >= lo && b <= hi; };
  const uint8_t b0 = byte(0);
  if (b0 < 0x80) return 1;
  if (in(b0, 0xc2, 0xdf)) return in(byte(1), 0x80, 0xbf) ? 2 : 0;
  if (in(b0, 0xe0, 0xef)) {
    const uint8_t lo = b0 == 0xe0 ? 0xa0 : 0x80, hi = b0 == 0xed ? 0x9f : 0xbf;
    return in(byte(1), lo, hi) && in(byte(2), 0x80, 0xbf) ? 3 : 0;
  }
  if (in(b0, 0xf0, 0xf4)) {
    const uint8_t lo = b0 == 0xf0 ? 0x90 : 0x80, hi = b0 == 0xf4 ? 0x8f : 0xbf;
    return in(byte(1), lo, hi) && in(byte(2), 0x80, 0xbf) && in(byte(3), 0x80, 0xbf) ? 4 : 0;
  }
  return 0;
}

}  // namespace

void check_utf8(std::string_view text, const std::string& name) {
  int64_t line = 1, column = 1;
  for (std::size_t at = 0; at < text.size();) {
    const std::size_t length = utf8_sequence_length(text, at);
    if (length == 0) {
      throw Error(fmt::format("byte 0x{:02x} (at byte offset {}) is not valid UTF-8", uint8_t(text[at]), at),
                  ErrorLocation{.file = name, .line = line, .column = column});
    }
    if (text[at] == '\n') {
      ++line;
      column = 1;
    } else {
      ++column;
    }
    at += length;
  }
}

toml::table parse_toml(std::string_view text, const std::string& name) {
  check_utf8(text, name);
  try {
    return toml::parse(text, name);
  } catch (const toml::parse_error& e) {
    const auto& begin = e.source().begin;
    throw Error(std::string(e.description()),
                ErrorLocation{.file = name, .line = int64_t(begin.line), .column = int64_t(begin.column)});
  }
}

toml::table parse_toml_file(const std::filesystem::path& path) {
  const std::vector<char> bytes = read_file_bytes(path);
  return parse_toml(std::string_view(bytes.data(), bytes.size()), path.string());
}

}  // namespace facecap
