#include "formats/natnet_request.hpp"

#include <cctype>

#include <fmt/format.h>

namespace facecap::formats::natnet {
namespace {

std::string_view trimmed(std::string_view text) {
  while (!text.empty() && std::isspace(static_cast<unsigned char>(text.front()))) text.remove_prefix(1);
  while (!text.empty() && std::isspace(static_cast<unsigned char>(text.back()))) text.remove_suffix(1);
  return text;
}

bool same_word(std::string_view a, std::string_view b) {
  if (a.size() != b.size()) return false;
  for (std::size_t i = 0; i < a.size(); ++i)
    if (std::tolower(static_cast<unsigned char>(a[i])) != std::tolower(static_cast<unsigned char>(b[i]))) return false;
  return true;
}

// "4.1" or "4.1.0.0": a bitstream is a layout, named by its major.minor.
std::optional<Version> major_minor(std::string_view text) {
  const auto version = parse_version(trimmed(text));
  if (!version) return std::nullopt;
  return Version{version->major, version->minor};
}

constexpr std::string_view kBitstream = "Bitstream";

}  // namespace

std::optional<Request> parse_request(std::string_view text) {
  text = trimmed(text);
  const auto comma = text.find(',');
  const std::string_view command = trimmed(text.substr(0, comma));
  if (comma != std::string_view::npos) {
    if (!same_word(command, kBitstream)) return std::nullopt;
    const auto version = major_minor(text.substr(comma + 1));
    if (!version) return std::nullopt;
    return Request{RequestKind::kSetBitstream, *version};
  }
  if (same_word(command, kBitstream)) return Request{RequestKind::kBitstreamQuery, {}};
  if (same_word(command, kRequestKinds.name(RequestKind::kFrameRate))) return Request{RequestKind::kFrameRate, {}};
  if (same_word(command, kRequestKinds.name(RequestKind::kAnalogSamplesPerMocapFrame)))
    return Request{RequestKind::kAnalogSamplesPerMocapFrame, {}};
  return std::nullopt;
}

std::string request_text(const Request& request) {
  switch (request.kind) {
    case RequestKind::kSetBitstream: return fmt::format("{},{}", kBitstream, request.bitstream.major_minor());
    case RequestKind::kBitstreamQuery: return std::string(kBitstream);
    case RequestKind::kFrameRate:
    case RequestKind::kAnalogSamplesPerMocapFrame: return std::string(kRequestKinds.name(request.kind));
  }
  return {};
}

std::string bitstream_reply(Version bitstream) { return fmt::format("{},{}", kBitstream, bitstream.major_minor()); }

std::optional<Version> parse_bitstream_reply(std::string_view text) {
  const auto request = parse_request(text);
  if (!request || request->kind != RequestKind::kSetBitstream) return std::nullopt;
  return request->bitstream;
}

}  // namespace facecap::formats::natnet
