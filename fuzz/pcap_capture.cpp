// libFuzzer target: the bytes as a pcap or pcapng capture, read to the end through the
// UDP framing (link layer, IPv4/IPv6, fragment reassembly). Bad input must give
// facecap::Error and nothing else; a capture read to its end accounts for every record.
#include <cstdint>
#include <cstdlib>
#include <span>

#include "core/error.hpp"
#include "drivers/capture/capture_file.hpp"

extern "C" int LLVMFuzzerTestOneInput(const uint8_t* data, size_t size) {
  try {
    facecap::capture::UdpCapture capture(std::span<const char>(reinterpret_cast<const char*>(data), size), "fuzz.pcap");
    facecap::formats::UdpDatagram datagram;
    while (capture.next(datagram)) {
    }
    const auto& counts = capture.counts();
    if (counts.records != counts.udp_records + counts.skipped() || counts.datagrams > counts.udp_records) std::abort();
  } catch (const facecap::Error&) {
  }
  return 0;
}
