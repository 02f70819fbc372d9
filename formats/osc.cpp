#include "formats/osc.hpp"

#include <fmt/format.h>

#include "core/error.hpp"

namespace facecap::formats::osc {

void OscWriter::begin_bundle(uint64_t timetag) {
  if (in_bundle_ || in_message_) throw Error("OSC: a bundle begun inside a bundle or a message");
  put_string("#bundle");
  writer_.u64(timetag);
  in_bundle_ = true;
}

void OscWriter::end_bundle() {
  if (!in_bundle_ || in_message_) throw Error("OSC: end of a bundle that is not open, or inside a message");
  in_bundle_ = false;
}

void OscWriter::begin_message(std::string_view address, std::string_view types) {
  if (in_message_) throw Error(fmt::format("OSC: message {} begun inside another", address));
  if (address.empty() || address[0] != '/') throw Error(fmt::format("OSC: address \"{}\" does not start with '/'", address));
  for (const char t : types)
    if (t != 'i' && t != 'f' && t != 's') throw Error(fmt::format("OSC: type tag '{}' is not supported", t));
  if (in_bundle_) {
    element_start_ = out_.size();
    writer_.i32(0);  // the element's size, patched by end_message()
  }
  put_string(address);
  std::string tags = ",";
  tags += types;
  put_string(tags);
  types_ = types;
  next_type_ = 0;
  in_message_ = true;
}

void OscWriter::next_argument(char type) {
  if (!in_message_ || next_type_ >= types_.size() || types_[next_type_] != type)
    throw Error(fmt::format("OSC: argument '{}' does not follow the message's type tags \"{}\"", type, types_));
  ++next_type_;
}

std::size_t OscWriter::int32(int32_t value) {
  next_argument('i');
  const std::size_t at = out_.size();
  writer_.i32(value);
  return at;
}

std::size_t OscWriter::float32(float value) {
  next_argument('f');
  const std::size_t at = out_.size();
  writer_.f32(value);
  return at;
}

std::size_t OscWriter::string(std::string_view value) {
  next_argument('s');
  const std::size_t at = out_.size();
  put_string(value);
  return at;
}

void OscWriter::end_message() {
  if (!in_message_ || next_type_ != types_.size())
    throw Error(fmt::format("OSC: message ended with {} of the arguments \"{}\"", next_type_, types_));
  in_message_ = false;
  if (in_bundle_) writer_.patch<int32_t>(element_start_, int32_t(out_.size() - element_start_ - 4));
}

void OscWriter::put_string(std::string_view value) {
  if (value.find('\0') != std::string_view::npos) throw Error("OSC: a string holds a NUL byte");
  writer_.bytes(value);
  writer_.zeros(string_size(value) - value.size());
}

void patch_float32(std::vector<char>& packet, std::size_t offset, float value) noexcept {
  ByteWriter(packet, ByteOrder::kBig).patch(offset, value);
}

}  // namespace facecap::formats::osc
