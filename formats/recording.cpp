#include "formats/recording.hpp"

#include <algorithm>
#include <cerrno>
#include <cmath>
#include <cstring>
#include <ctime>
#include <limits>
#include <unordered_map>

#include <fcntl.h>
#include <sys/mman.h>
#include <sys/stat.h>
#include <unistd.h>

#include <fmt/format.h>
#include <spdlog/spdlog.h>

#include "core/error.hpp"
#include "core/io.hpp"
#include "formats/byte_io.hpp"

namespace facecap::formats {
namespace {

constexpr char kMagic[8] = {'F', 'C', 'R', 'E', 'C', '\r', '\n', '\x1a'};
constexpr std::size_t kPreambleBytes = 16;
constexpr std::size_t kChunkHeaderBytes = 16;
constexpr std::size_t kIndexEntryBytes = 32;
constexpr std::size_t kTailPayloadBytes = 16;
constexpr std::size_t kTailChunkBytes = kChunkHeaderBytes + kTailPayloadBytes;

constexpr uint32_t fourcc(const char (&s)[5]) {
  return uint32_t(uint8_t(s[0])) | (uint32_t(uint8_t(s[1])) << 8) | (uint32_t(uint8_t(s[2])) << 16) |
         (uint32_t(uint8_t(s[3])) << 24);
}
constexpr uint32_t kHeadChunk = fourcc("HEAD");
constexpr uint32_t kHeadCopyChunk = fourcc("HCPY");
constexpr uint32_t kMarkerChunk = fourcc("MRKF");
constexpr uint32_t kSolvedChunk = fourcc("SLVF");
constexpr uint32_t kStartStateChunk = fourcc("STAT");
constexpr uint32_t kIndexChunk = fourcc("INDX");
constexpr uint32_t kTailChunk = fourcc("TAIL");

std::string fourcc_text(uint32_t code) {
  std::string s;
  for (int i = 0; i < 4; ++i) {
    const char c = char((code >> (8 * i)) & 0xff);
    s += (c >= 0x20 && c < 0x7f) ? c : '?';
  }
  return s;
}

// The checksum covers the chunk's fourcc and size as well as its payload, so a torn
// header is caught as surely as a torn payload.
uint64_t chunk_checksum(uint32_t code, uint32_t size, const char* payload) {
  Fnv1a64 hash;
  hash.add_value(code);
  hash.add_value(size);
  hash.add(payload, size);
  return hash.digest();
}

void put_string(ByteWriter& w, std::string_view s) {
  w.u32(uint32_t(s.size()));
  w.bytes(s);
}
std::string get_string(ByteReader& r, std::string_view what) {
  const uint32_t size = r.u32(what);
  return std::string(r.bytes(size, what));
}
void put_strings(ByteWriter& w, const std::vector<std::string>& list) {
  w.u32(uint32_t(list.size()));
  for (const auto& s : list) put_string(w, s);
}
std::vector<std::string> get_strings(ByteReader& r, std::string_view what) {
  const uint32_t count = r.u32(what);
  if (count > r.remaining() / 4) r.fail(fmt::format("{} count {} exceeds the chunk", what, count));
  std::vector<std::string> out;
  out.reserve(count);
  for (uint32_t i = 0; i < count; ++i) out.push_back(get_string(r, what));
  return out;
}

void put_timecode(ByteWriter& w, const Timecode& tc) {
  w.u8(tc.hours);
  w.u8(tc.minutes);
  w.u8(tc.seconds);
  w.u8(tc.frames);
  w.f32(tc.subframe);
  w.u16(tc.rate_hz);
  w.u16(0);
}
Timecode get_timecode(ByteReader& r) {
  Timecode tc;
  tc.hours = r.u8("timecode");
  tc.minutes = r.u8("timecode");
  tc.seconds = r.u8("timecode");
  tc.frames = r.u8("timecode");
  tc.subframe = r.f32("timecode");
  tc.rate_hz = r.u16("timecode");
  r.skip(2, "timecode");
  return tc;
}

void encode_header(ByteWriter& w, const RecordingHeader& h, int64_t created_unix_ns) {
  put_string(w, h.rig_name);
  w.u64(h.rig_hash);
  put_string(w, h.source_description);
  put_string(w, h.calibration);
  put_string(w, h.units);
  w.f64(h.rate_hz);
  w.i64(created_unix_ns);
  put_strings(w, h.marker_labels);
  put_strings(w, h.shape_names);
  // Format version 2 appends:
  put_string(w, h.rig_units);
  put_string(w, h.solver_settings);
  // Format version 3 appends the slate:
  for (const std::string* field : {&h.take, &h.actor, &h.scene, &h.shot, &h.notes}) put_string(w, *field);
}

void decode_header(ByteReader& r, RecordingHeader& h) {
  h.rig_name = get_string(r, "rig name");
  h.rig_hash = r.u64("rig hash");
  h.source_description = get_string(r, "source description");
  h.calibration = get_string(r, "calibration");
  h.units = get_string(r, "units");
  h.rate_hz = r.f64("rate");
  h.created_unix_ns = r.i64("creation time");
  h.marker_labels = get_strings(r, "marker labels");
  h.shape_names = get_strings(r, "shape names");
  if (h.format_version >= 2) {
    h.rig_units = get_string(r, "rig units");
    h.solver_settings = get_string(r, "solver settings");
  }
  if (h.format_version >= 3)
    for (std::string* field : {&h.take, &h.actor, &h.scene, &h.shot, &h.notes}) *field = get_string(r, "slate");
  // Later format versions may append fields; this reader ignores them.
}

void encode_marker_frame(ByteWriter& w, const MarkerFrame& f) {
  w.i64(f.frame_no);
  w.i64(f.source_time_ns);
  w.i64(f.receive_time_ns);
  put_timecode(w, f.timecode);
  w.u32(uint32_t(f.markers.size()));
  for (const Marker& m : f.markers) {
    w.i32(m.id);
    w.u32(m.flags);
    w.f64(m.position.x());
    w.f64(m.position.y());
    w.f64(m.position.z());
    const auto label = m.label.view();
    w.u8(uint8_t(label.size()));  // MarkerLabel holds at most 47 characters
    w.bytes(label);
  }
}

constexpr std::size_t kMinMarkerBytes = 4 + 4 + 24 + 1;

void decode_marker_frame(ByteReader& r, MarkerFrame& f) {
  f.frame_no = r.i64("frame number");
  f.source_time_ns = r.i64("source time");
  f.receive_time_ns = r.i64("receive time");
  f.timecode = get_timecode(r);
  const uint32_t count = r.u32("marker count");
  if (count > r.remaining() / kMinMarkerBytes) r.fail(fmt::format("marker count {} exceeds the chunk", count));
  f.markers.resize(count);
  for (Marker& m : f.markers) {
    m.id = r.i32("marker id");
    m.flags = r.u32("marker flags");
    const double x = r.f64("marker position");
    const double y = r.f64("marker position");
    const double z = r.f64("marker position");
    m.position = Eigen::Vector3d(x, y, z);
    const uint8_t length = r.u8("label length");
    m.label.assign(r.bytes(length, "label"));
  }
}

void encode_solved_frame(ByteWriter& w, const SolvedFrame& f) {
  w.i64(f.frame_no);
  w.i64(f.source_time_ns);
  w.i64(f.receive_time_ns);
  w.i64(f.solve_start_ns);
  w.i64(f.solve_end_ns);
  put_timecode(w, f.timecode);
  w.f64(f.head_rotation.w());
  w.f64(f.head_rotation.x());
  w.f64(f.head_rotation.y());
  w.f64(f.head_rotation.z());
  for (int i = 0; i < 3; ++i) w.f64(f.head_translation[i]);
  w.u32(f.collision_constraints);
  w.u32(f.markers_used);
  w.u32(f.flags);
  w.u32(uint32_t(f.stage_ns.size()));
  for (int64_t ns : f.stage_ns) w.i64(ns);
  w.u32(uint32_t(f.weights.size()));
  for (Eigen::Index i = 0; i < f.weights.size(); ++i) w.f32(f.weights[i]);
  w.u32(uint32_t(f.vertices.cols()));
  for (Eigen::Index i = 0; i < f.vertices.size(); ++i) w.f32(f.vertices.data()[i]);  // column-major: x y z per vertex
  // Format version 4 appends:
  w.i32(f.fold_deadline_rounds);
}

void decode_solved_frame(ByteReader& r, SolvedFrame& f) {
  f.frame_no = r.i64("frame number");
  f.source_time_ns = r.i64("source time");
  f.receive_time_ns = r.i64("receive time");
  f.solve_start_ns = r.i64("solve start");
  f.solve_end_ns = r.i64("solve end");
  f.timecode = get_timecode(r);
  const double qw = r.f64("head rotation"), qx = r.f64("head rotation"), qy = r.f64("head rotation"),
               qz = r.f64("head rotation");
  f.head_rotation = Eigen::Quaterniond(qw, qx, qy, qz);
  for (int i = 0; i < 3; ++i) f.head_translation[i] = r.f64("head translation");
  f.collision_constraints = r.u32("collision count");
  f.markers_used = r.u32("markers used");
  f.flags = r.u32("flags");
  const uint32_t stages = r.u32("stage count");
  if (stages > r.remaining() / 8) r.fail(fmt::format("stage count {} exceeds the chunk", stages));
  f.stage_ns.fill(0);
  for (uint32_t i = 0; i < stages; ++i) {
    const int64_t ns = r.i64("stage time");
    if (i < f.stage_ns.size()) f.stage_ns[i] = ns;
  }
  const uint32_t weights = r.u32("weight count");
  if (weights > r.remaining() / 4) r.fail(fmt::format("weight count {} exceeds the chunk", weights));
  f.weights.resize(weights);
  for (uint32_t i = 0; i < weights; ++i) f.weights[i] = r.f32("weight");
  const uint32_t vertices = r.u32("vertex count");
  if (vertices > r.remaining() / 12) r.fail(fmt::format("vertex count {} exceeds the chunk", vertices));
  f.vertices.resize(3, vertices);
  for (Eigen::Index i = 0; i < f.vertices.size(); ++i) f.vertices.data()[i] = r.f32("vertex");
  f.fold_deadline_rounds = r.has(4) ? r.i32("fold deadline rounds") : -1;  // format version 4
}

int64_t realtime_now_ns() {
  timespec ts{};
  clock_gettime(CLOCK_REALTIME, &ts);
  return int64_t(ts.tv_sec) * kNsPerSecond + ts.tv_nsec;
}

}  // namespace

// ---------------------------------------------------------------------------- writer

RecordingWriter::RecordingWriter(const std::filesystem::path& path, const RecordingHeader& header, Options options)
    : path_(path.string()), options_(options) {
  if (!options_.write) options_.write = ::pwrite;
  const int flags = O_WRONLY | O_CREAT | O_CLOEXEC | (options.overwrite ? O_TRUNC : O_EXCL);
  fd_ = ::open(path_.c_str(), flags, 0644);
  if (fd_ < 0) throw file_error(path_, fmt::format("cannot create recording: {}", std::strerror(errno)));
  ByteWriter w(buffer_);
  w.bytes(std::string_view(kMagic, sizeof kMagic));
  w.u16(kRecordingFormatVersion);
  w.u16(kRecordingReaderVersion);
  w.u32(0);  // reserved
  ByteWriter p(payload_);
  encode_header(p, header, header.created_unix_ns != 0 ? header.created_unix_ns : realtime_now_ns());
  head_payload_ = payload_;
  append_chunk(kHeadChunk, payload_);
  try {
    flush();  // the header reaches the file at once: a recording killed early still names its rig
  } catch (const Error&) {
    ::close(fd_);
    fd_ = -1;
    ::unlink(path_.c_str());  // a file without its header holds nothing
    throw;
  }
}

RecordingWriter::~RecordingWriter() {
  if (!is_open()) return;
  try {
    close();
  } catch (const Error& e) {
    spdlog::error("recording {}: closing failed: {}", path_, e.what());
  }
}

void RecordingWriter::append_chunk(uint32_t code, const std::vector<char>& payload) {
  if (payload.size() > std::numeric_limits<uint32_t>::max()) {
    throw file_error(path_, fmt::format("chunk of {} bytes is too large for a recording", payload.size()));
  }
  ByteWriter w(buffer_);
  const auto size = uint32_t(payload.size());
  w.u32(code);
  w.u32(size);
  w.u64(chunk_checksum(code, size, payload.data()));
  w.bytes(std::string_view(payload.data(), payload.size()));
  buffer_chunk_ends_.push_back(buffer_.size());
  if (buffer_.size() >= options_.buffer_bytes) flush();
}

void RecordingWriter::append_start_state(std::span<const char> state) {
  if (!is_open() || !failure_.empty())
    throw file_error(path_, failure_.empty() ? "append to a closed recording" : "recording stopped: " + failure_);
  if (!index_.empty() || start_state_written_) throw file_error(path_, "the start state goes before the first frame, once");
  payload_.assign(state.begin(), state.end());
  start_state_written_ = true;
  append_chunk(kStartStateChunk, payload_);
}

void RecordingWriter::append_marker_frame(const MarkerFrame& frame) {
  if (!is_open() || !failure_.empty())
    throw file_error(path_, failure_.empty() ? "append to a closed recording" : "recording stopped: " + failure_);
  payload_.clear();
  ByteWriter w(payload_);
  encode_marker_frame(w, frame);
  index_.push_back({ChunkKind::kMarkerFrame, bytes_written(), frame.frame_no, frame.source_time_ns});
  ++marker_frames_;
  append_chunk(kMarkerChunk, payload_);
}

void RecordingWriter::append_solved_frame(const SolvedFrame& frame) {
  if (!is_open() || !failure_.empty())
    throw file_error(path_, failure_.empty() ? "append to a closed recording" : "recording stopped: " + failure_);
  payload_.clear();
  ByteWriter w(payload_);
  encode_solved_frame(w, frame);
  index_.push_back({ChunkKind::kSolvedFrame, bytes_written(), frame.frame_no, frame.source_time_ns});
  ++solved_frames_;
  append_chunk(kSolvedChunk, payload_);
}

void RecordingWriter::write_buffer() {
  std::size_t done = 0;
  int error = 0;
  while (done < buffer_.size()) {
    // pwrite at the offset we track: a retry after a short write resumes exactly where
    // the file ends, and a file cut back below never gets a hole.
    const ssize_t n = options_.write(fd_, buffer_.data() + done, buffer_.size() - done, off_t(file_bytes_ + done));
    if (n < 0 && errno == EINTR) continue;
    if (n <= 0) {
      error = n < 0 ? errno : EIO;  // 0 bytes for a non-empty write: no progress is possible
      break;
    }
    done += std::size_t(n);
  }
  if (error == 0) {
    file_bytes_ += buffer_.size();
    buffer_.clear();
    buffer_chunk_ends_.clear();
    return;
  }
  // Keep the whole chunks that reached the file, drop the partial one and everything after.
  const auto whole = std::upper_bound(buffer_chunk_ends_.begin(), buffer_chunk_ends_.end(), done);
  const uint64_t good_end = file_bytes_ + (whole == buffer_chunk_ends_.begin() ? 0 : *(whole - 1));
  const bool cut = ::ftruncate(fd_, off_t(good_end)) == 0;
  file_bytes_ = good_end;
  buffer_.clear();
  buffer_chunk_ends_.clear();
  while (!index_.empty() && index_.back().offset >= good_end) {
    --(index_.back().kind == ChunkKind::kMarkerFrame ? marker_frames_ : solved_frames_);
    index_.pop_back();
  }
  const std::string reason =
      fmt::format("write failed: {}; the file keeps its first {} bytes ({} marker and {} solved frames){}",
                  std::strerror(error), good_end, marker_frames_, solved_frames_,
                  cut ? "" : fmt::format(", and could not be cut back to them ({}): readers drop the partial chunk",
                                         std::strerror(errno)));
  if (failure_.empty()) failure_ = reason;
  throw file_error(path_, reason);
}

void RecordingWriter::flush(bool durable) {
  if (!is_open()) return;
  if (!failure_.empty()) throw file_error(path_, "recording stopped: " + failure_);
  write_buffer();
  if (durable && ::fdatasync(fd_) != 0)
    throw file_error(path_, fmt::format("fdatasync failed: {}", std::strerror(errno)));
}

bool RecordingWriter::file_deleted() const {
  struct stat st {};
  return is_open() && ::fstat(fd_, &st) == 0 && st.st_nlink == 0;
}

void RecordingWriter::close() {
  if (!is_open()) return;
  const bool failed_before = !failure_.empty();
  try {
    append_chunk(kHeadCopyChunk, head_payload_);
    const uint64_t index_offset = bytes_written();
    payload_.clear();
    ByteWriter w(payload_);
    w.u32(uint32_t(index_.size()));
    for (const auto& e : index_) {
      w.u8(uint8_t(e.kind));
      w.zeros(7);
      w.u64(e.offset);
      w.i64(e.frame_no);
      w.i64(e.source_time_ns);
    }
    append_chunk(kIndexChunk, payload_);
    const uint64_t tail_offset = bytes_written();
    payload_.clear();
    w.u64(index_offset);
    w.u64(tail_offset);
    append_chunk(kTailChunk, payload_);
    write_buffer();
    if (::fdatasync(fd_) != 0) throw file_error(path_, fmt::format("fdatasync failed: {}", std::strerror(errno)));
  } catch (...) {
    ::close(fd_);
    fd_ = -1;
    if (failed_before) return;  // said once, by the write that failed; the file is readable by scanning
    throw;
  }
  const int rc = ::close(fd_);
  fd_ = -1;
  if (rc != 0) throw file_error(path_, fmt::format("close failed: {}", std::strerror(errno)));
}

// ---------------------------------------------------------------------------- reader

struct RecordingReader::Mapping {
  MappedFile file;
};

RecordingReader::RecordingReader(const std::filesystem::path& path, Options options)
    : name_(path.string()), options_(options) {
  mapping_ = std::make_unique<Mapping>(Mapping{MappedFile(path, options.no_follow)});
  open(mapping_->file.bytes());
}

RecordingReader::RecordingReader(std::span<const char> bytes, std::string name, Options options)
    : name_(std::move(name)), options_(options) {
  open(bytes);
}

RecordingReader::~RecordingReader() = default;
RecordingReader::RecordingReader(RecordingReader&&) noexcept = default;
RecordingReader& RecordingReader::operator=(RecordingReader&&) noexcept = default;

namespace {

struct ChunkView {
  uint32_t code = 0;
  std::size_t offset = 0;  // of the chunk header
  std::span<const char> payload;
};

// A complete chunk with a valid checksum at offset, or why there is none.
std::optional<ChunkView> chunk_at(std::span<const char> bytes, std::size_t offset, std::string& why) {
  if (offset > bytes.size() || bytes.size() - offset < kChunkHeaderBytes) {
    why = fmt::format("incomplete chunk header at byte {}", offset);
    return std::nullopt;
  }
  ByteReader r(bytes, "");
  r.seek(offset);
  const uint32_t code = r.u32();
  const uint32_t size = r.u32();
  [[maybe_unused]] const uint64_t checksum = r.u64();
  if (size > r.remaining()) {
    why = fmt::format("chunk {} at byte {} needs {} payload bytes, {} remain", fourcc_text(code), offset, size,
                      r.remaining());
    return std::nullopt;
  }
  const char* payload = bytes.data() + r.offset();
#ifndef FUZZING_BUILD_MODE_UNSAFE_FOR_PRODUCTION  // fuzzers reach the payload decoders past the checksum
  if (chunk_checksum(code, size, payload) != checksum) {
    why = fmt::format("checksum mismatch in chunk {} at byte {}", fourcc_text(code), offset);
    return std::nullopt;
  }
#endif
  return ChunkView{code, offset, std::span<const char>(payload, size)};
}

}  // namespace

void RecordingReader::open(std::span<const char> bytes) {
  bytes_ = bytes;
  ByteReader r(bytes, name_);
  if (bytes.size() < kPreambleBytes) {
    if (bytes.size() >= sizeof kMagic && std::memcmp(bytes.data(), kMagic, sizeof kMagic) != 0) {
      r.fail_at(0, "not a facecap recording (bad magic)");
    }
    r.fail_at(bytes.size(), "recording cut off inside its 16-byte preamble");
  }
  if (std::memcmp(bytes.data(), kMagic, sizeof kMagic) != 0) r.fail_at(0, "not a facecap recording (bad magic)");
  r.seek(sizeof kMagic);
  header_.format_version = r.u16();
  header_.min_reader_version = r.u16();
  if (header_.min_reader_version > kRecordingReaderVersion) {
    r.fail_at(10, fmt::format("recording format {} needs reader version {}; this reader is version {}",
                              header_.format_version, header_.min_reader_version, kRecordingReaderVersion));
  }
  std::string why;
  const auto head = chunk_at(bytes, kPreambleBytes, why);
  if (head && head->code != kHeadChunk) why = fmt::format("first chunk is {}, expected HEAD", fourcc_text(head->code));
  std::size_t chunks_begin = 0;
  if (head && head->code == kHeadChunk) {
    try {
      ByteReader header_reader(head->payload, name_ + " [HEAD]");
      decode_header(header_reader, header_);
      chunks_begin = kPreambleBytes + kChunkHeaderBytes + head->payload.size();
    } catch (const Error& e) {  // its checksum holds, yet it does not decode
      why = e.what();
    }
  }
  if (chunks_begin == 0) chunks_begin = recover_header(why);
  read_start_state(chunks_begin);
  if (!load_index(chunks_begin)) scan(chunks_begin);
  for (std::size_t i = 0; i < index_.size(); ++i) {
    (index_[i].kind == ChunkKind::kMarkerFrame ? marker_entries_ : solved_entries_).push_back(i);
  }
}

std::size_t RecordingReader::recover_header(std::string_view why) {
  const uint16_t format_version = header_.format_version, min_reader_version = header_.min_reader_version;
  auto keep_versions = [&] {
    header_.format_version = format_version;
    header_.min_reader_version = min_reader_version;
  };
  // The copy close() wrote: the same payload, so HEAD's size tells where the chunks begin.
  // close() writes it right before INDX: only a candidate followed by INDX is checksummed,
  // and only a few, so that a file of fake copies costs no more than a scan.
  constexpr int kMaxCopyCandidates = 8;
  int candidates = 0;
  std::string copy_why;
  for (std::size_t at = kPreambleBytes; at + kChunkHeaderBytes <= bytes_.size() && candidates < kMaxCopyCandidates; ++at) {
    uint32_t code = 0, size = 0, next = 0;
    std::memcpy(&code, bytes_.data() + at, 4);  // little-endian, as written
    if (code != kHeadCopyChunk) continue;
    std::memcpy(&size, bytes_.data() + at + 4, 4);
    const std::size_t end = at + kChunkHeaderBytes + size;
    if (end > bytes_.size() || bytes_.size() - end < 4) continue;
    std::memcpy(&next, bytes_.data() + end, 4);
    if (next != kIndexChunk) continue;
    ++candidates;
    const auto copy = chunk_at(bytes_, at, copy_why);
    if (!copy) continue;
    try {
      ByteReader copy_reader(copy->payload, fmt::format("{} [HCPY @ byte {}]", name_, at));
      decode_header(copy_reader, header_);
    } catch (const Error&) {
      header_ = RecordingHeader{};
      keep_versions();
      continue;
    }
    keep_versions();
    header_damage_ = fmt::format("HEAD damaged ({}); its fields read from the copy at byte {}", why, at);
    return kPreambleBytes + kChunkHeaderBytes + copy->payload.size();
  }
  if (!options_.salvage) {
    throw offset_error(name_, int64_t(kPreambleBytes),
                       fmt::format("recording header unreadable: {}, and the file has no intact copy of it (a "
                                   "recording not closed, or older than format 5); `facecap inspect --salvage` "
                                   "reads its frames without it",
                                   why));
  }
  // Salvaging: HEAD's own payload where it still decodes (its fields may be wrong), and
  // the frames found by scanning from just after the HEAD chunk's header: its size may be
  // the damaged field.
  std::string decoded = "its fields are unknown";
  if (bytes_.size() >= kPreambleBytes + kChunkHeaderBytes) {
    uint32_t size = 0;
    std::memcpy(&size, bytes_.data() + kPreambleBytes + 4, 4);
    const std::size_t payload_at = kPreambleBytes + kChunkHeaderBytes;
    try {
      ByteReader damaged(bytes_.subspan(payload_at, std::min<std::size_t>(size, bytes_.size() - payload_at)),
                         name_ + " [HEAD]");
      decode_header(damaged, header_);
      decoded = "its fields read from the damaged HEAD may be wrong";
    } catch (const Error&) {
      header_ = RecordingHeader{};
    }
  }
  keep_versions();
  header_damage_ = fmt::format("HEAD damaged ({}) and no intact copy: salvaged, {}; frames looked for from byte 32 on", why,
                               decoded);
  return kPreambleBytes + kChunkHeaderBytes;
}

void RecordingReader::read_start_state(std::size_t chunks_begin) {
  uint32_t code = 0;
  if (bytes_.size() < chunks_begin + kChunkHeaderBytes) return;
  std::memcpy(&code, bytes_.data() + chunks_begin, 4);  // little-endian, as written
  if (code != kStartStateChunk) return;
  std::string why;
  if (const auto chunk = chunk_at(bytes_, chunks_begin, why))
    start_state_ = chunk->payload;
  else
    start_state_damage_ = why;
}

bool RecordingReader::load_index(std::size_t chunks_begin) {
  if (bytes_.size() < chunks_begin + kTailChunkBytes) return false;
  const std::size_t tail_offset = bytes_.size() - kTailChunkBytes;
  std::string why;
  const auto tail = chunk_at(bytes_, tail_offset, why);
  if (!tail || tail->code != kTailChunk || tail->payload.size() != kTailPayloadBytes) return false;
  ByteReader t(tail->payload, name_);
  const uint64_t index_offset = t.u64();
  if (t.u64() != tail_offset || index_offset < chunks_begin || index_offset >= tail_offset) return false;
  const auto index = chunk_at(bytes_, std::size_t(index_offset), why);
  if (!index || index->code != kIndexChunk || index_offset + kChunkHeaderBytes + index->payload.size() != tail_offset)
    return false;
  ByteReader r(index->payload, name_);
  const uint32_t count = r.u32();
  if (count != r.remaining() / kIndexEntryBytes || r.remaining() % kIndexEntryBytes != 0) return false;
  std::vector<RecordingIndexEntry> entries(count);
  uint64_t previous_end = chunks_begin;
  for (auto& e : entries) {
    const uint8_t kind = r.u8();
    r.skip(7);
    e.kind = ChunkKind(kind);
    e.offset = r.u64();
    e.frame_no = r.i64();
    e.source_time_ns = r.i64();
    // Chunks follow each other without overlap and before the index.
    if (kind > uint8_t(ChunkKind::kSolvedFrame) || e.offset < previous_end ||
        e.offset > index_offset - kChunkHeaderBytes)  // not e.offset + 16: that can wrap
      return false;
    previous_end = e.offset + kChunkHeaderBytes;
  }
  // Every indexed chunk is checked once here, so a damaged one costs its frame only.
  for (std::size_t i = 0; i < entries.size(); ++i) {
    const RecordingIndexEntry& e = entries[i];
    const auto chunk = chunk_at(bytes_, std::size_t(e.offset), why);
    const uint32_t expected = e.kind == ChunkKind::kMarkerFrame ? kMarkerChunk : kSolvedChunk;
    if (chunk && chunk->code == expected) {
      index_.push_back(e);
      continue;
    }
    if (chunk) why = fmt::format("index points at a {} chunk at byte {}, expected {}", fourcc_text(chunk->code), e.offset,
                                 fourcc_text(expected));
    const uint64_t end = i + 1 < entries.size() ? entries[i + 1].offset : index_offset;
    skipped_.push_back({e.offset, end - e.offset, fmt::format("{} (frame {})", why, e.frame_no)});
  }
  return true;
}

std::size_t RecordingReader::resync(std::size_t from) const {
  // A frame chunk is at most a few MB (a solved mesh); a larger size is damage, and not
  // checksumming it keeps a hostile file from costing the square of its size.
  constexpr uint32_t kMaxResyncPayload = 64u << 20;
  std::string why;
  for (std::size_t at = from; at + kChunkHeaderBytes <= bytes_.size(); ++at) {
    uint32_t code = 0, size = 0;
    std::memcpy(&code, bytes_.data() + at, 4);  // little-endian, as written
    if (code != kMarkerChunk && code != kSolvedChunk && code != kIndexChunk && code != kTailChunk) continue;
    std::memcpy(&size, bytes_.data() + at + 4, 4);
    if (size <= kMaxResyncPayload && chunk_at(bytes_, at, why)) return at;
  }
  return bytes_.size();
}

void RecordingReader::scan(std::size_t chunks_begin) {
  index_rebuilt_ = true;
  std::size_t at = chunks_begin;
  while (at < bytes_.size()) {
    std::string why;
    const auto chunk = chunk_at(bytes_, at, why);
    const bool frame = chunk && (chunk->code == kMarkerChunk || chunk->code == kSolvedChunk);
    const bool short_frame = frame && chunk->payload.size() < 16;  // no room for its number and time
    if (short_frame) why = fmt::format("frame chunk at byte {} has only {} payload bytes", at, chunk->payload.size());
    if (!chunk || short_frame) {
      const std::size_t next = chunk ? at + kChunkHeaderBytes + chunk->payload.size() : resync(at + 1);
      if (next >= bytes_.size()) {
        truncated_ = true;
        stop_reason_ = why;
        return;
      }
      skipped_.push_back({at, next - at, why});
      at = next;
      continue;
    }
    if (frame) {
      ByteReader r(chunk->payload, name_);
      const int64_t frame_no = r.i64();
      const int64_t source_time_ns = r.i64();
      index_.push_back({chunk->code == kMarkerChunk ? ChunkKind::kMarkerFrame : ChunkKind::kSolvedFrame, at, frame_no,
                        source_time_ns});
    }
    // HEAD, INDX, TAIL and chunk kinds of later versions carry no frames: skipped.
    at += kChunkHeaderBytes + chunk->payload.size();
  }
}

std::string RecordingReader::damage_summary() const {
  std::string text = header_damage_;
  if (!skipped_.empty()) {
    if (!text.empty()) text += "; ";
    uint64_t bytes = 0;
    for (const Skipped& s : skipped_) bytes += s.bytes;
    text += fmt::format("{} damaged stretch{} skipped ({} bytes; the first: {})", skipped_.size(),
                       skipped_.size() == 1 ? "" : "es", bytes, skipped_.front().why);
  }
  if (truncated_) text += fmt::format("{}cut off: {}", text.empty() ? "" : "; ", stop_reason_);
  return text;
}

std::span<const char> RecordingReader::frame_payload(const std::vector<std::size_t>& entries, std::size_t i,
                                                     uint32_t expected_code) const {
  if (i >= entries.size()) {
    throw file_error(name_, fmt::format("{} frame {} requested, the recording has {}", fourcc_text(expected_code), i,
                                        entries.size()));
  }
  const uint64_t offset = index_[entries[i]].offset;
  std::string why;
  const auto chunk = chunk_at(bytes_, std::size_t(offset), why);
  if (!chunk) throw offset_error(name_, int64_t(offset), why);
  if (chunk->code != expected_code) {
    throw offset_error(
        name_, int64_t(offset),
        fmt::format("index points at a {} chunk, expected {}", fourcc_text(chunk->code), fourcc_text(expected_code)));
  }
  return chunk->payload;
}

void RecordingReader::read_marker_frame(std::size_t i, MarkerFrame& out) const {
  const auto payload = frame_payload(marker_entries_, i, kMarkerChunk);
  ByteReader r(payload, fmt::format("{} [MRKF @ byte {}]", name_, index_[marker_entries_[i]].offset));
  decode_marker_frame(r, out);
}

void RecordingReader::read_solved_frame(std::size_t i, SolvedFrame& out) const {
  const auto payload = frame_payload(solved_entries_, i, kSolvedChunk);
  ByteReader r(payload, fmt::format("{} [SLVF @ byte {}]", name_, index_[solved_entries_[i]].offset));
  decode_solved_frame(r, out);
}

// ---------------------------------------------------------------------------- takes

MarkerTake take_from_recording(const RecordingReader& reader, const ProgressFn& progress) {
  MarkerTake take;
  take.format = TakeFormat::kRecording;
  const RecordingHeader& h = reader.header();
  take.units = h.units;
  take.labels = h.marker_labels;
  std::unordered_map<std::string, std::size_t> slot_of;
  for (std::size_t k = 0; k < take.labels.size(); ++k) slot_of.emplace(take.labels[k], k);
  const double nan = std::numeric_limits<double>::quiet_NaN();
  std::size_t duplicates = 0;
  std::string first_duplicate;  // described when found
  const std::size_t sample_limit = max_take_samples(reader.size_bytes());
  MarkerFrame raw;
  constexpr std::size_t kUnfilled = std::size_t(-1);
  std::vector<std::size_t> filled_by;  // per slot, the marker of this frame that filled it
  std::string generated;
  const std::size_t count = reader.marker_frame_count();
  take.frames.reserve(count);
  for (std::size_t i = 0; i < count; ++i) {
    reader.read_marker_frame(i, raw);
    MarkerFrame& frame = take.frames.emplace_back();
    frame.frame_no = raw.frame_no;
    frame.source_time_ns = raw.source_time_ns;
    frame.receive_time_ns = raw.receive_time_ns;
    frame.timecode = raw.timecode;
    filled_by.assign(take.labels.size(), kUnfilled);
    for (std::size_t k = 0; k < raw.markers.size(); ++k) {
      const Marker& m = raw.markers[k];
      std::string_view label = m.label.view();
      if (label.empty()) {
        generated = m.id >= 0 ? fmt::format("id_{}", m.id) : fmt::format("unlabelled_{}", k);
        label = generated;
      }
      // Most sources send the same markers in the same order every frame: check the
      // slot of the same position before the map.
      std::size_t slot = k;
      if (k >= take.labels.size() || take.labels[k] != label) {
        auto [it, added] = slot_of.emplace(std::string(label), take.labels.size());
        if (added) {
          // Every frame gets a slot per label: marker ids that change every frame would
          // multiply into more slots than the file could ever describe.
          if (count * (take.labels.size() + 1) > sample_limit)
            throw file_error(reader.name(),
                             fmt::format("{} distinct marker labels by frame {} of {}: as a take (a slot per label in "
                                         "every frame) more than the {} marker samples a {}-byte file may expand to",
                                         take.labels.size() + 1, i + 1, count, sample_limit, reader.size_bytes()));
          take.labels.emplace_back(label);
          filled_by.push_back(kUnfilled);
        }
        slot = it->second;
      }
      if (frame.markers.size() < take.labels.size()) frame.markers.resize(take.labels.size());
      if (filled_by[slot] != kUnfilled) {
        if (duplicates++ == 0)
          first_duplicate = fmt::format("'{}' in frame {} (markers {} and {} of the frame)", label, raw.frame_no,
                                        filled_by[slot] + 1, k + 1);
        continue;
      }
      filled_by[slot] = k;
      frame.markers[slot] = m;
      frame.markers[slot].label.assign(label);
    }
    report_progress(progress, i + 1, count);
  }
  // Slots a frame did not fill (including labels first seen later) are missing markers.
  for (auto& frame : take.frames) {
    const std::size_t had = frame.markers.size();
    frame.markers.resize(take.labels.size());
    for (std::size_t k = 0; k < frame.markers.size(); ++k) {
      Marker& m = frame.markers[k];
      if (k >= had || m.label.empty()) {
        m.id = -1;
        m.label.assign(take.labels[k]);
        set_missing(m);
      } else if (!m.present()) {
        m.position = Eigen::Vector3d(nan, nan, nan);
      }
    }
  }
  take.first_frame = take.frames.empty() ? 1 : take.frames.front().frame_no;
  take.rate_hz = h.rate_hz;
  if (take.rate_hz <= 0 && take.frames.size() > 1) {
    // In double: the difference of two hostile i64 times overflows an i64.
    const double span_ns = double(take.frames.back().source_time_ns) - double(take.frames.front().source_time_ns);
    if (span_ns > 0) take.rate_hz = double(take.frames.size() - 1) * 1e9 / span_ns;
  }
  take.metadata = {
      {"format_version", fmt::format("{}", h.format_version)},
      {"min_reader_version", fmt::format("{}", h.min_reader_version)},
      {"rig_name", h.rig_name},
      {"rig_hash", fmt::format("{:016x}", h.rig_hash)},
      {"source", h.source_description},
      {"calibration_bytes", fmt::format("{}", h.calibration.size())},
      {"solved_frames", fmt::format("{}", reader.solved_frame_count())},
      {"start_state_bytes", fmt::format("{}", reader.start_state().size())},  // 0: a re-solve starts cold
      {"index", reader.index_rebuilt() ? "rebuilt by scanning" : "present"},
  };
  // The slate (format version 3), as docs/daemon.md promises `facecap inspect` shows it.
  for (const auto& [key, value] : {std::pair<const char*, const std::string&>{"take", h.take}, {"actor", h.actor},
                                   {"scene", h.scene}, {"shot", h.shot}, {"notes", h.notes}})
    if (!value.empty()) take.metadata.emplace_back(key, value);
  if (!reader.start_state_damage().empty())
    take.warnings.push_back(fmt::format("{}: start state unreadable: {}; a re-solve starts cold", reader.name(),
                                        reader.start_state_damage()));
  if (const std::string damage = reader.damage_summary(); !damage.empty())
    take.warnings.push_back(fmt::format("{}: recording damaged: {}; the rest was read", reader.name(), damage));
  if (duplicates > 0)
    take.warnings.push_back(fmt::format("{}: {} markers repeat a label within their frame, the first {}; the first "
                                        "marker with a label is kept",
                                        reader.name(), duplicates, first_duplicate));
  finish_take(take, reader.name());
  return take;
}

void write_recording(const std::filesystem::path& path, const MarkerTake& take, const std::string& source_description,
                     const ProgressFn& progress) {
  check_take_shape(take, "recording writer");
  RecordingHeader header;
  header.source_description = source_description;
  header.units = take.units;
  header.rate_hz = take.rate_hz;
  header.marker_labels = take.labels;
  RecordingWriter writer(path, header, RecordingWriter::Options{.overwrite = true});
  for (std::size_t f = 0; f < take.frames.size(); ++f) {
    writer.append_marker_frame(take.frames[f]);
    report_progress(progress, f + 1, take.frames.size());
  }
  writer.close();
}

}  // namespace facecap::formats
