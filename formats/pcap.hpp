#pragma once
// UDP datagrams out of the records of packet captures (.pcap and .pcapng). Pure framing:
// a record's bytes -> link layer -> IPv4/IPv6 (fragments reassembled) -> UDP; it knows
// neither how the records are read from the file (drivers/capture reads them with
// libpcap) nor what the datagrams carry.
//
// Link types, as libpcap's DLT_* numbers: Ethernet (with 802.1Q/802.1ad VLAN tags), Linux
// cooked (SLL and SLL2), raw IP (DLT_RAW, DLT_IPV4, DLT_IPV6) and BSD loopback (DLT_NULL,
// DLT_LOOP). Every other record (ARP, TCP, ICMP, a snap length that cut the datagram,
// headers that contradict the captured bytes, fragments whose datagram never completes)
// is skipped and counted in CaptureCounts.
#include <array>
#include <cstdint>
#include <memory>
#include <span>
#include <string>
#include <string_view>
#include <vector>

namespace facecap::formats {

struct IpAddress {
  uint8_t version = 4;              // 4 or 6
  std::array<uint8_t, 16> bytes{};  // IPv4 uses the first 4
  static IpAddress v4(uint8_t a, uint8_t b, uint8_t c, uint8_t d) noexcept;
  std::string to_string() const;  // "239.255.42.99", "fe80::1"
  bool operator==(const IpAddress&) const = default;
};

struct UdpDatagram {
  int64_t capture_time_ns = 0;  // the capture's clock (ns since the Unix epoch); for a
                                // reassembled datagram, the time of its last fragment
  std::size_t record = 0;       // 0-based index of the capture record that completed it
  IpAddress source, destination;
  uint16_t source_port = 0, destination_port = 0;
  std::vector<char> payload;
};

// Every capture record lands in exactly one of the buckets after `records` (once the
// capture has been read to its end).
struct CaptureCounts {
  std::size_t records = 0;               // records read from the capture
  std::size_t udp_records = 0;           // carried (part of) a UDP datagram that was yielded
  std::size_t not_ip = 0;                // link-layer protocol other than IPv4/IPv6 (ARP, LLDP, ...)
  std::size_t not_udp = 0;               // IP protocol other than UDP (TCP, ICMP, ...)
  std::size_t truncated = 0;             // the capture's snap length cut the datagram
  std::size_t malformed = 0;             // headers contradicting themselves or the bytes captured, or a time past 2262
  std::size_t unfinished_fragments = 0;  // IP fragments of datagrams that never completed
  std::size_t datagrams = 0;             // UDP datagrams yielded
  std::size_t reassembled = 0;           // of which were put together from IP fragments
  std::size_t skipped() const noexcept { return not_ip + not_udp + truncated + malformed + unfinished_fragments; }
};

// True for the magic numbers of pcap (microsecond or nanosecond, either byte order) and
// pcapng files.
bool looks_like_capture(std::span<const char> head) noexcept;
// "pcapng" for a pcapng file's first bytes, else "pcap".
std::string_view capture_file_format(std::span<const char> head) noexcept;

// True for the link types above.
bool supported_link_type(int link_type) noexcept;

// Turns a capture's records, in order, into UDP datagrams. Not thread-safe; not real-time
// safe (datagrams and fragments are allocated).
class UdpFramer {
 public:
  // `link_type` must be supported_link_type.
  explicit UdpFramer(int link_type);
  ~UdpFramer();
  UdpFramer(UdpFramer&&) noexcept;
  UdpFramer& operator=(UdpFramer&&) noexcept;

  // One record: `captured` its bytes, `wire_bytes` its length on the wire (more than
  // captured when the snap length cut it), stamped `seconds` + `nanoseconds`. True when
  // it completed a datagram, put in `out`; otherwise it is counted or held as a fragment.
  bool add_record(std::span<const uint8_t> captured, std::size_t wire_bytes, int64_t seconds, int64_t nanoseconds,
                  UdpDatagram& out);
  // The capture ended: fragments of datagrams that never completed are counted.
  void finish() noexcept;

  const CaptureCounts& counts() const noexcept;

 private:
  struct State;
  std::unique_ptr<State> state_;
};

}  // namespace facecap::formats
