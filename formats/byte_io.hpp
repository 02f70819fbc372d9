#pragma once
// Bounds-checked binary reading and little-endian writing, shared by every binary
// format (C3D, recordings). Every read checks the buffer end, so a parser built on
// ByteReader cannot read out of bounds on any input; failures throw Error naming the
// source and the byte offset.
#include <algorithm>
#include <bit>
#include <cstdint>
#include <cstring>
#include <span>
#include <string>
#include <string_view>
#include <vector>

#include "core/error.hpp"

namespace facecap::formats {

enum class ByteOrder : uint8_t { kLittle, kBig };

// How 32-bit reals are stored. C3D files from DEC (VAX) machines use VAX F_floating.
enum class RealFormat : uint8_t { kIeee, kVax };

// Decodes 4 bytes in VAX F_floating layout (as stored in a file) to an IEEE float.
float vax_f_to_float(const unsigned char bytes[4]) noexcept;

class ByteReader {
 public:
  ByteReader(std::span<const char> bytes, std::string name, ByteOrder order = ByteOrder::kLittle,
             RealFormat reals = RealFormat::kIeee)
      : bytes_(bytes), name_(std::move(name)), order_(order), reals_(reals) {}

  void set_encoding(ByteOrder order, RealFormat reals) noexcept {
    order_ = order;
    reals_ = reals;
  }

  std::size_t size() const noexcept { return bytes_.size(); }
  std::size_t offset() const noexcept { return offset_; }
  std::size_t remaining() const noexcept { return bytes_.size() - offset_; }
  const std::string& name() const noexcept { return name_; }
  std::span<const char> buffer() const noexcept { return bytes_; }

  // Moves to an absolute offset (may equal size()); throws past the end.
  void seek(std::size_t offset, std::string_view what = "position");
  void skip(std::size_t count, std::string_view what = "field") {
    require(count, what);
    offset_ += count;
  }
  // Throws unless count more bytes are available at the current offset.
  void require(std::size_t count, std::string_view what) const;
  bool has(std::size_t count) const noexcept { return count <= remaining(); }

  uint8_t u8(std::string_view what = "byte");
  int8_t i8(std::string_view what = "byte") { return static_cast<int8_t>(u8(what)); }
  uint16_t u16(std::string_view what = "16-bit word");
  int16_t i16(std::string_view what = "16-bit word") { return static_cast<int16_t>(u16(what)); }
  uint32_t u32(std::string_view what = "32-bit word");
  int32_t i32(std::string_view what = "32-bit word") { return static_cast<int32_t>(u32(what)); }
  uint64_t u64(std::string_view what = "64-bit word");
  int64_t i64(std::string_view what = "64-bit word") { return static_cast<int64_t>(u64(what)); }
  float f32(std::string_view what = "real");
  double f64(std::string_view what = "double");
  std::string_view bytes(std::size_t count, std::string_view what = "bytes");

  // Throws an Error at the current offset (or the given one) naming the source.
  [[noreturn]] void fail(std::string what) const { fail_at(offset_, std::move(what)); }
  [[noreturn]] void fail_at(std::size_t offset, std::string what) const;

 private:
  std::span<const char> bytes_;
  std::string name_;
  std::size_t offset_ = 0;
  ByteOrder order_;
  RealFormat reals_;
};

// Appends values to a byte vector, little-endian (our own formats, the C3D files we
// write) unless told big-endian (network formats: Live Link, OSC).
class ByteWriter {
 public:
  explicit ByteWriter(std::vector<char>& out, ByteOrder order = ByteOrder::kLittle) : out_(out), order_(order) {}
  std::size_t size() const noexcept { return out_.size(); }
  void u8(uint8_t v) { out_.push_back(static_cast<char>(v)); }
  void i8(int8_t v) { u8(static_cast<uint8_t>(v)); }
  void u16(uint16_t v) { put(v); }
  void i16(int16_t v) { put(v); }
  void u32(uint32_t v) { put(v); }
  void i32(int32_t v) { put(v); }
  void u64(uint64_t v) { put(v); }
  void i64(int64_t v) { put(v); }
  void f32(float v) { put(v); }
  void f64(double v) { put(v); }
  void bytes(std::string_view s) { out_.insert(out_.end(), s.begin(), s.end()); }
  void zeros(std::size_t count) { out_.insert(out_.end(), count, '\0'); }
  // Overwrites a value written earlier (sizes and offsets known only later, or a value
  // slot of a packet encoded once and refreshed per frame). RT-safe.
  template <typename T>
  void patch(std::size_t offset, T value) noexcept {
    store(out_.data() + offset, value);
  }

 private:
  template <typename T>
  void put(T v) {
    const auto at = out_.size();
    out_.resize(at + sizeof(T));
    store(out_.data() + at, v);
  }
  template <typename T>
  void store(char* at, T v) const noexcept {
    static_assert(std::endian::native == std::endian::little, "facecap assumes a little-endian host");
    char bytes[sizeof(T)];
    std::memcpy(bytes, &v, sizeof(T));
    if (order_ == ByteOrder::kBig) std::reverse(bytes, bytes + sizeof(T));
    std::memcpy(at, bytes, sizeof(T));
  }
  std::vector<char>& out_;
  ByteOrder order_;
};

}  // namespace facecap::formats
