#include "drivers/capture/capture_file.hpp"

#include <cstdio>
#include <vector>

#include <fmt/format.h>
#include <pcap/pcap.h>
#include <unistd.h>

#include "core/error.hpp"
#include "core/io.hpp"

namespace facecap::capture {

struct UdpCapture::State {
  std::string name;
  pcap_t* pcap = nullptr;
  std::string_view format;
  formats::UdpFramer framer;
  bool finished = false;

  // Takes `opened`; throws Error (closing it) unless its link type is supported.
  State(pcap_t* opened, std::string capture_name, std::string_view file_format)
      : name(std::move(capture_name)), pcap(opened), format(file_format), framer(pcap_datalink(opened)) {
    if (const int link_type = pcap_datalink(pcap); !formats::supported_link_type(link_type)) {
      const char* link_name = pcap_datalink_val_to_name(link_type);
      pcap_close(pcap);
      throw file_error(name, fmt::format("link type {} ({}) is not supported: Ethernet, Linux cooked (SLL, SLL2), "
                                         "raw IP and loopback are",
                                         link_type, link_name ? link_name : "unknown"));
    }
  }
  ~State() { pcap_close(pcap); }
  State(const State&) = delete;
  State& operator=(const State&) = delete;
};

UdpCapture::UdpCapture(const std::filesystem::path& path) {
  char head[4] = {};
  // A regular file only (a FIFO would keep libpcap waiting), read through the descriptor checked.
  const int fd = open_regular_file(path);
  FILE* file = ::fdopen(fd, "rb");
  if (!file) {
    ::close(fd);
    throw file_error(path.string(), "cannot open as a stream");
  }
  if (std::fread(head, 1, sizeof head, file) < sizeof head) head[0] = head[1] = head[2] = head[3] = 0;
  std::rewind(file);
  char error[PCAP_ERRBUF_SIZE] = {};
  pcap_t* pcap = pcap_fopen_offline_with_tstamp_precision(file, PCAP_TSTAMP_PRECISION_NANO, error);  // owns file
  if (!pcap) {
    std::fclose(file);
    throw file_error(path.string(), fmt::format("not a readable pcap or pcapng capture: {}", error));
  }
  state_ = std::make_unique<State>(pcap, path.string(), formats::capture_file_format(head));
}

UdpCapture::UdpCapture(std::span<const char> bytes, const std::string& name) {
  if (bytes.empty()) throw file_error(name, "empty: not a pcap or pcapng capture");
  FILE* file = fmemopen(const_cast<char*>(bytes.data()), bytes.size(), "rb");
  if (!file) throw file_error(name, "cannot open the bytes as a stream");
  char error[PCAP_ERRBUF_SIZE] = {};
  pcap_t* pcap = pcap_fopen_offline_with_tstamp_precision(file, PCAP_TSTAMP_PRECISION_NANO, error);
  if (!pcap) {
    std::fclose(file);  // pcap_close closes it once libpcap has taken it
    throw file_error(name, fmt::format("not a readable pcap or pcapng capture: {}", error));
  }
  state_ = std::make_unique<State>(pcap, name, formats::capture_file_format(bytes));
}

UdpCapture::~UdpCapture() = default;
UdpCapture::UdpCapture(UdpCapture&&) noexcept = default;
UdpCapture& UdpCapture::operator=(UdpCapture&&) noexcept = default;

bool UdpCapture::next(formats::UdpDatagram& out) {
  State& s = *state_;
  while (!s.finished) {
    pcap_pkthdr* header = nullptr;
    const u_char* data = nullptr;
    const int status = pcap_next_ex(s.pcap, &header, &data);
    if (status == PCAP_ERROR_BREAK) {
      s.finished = true;
      s.framer.finish();
      return false;
    }
    if (status != 1) {
      throw file_error(s.name, fmt::format("capture record {} is damaged: {}", s.framer.counts().records + 1,
                                           pcap_geterr(s.pcap)));
    }
    // Opened with nanosecond precision: tv_usec holds nanoseconds.
    if (s.framer.add_record(std::span(data, header->caplen), header->len, int64_t(header->ts.tv_sec),
                            int64_t(header->ts.tv_usec), out))
      return true;
  }
  return false;
}

const formats::CaptureCounts& UdpCapture::counts() const noexcept { return state_->framer.counts(); }

std::string_view UdpCapture::link_type_name() const noexcept {
  const char* name = pcap_datalink_val_to_name(pcap_datalink(state_->pcap));
  return name ? name : "unknown";
}

std::string_view UdpCapture::file_format() const noexcept { return state_->format; }

namespace {

formats::natnet::NatNetCapture read(UdpCapture& udp, const std::string& name,
                                    const formats::natnet::CaptureOptions& options) {
  formats::natnet::NatNetCapture capture;
  capture.file_format = udp.file_format();
  capture.link_type = udp.link_type_name();
  std::vector<formats::UdpDatagram> datagrams;
  try {
    formats::UdpDatagram d;
    while (udp.next(d)) {
      if (options.any_port || formats::natnet::on_natnet_port(d)) {
        datagrams.push_back(std::move(d));
      } else {
        ++capture.other_ports;
      }
    }
  } catch (const Error& e) {
    capture.damage = e.what();
  }
  capture.records = udp.counts();
  formats::natnet::decode_datagrams(datagrams, name, options, capture);
  return capture;
}

}  // namespace

formats::natnet::NatNetCapture read_natnet_capture(const std::filesystem::path& path,
                                                   const formats::natnet::CaptureOptions& options) {
  UdpCapture udp(path);
  return read(udp, path.filename().string(), options);
}

formats::natnet::NatNetCapture read_natnet_capture(std::span<const char> bytes, const std::string& name,
                                                   const formats::natnet::CaptureOptions& options) {
  UdpCapture udp(bytes, name);
  return read(udp, name, options);
}

}  // namespace facecap::capture
