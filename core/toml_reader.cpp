#include "core/toml_reader.hpp"

#include <algorithm>
#include <cstdint>
#include <string>

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

// toml++ 3.3 reaches __builtin_unreachable when it tests a non-ASCII character for
// whitespace and the character lies in U+00A1..U+0499 or some other ranges (é, any
// Cyrillic letter, ...). TOML allows non-ASCII text only inside strings and comments,
// where toml++ makes that test only after a backslash in a multi-line basic string (an
// escape, or a line-ending backslash and the whitespace it trims): a non-ASCII character
// anywhere it would be tested is refused first. A quote counts as opening a string only
// where TOML allows one (a key or a value); elsewhere (`+"é"`) toml++ reads on as a bare
// value and tests every character.
void check_non_ascii_placement(std::string_view text, const std::string& name) {
  enum class State { kCode, kComment, kBasic, kLiteral, kMultiBasic, kMultiLiteral } state = State::kCode;
  bool trimming = false;  // in a multi-line basic string, after a backslash and whitespace
  char before = '\n';     // in code, the last character other than a space or tab
  int64_t line = 1, column = 1;
  for (std::size_t at = 0; at < text.size();) {
    const char c = text[at];
    const auto starts = [&](std::string_view s) { return text.substr(at, s.size()) == s; };
    std::size_t step = std::max<std::size_t>(1, utf8_sequence_length(text, at));  // text is valid UTF-8 here
    const auto refuse = [&](const char* what) {
      throw Error(what, ErrorLocation{.file = name, .line = line, .column = column});
    };
    const bool space = c == ' ' || c == '\t' || c == '\r' || c == '\n';
    switch (state) {
      case State::kCode:
        if (uint8_t(c) >= 0x80) refuse("non-ASCII character outside a string or comment (quote the text)");
        if (c == '#') {
          state = State::kComment;
        } else if ((c == '"' || c == '\'') && std::string_view("\n=[,{.").find(before) != std::string_view::npos) {
          if (starts(R"(""")")) state = State::kMultiBasic, step = 3;
          else if (starts("'''")) state = State::kMultiLiteral, step = 3;
          else state = c == '"' ? State::kBasic : State::kLiteral;
        }
        if (c != ' ' && c != '\t') before = c;
        break;
      case State::kComment:
        if (c == '\n') state = State::kCode, before = '\n';
        break;
      case State::kBasic:  // an escape skips the ASCII character after the backslash (\" does not end it)
        if (c == '\\' && at + 1 < text.size() && uint8_t(text[at + 1]) < 0x80 && text[at + 1] != '\n') step = 2;
        else if (c == '"' || c == '\n') state = State::kCode, before = c;  // unterminated: toml++ reports it
        break;
      case State::kLiteral:
        if (c == '\'' || c == '\n') state = State::kCode, before = c;
        break;
      case State::kMultiBasic:
        if (trimming) {  // toml++ tests each character for whitespace here
          if (uint8_t(c) >= 0x80) refuse("non-ASCII character in the whitespace a line-ending backslash trims");
          if (space) break;
          trimming = false;  // c is content again
        }
        if (c == '\\') {
          const char next = at + 1 < text.size() ? text[at + 1] : '\0';
          if (uint8_t(next) >= 0x80) {  // the escaped character is tested too
            ++column;
            refuse("non-ASCII character after a backslash in a multi-line string");
          }
          trimming = next == ' ' || next == '\t' || next == '\r' || next == '\n';
          step = trimming ? 1 : 2;
        } else if (starts(R"(""")")) {
          state = State::kCode, before = c, step = 3;
        }
        break;
      case State::kMultiLiteral:
        if (starts("'''")) state = State::kCode, before = c, step = 3;
        break;
    }
    for (std::size_t i = at; i < at + step && i < text.size(); ++i) {
      if (text[i] == '\n') {
        ++line;
        column = 1;
      } else if ((uint8_t(text[i]) & 0xc0) != 0x80) {
        ++column;  // characters, not bytes
      }
    }
    at += step;
  }
}

// The characters toml++ 3.3's is_non_ascii_horizontal_whitespace cannot test (its table
// sends them to __builtin_unreachable).
bool untestable_by_toml(char32_t c) noexcept {
  if (c < 0xa1 || c > 0xfefe || c == 0x3000) return false;
  const auto block = (c - 0xa0) / 0x3fa;
  return block == 0 || block == 11 || block == 63;
}

// The text with each such character replaced by '~' (one character for one, so line and
// column stay), or empty when it has none.
std::string with_untestable_replaced(std::string_view text) {
  std::string out;
  for (std::size_t at = 0; at < text.size();) {
    const std::size_t length = utf8_sequence_length(text, at);  // text is valid UTF-8 here
    char32_t c = uint8_t(text[at]);
    if (length > 1) {
      c &= 0x7fu >> length;
      for (std::size_t i = 1; i < length; ++i) c = (c << 6) | (uint8_t(text[at + i]) & 0x3fu);
    }
    if (untestable_by_toml(c)) {
      if (out.empty()) out.assign(text.substr(0, at));
      out += '~';
    } else if (!out.empty()) {
      out.append(text.substr(at, length));
    }
    at += length;
  }
  return out;
}

toml::table parse_or_throw(std::string_view text, const std::string& name) {
  try {
    return toml::parse(text, name);
  } catch (const toml::parse_error& e) {
    const auto& begin = e.source().begin;
    throw Error(std::string(e.description()),
                ErrorLocation{.file = name, .line = int64_t(begin.line), .column = int64_t(begin.column)});
  }
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
  check_non_ascii_placement(text, name);
  // The scan cannot see every place invalid TOML makes toml++ test a character (it reads
  // `x = +="é"` on as one bare value): the text with those characters replaced by '~'
  // must parse first. Then they sit where toml++ never tests them but for what the scan
  // refused.
  if (const std::string stand_in = with_untestable_replaced(text); !stand_in.empty()) parse_or_throw(stand_in, name);
  return parse_or_throw(text, name);
}

toml::table parse_toml_file(const std::filesystem::path& path) {
  const std::vector<char> bytes = read_file_bytes(path);
  return parse_toml(std::string_view(bytes.data(), bytes.size()), path.string());
}

}  // namespace facecap
