#include "formats/byte_io.hpp"

#include <cmath>
#include <limits>

#include <fmt/format.h>

namespace facecap::formats {

float vax_f_to_float(const unsigned char b[4]) noexcept {
  // VAX F_floating is two little-endian 16-bit words: the first holds sign, 8-bit
  // exponent (bias 128) and the top 7 mantissa bits, the second the low 16 bits.
  // Value = 0.1m * 2^(e-128) = 1.m * 2^(e-129).
  const uint32_t high = uint32_t(b[0]) | (uint32_t(b[1]) << 8);
  const uint32_t low = uint32_t(b[2]) | (uint32_t(b[3]) << 8);
  const bool negative = (high & 0x8000u) != 0;
  const int exponent = int((high >> 7) & 0xffu);
  const uint32_t mantissa = ((high & 0x7fu) << 16) | low;
  if (exponent == 0) return negative ? std::numeric_limits<float>::quiet_NaN() : 0.0f;  // reserved operand
  const double magnitude = std::ldexp(1.0 + double(mantissa) / double(1u << 23), exponent - 129);
  return static_cast<float>(negative ? -magnitude : magnitude);
}

void ByteReader::fail_at(std::size_t offset, std::string what) const {
  throw offset_error(name_, static_cast<int64_t>(offset), std::move(what));
}

void ByteReader::require(std::size_t count, std::string_view what) const {
  if (count > remaining()) {
    fail(fmt::format("unexpected end of data reading {} ({} bytes needed, {} left of {})", what, count, remaining(),
                     bytes_.size()));
  }
}

void ByteReader::seek(std::size_t offset, std::string_view what) {
  if (offset > bytes_.size()) {
    fail(fmt::format("{} at byte {} lies past the end of the data ({} bytes)", what, offset, bytes_.size()));
  }
  offset_ = offset;
}

uint8_t ByteReader::u8(std::string_view what) {
  require(1, what);
  return static_cast<uint8_t>(bytes_[offset_++]);
}

uint16_t ByteReader::u16(std::string_view what) {
  require(2, what);
  const auto* p = reinterpret_cast<const unsigned char*>(bytes_.data() + offset_);
  offset_ += 2;
  return order_ == ByteOrder::kLittle ? uint16_t(p[0] | (p[1] << 8)) : uint16_t((p[0] << 8) | p[1]);
}

uint32_t ByteReader::u32(std::string_view what) {
  require(4, what);
  const auto* p = reinterpret_cast<const unsigned char*>(bytes_.data() + offset_);
  offset_ += 4;
  if (order_ == ByteOrder::kLittle) {
    return uint32_t(p[0]) | (uint32_t(p[1]) << 8) | (uint32_t(p[2]) << 16) | (uint32_t(p[3]) << 24);
  }
  return (uint32_t(p[0]) << 24) | (uint32_t(p[1]) << 16) | (uint32_t(p[2]) << 8) | uint32_t(p[3]);
}

uint64_t ByteReader::u64(std::string_view what) {
  const uint64_t first = u32(what);
  const uint64_t second = u32(what);
  return order_ == ByteOrder::kLittle ? (first | (second << 32)) : ((first << 32) | second);
}

float ByteReader::f32(std::string_view what) {
  if (reals_ == RealFormat::kVax) {
    require(4, what);
    const auto* p = reinterpret_cast<const unsigned char*>(bytes_.data() + offset_);
    offset_ += 4;
    return vax_f_to_float(p);
  }
  return std::bit_cast<float>(u32(what));
}

double ByteReader::f64(std::string_view what) { return std::bit_cast<double>(u64(what)); }

std::string_view ByteReader::bytes(std::size_t count, std::string_view what) {
  require(count, what);
  std::string_view out(bytes_.data() + offset_, count);
  offset_ += count;
  return out;
}

}  // namespace facecap::formats
