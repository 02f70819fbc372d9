// UDP datagrams out of packet captures: every supported link type, IPv4 and IPv6 fragment
// reassembly, and every kind of record that is skipped, on captures built byte by byte;
// the real Motive session capture checked against tshark's reading of it.
#include <random>

#include <catch2/catch.hpp>

#include "core/error.hpp"
#include "core/io.hpp"
#include "drivers/capture/capture_file.hpp"
#include "tests/capture_test_support.hpp"
#include "tests/test_support.hpp"

using namespace facecap;
using namespace facecap::capture;
using namespace facecap::formats;
using namespace facecap::test;

namespace {

// libpcap's LINKTYPE_ values as stored in files (tcpdump.org/linktypes.html).
constexpr uint32_t kEthernet = 1, kNull = 0, kLoop = 108, kRaw = 101, kSll = 113, kSll2 = 276, kIpv4 = 228, kIpv6 = 229,
                   kIeee80211 = 105;

constexpr std::array<uint8_t, 4> kServer{192, 168, 0, 106};
constexpr std::array<uint8_t, 4> kGroup{239, 255, 42, 99};
constexpr int64_t kTime = 1'509'244'025'141'882'123;  // nanoseconds survive the round trip

Bytes payload_of(std::size_t size, uint8_t seed) {
  Bytes b(size);
  for (std::size_t i = 0; i < size; ++i) b[i] = uint8_t(seed + i * 7);
  return b;
}

struct Read {
  std::vector<UdpDatagram> datagrams;
  CaptureCounts counts;
  std::string link;
};

Read read_all(const std::vector<char>& file) {
  UdpCapture capture(file, "test.pcap");
  Read read;
  UdpDatagram d;
  while (capture.next(d)) read.datagrams.push_back(d);
  read.counts = capture.counts();
  read.link = std::string(capture.link_type_name());
  // Every record is in exactly one bucket.
  CHECK(read.counts.records == read.counts.udp_records + read.counts.skipped());
  CHECK(read.counts.datagrams == read.datagrams.size());
  return read;
}

void check_datagram(const UdpDatagram& d, const Bytes& payload) {
  CHECK(d.capture_time_ns == kTime);
  CHECK(d.source == IpAddress::v4(192, 168, 0, 106));
  CHECK(d.destination.to_string() == "239.255.42.99");
  CHECK(d.source_port == 1511);
  CHECK(d.destination_port == 1511);
  CHECK(Bytes(d.payload.begin(), d.payload.end()) == payload);
}

}  // namespace

TEST_CASE("UDP datagrams come out of every supported link type", "[pcap]") {
  const Bytes payload = payload_of(100, 3);
  const Bytes ip = ipv4_packet(kServer, kGroup, 17, udp_segment(1511, 1511, payload));
  Bytes sll{0, 0, 0, 1, 0, 6, 0, 0x11, 0x22, 0x33, 0x44, 0x55, 0, 0};  // packet type, ARPHRD, address
  put_be16(sll, 0x0800);
  Bytes sll2;
  put_be16(sll2, 0x0800);
  sll2.insert(sll2.end(), {0, 0, 0, 0, 0, 2, 0, 1, 0, 6, 0, 0x11, 0x22, 0x33, 0x44, 0x55, 0, 0});
  Bytes null_le, null_be, loop;
  put_le32(null_le, 2);  // AF_INET, captured on a little-endian host
  put_be32(null_be, 2);  // ... on a big-endian one
  put_be32(loop, 2);
  const std::vector<std::tuple<uint32_t, Bytes, std::string>> cases{
      {kEthernet, ethernet_frame(0x0800, ip), "EN10MB"},
      {kEthernet, ethernet_frame(0x0800, ip, {0x0005, 0x0064}), "EN10MB"},     // two VLAN tags
      {kEthernet, concat(ethernet_frame(0x0800, ip), Bytes(6, 0)), "EN10MB"},  // Ethernet padding
      {kSll, concat(sll, ip), "LINUX_SLL"},
      {kSll2, concat(sll2, ip), "LINUX_SLL2"},
      {kRaw, ip, "RAW"},
      {kIpv4, ip, "IPV4"},
      {kNull, concat(null_le, ip), "NULL"},
      {kNull, concat(null_be, ip), "NULL"},
      {kLoop, concat(loop, ip), "LOOP"},
  };
  for (const auto& [link, record, name] : cases) {
    INFO(name);
    const Read read = read_all(pcap_file(link, {{kTime, record}}));
    CHECK(read.link == name);
    REQUIRE(read.datagrams.size() == 1);
    check_datagram(read.datagrams[0], payload);
    CHECK(read.counts.udp_records == 1);
  }
}

TEST_CASE("IPv4 fragments are reassembled in any order, repeated or overlapping, into one datagram", "[pcap]") {
  const Bytes payload = payload_of(4000, 9);  // a NatNet model definition can be this big
  const Bytes segment = udp_segment(1511, 1511, payload);
  const auto fragments = ipv4_fragments(kServer, kGroup, segment, 77, 1480);
  REQUIRE(fragments.size() == 3);
  // Bytes 1000..2000 again, overlapping the first two fragments.
  const Bytes overlap =
      ipv4_packet(kServer, kGroup, 17, Bytes(segment.begin() + 1000, segment.begin() + 2000), 77, 0x2000 | 1000 / 8);
  // Another datagram's lone first fragment, interleaved, never completes.
  const auto lonely = ipv4_fragments(kServer, kGroup, udp_segment(1510, 50000, payload_of(3000, 1)), 78, 1480);
  std::vector<PcapRecord> records;
  for (const Bytes* ip : {&fragments[2], &lonely[0], &fragments[1], &fragments[1], &overlap, &fragments[0]}) {
    records.push_back({kTime, ethernet_frame(0x0800, *ip)});
  }
  const Read read = read_all(pcap_file(kEthernet, records));
  REQUIRE(read.datagrams.size() == 1);
  check_datagram(read.datagrams[0], payload);
  CHECK(read.datagrams[0].record == 5);  // completed by the sixth record
  CHECK(read.counts.records == 6);
  CHECK(read.counts.udp_records == 5);
  CHECK(read.counts.reassembled == 1);
  CHECK(read.counts.unfinished_fragments == 1);
}

TEST_CASE("IPv6 datagrams, with extension headers and fragments, come out whole", "[pcap]") {
  std::array<uint8_t, 16> source{0xfe, 0x80}, destination{0xff, 0x02};
  source[15] = 1;
  destination[15] = 0x99;
  const Bytes payload = payload_of(2000, 5);
  const Bytes segment = udp_segment(1511, 1511, payload);
  const Bytes hop_by_hop{58 /* replaced below */, 0, 1, 4, 0, 0, 0, 0};  // 8 bytes of PadN options
  auto with_next = [](Bytes header, uint8_t next) {
    header[0] = next;
    return header;
  };
  std::vector<PcapRecord> records{
      // Whole, behind a hop-by-hop options header.
      {kTime, ethernet_frame(0x86dd, ipv6_packet(source, destination, 0, concat(with_next(hop_by_hop, 17), segment)))},
      // Fragmented in two (1232 is a multiple of 8), second fragment first.
      {kTime, ethernet_frame(0x86dd,
                             ipv6_packet(source, destination, 44,
                                         ipv6_fragment(9, 1232, false, Bytes(segment.begin() + 1232, segment.end()))))},
      {kTime,
       ethernet_frame(0x86dd, ipv6_packet(source, destination, 44,
                                          ipv6_fragment(9, 0, true, Bytes(segment.begin(), segment.begin() + 1232))))},
  };
  const Read read = read_all(pcap_file(kEthernet, records));
  REQUIRE(read.datagrams.size() == 2);
  for (const UdpDatagram& d : read.datagrams) {
    CHECK(d.source.version == 6);
    CHECK(d.source.to_string() == "fe80::1");
    CHECK(d.destination.to_string() == "ff02::99");
    CHECK(d.destination_port == 1511);
    CHECK(Bytes(d.payload.begin(), d.payload.end()) == payload);
  }
  CHECK(read.counts.reassembled == 1);
  CHECK(read.counts.udp_records == 3);
  // Raw IPv6 link type too.
  const Read raw = read_all(pcap_file(kIpv6, {{kTime, ipv6_packet(source, destination, 17, segment)}}));
  REQUIRE(raw.datagrams.size() == 1);
  CHECK(raw.datagrams[0].payload.size() == payload.size());
}

TEST_CASE("Records that are not whole UDP datagrams are skipped and counted by reason", "[pcap]") {
  const Bytes ip = ipv4_packet(kServer, kGroup, 17, udp_segment(1511, 1511, payload_of(200, 1)));
  Bytes bad_ihl = ip;
  bad_ihl[0] = 0x44;  // header length 16 bytes
  Bytes bad_udp_length = ip;
  bad_udp_length[20 + 4] = 0;
  bad_udp_length[20 + 5] = 4;  // UDP length 4 < its own header
  Bytes cut = ethernet_frame(0x0800, ip);
  const auto original = uint32_t(cut.size());
  cut.resize(100);  // what a snap length of 100 keeps
  const std::vector<PcapRecord> records{
      {kTime, ethernet_frame(0x0806, Bytes(28, 0))},                                   // ARP
      {kTime, ethernet_frame(0x0800, ipv4_packet(kServer, kGroup, 6, Bytes(40, 0)))},  // TCP
      {kTime, ethernet_frame(0x0800, ipv4_packet(kServer, kGroup, 1, Bytes(8, 0)))},   // ICMP
      {kTime, cut, original},
      {kTime, ethernet_frame(0x0800, bad_ihl)},
      {kTime, ethernet_frame(0x0800, bad_udp_length)},
      {kTime, ethernet_frame(0x0800, Bytes(ip.begin(), ip.begin() + 30))},  // shorter than its header says, not cut
      {kTime, Bytes(10, 0)},                                                // shorter than Ethernet
      {kTime, ethernet_frame(0x0800, ip)},                                  // the one good datagram
  };
  const Read read = read_all(pcap_file(kEthernet, records));
  CHECK(read.datagrams.size() == 1);
  CHECK(read.counts.records == 9);
  CHECK(read.counts.not_ip == 1);
  CHECK(read.counts.not_udp == 2);
  CHECK(read.counts.truncated == 1);
  CHECK(read.counts.malformed == 4);
  CHECK(read.counts.udp_records == 1);
}

TEST_CASE("pcapng captures read like pcap ones; stamps past int64 nanoseconds are refused", "[pcap]") {
  const Bytes ip = ipv4_packet(kServer, kGroup, 17, udp_segment(1511, 1511, payload_of(64, 2)));
  // 12768243091 s after 1970 (year 2374): a valid pcapng stamp, past 2^63 ns.
  const auto file = pcapng_file(kEthernet, {{uint64_t(kTime) / 1000, ethernet_frame(0x0800, ip)},
                                            {uint64_t(12768243091) * 1'000'000, ethernet_frame(0x0800, ip)}});
  UdpCapture capture(file, "far.pcapng");
  CHECK(capture.file_format() == "pcapng");
  UdpDatagram d;
  REQUIRE(capture.next(d));
  CHECK(d.capture_time_ns == kTime / 1000 * 1000);  // microsecond resolution
  CHECK_FALSE(capture.next(d));
  CHECK(capture.counts().malformed == 1);
}

TEST_CASE("Fragment reassembly stays bounded and refuses contradictions", "[pcap]") {
  std::vector<PcapRecord> records;
  // 70 datagrams each missing its last fragment: the 64-datagram table gives way.
  for (uint16_t id = 0; id < 70; ++id) {
    const auto fragments = ipv4_fragments(kServer, kGroup, udp_segment(1, 2, payload_of(2000, 0)), id, 1480);
    records.push_back({kTime, ethernet_frame(0x0800, fragments[0])});
  }
  // A fragment past 65535 bytes, and a "more fragments" one whose size is not a multiple of 8.
  records.push_back({kTime, ethernet_frame(0x0800, ipv4_packet(kServer, kGroup, 17, Bytes(100, 0), 500, 0x1fff))});
  records.push_back({kTime, ethernet_frame(0x0800, ipv4_packet(kServer, kGroup, 17, Bytes(13, 0), 501, 0x2000))});
  const Read read = read_all(pcap_file(kEthernet, records));
  CHECK(read.datagrams.empty());
  CHECK(read.counts.unfinished_fragments == 70);  // 6 evicted on the way, 64 left at the end
  CHECK(read.counts.malformed == 2);
}

TEST_CASE("Captures libpcap cannot read, or of unsupported link types, are refused with the file named", "[pcap]") {
  CHECK_THROWS_WITH(UdpCapture(pcap_file(kIeee80211, {}), "wifi.pcap"),
                    Catch::Contains("wifi.pcap") && Catch::Contains("link type 105 (IEEE802_11) is not supported"));
  const std::vector<char> noise(100, 'x');
  CHECK_THROWS_WITH(UdpCapture(noise, "noise.pcap"),
                    Catch::Contains("noise.pcap: not a readable pcap or pcapng capture"));
  CHECK_THROWS_AS(UdpCapture(std::vector<char>{}, "empty.pcap"), Error);
  CHECK_THROWS_WITH(UdpCapture(std::filesystem::path("/nonexistent/x.pcap")), Catch::Contains("/nonexistent/x.pcap"));
  // A record cut off by the end of the file: an Error naming the record, after the good ones.
  auto file = pcap_file(kRaw, {{kTime, ipv4_packet(kServer, kGroup, 17, udp_segment(1, 2, Bytes(10, 0)))},
                               {kTime, ipv4_packet(kServer, kGroup, 17, udp_segment(1, 2, Bytes(10, 0)))}});
  file.resize(file.size() - 5);
  UdpCapture capture(file, "cut.pcap");
  UdpDatagram d;
  CHECK(capture.next(d));
  CHECK_THROWS_WITH(capture.next(d), Catch::Contains("cut.pcap: capture record 2 is damaged"));
  CHECK(looks_like_capture(file));
  CHECK_FALSE(looks_like_capture(noise));
}

TEST_CASE("Mutated captures yield datagrams or throw Error, never crash", "[pcap][corruption]") {
  std::vector<PcapRecord> records;
  for (const auto& f : ipv4_fragments(kServer, kGroup, udp_segment(1511, 1511, payload_of(3000, 2)), 5, 1480)) {
    records.push_back({kTime, ethernet_frame(0x0800, f)});
  }
  records.push_back({kTime, ethernet_frame(0x86dd, ipv6_packet({}, {}, 17, udp_segment(1, 2, Bytes(30, 1))))});
  const auto original = pcap_file(kEthernet, records);
  std::mt19937 rng(23);
  std::size_t refused = 0, read = 0;
  for (int i = 0; i < 1500; ++i) {
    auto mutant = original;
    for (int n = int(rng() % 8) + 1; n > 0; --n) mutant[24 + rng() % (mutant.size() - 24)] = char(rng());
    if (rng() % 3 == 0) mutant.resize(24 + rng() % (mutant.size() - 24));
    try {
      UdpCapture capture(mutant, "mutant.pcap");
      UdpDatagram d;
      while (capture.next(d)) {
      }
      const CaptureCounts& c = capture.counts();
      CHECK(c.records == c.udp_records + c.skipped());
      ++read;
    } catch (const Error&) {
      ++refused;
    }
  }
  CHECK(read + refused == 1500);
  CHECK(read > 0);
  CHECK(refused > 0);
}

TEST_CASE("The real Motive session capture yields the datagrams tshark sees", "[pcap][shared]") {
  // Expected values from `tshark -r traffic.pcapng -T fields -e frame.time_epoch -e ip.src
  // -e udp.srcport -e ip.dst -e udp.dstport -e udp.length` (Wireshark 4.0), run by hand.
  FACECAP_REQUIRE_SHARED_DATA(path, "natnet/traffic.pcapng");
  UdpCapture capture(path);
  CHECK(capture.file_format() == "pcapng");
  CHECK(capture.link_type_name() == "EN10MB");
  std::vector<UdpDatagram> all;
  UdpDatagram d;
  while (capture.next(d)) all.push_back(d);
  REQUIRE(all.size() == 550);
  CHECK(capture.counts().records == 550);
  CHECK(capture.counts().skipped() == 0);
  CHECK(all[0].capture_time_ns == 1'509'244'022'606'067'000);
  CHECK(all[0].source.to_string() == "192.168.0.100");
  CHECK(all[0].source_port == 49465);
  CHECK(all[0].destination.to_string() == "192.168.0.255");
  CHECK(all[0].destination_port == 1510);
  CHECK(all[0].payload.size() == 276 - 8);
  CHECK(all[10].capture_time_ns == 1'509'244'025'141'882'000);
  CHECK(all[10].destination.to_string() == "239.255.42.99");
  CHECK(all[549].capture_time_ns == 1'509'244'029'450'703'000);
  std::size_t to_data_port = 0, payload_bytes = 0;
  for (const auto& datagram : all) {
    to_data_port += datagram.destination_port == 1511;
    payload_bytes += datagram.payload.size();
  }
  CHECK(to_data_port == 518);
  CHECK(payload_bytes == 176075);  // sum of tshark's data.len
}
