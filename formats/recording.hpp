#pragma once
// facecap recordings (.fcrec): raw marker frames and solved frames as written by the
// recorder, read back by replay, convert and inspect. Byte layout: docs/recording-format.md.
//
// A file is a preamble (magic, format version, minimum reader version) and a sequence of
// checksummed chunks: one HEAD (rig identity, calibration, source), then MRKF (marker
// frame) and SLVF (solved frame) chunks in the order they were appended, and at close an
// INDX chunk and a fixed-size TAIL pointing at it. A file without a valid tail (process
// killed, disk full) is scanned instead, and reads back up to its last complete chunk.
#include <cstdint>
#include <filesystem>
#include <memory>
#include <span>
#include <string>
#include <vector>

#include <sys/types.h>

#include "core/frame.hpp"
#include "formats/take.hpp"

namespace facecap::formats {

// 2: HEAD gains rig_units and solver_settings (version 1 readers skip them).
// 3: HEAD gains the slate: take, actor, scene, shot, notes (older readers skip them).
// 4: an optional STAT chunk after HEAD holds the solve's state before the first frame;
//    SLVF gains fold_deadline_rounds (older readers skip both).
// 5: close() writes HCPY, a copy of HEAD, before INDX, so that a damaged HEAD costs no
//    frames (older readers skip it).
inline constexpr uint16_t kRecordingFormatVersion = 5;
// Readers of this version understand files whose minimum reader version is <= this.
inline constexpr uint16_t kRecordingReaderVersion = 1;

struct RecordingHeader {
  uint16_t format_version = kRecordingFormatVersion;  // as read; writers write theirs
  uint16_t min_reader_version = kRecordingReaderVersion;
  std::string rig_name;                    // empty for marker-only recordings
  uint64_t rig_hash = 0;                   // identity of the rig the solved frames refer to
  std::string source_description;          // "natnet 10.0.0.5:1511", "converted from take.c3d", ...
  std::string calibration;                 // calibration as text (TOML), may be empty
  std::string units;                       // marker units ("mm", "cm", "m")
  double rate_hz = 0.0;                    // nominal frame rate, 0 when unknown
  int64_t created_unix_ns = 0;             // wall clock at open (CLOCK_REALTIME)
  std::vector<std::string> marker_labels;  // expected marker set, may be empty
  std::vector<std::string> shape_names;    // rig shapes, the order of SolvedFrame::weights
  // Format version 2 (empty when read from version 1):
  std::string rig_units;                   // the solved frames' length unit ("mm", "cm", "m")
  std::string solver_settings;             // the [solver] section the frames were solved with (TOML)
  // Format version 3 (empty when read from older versions): the slate.
  std::string take, actor, scene, shot, notes;
};

enum class ChunkKind : uint8_t { kMarkerFrame, kSolvedFrame };

struct RecordingIndexEntry {
  ChunkKind kind = ChunkKind::kMarkerFrame;
  uint64_t offset = 0;  // of the chunk header
  int64_t frame_no = 0;
  int64_t source_time_ns = 0;
};

// Appends frames to a new recording. Not real-time safe (allocates, writes, checksums):
// call it from a recorder thread fed by a queue. Every append adds one whole chunk to an
// in-memory buffer that reaches the file on flush() or when it grows past a limit, so a
// killed process leaves whole chunks and at most one partial chunk at the end.
//
// A write that fails (disk full, file too large, I/O error) never leaves a partial chunk
// to be written again on top of itself: the file is cut back to its last whole chunk, the
// writer fails (appends and flushes throw, the first with the reason), the frames that
// did not reach the file are subtracted from the counts, and close() still tries to add
// the index; without it readers find every frame by scanning.
class RecordingWriter {
 public:
  // Writes size bytes at offset like pwrite(2); tests inject failures and short writes.
  using WriteFn = ssize_t (*)(int fd, const void* data, std::size_t size, off_t offset);
  struct Options {
    bool overwrite = false;                           // else an existing file is an error
    std::size_t buffer_bytes = std::size_t(1) << 20;  // flush automatically past this
    WriteFn write = nullptr;                          // null: pwrite(2)
  };
  // Creates the file and writes the preamble and HEAD chunk. Throws Error (and leaves no
  // file behind when the header could not be written).
  RecordingWriter(const std::filesystem::path& path, const RecordingHeader& header, Options options);
  RecordingWriter(const std::filesystem::path& path, const RecordingHeader& header)
      : RecordingWriter(path, header, Options{}) {}
  ~RecordingWriter();  // closes (writes the index) if close() was not called; logs errors
  RecordingWriter(const RecordingWriter&) = delete;
  RecordingWriter& operator=(const RecordingWriter&) = delete;

  // The solve's state before the first frame (STAT: a versioned payload the pipeline
  // encodes, pipeline/pipeline_state.hpp), so that a recording started mid-run re-solves
  // to itself from its first frame. At most once, before any frame; throws Error
  // otherwise, and as the appends below do.
  void append_start_state(std::span<const char> state);
  // Throws Error when the writer is closed or has failed, or when flushing fails.
  void append_marker_frame(const MarkerFrame& frame);
  void append_solved_frame(const SolvedFrame& frame);
  // Hands buffered chunks to the kernel; durable also waits for the disk (fdatasync).
  void flush(bool durable = false);
  // Writes INDX and TAIL, syncs and closes. Further appends throw. Throws Error when the
  // last chunks cannot be written (the file then ends at its last whole chunk). After a
  // failure it only tries to add the index and closes, without throwing again.
  void close();

  bool is_open() const noexcept { return fd_ >= 0; }
  // Why writing stopped (empty while none failed).
  const std::string& failure() const noexcept { return failure_; }
  // True when the file was deleted (or its directory removed) while open: fstat's link
  // count is 0, and nothing written reaches a file anyone can open.
  bool file_deleted() const;
  // Frames in the file or buffered for it: after a failure, only those in the file.
  std::size_t marker_frames() const noexcept { return marker_frames_; }
  std::size_t solved_frames() const noexcept { return solved_frames_; }
  uint64_t bytes_written() const noexcept { return file_bytes_ + buffer_.size(); }

 private:
  void append_chunk(uint32_t fourcc, const std::vector<char>& payload);
  // Writes the buffer at file_bytes_; on failure cuts the file back to its last whole
  // chunk, drops the lost frames from the index and counts, and throws.
  void write_buffer();

  std::string path_;
  Options options_;
  int fd_ = -1;
  uint64_t file_bytes_ = 0;  // bytes in the file, always ending with a whole chunk
  std::vector<char> buffer_;
  std::vector<std::size_t> buffer_chunk_ends_;  // where each chunk in buffer_ ends
  std::vector<char> payload_;  // reused per frame
  std::vector<char> head_payload_;  // written again at close (HCPY)
  std::vector<RecordingIndexEntry> index_;
  std::size_t marker_frames_ = 0;
  std::size_t solved_frames_ = 0;
  bool start_state_written_ = false;
  std::string failure_;
};

struct RecordingReadOptions {
  // A HEAD that is damaged and has no intact copy (HCPY) is refused unless salvaging:
  // then its fields are taken from the damaged payload where it still decodes (else left
  // empty) and the frames are looked for from byte 32 on, with header_damage() saying so.
  bool salvage = false;
  bool no_follow = false;  // refuse a symlink rather than follow it (listing a directory)
};

// Reads a recording held in memory or mapped from a file. Frames are decoded on demand,
// each chunk's checksum checked as it is read.
class RecordingReader {
 public:
  using Options = RecordingReadOptions;
  // Maps the file read-only (a regular file only). Throws Error (not a recording, newer
  // than this reader, cut off before its header is complete, HEAD damaged without salvage).
  explicit RecordingReader(const std::filesystem::path& path, Options options = {});
  // Reads from a buffer the caller keeps alive (tests, fuzzing).
  RecordingReader(std::span<const char> bytes, std::string name, Options options = {});
  ~RecordingReader();
  RecordingReader(RecordingReader&&) noexcept;
  RecordingReader& operator=(RecordingReader&&) noexcept;

  const RecordingHeader& header() const noexcept { return header_; }
  const std::string& name() const noexcept { return name_; }
  std::size_t size_bytes() const noexcept { return bytes_.size(); }
  // The index as written at close, or rebuilt by scanning.
  const std::vector<RecordingIndexEntry>& index() const noexcept { return index_; }
  bool index_rebuilt() const noexcept { return index_rebuilt_; }
  // True when the file ends in an incomplete or damaged chunk (writer killed); the
  // frames before it are all readable. stop_reason says what was found where.
  bool truncated() const noexcept { return truncated_; }
  const std::string& stop_reason() const noexcept { return stop_reason_; }
  // Damaged stretches before the end, skipped: the reader went on at the next chunk
  // whose checksum holds (or, with an index, the next indexed frame).
  struct Skipped {
    uint64_t offset = 0;  // where the damaged chunk starts
    uint64_t bytes = 0;   // how many bytes were skipped
    std::string why;
  };
  const std::vector<Skipped>& skipped() const noexcept { return skipped_; }
  // What could not be read, in one line ("" when the whole file was read): the stretches
  // skipped and where the file was cut off.
  std::string damage_summary() const;
  // Why HEAD could not be read and where its fields came from instead ("" when HEAD was
  // intact): its copy written at close, or (salvaging) the damaged HEAD itself or nothing.
  const std::string& header_damage() const noexcept { return header_damage_; }

  // The STAT chunk's payload (RecordingWriter::append_start_state), empty when the
  // recording has none; start_state_damage() says why one could not be read ("" when
  // there was none or it was read).
  std::span<const char> start_state() const noexcept { return start_state_; }
  const std::string& start_state_damage() const noexcept { return start_state_damage_; }

  std::size_t marker_frame_count() const noexcept { return marker_entries_.size(); }
  std::size_t solved_frame_count() const noexcept { return solved_entries_.size(); }
  // Decodes the i-th marker / solved frame into out (its storage is reused). Throws Error
  // on a checksum mismatch or malformed payload.
  void read_marker_frame(std::size_t i, MarkerFrame& out) const;
  void read_solved_frame(std::size_t i, SolvedFrame& out) const;

 private:
  struct Mapping;
  void open(std::span<const char> bytes);
  // When HEAD is damaged: the header from its copy, or salvaged; returns where the
  // chunks after HEAD begin (or the first offset to scan from).
  std::size_t recover_header(std::string_view why);
  // The STAT chunk, when the chunks begin with one.
  void read_start_state(std::size_t chunks_begin);
  bool load_index(std::size_t chunks_begin);
  void scan(std::size_t chunks_begin);
  // The first offset at or after from where a whole chunk of a known kind with a valid
  // checksum starts, or the file's size when there is none.
  std::size_t resync(std::size_t from) const;
  // The checked payload of entries[i]'s chunk, which must be of expected_code's kind.
  std::span<const char> frame_payload(const std::vector<std::size_t>& entries, std::size_t i,
                                      uint32_t expected_code) const;

  std::string name_;
  Options options_;
  std::unique_ptr<Mapping> mapping_;  // owns the mapped file, when there is one
  std::span<const char> bytes_;
  RecordingHeader header_;
  std::vector<RecordingIndexEntry> index_;
  std::vector<std::size_t> marker_entries_;  // positions in index_
  std::vector<std::size_t> solved_entries_;
  std::span<const char> start_state_;
  std::string start_state_damage_;
  std::string header_damage_;
  bool index_rebuilt_ = false;
  bool truncated_ = false;
  std::string stop_reason_;
  std::vector<Skipped> skipped_;
};

// A recording's marker frames as a take: one slot per distinct label in order of first
// appearance (unlabelled markers are named id_<id>), absent markers missing. A label
// repeated within a frame keeps its first marker (with a warning naming the frame and
// both markers). Throws Error when labels x frames exceeds max_take_samples of the file.
MarkerTake take_from_recording(const RecordingReader& reader, const ProgressFn& progress = {});

// Writes a take's frames as a marker-only recording (the HEAD names the source).
void write_recording(const std::filesystem::path& path, const MarkerTake& take, const std::string& source_description,
                     const ProgressFn& progress = {});

}  // namespace facecap::formats
