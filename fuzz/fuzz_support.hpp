#pragma once
// What every fuzz target shares: bytes as a span or text, and the one outcome that is not
// a finding. facecap's Error is how a parser refuses bad input; anything else escaping
// (std::bad_alloc, std::out_of_range, ...) reaches libFuzzer, which reports it as a crash,
// as it does sanitizer reports and timeouts.
#include <cstddef>
#include <cstdint>
#include <span>
#include <string_view>

#include "core/error.hpp"

namespace facecap::fuzz {

inline std::span<const char> bytes_of(const uint8_t* data, std::size_t size) {
  return {reinterpret_cast<const char*>(data), size};
}
inline std::string_view text_of(const uint8_t* data, std::size_t size) {
  return {reinterpret_cast<const char*>(data), size};
}

template <typename Parse>
int parse_refusing_errors(Parse&& parse) {
  try {
    parse();
  } catch (const Error&) {
  }
  return 0;
}

}  // namespace facecap::fuzz
