#pragma once
// Line and field splitting and number parsing shared by the text formats (TRC, CSV).
#include <charconv>
#include <cstdint>
#include <optional>
#include <string>
#include <string_view>
#include <vector>

#include "core/error.hpp"

namespace facecap::formats {

// An error at a line and (1-based, in characters) column of a text file.
Error text_error(const std::string& file, int64_t line, int64_t column, std::string what);

// Yields the lines of a text, accepting LF, CRLF, CR CR LF (seen in TRC exports) and
// bare CR line endings; line numbers count from 1.
class LineCursor {
 public:
  explicit LineCursor(std::string_view text);
  // False at the end of the text.
  bool next(std::string_view& line);
  int64_t line_number() const noexcept { return line_number_; }
  std::size_t offset() const noexcept { return offset_; }

 private:
  std::string_view text_;
  std::size_t offset_ = 0;
  int64_t line_number_ = 0;
  bool bare_cr_ = false;  // the text has CR but no LF: old Mac line endings
};

std::string_view trim_spaces(std::string_view s) noexcept;

// ASCII case-insensitive equality (header keys, C3D names, column names).
bool equals_ignore_case(std::string_view a, std::string_view b) noexcept;

// Splits on one delimiter; empty fields are kept.
void split_fields(std::string_view line, char delimiter, std::vector<std::string_view>& out);
// Splits on runs of spaces and tabs; no empty fields.
void split_whitespace(std::string_view line, std::vector<std::string_view>& out);

// Parses a whole field (surrounding spaces allowed, leading '+' allowed) as a number.
std::optional<double> parse_double(std::string_view field) noexcept;
std::optional<int64_t> parse_int(std::string_view field) noexcept;

// Shortest decimal text that reads back to the same float (or double).
std::string format_shortest(float value);
std::string format_shortest(double value);

}  // namespace facecap::formats
