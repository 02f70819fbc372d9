#include "core/error.hpp"

#include <fmt/format.h>

namespace facecap {

std::string ErrorLocation::to_string() const {
  std::string out = file;
  if (line >= 0) {
    out += fmt::format(":{}", line);
    if (column >= 0) out += fmt::format(":{}", column);
  }
  if (offset >= 0) out += fmt::format(" @ byte {}", offset);
  if (!key.empty()) out += fmt::format(" [{}]", key);
  return out;
}

static std::string compose(const std::string& what, const ErrorLocation& where) {
  const std::string loc = where.to_string();
  return loc.empty() ? what : loc + ": " + what;
}

Error::Error(std::string what, ErrorLocation where)
    : std::runtime_error(compose(what, where)), message_(std::move(what)), where_(std::move(where)) {}

Error file_error(const std::string& file, std::string what) {
  return Error(std::move(what), ErrorLocation{.file = file});
}
Error line_error(const std::string& file, int64_t line, std::string what) {
  return Error(std::move(what), ErrorLocation{.file = file, .line = line});
}
Error offset_error(const std::string& file, int64_t offset, std::string what) {
  return Error(std::move(what), ErrorLocation{.file = file, .offset = offset});
}

}  // namespace facecap
