#pragma once
// Packet captures built byte by byte for tests: the classic pcap file format and the
// Ethernet / IPv4 / IPv6 / UDP headers inside it, written from the formats' definitions
// (not with libpcap, which reads them back).
#include <array>
#include <cstdint>
#include <string>
#include <vector>

namespace facecap::test {

using Bytes = std::vector<uint8_t>;

inline void put_be16(Bytes& b, uint16_t v) {
  b.push_back(uint8_t(v >> 8));
  b.push_back(uint8_t(v));
}
inline void put_be32(Bytes& b, uint32_t v) {
  put_be16(b, uint16_t(v >> 16));
  put_be16(b, uint16_t(v));
}
inline void put_le32(Bytes& b, uint32_t v) {
  for (int i = 0; i < 4; ++i) b.push_back(uint8_t(v >> (8 * i)));
}
inline Bytes concat(Bytes a, const Bytes& b) {
  a.insert(a.end(), b.begin(), b.end());
  return a;
}
inline Bytes bytes_of(const std::vector<char>& chars) { return Bytes(chars.begin(), chars.end()); }

struct PcapRecord {
  int64_t time_ns = 0;
  Bytes bytes;
  uint32_t original_length = 0;  // 0: as captured; larger: the snap length cut the packet
};

// A little-endian, nanosecond-resolution pcap file (magic a1b23c4d) of one link type.
inline std::vector<char> pcap_file(uint32_t link_type, const std::vector<PcapRecord>& records,
                                   uint32_t snap_length = 65535) {
  Bytes out;
  put_le32(out, 0xa1b23c4d);
  put_le32(out, 2 | (4u << 16));  // version 2.4
  put_le32(out, 0);               // this zone
  put_le32(out, 0);               // sigfigs
  put_le32(out, snap_length);
  put_le32(out, link_type);
  for (const PcapRecord& r : records) {
    put_le32(out, uint32_t(r.time_ns / 1'000'000'000));
    put_le32(out, uint32_t(r.time_ns % 1'000'000'000));
    put_le32(out, uint32_t(r.bytes.size()));
    put_le32(out, r.original_length ? r.original_length : uint32_t(r.bytes.size()));
    out.insert(out.end(), r.bytes.begin(), r.bytes.end());
  }
  return std::vector<char>(out.begin(), out.end());
}

// A little-endian pcapng file: one section, one interface of `link_type` at the default
// microsecond resolution, one enhanced packet block per (microseconds since 1970, packet).
inline std::vector<char> pcapng_file(uint16_t link_type, const std::vector<std::pair<uint64_t, Bytes>>& records) {
  Bytes out;
  const auto block = [&](uint32_t type, const Bytes& body) {
    put_le32(out, type);
    put_le32(out, uint32_t(12 + body.size()));
    out.insert(out.end(), body.begin(), body.end());
    put_le32(out, uint32_t(12 + body.size()));
  };
  Bytes section;
  put_le32(section, 0x1a2b3c4d);  // byte-order magic
  put_le32(section, 1);           // version 1.0
  put_le32(section, 0xffffffff);  // section length unknown (64 bits)
  put_le32(section, 0xffffffff);
  block(0x0a0d0d0a, section);
  Bytes interface;
  put_le32(interface, link_type);  // link type (16 bits) and reserved (16)
  put_le32(interface, 65535);      // snap length
  block(1, interface);
  for (const auto& [micros, bytes] : records) {
    Bytes packet;
    put_le32(packet, 0);  // interface
    put_le32(packet, uint32_t(micros >> 32));
    put_le32(packet, uint32_t(micros));
    put_le32(packet, uint32_t(bytes.size()));  // captured
    put_le32(packet, uint32_t(bytes.size()));  // on the wire
    packet.insert(packet.end(), bytes.begin(), bytes.end());
    packet.resize((packet.size() + 3) / 4 * 4, 0);
    block(6, packet);
  }
  return std::vector<char>(out.begin(), out.end());
}

inline Bytes udp_segment(uint16_t source_port, uint16_t destination_port, const Bytes& payload) {
  Bytes b;
  put_be16(b, source_port);
  put_be16(b, destination_port);
  put_be16(b, uint16_t(8 + payload.size()));
  put_be16(b, 0);  // checksum: none, as offloading NICs capture it
  return concat(b, payload);
}

// An IPv4 packet; `fragment` holds the flags (0x2000 more fragments) and offset / 8.
inline Bytes ipv4_packet(std::array<uint8_t, 4> source, std::array<uint8_t, 4> destination, uint8_t protocol,
                         const Bytes& payload, uint16_t id = 1, uint16_t fragment = 0) {
  Bytes b{0x45, 0};
  put_be16(b, uint16_t(20 + payload.size()));
  put_be16(b, id);
  put_be16(b, fragment);
  b.push_back(64);  // TTL
  b.push_back(protocol);
  put_be16(b, 0);  // header checksum: not checked by readers of captures
  b.insert(b.end(), source.begin(), source.end());
  b.insert(b.end(), destination.begin(), destination.end());
  return concat(b, payload);
}

// Splits a UDP segment into IPv4 fragments of at most `chunk` payload bytes (a multiple
// of 8), in order.
inline std::vector<Bytes> ipv4_fragments(std::array<uint8_t, 4> source, std::array<uint8_t, 4> destination,
                                         const Bytes& segment, uint16_t id, std::size_t chunk) {
  std::vector<Bytes> out;
  for (std::size_t at = 0; at < segment.size(); at += chunk) {
    const std::size_t n = std::min(chunk, segment.size() - at);
    const bool more = at + n < segment.size();
    out.push_back(ipv4_packet(source, destination, 17,
                              Bytes(segment.begin() + long(at), segment.begin() + long(at + n)), id,
                              uint16_t((more ? 0x2000 : 0) | (at / 8))));
  }
  return out;
}

// An IPv6 packet whose payload starts with the header `next_header` names.
inline Bytes ipv6_packet(const std::array<uint8_t, 16>& source, const std::array<uint8_t, 16>& destination,
                         uint8_t next_header, const Bytes& payload) {
  Bytes b{0x60, 0, 0, 0};
  put_be16(b, uint16_t(payload.size()));
  b.push_back(next_header);
  b.push_back(64);  // hop limit
  b.insert(b.end(), source.begin(), source.end());
  b.insert(b.end(), destination.begin(), destination.end());
  return concat(b, payload);
}

// The IPv6 fragment extension header (next header UDP) followed by `data`.
inline Bytes ipv6_fragment(uint32_t id, std::size_t offset, bool more, const Bytes& data) {
  Bytes b{17, 0};
  put_be16(b, uint16_t(offset / 8 << 3 | (more ? 1 : 0)));
  put_be32(b, id);
  return concat(b, data);
}

inline Bytes ethernet_frame(uint16_t ethertype, const Bytes& payload, std::vector<uint16_t> vlan_tags = {}) {
  Bytes b{0x01, 0x00, 0x5e, 0x7f, 0x2a, 0x63, 0x00, 0x11, 0x22, 0x33, 0x44, 0x55};
  for (const uint16_t tag : vlan_tags) {
    put_be16(b, 0x8100);
    put_be16(b, tag);
  }
  put_be16(b, ethertype);
  return concat(b, payload);
}

}  // namespace facecap::test
