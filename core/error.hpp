#pragma once
// The error type of everything that is not on the real-time path: it says what went
// wrong and where (file, line, byte offset, key), so an operator can fix the input.
#include <cstdint>
#include <stdexcept>
#include <string>

namespace facecap {

struct ErrorLocation {
  std::string file;        // path or logical source ("config", "udp:1511")
  int64_t line = -1;       // 1-based, -1 when not meaningful
  int64_t column = -1;     // 1-based
  int64_t offset = -1;     // byte offset, -1 when not meaningful
  std::string key;         // config key path, chunk name, field
  std::string to_string() const;  // "file:line:col", "file @ byte N", "file [key]"
};

class Error : public std::runtime_error {
 public:
  Error(std::string what, ErrorLocation where = {});
  const std::string& message() const noexcept { return message_; }
  const ErrorLocation& where() const noexcept { return where_; }

 private:
  std::string message_;
  ErrorLocation where_;
};

// Convenience constructors for the common locations.
Error file_error(const std::string& file, std::string what);
Error line_error(const std::string& file, int64_t line, std::string what);
Error offset_error(const std::string& file, int64_t offset, std::string what);

}  // namespace facecap
