// The usb and hid drivers through the real libusb and hidapi, against devices faked below
// them by umockdev (tests/fake_marker_devices.hpp): enumeration by ids and serial, a frame
// spanning many packets, a bad CRC counted and dropped, and a device unplugged and plugged
// in again while facecapd runs, its frames resuming and the gap reported.
#include <atomic>
#include <cmath>
#include <regex>
#include <thread>

#include <catch2/catch.hpp>
#include <fmt/format.h>

#include "config/config_file.hpp"
#include "core/error.hpp"
#include "core/time.hpp"
#include "daemon/daemon.hpp"
#include "drivers/hid/hid_source.hpp"
#include "drivers/sim/sim_source.hpp"
#include "drivers/usb/usb_source.hpp"
#include "pipeline/calibration.hpp"
#include "pipeline/settings.hpp"
#include "solver/builtin_face.hpp"
#include "tests/fake_marker_devices.hpp"

using namespace facecap;
using namespace facecap::formats::device;
using facecap::formats::device::kMarkerOccluded;
using Catch::Contains;

namespace {

struct Usb {
  using Fake = test::FakeUsbMarkerDevice;
  using Source = drivers::UsbSource;
  static constexpr const char* kName = "usb";
};
struct Hid {
  using Fake = test::FakeHidMarkerDevice;
  using Source = drivers::HidSource;
  static constexpr const char* kName = "hid";
};

#define REQUIRE_UMOCKDEV(bed)                          \
  if (!(bed).active()) {                               \
    WARN(::facecap::test::Umockdev::inactive_message()); \
    return;                                            \
  }

std::vector<std::string> slot_labels(std::size_t n) {
  std::vector<std::string> labels;
  for (std::size_t i = 0; i < n; ++i) labels.push_back(fmt::format("M{:03d}", i));
  return labels;
}

test::FakeDeviceSpec spec(std::string serial, std::string port, Units units = Units::kMillimetres) {
  test::FakeDeviceSpec s;
  s.serial = std::move(serial);
  s.port = std::move(port);
  s.info.marker_capacity = 64;
  s.info.rate_mhz = 120000;
  s.info.max_rate_mhz = 240000;
  s.info.units = units;
  s.info.capabilities = kCapabilityRateSettable;
  s.info.max_chunk_bytes = 64;
  s.info.clock_hz = 1000000;
  return s;
}

drivers::MarkerDeviceOptions options(std::string serial = "") {
  drivers::MarkerDeviceOptions o;
  o.vendor_id = 0x1209;
  o.product_id = 0x0001;
  o.serial = std::move(serial);
  return o;
}

template <typename Predicate>
bool wait_for(Predicate done, int64_t timeout_ns = 10 * kNsPerSecond) {
  const int64_t give_up = monotonic_now_ns() + timeout_ns;
  while (!done()) {
    if (monotonic_now_ns() > give_up) return false;
    std::this_thread::sleep_for(std::chrono::milliseconds(2));
  }
  return true;
}

// The newest frame the source hands out within the timeout.
bool take(drivers::MarkerSource& source, MarkerFrame& frame) {
  return wait_for([&] { return source.take_frame(monotonic_now_ns(), frame); }, 5 * kNsPerSecond);
}

DeviceFrame grid_frame(uint32_t frame_no, uint16_t markers) {
  DeviceFrame f;
  f.frame_no = frame_no;
  f.device_time = 1234567 + uint64_t(frame_no) * 8333;
  for (uint16_t id = 0; id < markers; ++id)
    f.markers.push_back({id, 0, {float(id % 8) * 1.5f, float(id / 8) * 1.5f, 50.0f + float(frame_no) * 0.01f}});
  return f;
}

// The sim's frames streamed by a fake device at the sim's rate, numbered by the device's
// clock whether anyone reads them or not (as a device that stays powered does).
class SimStreamer {
 public:
  SimStreamer(test::FakeDeviceBase& device, drivers::SimSource& sim)
      : device_(device), sim_(sim), thread_([this] { run(); }) {}
  ~SimStreamer() {
    running_ = false;
    thread_.join();
  }
  // Stops sending (the device keeps counting) once the host has read what was sent.
  void pause() {
    paused_ = true;
    sending_.wait(true);
  }
  void resume() {
    mark_next_ = true;
    paused_ = false;
  }
  int64_t last_sent() const { return last_sent_; }
  int64_t first_sent_after_resume() const { return first_after_resume_; }

 private:
  void run() {
    const int64_t period_ns = int64_t(std::llround(kNsPerSecond / sim_.info().nominal_rate_hz));
    MarkerFrame frame = make_marker_frame(sim_.info().labels);
    int64_t next_ns = monotonic_now_ns();
    for (int64_t n = 0; running_; ++n, next_ns += period_ns) {
      sleep_until(next_ns);
      sending_ = !paused_;
      sending_.notify_all();
      if (paused_ || !device_.streaming()) continue;
      sim_.render_frame(n, frame);
      DeviceFrame out;
      out.frame_no = uint32_t(n);
      out.device_time = uint64_t(n * period_ns / 1000);  // a microsecond clock
      for (std::size_t k = 0; k < frame.markers.size(); ++k) {
        const Marker& m = frame.markers[k];
        out.markers.push_back({uint16_t(k), uint16_t(m.present() ? 0 : kMarkerOccluded),
                               {float(m.position.x()), float(m.position.y()), float(m.position.z())}});
      }
      device_.send_frame(out);
      if (mark_next_.exchange(false)) first_after_resume_ = n;
      last_sent_ = n;
      device_.wait_until_read(kNsPerSecond);  // false when unplugged meanwhile
    }
  }

  test::FakeDeviceBase& device_;
  drivers::SimSource& sim_;
  std::atomic<bool> running_{true}, paused_{false}, sending_{false}, mark_next_{false};
  std::atomic<int64_t> last_sent_{-1}, first_after_resume_{-1};
  std::thread thread_;
};

Units units_of(const std::string& text) {
  return text == "m" ? Units::kMetres : text == "cm" ? Units::kCentimetres : Units::kMillimetres;
}

std::shared_ptr<const Rig> builtin_rig() {
  return std::shared_ptr<const Rig>(std::shared_ptr<const Rig>(), &BuiltinFace::instance().rig());
}

}  // namespace

TEMPLATE_TEST_CASE("a marker device is found by vendor, product and serial among others", "", Usb, Hid) {
  test::Umockdev bed;
  REQUIRE_UMOCKDEV(bed);
  typename TestType::Fake a(bed, spec("SN-A", "1"));
  typename TestType::Fake b(bed, spec("SN-B", "2"));
  test::FakeDeviceSpec other = spec("SN-C", "3");
  other.marker_interface = false;  // same ids, another interface: not a marker device
  typename TestType::Fake c(bed, other);

  typename TestType::Source by_serial(options("SN-B"), slot_labels(52));
  by_serial.open();
  CHECK_THAT(by_serial.description(), Contains("serial SN-B") && Contains("protocol 1.0, 64 markers at 120 Hz in mm"));

  typename TestType::Source not_c(options("SN-C"), slot_labels(52));
  CHECK_THROWS_WITH(not_c.open(), Contains(fmt::format("no usable {} marker device 1209:0001, serial SN-C found",
                                                       std::string(TestType::kName) == "usb" ? "USB" : "HID")) &&
                                       Contains(fmt::format("source.{}.wait_for_device = true", TestType::kName)));

  drivers::MarkerDeviceOptions other_product = options();
  other_product.product_id = 0x0002;
  typename TestType::Source absent(other_product, slot_labels(52));
  CHECK_THROWS_WITH(absent.open(), Contains("1209:0002 found") && Contains("docs/usb-hid-protocol.md"));

  other_product.wait_for_device = true;  // absent, but waited for
  typename TestType::Source waiting(other_product, slot_labels(52));
  waiting.open();
  CHECK_THAT(std::string(waiting.health().state.view()), Contains("waiting") && Contains("1209:0002 to be plugged in"));
}

TEMPLATE_TEST_CASE("a frame spanning 16 packets arrives whole, in millimetres, in its slots", "", Usb, Hid) {
  test::Umockdev bed;
  REQUIRE_UMOCKDEV(bed);
  typename TestType::Fake device(bed, spec("SN-1", "1", Units::kCentimetres));
  drivers::MarkerDeviceOptions o = options();
  o.rate_hz = 240;
  typename TestType::Source source(o, slot_labels(52));
  source.open();
  source.start({.epoch_ns = monotonic_now_ns()});
  REQUIRE(wait_for([&] { return device.streaming(); }));
  CHECK(device.rate_mhz() == 240000);

  DeviceFrame sent = grid_frame(7, 53);  // ids 0..52: id 52 has no slot
  sent.markers[5].flags = kMarkerOccluded;
  sent.markers[6].flags = formats::device::kMarkerUnlabelled;
  REQUIRE(encode_frame_chunks(sent, 64).size() == 16);
  device.send_frame(sent);
  MarkerFrame got = make_marker_frame(slot_labels(52));
  REQUIRE(take(source, got));
  CHECK(got.frame_no == 7);
  CHECK(got.source_time_ns == (1234567 + 7 * 8333) * kNsPerUs);
  for (std::size_t k = 0; k < 52; ++k) {
    INFO("slot " << k);
    if (k == 5) {
      CHECK_FALSE(got.markers[k].present());
      continue;
    }
    const auto& p = sent.markers[k].position;
    CHECK(got.markers[k].present());
    CHECK((got.markers[k].position - 10.0 * Eigen::Vector3d(p[0], p[1], p[2])).norm() < 1e-4);  // cm -> mm
  }
  CHECK(got.markers[6].flags == facecap::kMarkerUnlabelled);
  CHECK(source.markers_ignored() == 1);
  CHECK(source.health().errors == 0);
  source.stop();
  CHECK_FALSE(device.streaming());  // stop asked the device to stop
}

TEMPLATE_TEST_CASE("a device absent at start is waited for and streams once plugged in", "", Usb, Hid) {
  test::Umockdev bed;
  REQUIRE_UMOCKDEV(bed);
  typename TestType::Fake device(bed, spec("SN-1", "1"), /*plugged_in=*/false);
  drivers::MarkerDeviceOptions o = options();
  o.wait_for_device = true;
  typename TestType::Source source(o, slot_labels(52));
  source.open();
  CHECK_THAT(source.description(), Contains("not present yet"));
  source.start({.epoch_ns = monotonic_now_ns()});
  std::this_thread::sleep_for(std::chrono::milliseconds(300));
  CHECK_THAT(std::string(source.health().state.view()), Contains("waiting 0.") && Contains("to be plugged in"));
  device.plug();
  REQUIRE(wait_for([&] { return device.streaming(); }));
  device.send_frame(grid_frame(1, 52));
  MarkerFrame got = make_marker_frame(slot_labels(52));
  REQUIRE(take(source, got));
  CHECK(got.present_count() == 52);
  CHECK(source.health().state.empty());  // streaming as if it had been there all along
  CHECK(source.health().reconnects == 0);
  source.stop();
}

TEMPLATE_TEST_CASE("a frame with a bad CRC is counted and dropped and the next one delivered", "", Usb, Hid) {
  test::Umockdev bed;
  REQUIRE_UMOCKDEV(bed);
  typename TestType::Fake device(bed, spec("SN-1", "1"));
  typename TestType::Source source(options(), slot_labels(52));
  source.open();
  source.start({.epoch_ns = monotonic_now_ns()});
  REQUIRE(wait_for([&] { return device.streaming(); }));
  MarkerFrame got = make_marker_frame(slot_labels(52));

  device.send_frame(grid_frame(1, 52));
  REQUIRE(take(source, got));
  CHECK(got.frame_no == 1);

  auto chunks = encode_frame_chunks(grid_frame(2, 52), 64);
  chunks.back().back() ^= 0xFF;  // the CRC's last byte
  for (auto& chunk : chunks) device.send_chunk(chunk);
  device.send_frame(grid_frame(3, 52));
  REQUIRE(take(source, got));
  CHECK(got.frame_no == 3);
  CHECK(source.health().errors == 1);
  CHECK(source.frames_dropped() == 1);
  CHECK(source.health().frames_overwritten == 0);  // frame 2 never reached the mailbox
  source.stop();
}

TEMPLATE_TEST_CASE("unplugged and plugged in again while facecapd runs: frames resume and the gap is reported", "",
                   Usb, Hid) {
  test::Umockdev bed;
  REQUIRE_UMOCKDEV(bed);
  // The device streams the sim's performance of the default marker set (48 face + 4 head).
  const config::DaemonConfig defaults = config::default_config();
  const auto rig = builtin_rig();
  const pipeline::Calibration calibration = pipeline::load_calibration(pipeline::calibration_spec(defaults), *rig);
  drivers::SimSource sim(defaults.source.sim, rig, pipeline::rest_marker_set(calibration));
  sim.open();
  typename TestType::Fake device(bed, spec("SN-1", "1", units_of(sim.info().units)));
  SimStreamer streamer(device, sim);

  const std::string shm = fmt::format("facecap-test-{}-{}-replug", ::getpid(), TestType::kName);
  daemon::Daemon d({.handle_signals = false},
                   config::load_config("", {fmt::format("source.driver={}", TestType::kName),
                                            fmt::format("source.{}.vendor_id=4617", TestType::kName),
                                            fmt::format("source.{}.serial=SN-1", TestType::kName),
                                            "outputs.shm.name=" + shm, "loop.realtime=false"}));
  d.start();
  std::thread supervisor([&] { d.run(); });
  struct StopAtExit {  // also when a REQUIRE ends the test early
    daemon::Daemon& d;
    std::thread& supervisor;
    ~StopAtExit() {
      d.request_stop();
      supervisor.join();
    }
  } stop_at_exit{d, supervisor};
  auto solved = [&] { return d.loop()->counters().frames_solved.load(); };
  auto state = [&] { return std::string(d.source()->health().state.view()); };

  REQUIRE(wait_for([&] { return solved() >= 60; }));
  streamer.pause();
  const int64_t last_before = streamer.last_sent();
  device.unplug();
  REQUIRE(wait_for([&] { return state().find("lost") != std::string::npos; }));
  const uint64_t solved_while_away = solved();
  std::this_thread::sleep_for(std::chrono::milliseconds(500));
  CHECK(solved() <= solved_while_away + 1);  // nothing new to solve (one frame may have been in the mailbox)
  CHECK_THAT(state(), Contains("waiting for it to return"));
  CHECK_THAT(d.status_line(d.figures_since_start()), Contains("source: ") && Contains("lost"));

  device.plug();
  streamer.resume();
  REQUIRE(wait_for([&] { return solved() >= solved_while_away + 60; }));
  REQUIRE(wait_for([&] { return state().find("streaming again") != std::string::npos; }));
  const int64_t first_after = streamer.first_sent_after_resume();
  INFO(state());
  CHECK(first_after > last_before + 1);
  CHECK_THAT(state(), Contains(fmt::format("({} frames missed)", first_after - last_before - 1)));
  CHECK(std::regex_search(state(), std::regex("after a 0\\.[5-9][0-9] s gap|after a [1-9]\\.[0-9]+ s gap")));
  CHECK(d.source()->health().reconnects == 1);
}
