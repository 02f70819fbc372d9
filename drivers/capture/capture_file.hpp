#pragma once
// Packet-capture files (.pcap, .pcapng) read with libpcap: the records go through the
// pure framing of formats/pcap.hpp, and NatNet captures through formats/natnet_capture.hpp.
// The one place facecap links libpcap; the replay driver and the tools read captures here.
// Not thread-safe; not real-time safe (libpcap reads the file, datagrams are allocated).
#include <filesystem>
#include <memory>
#include <span>
#include <string>
#include <string_view>

#include "formats/natnet_capture.hpp"
#include "formats/pcap.hpp"

namespace facecap::capture {

// Reads a capture's UDP datagrams record by record.
class UdpCapture {
 public:
  // Opens a file; throws Error naming it when libpcap cannot read it or its link type is
  // not one formats::supported_link_type accepts.
  explicit UdpCapture(const std::filesystem::path& path);
  // Reads a capture held in memory (tests, fuzzing); `bytes` must outlive this object.
  UdpCapture(std::span<const char> bytes, const std::string& name);
  ~UdpCapture();
  UdpCapture(UdpCapture&&) noexcept;
  UdpCapture& operator=(UdpCapture&&) noexcept;

  // The next UDP datagram into `out`; false once the capture is exhausted. Throws Error
  // naming the record when the file is damaged (a record cut short, a bad block).
  bool next(formats::UdpDatagram& out);

  const formats::CaptureCounts& counts() const noexcept;
  // libpcap's name of the link type: "EN10MB", "LINUX_SLL", ...
  std::string_view link_type_name() const noexcept;
  // "pcap" or "pcapng".
  std::string_view file_format() const noexcept;

 private:
  struct State;
  std::unique_ptr<State> state_;
};

// The NatNet traffic of a capture: its datagrams to or from NatNet's ports (every one
// with options.any_port), parsed. Throws Error when the file is not a capture libpcap
// reads or has an unsupported link type; everything after that (damage at the end
// included) is counted or noted in the result, not thrown.
formats::natnet::NatNetCapture read_natnet_capture(const std::filesystem::path& path,
                                                   const formats::natnet::CaptureOptions& options = {});
formats::natnet::NatNetCapture read_natnet_capture(std::span<const char> bytes, const std::string& name,
                                                   const formats::natnet::CaptureOptions& options = {});

}  // namespace facecap::capture
