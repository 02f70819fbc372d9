// facecap inspect and convert, run as processes the way operators run them.
#include <cstdio>
#include <fstream>
#include <sstream>

#include <catch2/catch.hpp>
#include <nlohmann/json.hpp>
#include <sys/wait.h>

#include "core/io.hpp"
#include "formats/c3d.hpp"
#include "formats/livelinkface.hpp"
#include "formats/natnet.hpp"
#include "formats/recording.hpp"
#include "tests/capture_test_support.hpp"
#include "tests/formats_test_support.hpp"
#include "tests/test_support.hpp"

using namespace facecap;
using namespace facecap::formats;

namespace {

using test::Run;
using test::run_facecap;
using test::slurp;


}  // namespace

TEST_CASE("facecap inspect --json lists format, frames, rate, markers, labels, units, gaps, first frame", "[tools]") {
  const auto dir = facecap::test::scratch_dir("tool-inspect");
  const MarkerTake take = facecap::test::synthetic_take(25, 5, 50.0);  // marker 3 missing in frame 0
  write_take(dir / "take.c3d", take);
  const Run run = run_facecap(dir, {"inspect", (dir / "take.c3d").string(), "--json"});
  INFO(run.err);
  REQUIRE(run.exit_code == 0);
  const auto j = nlohmann::json::parse(run.out);
  CHECK(j["format"] == "c3d");
  CHECK(j["frames"] == 25);
  CHECK(j["rate_hz"] == 50.0);
  CHECK(j["markers"] == 5);
  CHECK(j["labels"] == std::vector<std::string>{"M000", "M001", "M002", "M003", "M004"});
  CHECK(j["units"] == "mm");
  CHECK(j["gaps"] == count_gaps(take).missing_samples);
  REQUIRE(j["first_frame"].size() == 5);
  CHECK(j["first_frame"][3].is_null());
  const auto& first = take.frames[0].markers;
  for (std::size_t k = 0; k < 5; ++k) {
    if (first[k].present()) {
      CHECK(j["first_frame"][k][0].get<double>() == Approx(first[k].position.x()).margin(1e-4));
      CHECK(j["first_frame"][k][2].get<double>() == Approx(first[k].position.z()).margin(1e-4));
    } else {
      CHECK(j["first_frame"][k].is_null());
    }
  }
}

TEST_CASE("facecap inspect reads Live Link Face CSV and recordings", "[tools]") {
  const auto dir = facecap::test::scratch_dir("tool-inspect-kinds");
  FaceTake face;
  for (int i = 0; i < 6; ++i) {
    FaceFrame& f = face.frames.emplace_back();
    f.timecode = *parse_livelink_timecode(fmt::format("01:00:00:{:02}.000", i));
    f.tracked = i != 2;
    f.weights.fill(f.tracked ? 0.5f : NAN);
  }
  const std::string csv = write_livelinkface(face);
  facecap::test::write_text(dir / "face.csv", csv);
  const Run csv_run = run_facecap(dir, {"inspect", (dir / "face.csv").string(), "--json"});
  INFO(csv_run.err);
  REQUIRE(csv_run.exit_code == 0);
  const auto j = nlohmann::json::parse(csv_run.out);
  CHECK(j["format"] == "livelinkface");
  CHECK(j["frames"] == 6);
  CHECK(j["gaps"] == 1);
  CHECK(j["rate_hz"] == 60.0);
  CHECK(j["first_weights"]["JawOpen"] == 0.5);

  write_take(dir / "take.fcrec", facecap::test::synthetic_take(10, 2));
  const Run rec_run = run_facecap(dir, {"inspect", (dir / "take.fcrec").string()});
  INFO(rec_run.err);
  REQUIRE(rec_run.exit_code == 0);
  CHECK(rec_run.out.find("format    fcrec") != std::string::npos);
  CHECK(rec_run.out.find("frames    10") != std::string::npos);
  CHECK(rec_run.out.find("M001") != std::string::npos);
}

TEST_CASE("facecap convert C3D -> TRC -> fcrec keeps the take, progress on request", "[tools]") {
  const auto dir = facecap::test::scratch_dir("tool-convert");
  const MarkerTake take = facecap::test::synthetic_take(1200, 4);
  write_take(dir / "in.c3d", take);
  const Run to_trc = run_facecap(dir, {"convert", (dir / "in.c3d").string(), (dir / "out.trc").string(), "--progress"});
  INFO(to_trc.err);
  REQUIRE(to_trc.exit_code == 0);
  CHECK(to_trc.out.find("1200 frames, 4 markers") != std::string::npos);
  CHECK(to_trc.err.find("writing out.trc: 100% (1200/1200 frames") != std::string::npos);
  const Run to_rec = run_facecap(dir, {"convert", (dir / "out.trc").string(), (dir / "out.fcrec").string()});
  REQUIRE(to_rec.exit_code == 0);
  CHECK(to_rec.err.empty());  // no terminal, no --progress: no bar
  facecap::test::require_same_points(take, read_take(dir / "out.fcrec"), 1e-4);

  const Run refused = run_facecap(dir, {"convert", (dir / "in.c3d").string(), (dir / "out.trc").string()});
  CHECK(refused.exit_code == 1);
  CHECK(refused.err.find("out.trc: exists; pass --force") != std::string::npos);
  CHECK(run_facecap(dir, {"convert", (dir / "in.c3d").string(), (dir / "out.trc").string(), "--force"}).exit_code == 0);
}

TEST_CASE("facecap inspect and convert report bad input with file and place", "[tools]") {
  const auto dir = facecap::test::scratch_dir("tool-errors");
  auto bytes = write_c3d(facecap::test::synthetic_take(5, 2));
  bytes.resize(bytes.size() - 512);  // data cut short
  write_file_atomically(dir / "short.c3d", bytes);
  const Run run = run_facecap(dir, {"inspect", (dir / "short.c3d").string()});
  CHECK(run.exit_code == 1);
  CHECK(run.err.find("short.c3d @ byte 1024: data section holds 0 complete frames") != std::string::npos);
  CHECK(run.out.empty());

  const Run csv = run_facecap(dir, {"convert", (dir / "short.c3d").string(), (dir / "x.csv").string()});
  CHECK(csv.exit_code == 1);
  CHECK(csv.err.find("short.c3d: a Live Link Face CSV is written from a .fcrec recording's solved frames") !=
        std::string::npos);
}

TEST_CASE("facecap inspect exits 1 with the reader's message on a C3D claiming 4e9 points", "[tools][hostile]") {
  // It aborted with an uncaught std::bad_alloc (exit 134).
  const auto dir = facecap::test::scratch_dir("tool-hostile");
  const auto bytes = facecap::test::c3d_with_real_point_count(4e9f);
  std::ofstream(dir / "used.c3d", std::ios::binary).write(bytes.data(), std::streamsize(bytes.size()));
  const Run run = run_facecap(dir, {"inspect", (dir / "used.c3d").string()});
  CHECK(run.exit_code == 1);
  CHECK_THAT(run.err, Catch::Contains("facecap: error:") && Catch::Contains("used.c3d @ byte 536") &&
                          Catch::Contains("POINT:USED is 4000000000"));
}

TEST_CASE("facecap inspect on shared data: Eb015pi JSON and --time", "[tools][shared]") {
  FACECAP_REQUIRE_SHARED_DATA(path, "c3d/Eb015pi.c3d");
  const auto dir = facecap::test::scratch_dir("tool-inspect-shared");
  const Run run = run_facecap(dir, {"inspect", path.string(), "--json", "--time", "--repeat", "3"});
  INFO(run.err);
  REQUIRE(run.exit_code == 0);
  const auto j = nlohmann::json::parse(run.out);
  CHECK(j["frames"] == 450);
  CHECK(j["markers"] == 26);
  CHECK(j["gaps"] == 226);
  CHECK(j["labels"][0] == "RFT1");
  CHECK(j["first_frame"][0][0].get<double>() == Approx(248.583).margin(1e-3));
  CHECK(j["read_ms"]["reads"] == 3);
  CHECK(j["read_ms"]["min"].get<double>() > 0.0);
}

TEST_CASE("facecap inspect decodes a NatNet capture: all 518 frames with markers, bodies and sets",
          "[tools][natnet][shared]") {
  // Expected values from the UDP payloads tshark shows (`tshark -r traffic.pcapng -Y
  // udp.dstport==1511 -T fields -e data.data`) decoded with Python's struct module
  // ('<i' counts, '<i7ffh' rigid bodies, '<i4fhf' labelled markers), run once by hand.
  FACECAP_REQUIRE_SHARED_DATA(path, "natnet/traffic.pcapng");
  const auto dir = facecap::test::scratch_dir("tool-inspect-natnet");
  const Run run = run_facecap(dir, {"inspect", path.string(), "--json", "--frames"});
  INFO(run.err);
  REQUIRE(run.exit_code == 0);
  const auto j = nlohmann::json::parse(run.out);
  CHECK(j["frames"] == 518);
  CHECK(j["natnet_version"] == "3.0");
  CHECK(j["rate_hz"].get<double>() == Approx(120.0).epsilon(1e-9));
  const auto& frames = j["frame_list"];
  REQUIRE(frames.size() == 518);
  std::size_t labelled = 0, bodies = 0, sets = 0;
  for (const auto& f : frames) {
    labelled += f["labelled_markers"].size();
    bodies += f["rigid_bodies"].size();
    sets += f["marker_sets"].size();
    CHECK(f["timecode"] == "00:00:00:00.0");
  }
  CHECK(labelled == 3108);  // 6 a frame
  CHECK(bodies == 518);
  CHECK(sets == 0);  // Motive sent its marker sets' definitions but no marker-set data
  const auto& first = frames[0];
  CHECK(first["frame_number"] == 162734);
  CHECK(first["timestamp_s"].get<double>() == 1356.1166666666666);
  const auto& marker = first["labelled_markers"][0];
  CHECK(marker["id"] == 131073);
  CHECK(marker["model_id"] == 2);
  CHECK(marker["marker_id"] == 1);
  CHECK(marker["occluded"] == false);
  CHECK(marker["pos"][0].get<double>() == double(0.12721621990203857f));
  CHECK(marker["pos"][2].get<double>() == double(-0.8858283758163452f));
  CHECK(first["labelled_markers"][5]["model_id"] == 0);
  CHECK(first["labelled_markers"][5]["marker_id"] == 50007);
  const auto& body = first["rigid_bodies"][0];
  CHECK(body["id"] == 2);
  CHECK(body["rot"][3].get<double>() == double(-0.8573576807975769f));
  const auto& last = frames[517];
  CHECK(last["frame_number"] == 163251);
  CHECK(last["rigid_bodies"][0]["pos"][0].get<double>() == double(0.17443732917308807f));
  CHECK(last["labelled_markers"][5]["pos"][2].get<double>() == double(-0.8401832580566406f));

  const Run summary = run_facecap(dir, {"inspect", path.string()});
  REQUIRE(summary.exit_code == 0);
  CHECK(summary.out.find("natnet    bitstream 3.0 (from server info)") != std::string::npos);
  CHECK(summary.out.find("NAT_FRAMEOFDATA            518") != std::string::npos);
  CHECK(summary.out.find("frames    518 (numbers 162734..163251") != std::string::npos);
  CHECK(summary.out.find("rigid body   RaceQuad") != std::string::npos);
  CHECK(summary.out.find("skipped   0 records") != std::string::npos);

  // The capture options belong to captures.
  const Run refused = run_facecap(dir, {"inspect", path.string(), "--natnet-version", "2.9"});
  CHECK(refused.exit_code != 0);
  CHECK(refused.err.find("a NatNet bitstream 3.x or 4.x") != std::string::npos);
}

TEST_CASE("facecap inspect on a capture without a session start uses --natnet-version", "[tools][natnet]") {
  // Two 4.1 frames sent to the data port and nothing else: without --natnet-version they
  // are read as 3.0 and refused, with the record and byte named.
  namespace natnet = formats::natnet;
  using namespace facecap::test;
  const auto dir = scratch_dir("tool-inspect-natnet-option");
  std::vector<PcapRecord> records;
  for (int32_t n = 1; n <= 2; ++n) {
    natnet::FrameOfData frame;
    frame.frame_number = n;
    frame.timestamp_s = n / 100.0;
    frame.labelled_markers = {{7, {1.f, 2.f, 3.f}, 0.01f, 0x01, 0.f}};
    const auto packet = bytes_of(natnet::encode_message({natnet::MessageId::kFrameOfData, frame}, natnet::kBitstream41));
    const auto ip = ipv4_packet({10, 0, 0, 1}, {239, 255, 42, 99}, 17, udp_segment(1511, 1511, packet));
    records.push_back({n * 10'000'000, ethernet_frame(0x0800, ip)});
  }
  const auto capture = (dir / "frames.pcap").string();
  write_file_atomically(capture, pcap_file(1, records));
  const Run as41 = run_facecap(dir, {"inspect", capture, "--json", "--frames", "--natnet-version", "4.1"});
  INFO(as41.err);
  REQUIRE(as41.exit_code == 0);
  const auto j = nlohmann::json::parse(as41.out);
  CHECK(j["frames"] == 2);
  CHECK(j["natnet_version"] == "4.1");
  CHECK(j["rate_hz"].get<double>() == Approx(100.0));
  CHECK(j["frame_list"][1]["labelled_markers"][0]["occluded"] == true);

  const Run as30 = run_facecap(dir, {"inspect", capture});
  REQUIRE(as30.exit_code == 0);
  CHECK(as30.out.find("natnet    bitstream 3.0 (from option)") != std::string::npos);
  CHECK(as30.out.find("2 not NatNet") != std::string::npos);
  CHECK(as30.out.find("error     frames.pcap record 1 @ byte ") != std::string::npos);
}

TEST_CASE("facecap inspect and convert read a damaged recording's other frames and say what they skipped", "[tools]") {
  // 120 loop frames (markers and weights), one bit flipped in a marker and in a solved
  // chunk, the tail cut off (the writer killed): 119 of each kind read back.
  const auto dir = facecap::test::scratch_dir("tool-damaged-recording");
  const MarkerTake take = facecap::test::synthetic_take(120, 4);
  RecordingHeader header;
  header.units = take.units;
  header.rate_hz = take.rate_hz;
  header.marker_labels = take.labels;
  header.shape_names = {"jawOpen", "eyeBlinkLeft"};
  header.rig_units = "cm";
  std::vector<uint64_t> marker_chunk, solved_chunk;
  {
    RecordingWriter writer(dir / "clean.fcrec", header);
    SolvedFrame solved;
    solved.resize(2, 0);
    for (std::size_t i = 0; i < take.frames.size(); ++i) {
      marker_chunk.push_back(writer.bytes_written());
      writer.append_marker_frame(take.frames[i]);
      solved.frame_no = take.frames[i].frame_no;
      solved.weights << 0.5f, float(i) / 200.0f;
      solved_chunk.push_back(writer.bytes_written());
      writer.append_solved_frame(solved);
    }
    writer.close();
  }
  std::vector<char> bytes = read_file_bytes(dir / "clean.fcrec");
  bytes[marker_chunk[30] + 100] ^= 0x04;
  bytes[solved_chunk[80] + 9] ^= 0x40;  // the checksum
  bytes.resize(bytes.size() - 8);
  write_file_atomically(dir / "damaged.fcrec", bytes);

  const Run inspect = run_facecap(dir, {"inspect", (dir / "damaged.fcrec").string(), "--json"});
  INFO(inspect.err);
  REQUIRE(inspect.exit_code == 0);
  const auto j = nlohmann::json::parse(inspect.out);
  CHECK(j["frames"] == 119);
  CHECK(j["solved"]["frames"] == 119);
  CHECK_THAT(j["warnings"].dump(), Catch::Contains("recording damaged: 2 damaged stretches skipped") &&
                                       Catch::Contains(fmt::format("at byte {}", marker_chunk[30])));

  const Run trc = run_facecap(dir, {"convert", (dir / "damaged.fcrec").string(), (dir / "out.trc").string()});
  INFO(trc.err);
  REQUIRE(trc.exit_code == 0);
  CHECK_THAT(trc.err, Catch::Contains("2 damaged stretches skipped"));
  CHECK(read_take(dir / "out.trc").frames.size() == 119);

  const Run csv = run_facecap(dir, {"convert", (dir / "damaged.fcrec").string(), (dir / "out.csv").string()});
  INFO(csv.err);
  REQUIRE(csv.exit_code == 0);
  CHECK_THAT(csv.err, Catch::Contains("damaged: 2 damaged stretches skipped"));
  CHECK(read_livelinkface(dir / "out.csv").frames.size() == 119);
}

TEST_CASE("facecap inspect and convert --salvage read a recording whose HEAD is damaged and has no copy", "[tools][salvage]") {
  const auto dir = facecap::test::scratch_dir("tool-salvage");
  write_take(dir / "take.fcrec", facecap::test::synthetic_take(50, 5, 60.0));
  std::vector<char> bytes = read_file_bytes(dir / "take.fcrec");
  // As a writer killed before close() leaves it (no HEAD copy), less the last frame, and
  // HEAD's first string made 4,096 bytes longer than the chunk.
  bytes.resize(std::size_t(RecordingReader(bytes, "take").index().back().offset));
  bytes[33] = char(bytes[33] ^ 0x10);
  write_file_atomically(dir / "damaged.fcrec", bytes);

  const Run refused = run_facecap(dir, {"inspect", (dir / "damaged.fcrec").string()});
  CHECK(refused.exit_code == 1);
  CHECK_THAT(refused.err, Catch::Contains("damaged.fcrec @ byte 16") && Catch::Contains("--salvage"));
  const Run inspect = run_facecap(dir, {"inspect", "--salvage", "--json", (dir / "damaged.fcrec").string()});
  INFO(inspect.err);
  REQUIRE(inspect.exit_code == 0);
  const auto j = nlohmann::json::parse(inspect.out);
  CHECK(j["frames"] == 49);
  CHECK(j["markers"] == 5);
  CHECK_THAT(j["warnings"].dump(), Catch::Contains("HEAD damaged") && Catch::Contains("salvaged"));
  const Run convert = run_facecap(dir, {"convert", "--salvage", (dir / "damaged.fcrec").string(), (dir / "repaired.fcrec").string()});
  INFO(convert.err);
  REQUIRE(convert.exit_code == 0);
  const RecordingReader repaired(dir / "repaired.fcrec");
  CHECK(repaired.header_damage().empty());
  CHECK(repaired.marker_frame_count() == 49);
}
