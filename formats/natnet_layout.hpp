#pragma once
// Private to formats/natnet*.cpp. Each NatNet layout is written once, as a function
// template over an IO that is either Reading (bytes -> fields) or Writing (fields ->
// bytes), so the parser and the encoder cannot disagree about a single byte:
//
//   template <class IO, class Body>  // Body is const for Writing
//   void echo_layout(IO& io, Body& echo) { io.value(echo.client_time, "client time"); }
#include <array>
#include <cstdint>
#include <string>
#include <string_view>
#include <type_traits>
#include <vector>

#include <fmt/format.h>

#include "core/error.hpp"
#include "formats/byte_io.hpp"
#include "formats/natnet.hpp"

namespace facecap::formats::natnet::detail {

// Which optional parts a bitstream carries (PacketClient.cpp, NatNet SDK 4.3).
struct Layout {
  explicit Layout(Version v)
      : byte_counts(v >= kBitstream41),
        assets(v >= kBitstream41),
        precision_timestamp(v >= kBitstream41),
        rigid_body_marker_names(v >= kBitstream40),
        rigid_body_rotation(v >= kBitstream42) {}
  bool byte_counts;              // i32 byte count after each frame section's count and each description's type
  bool assets;                   // frame and description sections for assets
  bool precision_timestamp;      // u32 seconds, u32 fraction before the frame params
  bool rigid_body_marker_names;  // rigid-body descriptions name their markers
  bool rigid_body_rotation;      // rigid-body descriptions carry a rotation from the parent
};

class Reading {
 public:
  static constexpr bool kReading = true;
  explicit Reading(ByteReader& in) : in_(in) {}
  ByteReader& reader() noexcept { return in_; }

  template <typename T>
  void value(T& v, std::string_view what) {
    if constexpr (std::is_same_v<T, bool>) {
      v = in_.u8(what) != 0;
    } else if constexpr (std::is_same_v<T, float>) {
      v = in_.f32(what);
    } else if constexpr (std::is_same_v<T, double>) {
      v = in_.f64(what);
    } else {
      static_assert(std::is_integral_v<T>);
      if constexpr (sizeof(T) == 1) v = T(in_.u8(what));
      if constexpr (sizeof(T) == 2) v = T(in_.u16(what));
      if constexpr (sizeof(T) == 4) v = T(in_.u32(what));
      if constexpr (sizeof(T) == 8) v = T(in_.u64(what));
    }
  }
  template <typename T, std::size_t N>
  void value(std::array<T, N>& values, std::string_view what) {
    for (T& v : values) value(v, what);
  }

  // A NUL-terminated string.
  void cstring(std::string& s, std::string_view what) {
    const auto rest = in_.buffer().subspan(in_.offset());
    const auto nul = std::string_view(rest.data(), rest.size()).find('\0');
    if (nul == std::string_view::npos) in_.fail(fmt::format("{} has no terminating NUL before the end", what));
    s.assign(rest.data(), nul);
    in_.skip(nul + 1, what);
  }

  // Exactly `count` raw bytes.
  void bytes(std::string& s, std::size_t count, std::string_view what) {
    const auto view = in_.bytes(count, what);
    s.assign(view.data(), view.size());
  }

  // An i32 count, bounded by the bytes left (each item takes at least min_item_bytes)
  // before `items` is sized to it.
  template <typename T>
  void count(std::vector<T>& items, std::size_t min_item_bytes, std::string_view what) {
    const std::size_t at = in_.offset();
    const int32_t n = in_.i32(what);
    if (n < 0) in_.fail_at(at, fmt::format("{} count {} is negative", what, n));
    if (uint64_t(n) * min_item_bytes > in_.remaining()) {
      in_.fail_at(at, fmt::format("{} count {} needs at least {} bytes, {} left", what, n, uint64_t(n) * min_item_bytes,
                                  in_.remaining()));
    }
    items.clear();
    items.resize(std::size_t(n));
  }

  // When `counted`, an i32 byte count followed by what `body` reads, which must use
  // exactly that many bytes; otherwise just `body`.
  template <typename F>
  void byte_counted(bool counted, std::string_view what, F&& body) {
    if (!counted) {
      body();
      return;
    }
    const std::size_t at = in_.offset();
    const int32_t declared = in_.i32(what);
    if (declared < 0 || std::size_t(declared) > in_.remaining()) {
      in_.fail_at(at, fmt::format("{} byte count {} is outside the {} bytes left", what, declared, in_.remaining()));
    }
    const std::size_t start = in_.offset();
    body();
    const std::size_t used = in_.offset() - start;
    if (used != std::size_t(declared)) {
      in_.fail_at(at, fmt::format("{} byte count says {} bytes, its contents took {}", what, declared, used));
    }
  }

 private:
  ByteReader& in_;
};

class Writing {
 public:
  static constexpr bool kReading = false;
  explicit Writing(ByteWriter& out) : out_(out) {}
  ByteWriter& writer() noexcept { return out_; }

  template <typename T>
  void value(const T& v, std::string_view) {
    if constexpr (std::is_same_v<T, bool>) {
      out_.u8(v ? 1 : 0);
    } else if constexpr (std::is_same_v<T, float>) {
      out_.f32(v);
    } else if constexpr (std::is_same_v<T, double>) {
      out_.f64(v);
    } else {
      static_assert(std::is_integral_v<T>);
      if constexpr (sizeof(T) == 1) out_.u8(uint8_t(v));
      if constexpr (sizeof(T) == 2) out_.u16(uint16_t(v));
      if constexpr (sizeof(T) == 4) out_.u32(uint32_t(v));
      if constexpr (sizeof(T) == 8) out_.u64(uint64_t(v));
    }
  }
  template <typename T, std::size_t N>
  void value(const std::array<T, N>& values, std::string_view what) {
    for (const T& v : values) value(v, what);
  }

  void cstring(const std::string& s, std::string_view what) {
    if (s.find('\0') != std::string::npos) {
      throw Error(
          fmt::format("NatNet {} '{}' contains a NUL byte and cannot be sent", what, s.substr(0, s.find('\0'))));
    }
    out_.bytes(s);
    out_.u8(0);
  }

  // `count` is the reader's business: the writer writes `s` whole.
  void bytes(const std::string& s, std::size_t, std::string_view) { out_.bytes(s); }

  template <typename T>
  void count(const std::vector<T>& items, std::size_t, std::string_view what) {
    if (items.size() > std::size_t(INT32_MAX))
      throw Error(fmt::format("NatNet {} count {} exceeds 2^31", what, items.size()));
    out_.i32(int32_t(items.size()));
  }

  template <typename F>
  void byte_counted(bool counted, std::string_view, F&& body) {
    if (!counted) {
      body();
      return;
    }
    const std::size_t at = out_.size();
    out_.i32(0);
    body();
    out_.patch(at, int32_t(out_.size() - at - 4));  // the whole packet is below 64 KiB, checked later
  }

 private:
  ByteWriter& out_;
};

// `i32 n | [i32 byte count] | n items`, the shape of every frame section.
template <typename IO, typename Items, typename F>
void list_layout(IO& io, Items& items, std::size_t min_item_bytes, bool byte_counted, std::string_view what,
                 F&& item_layout) {
  io.count(items, min_item_bytes, what);
  io.byte_counted(byte_counted, what, [&] {
    for (auto& item : items) item_layout(item);
  });
}

// Frame and model-definition layouts (natnet_frame.cpp, natnet_models.cpp).
void read_frame_of_data(ByteReader& in, const Layout& layout, FrameOfData& frame);
void write_frame_of_data(ByteWriter& out, const Layout& layout, const FrameOfData& frame);
void read_model_definitions(ByteReader& in, const Layout& layout, ModelDefinitions& models);
void write_model_definitions(ByteWriter& out, const Layout& layout, const ModelDefinitions& models);

}  // namespace facecap::formats::natnet::detail
