// NatNet frames to marker frames (formats/natnet_markers.hpp) on real Motive packets and
// on frames written for each case: the marker set's slots from labelled markers and their
// flags, from marker set data, unlabelled points, new model definitions followed by name;
// a capture replayed as a take; and the text requests natnet-serve answers.
#include <cmath>

#include <catch2/catch.hpp>

#include "core/error.hpp"
#include "core/io.hpp"
#include "drivers/capture/capture_file.hpp"
#include "formats/natnet_markers.hpp"
#include "formats/natnet_request.hpp"
#include "tests/test_support.hpp"

using namespace facecap;
using namespace facecap::capture;
using namespace facecap::formats::natnet;
using Catch::Contains;

namespace {

Eigen::Vector3d vec(const Position& p) { return {double(p[0]), double(p[1]), double(p[2])}; }

FrameOfData real_frame(const std::filesystem::path& file) {
  return std::get<FrameOfData>(parse_message(read_file_bytes(file), kBitstream30, file.filename().string()).body);
}

// The real occluded packet's rigid body (id 7) described as Motive does: a marker set and a
// rigid body of one name.
ModelDefinitions fake_tree_models() {
  ModelDefinitions defs;
  defs.models = {MarkerSetDescription{"FakeTree", {"M1", "M2", "M3", "M4", "M5"}},
                 RigidBodyDescription{"FakeTree", 7, -1, {}, {0, 0, 0, 1}, {}},
                 MarkerSetDescription{"all", {"FakeTree_1", "FakeTree_2", "FakeTree_3", "FakeTree_4", "FakeTree_5"}}};
  return defs;
}

}  // namespace

TEST_CASE("a real Motive frame's labelled markers fill the marker set's slots with its occlusion", "[natnet]") {
  FACECAP_REQUIRE_SHARED_DATA(dir, "natnet");
  const FrameOfData frame = real_frame(dir / "mocapframe_packet_occluded_v3.bin");
  FrameConverter converter({.marker_set = "FakeTree", .unlabelled_slots = 2}, fake_tree_models(), "Motive");
  REQUIRE(converter.labels() == std::vector<std::string>{"M1", "M2", "M3", "M4", "M5", "unlabelled_1", "unlabelled_2"});
  MarkerFrame out = make_marker_frame(converter.labels());
  const ConversionCounts counts = converter.convert(frame, out);

  CHECK(out.frame_no == 269007);
  // Marker 1 has no labelled marker this frame, marker 2 is occluded: both missing, though
  // the marker set data holds positions for them (the rigid body's).
  CHECK_FALSE(out.markers[0].present());
  CHECK_FALSE(out.markers[1].present());
  CHECK(out.markers[1].id == (7 << 16 | 2));
  CHECK(std::isnan(out.markers[1].position.x()));
  for (std::size_t k = 2; k < 5; ++k) {
    INFO("slot " << k);
    REQUIRE(out.markers[k].present());
    CHECK(out.markers[k].id == int32_t(7 << 16 | (k + 1)));
    CHECK(out.markers[k].position == vec(frame.labelled_markers[k - 1].position));
    CHECK(out.markers[k].flags == 0);
  }
  CHECK(out.markers[2].position == Eigen::Vector3d(double(-0.12027807533740997f), double(0.18182460963726044f),
                                                   double(0.462637722492218f)));
  CHECK(counts.set_markers == 3);
  CHECK(counts.unlabelled == 0);
  CHECK_FALSE(out.markers[5].present());
  CHECK((out.markers[5].flags & kMarkerUnlabelled) != 0);
}

TEST_CASE("a real Motive capture replays as a take of the rigid body's markers at its recorded timing", "[natnet]") {
  FACECAP_REQUIRE_SHARED_DATA(dir, "natnet");
  const NatNetCapture capture = read_natnet_capture(dir / "traffic.pcapng");
  const formats::MarkerTake take = capture_take(capture, {.marker_set = "RaceQuad", .unlabelled_slots = 2}, "traffic");
  CHECK(take.format == formats::TakeFormat::kNatNetCapture);
  REQUIRE(take.labels ==
          std::vector<std::string>{"Marker1", "Marker2", "Marker3", "Marker4", "Marker5", "unlabelled_1", "unlabelled_2"});
  REQUIRE(take.frames.size() == 518);
  CHECK(take.first_frame == 162734);
  CHECK(take.frames.back().frame_no == 163251);
  CHECK(take.rate_hz == Approx(120.0).epsilon(1e-6));
  CHECK(take.units == "m");
  CHECK(take.metadata_value("server") == "Motive");
  CHECK(take.metadata_value("bitstream") == "3.0");
  formats::check_take_shape(take, "traffic");

  const MarkerFrame& first = take.frames.front();
  CHECK(first.markers[0].id == 131073);
  CHECK(first.markers[0].position ==
        Eigen::Vector3d(double(0.12721621990203857f), double(1.5050275325775146f), double(-0.8858283758163452f)));
  CHECK(first.markers[4].position.x() == double(0.32139891386032104f));
  // The one point without a model goes to the first unlabelled slot; the second stays empty.
  CHECK(first.markers[5].id == 50007);
  CHECK(first.markers[5].flags == kMarkerUnlabelled);
  CHECK(first.markers[5].position.x() == double(0.17081165313720703f));
  CHECK_FALSE(first.markers[6].present());
  CHECK(first.present_count() == 6);

  std::size_t complete = 0;
  for (std::size_t i = 0; i < take.frames.size(); ++i) {
    complete += take.frames[i].present_count() == 6;
    if (i > 0) CHECK(take.frames[i].source_time_ns > take.frames[i - 1].source_time_ns);
  }
  CHECK(complete == 518);
  // Capture times (the recorded timing, 4.308821 s from the first frame to the last), not
  // Motive's timestamps (517 / 120 = 4.308333 s).
  const auto first_frame = std::find_if(capture.messages.begin(), capture.messages.end(), [](const CapturedMessage& m) {
    return m.message.id == MessageId::kFrameOfData;
  });
  CHECK(first.source_time_ns == first_frame->capture_time_ns);
  CHECK(take.frames.back().source_time_ns - first.source_time_ns == 4'308'821'000);

  CHECK_THROWS_WITH(capture_take(capture, {.marker_set = "Face"}, "traffic"),
                    Contains("no marker set 'Face'") && Contains("'RaceQuad', 'all'"));
  CHECK_THROWS_WITH(formats::read_take(dir / "traffic.pcapng"), Contains("a packet capture"));
}

TEST_CASE("without labelled markers of its model the marker set data fills the slots, (0, 0, 0) missing", "[natnet]") {
  ModelDefinitions defs;
  defs.models = {MarkerSetDescription{"Face", {"Brow", "Chin", "Nose"}}};
  FrameConverter converter({.marker_set = "Face"}, defs, "10.0.0.5");
  FrameOfData frame;
  frame.frame_number = 12;
  frame.marker_sets = {{"all", {{9.f, 9.f, 9.f}}}, {"Face", {{0.1f, 0.2f, 0.3f}, {0.f, 0.f, 0.f}, {0.4f, 0.5f, 0.6f}}}};
  frame.labelled_markers = {{5 << 16 | 1, {7.f, 7.f, 7.f}, 0.01f, 0, 0.f}};  // another model's
  MarkerFrame out = make_marker_frame(converter.labels());
  CHECK(converter.convert(frame, out).set_markers == 2);
  CHECK(out.markers[0].position == vec({0.1f, 0.2f, 0.3f}));
  CHECK_FALSE(out.markers[1].present());
  CHECK(out.markers[2].position == vec({0.4f, 0.5f, 0.6f}));
}

TEST_CASE("a 4.1 asset's markers are found by their ids, model-solved flagged, points without a model unlabelled",
          "[natnet]") {
  ModelDefinitions defs;
  AssetDescription face{"Anna", 1, 21, {}, {}};
  face.markers = {{"Anna_Chin", 40, {}, 0.01f, 0}, {"Anna_Brow", 17, {}, 0.01f, 0}, {"Nose", 3, {}, 0.01f, 0}};
  defs.models = {MarkerSetDescription{"Anna", {"Brow", "Chin", "Nose"}}, face};
  FrameConverter converter({.marker_set = "Anna", .unlabelled_slots = 1, .timecode_rate_hz = 25}, defs, "Motive");
  FrameOfData frame;
  frame.frame_number = 1000;
  frame.timestamp_s = 2.5;
  frame.timecode = 0x0102031e;  // 01:02:03:30
  frame.timecode_subframe = 1;
  frame.labelled_markers = {{21 << 16 | 40, {0.f, -0.1f, 0.05f}, 0.01f, 0x04, 0.f},   // Chin, model solved
                            {21 << 16 | 17, {0.f, 0.1f, 0.05f}, 0.01f, 0x02, 0.f},    // Brow
                            {21 << 16 | 3, {0.f, 0.f, 0.1f}, 0.01f, 0x01, 0.f},       // Nose, occluded
                            {50001, {1.f, 1.f, 1.f}, 0.01f, 0x10, 0.f},               // no model
                            {50002, {2.f, 2.f, 2.f}, 0.01f, 0x10, 0.f}};              // no slot left
  MarkerFrame out = make_marker_frame(converter.labels());
  const ConversionCounts counts = converter.convert(frame, out);
  CHECK(out.frame_no == 1000);
  CHECK(out.source_time_ns == 2'500'000'000);
  CHECK(out.timecode == facecap::Timecode{1, 2, 3, 30, 1.0f, 25});
  CHECK(out.markers[0].position == vec({0.f, 0.1f, 0.05f}));
  CHECK(out.markers[0].flags == 0);
  CHECK(out.markers[1].position == vec({0.f, -0.1f, 0.05f}));
  CHECK(out.markers[1].flags == kMarkerModelSolved);
  CHECK_FALSE(out.markers[2].present());
  CHECK(out.markers[3].id == 50001);
  CHECK(out.markers[3].flags == kMarkerUnlabelled);
  CHECK(counts.set_markers == 2);
  CHECK(counts.unlabelled == 1);
  CHECK(counts.unlabelled_dropped == 1);
}

TEST_CASE("new model definitions are followed by marker name, and what changed is said", "[natnet]") {
  ModelDefinitions defs;
  defs.models = {MarkerSetDescription{"Face", {"Brow", "Chin", "Nose"}}, RigidBodyDescription{"Face", 4, -1, {}, {}, {}}};
  FrameConverter converter({.marker_set = "Face"}, defs, "10.0.0.5");
  // The server restarted with the set reordered, Chin gone, Lip new, and another model id.
  ModelDefinitions later;
  later.models = {MarkerSetDescription{"Face", {"Nose", "Lip", "Brow"}}, RigidBodyDescription{"Face", 9, -1, {}, {}, {}}};
  const std::string note = converter.follow(later);
  CHECK_THAT(note, Contains("no longer has 1 of its markers (Chin)") && Contains("did not have at the start (Lip)"));
  CHECK(converter.labels() == std::vector<std::string>{"Brow", "Chin", "Nose"});
  FrameOfData frame;
  frame.labelled_markers = {{9 << 16 | 1, {0.3f, 0.f, 0.f}, 0.01f, 0, 0.f},   // Nose
                            {9 << 16 | 2, {0.5f, 0.f, 0.f}, 0.01f, 0, 0.f},   // Lip
                            {9 << 16 | 3, {0.1f, 0.f, 0.f}, 0.01f, 0, 0.f},   // Brow
                            {4 << 16 | 2, {0.9f, 0.f, 0.f}, 0.01f, 0, 0.f}};  // the old id: nobody's now
  MarkerFrame out = make_marker_frame(converter.labels());
  CHECK(converter.convert(frame, out).set_markers == 2);
  CHECK(out.markers[0].position.x() == double(0.1f));
  CHECK_FALSE(out.markers[1].present());
  CHECK(out.markers[2].position.x() == double(0.3f));

  ModelDefinitions gone;
  CHECK_THAT(converter.follow(gone), Contains("not in 10.0.0.5's model definitions now"));
  CHECK(converter.convert(frame, out).set_markers == 0);
  CHECK(converter.follow(defs).empty());
}

TEST_CASE("without a marker set every marker seen is an unlabelled point, legacy other markers when none", "[natnet]") {
  FrameConverter converter({.unlabelled_slots = 3}, {}, "Motive");
  FrameOfData frame;
  frame.labelled_markers = {{2 << 16 | 1, {0.1f, 0.f, 0.f}, 0.01f, 0, 0.f},
                            {2 << 16 | 2, {0.2f, 0.f, 0.f}, 0.01f, 0x01, 0.f},  // occluded: not seen
                            {50003, {0.3f, 0.f, 0.f}, 0.01f, 0x10, 0.f}};
  MarkerFrame out = make_marker_frame(converter.labels());
  CHECK(converter.convert(frame, out).unlabelled == 2);
  CHECK(out.markers[0].position.x() == double(0.1f));
  CHECK(out.markers[1].position.x() == double(0.3f));
  CHECK_FALSE(out.markers[2].present());
  FrameOfData legacy;
  legacy.other_markers = {{1.f, 2.f, 3.f}};
  CHECK(converter.convert(legacy, out).unlabelled == 1);
  CHECK(out.markers[0].position == Eigen::Vector3d(1, 2, 3));

  CHECK_THROWS_WITH(FrameConverter({}, {}, "10.0.0.5"), Contains("10.0.0.5: no marker to take"));
  ModelDefinitions defs;
  defs.models = {MarkerSetDescription{"Anna", {"Brow"}}, MarkerSetDescription{"Ben", {"Brow"}}};
  CHECK_THROWS_WITH(FrameConverter({.marker_set = "Cleo"}, defs, "10.0.0.5"),
                    Contains("NatNet server 10.0.0.5 has no marker set 'Cleo' (its marker sets: 'Anna', 'Ben')"));
}

TEST_CASE("natnet request texts: the commands natnet-serve answers, in any case, and nothing else", "[natnet]") {
  CHECK(parse_request("FrameRate") == Request{RequestKind::kFrameRate, {}});
  CHECK(parse_request(" framerate ") == Request{RequestKind::kFrameRate, {}});
  CHECK(parse_request("Bitstream") == Request{RequestKind::kBitstreamQuery, {}});
  CHECK(parse_request("Bitstream,3.1") == Request{RequestKind::kSetBitstream, kBitstream31});
  CHECK(parse_request("bitstream, 4.1.0.0") == Request{RequestKind::kSetBitstream, kBitstream41});
  CHECK(parse_request("Bitstream,2.9") == Request{RequestKind::kSetBitstream, Version{2, 9}});  // caller refuses it
  CHECK(parse_request("AnalogSamplesPerMocapFrame") == Request{RequestKind::kAnalogSamplesPerMocapFrame, {}});
  for (const char* unknown : {"", "Bitstream,", "Bitstream,four", "Bitstream,4.1,x", "FrameRate,2", "TimelinePlay",
                              "Bitstream4.1", "Bitstream,4.1.0.0.0"})
    CHECK_FALSE(parse_request(unknown));
  CHECK(request_text({RequestKind::kSetBitstream, kBitstream31}) == "Bitstream,3.1");
  CHECK(request_text({RequestKind::kFrameRate, {}}) == "FrameRate");
  CHECK(bitstream_reply(Version{4, 1, 0, 0}) == "Bitstream,4.1");
  CHECK(parse_bitstream_reply("Bitstream,4.1") == kBitstream41);
  CHECK_FALSE(parse_bitstream_reply("FrameRate"));
}
