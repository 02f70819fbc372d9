// Writes small valid inputs for every fuzz target (seeds/<target>/...) and the
// dictionaries generated from tables in the code (seeds/dict/...), into the directory
// given as the first argument. Run by the build (fuzz/CMakeLists.txt).
#include <cstdio>
#include <filesystem>
#include <fstream>
#include <string>
#include <tuple>

#include <fmt/format.h>

#include "config/config_file.hpp"
#include "config/schema.hpp"
#include "core/error.hpp"
#include "core/io.hpp"
#include "formats/arkit.hpp"
#include "formats/c3d.hpp"
#include "formats/livelinkface.hpp"
#include "formats/marker_device.hpp"
#include "formats/natnet.hpp"
#include "formats/natnet_request.hpp"
#include "formats/recording.hpp"
#include "formats/trc.hpp"
#include "outputs/udp/udp_stream_encoding.hpp"
#include "pipeline/pipeline_state.hpp"
#include "solver/align/profile.hpp"
#include "solver/gltf_rig.hpp"
#include "solver/obj_mesh.hpp"
#include "solver/rig_cache.hpp"

namespace fs = std::filesystem;
using namespace facecap;
using namespace facecap::formats;
namespace udp_stream = facecap::outputs::udp_stream;

namespace {

void write(const fs::path& path, std::string_view bytes) {
  fs::create_directories(path.parent_path());
  std::ofstream(path, std::ios::binary | std::ios::trunc).write(bytes.data(), std::streamsize(bytes.size()));
}
void write(const fs::path& path, const std::vector<char>& bytes) { write(path, std::string_view(bytes.data(), bytes.size())); }

MarkerTake small_take(std::size_t frames, std::size_t markers) {
  MarkerTake take;
  take.rate_hz = 60.0;
  take.units = "mm";
  for (std::size_t k = 0; k < markers; ++k) take.labels.push_back(fmt::format("M{}", k));
  for (std::size_t f = 0; f < frames; ++f) {
    MarkerFrame& frame = append_empty_frame(take, int64_t(f) + 1, int64_t(f) * 16666667);
    for (std::size_t k = 0; k < markers; ++k) {
      if ((f + k) % 5 == 4) continue;  // stays missing
      frame.markers[k].flags = 0;
      frame.markers[k].position = Eigen::Vector3d(double(k), 10.0 + double(f), -0.5 * double(k + f));
    }
  }
  return take;
}

// Two quads, two shapes: the smallest rig every rig format can hold.
Rig small_rig() {
  Rig rig;
  rig.name = "tiny";
  rig.neutral.resize(3, 6);
  rig.neutral << 0, 1, 2, 0, 1, 2, 0, 0, 0, 1, 1, 1, 0, 0, 0, 0, 0, 0;
  rig.triangles.resize(3, 4);
  rig.triangles << 0, 0, 1, 1, 1, 4, 2, 5, 4, 3, 5, 4;
  rig.shape_names = {"jawOpen", "eyeBlink_L"};
  rig.deltas = Eigen::MatrixXd::Zero(18, 2);
  rig.deltas(3 * 4 + 2, 0) = 0.5;
  rig.deltas(3 * 3 + 1, 1) = -0.25;
  return rig;
}

// A start state (STAT) with every part: 2 shapes, 6 vertices, `markers` markers.
std::vector<char> start_state_seed(std::size_t markers) {
  const auto K = Eigen::Index(markers);
  pipeline::SolvePipeline::State state;
  state.mapper.accepted_targets = Eigen::Matrix3Xd::Constant(3, K, 0.5);
  state.mapper.accepted_ns.assign(markers, 1000);
  state.solver.previous = state.solver.previous_linear = state.weights = Eigen::VectorXd::Constant(2, 0.25);
  state.vertices = Eigen::Matrix3Xd::Zero(3, 6);
  auto& labeller = state.labeller.emplace();
  labeller.last = labeller.velocity = labeller.last_in_reference = Eigen::Matrix3Xd::Ones(3, K);
  labeller.lost_frames.assign(markers, 0);
  labeller.ever_seen.assign(markers, 1);
  const auto filter = [](Eigen::Index rows, Eigen::Index channels) {
    const Eigen::MatrixXd values = Eigen::MatrixXd::Ones(rows, channels);
    return pipeline::OneEuroFilter::State{values, values, values, std::vector<uint8_t>(std::size_t(channels), 1), 1000, true};
  };
  state.target_filter = filter(3, K);
  state.weight_filter = filter(1, 2);
  std::vector<char> bytes;
  pipeline::encode_pipeline_state(state, bytes);
  return bytes;
}

void write_recordings(const fs::path& dir) {
  fs::create_directories(dir);
  const MarkerTake take = small_take(6, 3);
  write_recording(dir / "markers.fcrec", take, "fuzz seed");
  RecordingHeader header;
  header.rig_name = "tiny";
  header.units = "mm";
  header.rate_hz = 60.0;
  header.marker_labels = take.labels;
  header.shape_names = {"jawOpen", "eyeBlink_L"};
  header.calibration = "version = 1\n";
  header.solver_settings = "[solver]\nmethod = \"ours\"\n";
  {
    RecordingWriter writer(dir / "solved.fcrec", header, RecordingWriter::Options{.overwrite = true});
    writer.append_start_state(start_state_seed(take.labels.size()));
    SolvedFrame solved;
    solved.resize(2, 6);
    for (std::size_t f = 0; f < take.frames.size(); ++f) {
      writer.append_marker_frame(take.frames[f]);
      solved.frame_no = int64_t(f) + 1;
      solved.weights[0] = 0.1f * float(f);
      writer.append_solved_frame(solved);
    }
    writer.close();
  }
  // Cut off before its index: the reader scans the chunks instead.
  auto bytes = read_file_bytes(dir / "solved.fcrec");
  bytes.resize(bytes.size() * 2 / 3);
  write(dir / "cut.fcrec", bytes);
  // A flipped bit in a chunk of each: the reader skips it and resynchronises on the next.
  bytes[bytes.size() / 2] ^= 0x08;
  write(dir / "damaged-cut.fcrec", bytes);
  auto whole = read_file_bytes(dir / "solved.fcrec");
  whole[whole.size() / 3] ^= 0x08;
  write(dir / "damaged.fcrec", whole);
}

align::Calibration small_calibration(const Rig& rig) {
  align::Calibration c;
  c.rig_name = rig.name;
  c.rig_hash = rig.content_hash();
  c.source_take = "take.trc";
  c.source_frame = 12;
  c.take_to_rig.scale = 0.1;
  c.take_to_rig.translation = Eigen::Vector3d(1.0, -2.0, 0.5);
  for (int k = 0; k < 3; ++k) {
    align::MarkerCalibration m;
    m.label = fmt::format("M{}", k);
    m.binding = MarkerBinding{m.label, {k, k + 1, k + 3}, Eigen::Vector3d(0.5, 0.25, 0.25)};
    m.neutral = Eigen::Vector3d(10.0 * k, 5.0, 1.0);
    m.bound_point = c.take_to_rig.apply(m.neutral) - Eigen::Vector3d(0.01, 0.0, 0.0);
    m.residual_mm = 0.1;
    c.markers.push_back(m);
  }
  c.stable_markers = {"M0", "M1", "M2"};
  c.notes = {"a note"};
  return c;
}

// The udp_stream_reassembly target's input: datagrams, each a little-endian u16 length
// and its bytes. A schema, then a frame of a small rig with vertices (several chunks).
void write_udp_stream(const fs::path& dir) {
  const Rig rig = small_rig();
  udp_stream::StreamSchema schema{.rig_hash = 0x1234, .rig_name = rig.name, .shape_names = rig.shape_names,
                                  .arkit_names = {"JawOpen", "EyeBlinkLeft"}, .vertex_count = 400,
                                  .frame_rate_hz = 240.0};
  std::vector<char> message;
  const uint32_t schema_id = udp_stream::encode_schema(schema, 0, message);
  std::string stream;
  const auto append = [&](const std::vector<std::vector<char>>& datagrams) {
    for (const auto& d : datagrams) {
      stream += char(d.size() & 0xff);
      stream += char(d.size() >> 8);
      stream.append(d.data(), d.size());
    }
  };
  append(udp_stream::datagrams(udp::kSchemaMessage, 7, 0, message));
  write(dir / "schema.bin", stream);
  SolvedFrame frame;
  frame.resize(2, 400);
  frame.weights << 0.25f, 0.75f;
  frame.vertices.setConstant(1.5f);
  udp_stream::encode_frame(frame, {.schema_id = schema_id, .rig_hash = 0x1234, .publish_time_ns = 1000}, true, message);
  append(udp_stream::datagrams(udp::kFrameMessage, 7, 1, message));
  write(dir / "schema_and_frame.bin", stream);
}

// A client's conversation with natnet-serve as the natnet_serve_requests target reads it
// (each datagram after its 2-byte little-endian length): connect asking for 4.1, the
// requests, the model definitions, a keep-alive, disconnect.
std::string natnet_conversation() {
  namespace nn = natnet;
  nn::Connect connect;
  connect.sender.name = nn::NameField::from_text("fuzz seed");
  connect.sender.natnet_version = {4, 1, 0, 0};
  connect.options = nn::ConnectOptions{};
  connect.options->bitstream = {4, 1, 0, 0};
  std::vector<nn::Message> messages = {{nn::MessageId::kConnect, connect}};
  for (const char* text : {"Bitstream", "Bitstream,3.1", "FrameRate", "AnalogSamplesPerMocapFrame", "Nonsense"})
    messages.push_back({nn::MessageId::kRequest, nn::Text{text}});
  messages.push_back({nn::MessageId::kRequestModelDef, nn::RawPayload{}});
  messages.push_back({nn::MessageId::kKeepAlive, nn::RawPayload{}});
  messages.push_back({nn::MessageId::kDisconnect, nn::RawPayload{}});
  std::string out;
  for (const nn::Message& m : messages) {
    const std::vector<char> bytes = nn::encode_message(m, nn::kBitstream41);
    out += char(bytes.size() & 0xff);
    out += char(bytes.size() >> 8);
    out.append(bytes.begin(), bytes.end());
  }
  return out;
}

void write_dictionaries(const fs::path& dir) {
  std::string llf;
  for (const auto& shape : kArkitShapes) llf += fmt::format("\"{}\"\n", shape.arkit);
  for (auto angle : kLiveLinkAngleNames) llf += fmt::format("\"{}\"\n", angle);
  llf += "\"Timecode\"\n\"BlendShapeCount\"\n\"23:59:59:59.999\"\n\"00:00:00:00.000\"\n";
  write(dir / "livelinkface.dict", llf);
  std::string keys;
  for (const auto& key : config::config_schema()) keys += fmt::format("\"{}\"\n\"[{}]\"\n", key.name(), key.section());
  keys += "\"=\"\n\"[[\"\n\"\\\"\"\n\"true\"\n\"1e309\"\n\"nan\"\n";
  write(dir / "facecapd_config.dict", keys);
}

}  // namespace

int main(int argc, char** argv) {
  if (argc != 2) {
    std::fprintf(stderr, "usage: %s SEED_DIR\n", argv[0]);
    return 2;
  }
  const fs::path out = argv[1];
  try {
    const MarkerTake take = small_take(8, 4);
    write(out / "c3d/small.c3d", write_c3d(take));
    write(out / "c3d/empty.c3d", write_c3d(small_take(0, 2)));
    write(out / "c3d/labels2.c3d", write_c3d(small_take(1, 260)));  // LABELS2 past 255 points
    write(out / "trc/small.trc", write_trc(take, "small.trc"));
    write_recordings(out / "fcrec");
    write(out / "pipeline_state/every_part.bin", start_state_seed(take.labels.size()));

    FaceTake face;
    for (int i = 0; i < 6; ++i) {
      FaceFrame& f = face.frames.emplace_back();
      f.timecode = *parse_livelink_timecode(fmt::format("23:59:59:{:02}.250", 54 + i));
      f.tracked = i != 3;
      f.weights.fill(0.125f * float(i % 3));
    }
    write(out / "livelinkface/small.csv", write_livelinkface(face));

    const Rig rig = small_rig();
    const std::string neutral = format_obj(rig.neutral, rig.triangles);
    write(out / "obj/neutral.obj", neutral);
    write(out / "obj/quads.obj", "v 0 0 0\nv 1 0 0\nv 1 1 0\nv 0 1 0\nvt 0 0\nvn 0 0 1\nf 1/1/1 2/1/1 3/1/1 4/1/1\nf -1 -2 -3\n");
    // A neutral, then a shape after the separator line the obj target splits at.
    write(out / "obj/neutral_and_shape.obj", neutral + "#shape\n" + format_obj(rig.shape_positions(0), rig.triangles));
    write(out / "rig_manifest/rig.toml",
          "name = \"tiny\"\nneutral = \"neutral.obj\"\n[shapes]\njawOpen = \"jaw_open.obj\"\n\"eye blink\" = \"sub/blink.obj\"\n");
    const fs::path gltf_dir = out / "gltf";
    fs::create_directories(gltf_dir);
    save_gltf_rig(rig, (gltf_dir / "tiny.gltf").string());
    save_gltf_rig(rig, (gltf_dir / "tiny.glb").string());
    write(out / "rig_cache/tiny.fcrig", serialize_rig(rig, RigCacheKey{0x1234}));

    write(out / "facecapd_config/defaults.toml", config::render_documented_defaults());
    write(out / "facecapd_config/small.toml",
          "version = 1\n[loop]\nrate_hz = 240\n[source]\ndriver = \"sim\"\n[solver]\nmethod = \"ours\"\n");
    // A marker device's info block and a frame cut into 64-byte chunks, back to back.
    formats::device::DeviceFrame device_frame{.frame_no = 7, .device_time = 123456};
    for (uint16_t k = 0; k < 5; ++k) device_frame.markers.push_back({.id = k, .position = {1.5f * k, -2.0f, 30.0f}});
    std::string chunks;
    for (const auto& chunk : formats::device::encode_frame_chunks(device_frame, 64)) chunks.append(chunk.begin(), chunk.end());
    write(out / "marker_device_packet/frame.bin", chunks);
    const auto info = formats::device::encode_info({.marker_capacity = 64, .rate_mhz = 120000, .max_rate_mhz = 240000, .max_chunk_bytes = 64, .clock_hz = 1000000});
    write(out / "marker_device_packet/info.bin", std::string(info.begin(), info.end()));
    // Two cameras in the `cameras:` layout and OpenCV's stereo layout.
    const std::string matrix =
        "!!opencv-matrix\n      rows: 3\n      cols: 3\n      dt: d\n      data: [800, 0, 320, 0, 800, 240, 0, 0, 1]\n";
    write(out / "camera_calibration/cameras.yaml",
          "%YAML:1.0\n---\nunits: mm\ncameras:\n  - name: left\n    image_width: 640\n    image_height: 480\n"
          "    camera_matrix: " + matrix + "    distortion_coefficients: [-0.1, 0.01, 0, 0, 0]\n"
          "    rotation: [0, 0, 0]\n    translation: [0, 0, 0]\n  - name: right\n    camera_matrix: " + matrix +
          "    rotation: [0, -0.5, 0]\n    translation: [-250, 0, 60]\n");
    write(out / "camera_calibration/stereo.yml",
          "M1: " + matrix + "D1: [0, 0, 0, 0]\nM2: " + matrix + "D2: [0, 0, 0, 0]\nR: [0, 0.5, 0]\nT: [-25, 0, 3]\n");
    // 48 bytes that keep OpenCV 4.6's FileStorage busy forever (our reader refuses them).
    write(out / "camera_calibration/opencv_hang.json", "{\"a\":\"$base64$AAAAAAAAAAAAAAAAAAAAAAAAAAAAAAAA\"}");
    const std::string profile = align::write_calibration_profile(small_calibration(rig));
    write(out / "calibration_profile/profile.toml", profile);
    // Without its checksum line, so that mutations are not all refused by the checksum.
    const auto checksum_at = profile.find("checksum = ");
    write(out / "calibration_profile/unchecked.toml",
          profile.substr(0, checksum_at) + profile.substr(profile.find('\n', checksum_at) + 1));
    write_udp_stream(out / "udp_stream_reassembly");
    write(out / "natnet_serve_requests/conversation.bin", natnet_conversation());
    // Control API requests (the target's token is "s3cret" for inputs of odd length).
    write(out / "control_request/status.http", "GET /status HTTP/1.1\r\nHost: x\r\n\r\n");
    write(out / "control_request/stream.http",
          "GET /stream?rate=20&vertices=1 HTTP/1.1\r\nHost: x\r\nAuthorization: Bearer s3cret\r\n\r\n");
    for (const auto& [name, target, body] : {std::tuple{"actor", "/actor", R"({"name": "alice"})"},
                                             {"calibrate", "/calibrate", R"({"seconds": 2.5, "save": "bob"})"},
                                             {"record_start", "/record/start",
                                              R"({"take": "t1", "actor": "a", "scene": "s", "shot": "2", "notes": "n", "markers_only": true})"},
                                             {"record_stop", "/record/stop", "{}"}})
      write(out / fmt::format("control_request/{}.http", name),
            fmt::format("POST {} HTTP/1.1\r\nHost: x\r\nContent-Type: application/json\r\nContent-Length: {}\r\n\r\n{}",
                        target, std::string_view(body).size(), body));
    // Login, a session cookie, logout, and pages of this and another origin.
    for (const auto& [name, target, headers, body] :
         {std::tuple{"login", "/login", "Origin: http://x\r\n", R"({"token": "s3cret"})"},
          {"login_viewer", "/login", "", R"({"token": "v1ewer"})"},
          {"logout", "/logout", "Cookie: a=b; facecap_session=0123456789abcdef0123456789abcdef0123456789abcdef0123456789abcdef\r\n", "{}"},
          {"record_other_origin", "/record/start", "Origin: http://127.0.0.1:9999\r\nReferer: http://x/index.html\r\n", "{}"}})
      write(out / fmt::format("control_request/{}.http", name),
            fmt::format("POST {} HTTP/1.1\r\nHost: x\r\n{}Content-Type: application/json\r\nContent-Length: {}\r\n\r\n{}",
                        target, headers, std::string_view(body).size(), body));
    write(out / "control_request/session.http",
          "GET /session HTTP/1.1\r\nHost: 127.0.0.1:8765\r\nCookie: facecap_session=00\r\n\r\n");
    write_dictionaries(out / "dict");
  } catch (const std::exception& e) {
    std::fprintf(stderr, "fuzz_seeds: %s\n", e.what());
    return 1;
  }
  return 0;
}
