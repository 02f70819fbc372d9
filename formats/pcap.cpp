#include "formats/pcap.hpp"

#include <algorithm>
#include <cstring>
#include <optional>

#include <arpa/inet.h>
#include <pcap/dlt.h>  // the DLT_* numbers only: libpcap itself is not linked

namespace facecap::formats {

IpAddress IpAddress::v4(uint8_t a, uint8_t b, uint8_t c, uint8_t d) noexcept {
  IpAddress address;
  address.bytes[0] = a;
  address.bytes[1] = b;
  address.bytes[2] = c;
  address.bytes[3] = d;
  return address;
}

std::string IpAddress::to_string() const {
  char text[INET6_ADDRSTRLEN] = {};
  inet_ntop(version == 6 ? AF_INET6 : AF_INET, bytes.data(), text, sizeof text);
  return text;
}

namespace {

constexpr uint32_t kPcapMagicMicro = 0xa1b2c3d4;
constexpr uint32_t kPcapMagicNano = 0xa1b23c4d;
constexpr uint32_t kPcapngBlockType = 0x0a0d0d0a;  // a palindrome: the same in both byte orders

std::optional<uint32_t> magic(std::span<const char> head) noexcept {
  if (head.size() < 4) return std::nullopt;
  uint32_t value;
  std::memcpy(&value, head.data(), 4);
  return value;
}

uint16_t be16(std::span<const uint8_t> b, std::size_t at) noexcept { return uint16_t(b[at] << 8 | b[at + 1]); }
uint32_t be32(std::span<const uint8_t> b, std::size_t at) noexcept {
  return uint32_t(b[at]) << 24 | uint32_t(b[at + 1]) << 16 | uint32_t(b[at + 2]) << 8 | b[at + 3];
}

}  // namespace

bool supported_link_type(int link_type) noexcept {
  switch (link_type) {
    case DLT_EN10MB:
    case DLT_LINUX_SLL:
    case DLT_LINUX_SLL2:
    case DLT_RAW:
    case DLT_IPV4:
    case DLT_IPV6:
    case DLT_NULL:
    case DLT_LOOP: return true;
    default: return false;
  }
}

namespace {

enum class Outcome { kDatagram, kFragmentHeld, kNotIp, kNotUdp, kTruncated, kMalformed };

struct FragmentKey {
  IpAddress source, destination;
  uint32_t id = 0;
  bool operator==(const FragmentKey&) const = default;
};

// IPv4 and IPv6 fragment reassembly for UDP: fragments are copied into place until the
// last one is known and every byte before it has arrived. Bounded: at most kMaxPending
// datagrams in progress (the oldest gives way) and none beyond 65535 bytes.
class Reassembler {
 public:
  static constexpr std::size_t kMaxPending = 64;
  static constexpr uint32_t kMaxDatagramBytes = 65535;

  struct Added {
    Outcome outcome = Outcome::kFragmentHeld;  // kFragmentHeld, kDatagram or kMalformed
    std::size_t records = 0;                   // kDatagram: the records it was made of
    std::size_t evicted_records = 0;           // fragments of a datagram given up to make room
  };

  // `data` is the fragment's part of the IP payload, starting at byte `offset`.
  Added add(const FragmentKey& key, uint32_t offset, std::span<const uint8_t> data, bool more,
            std::vector<char>& completed) {
    Added added;
    const uint64_t end = uint64_t(offset) + data.size();
    if (end > kMaxDatagramBytes || (more && data.size() % 8 != 0)) return {Outcome::kMalformed};
    auto it = std::find_if(pending_.begin(), pending_.end(), [&](const Pending& p) { return p.key == key; });
    if (it == pending_.end()) {
      if (pending_.size() == kMaxPending) {
        added.evicted_records = pending_.front().records;
        pending_.erase(pending_.begin());
      }
      pending_.push_back(Pending{key});
      it = pending_.end() - 1;
    }
    Pending& p = *it;
    if ((p.total && end > *p.total) || (!more && (end < p.highest_end || (p.total && *p.total != end)))) {
      added.outcome = Outcome::kMalformed;  // contradicts the fragments before it
      return added;
    }
    if (!more) p.total = uint32_t(end);
    p.highest_end = std::max(p.highest_end, uint32_t(end));
    if (p.bytes.size() < end) p.bytes.resize(end);
    std::copy(data.begin(), data.end(), p.bytes.begin() + offset);
    add_range(p.ranges, offset, uint32_t(end));
    ++p.records;
    const bool complete = p.total && p.ranges.size() == 1 && p.ranges[0].first == 0 && p.ranges[0].second == *p.total;
    if (!complete) return added;
    completed.assign(p.bytes.begin(), p.bytes.begin() + *p.total);
    added.outcome = Outcome::kDatagram;
    added.records = p.records;
    pending_.erase(it);
    return added;
  }

  // Gives up every datagram in progress; returns how many records they held.
  std::size_t drop_all() noexcept {
    std::size_t records = 0;
    for (const Pending& p : pending_) records += p.records;
    pending_.clear();
    return records;
  }

 private:
  struct Pending {
    FragmentKey key;
    std::vector<char> bytes;
    std::vector<std::pair<uint32_t, uint32_t>> ranges;  // [begin, end) received, sorted, disjoint
    std::optional<uint32_t> total;                      // known once the last fragment came
    uint32_t highest_end = 0;
    std::size_t records = 0;
  };

  // Inserts [begin, end) into sorted, disjoint ranges, merging what touches: at most one
  // range per gap, so a flood of fragments stays cheap.
  static void add_range(std::vector<std::pair<uint32_t, uint32_t>>& ranges, uint32_t begin, uint32_t end) {
    auto first = std::lower_bound(ranges.begin(), ranges.end(), begin,
                                  [](const auto& range, uint32_t at) { return range.second < at; });
    auto last = first;
    while (last != ranges.end() && last->first <= end) {
      begin = std::min(begin, last->first);
      end = std::max(end, last->second);
      ++last;
    }
    first = ranges.erase(first, last);
    ranges.insert(first, {begin, end});
  }

  std::vector<Pending> pending_;
};

}  // namespace

std::string_view capture_file_format(std::span<const char> head) noexcept {
  return magic(head) == kPcapngBlockType ? "pcapng" : "pcap";
}

bool looks_like_capture(std::span<const char> head) noexcept {
  const auto m = magic(head);
  if (!m) return false;
  const uint32_t swapped = __builtin_bswap32(*m);
  return *m == kPcapngBlockType || *m == kPcapMagicMicro || *m == kPcapMagicNano || swapped == kPcapMagicMicro ||
         swapped == kPcapMagicNano;
}

struct UdpFramer::State {
  int link_type = 0;
  CaptureCounts counts;
  Reassembler reassembler;

  // One record: the link layer, then IP. `cut`: the snap length shortened it.
  Outcome decode(std::span<const uint8_t> b, bool cut, UdpDatagram& out) {
    const Outcome short_of_bytes = cut ? Outcome::kTruncated : Outcome::kMalformed;
    std::size_t at = 0;
    int ip_version = 0;
    auto ethertype_version = [](uint16_t type) { return type == 0x0800 ? 4 : type == 0x86dd ? 6 : 0; };
    switch (link_type) {
      case DLT_EN10MB: {
        if (b.size() < 14) return short_of_bytes;
        uint16_t type = be16(b, 12);
        at = 14;
        while (type == 0x8100 || type == 0x88a8 || type == 0x9100) {  // VLAN tags
          if (b.size() < at + 4) return short_of_bytes;
          type = be16(b, at + 2);
          at += 4;
        }
        ip_version = ethertype_version(type);
        break;
      }
      case DLT_LINUX_SLL:
        if (b.size() < 16) return short_of_bytes;
        ip_version = ethertype_version(be16(b, 14));
        at = 16;
        break;
      case DLT_LINUX_SLL2:
        if (b.size() < 20) return short_of_bytes;
        ip_version = ethertype_version(be16(b, 0));
        at = 20;
        break;
      case DLT_NULL:
      case DLT_LOOP: {
        if (b.size() < 4) return short_of_bytes;
        // DLT_NULL holds the address family in the capturing host's byte order.
        uint32_t family = be32(b, 0);
        if (link_type == DLT_NULL && family > 0xffff) family = __builtin_bswap32(family);
        ip_version = family == 2 ? 4 : (family == 10 || family == 24 || family == 28 || family == 30) ? 6 : 0;
        at = 4;
        break;
      }
      default:  // raw IP: the version nibble says which
        if (b.empty()) return short_of_bytes;
        ip_version = b[0] >> 4;
        break;
    }
    if (ip_version == 4) return ipv4(b, at, cut, out);
    if (ip_version == 6) return ipv6(b, at, cut, out);
    return link_type == DLT_RAW || link_type == DLT_IPV4 || link_type == DLT_IPV6 ? Outcome::kMalformed
                                                                                  : Outcome::kNotIp;
  }

  Outcome ipv4(std::span<const uint8_t> b, std::size_t at, bool cut, UdpDatagram& out) {
    const Outcome short_of_bytes = cut ? Outcome::kTruncated : Outcome::kMalformed;
    if (b.size() < at + 20) return short_of_bytes;
    const std::size_t header = std::size_t(b[at] & 0x0f) * 4;
    const std::size_t total = be16(b, at + 2);
    if ((b[at] >> 4) != 4 || header < 20 || total < header) return Outcome::kMalformed;
    if (b.size() < at + total) return short_of_bytes;
    if (b[at + 9] != 17) return Outcome::kNotUdp;
    out.source = IpAddress::v4(b[at + 12], b[at + 13], b[at + 14], b[at + 15]);
    out.destination = IpAddress::v4(b[at + 16], b[at + 17], b[at + 18], b[at + 19]);
    const uint16_t fragment = be16(b, at + 6);
    const bool more = (fragment & 0x2000) != 0;
    const uint32_t offset = uint32_t(fragment & 0x1fff) * 8;
    const auto payload = b.subspan(at + header, total - header);
    if (!more && offset == 0) return udp(payload, cut, out);
    return fragment_of(FragmentKey{out.source, out.destination, be16(b, at + 4)}, offset, payload, more, out);
  }

  Outcome ipv6(std::span<const uint8_t> b, std::size_t at, bool cut, UdpDatagram& out) {
    const Outcome short_of_bytes = cut ? Outcome::kTruncated : Outcome::kMalformed;
    if (b.size() < at + 40) return short_of_bytes;
    const std::size_t payload_length = be16(b, at + 4);
    if ((b[at] >> 4) != 6 || payload_length == 0) return Outcome::kMalformed;  // 0: jumbogram, not supported
    if (b.size() < at + 40 + payload_length) return short_of_bytes;
    out.source.version = out.destination.version = 6;
    std::copy_n(b.begin() + long(at) + 8, 16, out.source.bytes.begin());
    std::copy_n(b.begin() + long(at) + 24, 16, out.destination.bytes.begin());
    const std::size_t end = at + 40 + payload_length;
    std::size_t p = at + 40;
    uint8_t next = b[at + 6];
    while (true) {
      switch (next) {
        case 17: return udp(b.subspan(p, end - p), cut, out);
        case 0:     // hop-by-hop options
        case 43:    // routing
        case 60: {  // destination options
          if (end < p + 2) return Outcome::kMalformed;
          const std::size_t length = (std::size_t(b[p + 1]) + 1) * 8;
          next = b[p];
          p += length;
          if (p > end) return Outcome::kMalformed;
          break;
        }
        case 44: {  // fragment
          if (end < p + 8) return Outcome::kMalformed;
          if (b[p] != 17) return Outcome::kNotUdp;
          const uint16_t field = be16(b, p + 2);
          const FragmentKey key{out.source, out.destination, be32(b, p + 4)};
          return fragment_of(key, uint32_t(field >> 3) * 8, b.subspan(p + 8, end - p - 8), (field & 1) != 0, out);
        }
        default: return Outcome::kNotUdp;
      }
    }
  }

  Outcome fragment_of(const FragmentKey& key, uint32_t offset, std::span<const uint8_t> data, bool more,
                      UdpDatagram& out) {
    const auto added = reassembler.add(key, offset, data, more, reassembled_);
    counts.unfinished_fragments += added.evicted_records;
    if (added.outcome != Outcome::kDatagram) return added.outcome;
    // The records before this one are accounted here; this one by the caller.
    const auto whole = std::span(reinterpret_cast<const uint8_t*>(reassembled_.data()), reassembled_.size());
    const Outcome outcome = udp(whole, false, out);
    if (outcome == Outcome::kDatagram) {
      counts.udp_records += added.records - 1;
      ++counts.reassembled;
    } else {
      counts.malformed += added.records - 1;
    }
    return outcome;
  }

  static Outcome udp(std::span<const uint8_t> b, bool cut, UdpDatagram& out) {
    const Outcome short_of_bytes = cut ? Outcome::kTruncated : Outcome::kMalformed;
    if (b.size() < 8) return short_of_bytes;
    const std::size_t length = be16(b, 4);
    if (length < 8) return Outcome::kMalformed;
    if (length > b.size()) return short_of_bytes;
    out.source_port = be16(b, 0);
    out.destination_port = be16(b, 2);
    out.payload.assign(b.begin() + 8, b.begin() + long(length));
    return Outcome::kDatagram;
  }

  std::vector<char> reassembled_;
};

UdpFramer::UdpFramer(int link_type) : state_(std::make_unique<State>()) { state_->link_type = link_type; }
UdpFramer::~UdpFramer() = default;
UdpFramer::UdpFramer(UdpFramer&&) noexcept = default;
UdpFramer& UdpFramer::operator=(UdpFramer&&) noexcept = default;

bool UdpFramer::add_record(std::span<const uint8_t> captured, std::size_t wire_bytes, int64_t seconds,
                           int64_t nanoseconds, UdpDatagram& out) {
  State& s = *state_;
  const std::size_t record = s.counts.records++;
  // pcapng stamps reach far beyond int64 nanoseconds (year 2262).
  int64_t time_ns = 0;
  if (__builtin_mul_overflow(seconds, int64_t(1'000'000'000), &time_ns) ||
      __builtin_add_overflow(time_ns, nanoseconds, &time_ns)) {
    ++s.counts.malformed;
    return false;
  }
  out = UdpDatagram{};
  switch (s.decode(captured, captured.size() < wire_bytes, out)) {
    case Outcome::kDatagram:
      ++s.counts.udp_records;
      ++s.counts.datagrams;
      out.record = record;
      out.capture_time_ns = time_ns;
      return true;
    case Outcome::kFragmentHeld: break;
    case Outcome::kNotIp: ++s.counts.not_ip; break;
    case Outcome::kNotUdp: ++s.counts.not_udp; break;
    case Outcome::kTruncated: ++s.counts.truncated; break;
    case Outcome::kMalformed: ++s.counts.malformed; break;
  }
  return false;
}

void UdpFramer::finish() noexcept { state_->counts.unfinished_fragments += state_->reassembler.drop_all(); }

const CaptureCounts& UdpFramer::counts() const noexcept { return state_->counts; }

}  // namespace facecap::formats
