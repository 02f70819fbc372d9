#include "outputs/shm/shm_writer.hpp"

#include <algorithm>
#include <cerrno>
#include <csignal>
#include <cstring>
#include <random>

#include <fcntl.h>
#include <fmt/format.h>
#include <sys/mman.h>
#include <sys/stat.h>
#include <unistd.h>

#include "core/error.hpp"
#include "core/log.hpp"
#include "core/time.hpp"

namespace facecap::outputs {
namespace {

using namespace facecap::shm;

// A writer that has not beaten for this long is considered dead.
constexpr int64_t kStaleWriterNs = 2 * kNsPerSecond;
constexpr mode_t kSegmentMode = 0640;  // owner writes, the facecap group reads

bool process_alive(pid_t pid) { return pid > 0 && (::kill(pid, 0) == 0 || errno == EPERM); }

// Explains who holds an existing segment, or returns empty when it may be removed.
std::string existing_segment_owner(const std::string& name) {
  const int fd = shm_open(name.c_str(), O_RDONLY, 0);
  if (fd < 0) return {};
  struct stat st {};
  std::string owner;
  if (fstat(fd, &st) == 0 && std::size_t(st.st_size) >= sizeof(Header)) {
    void* p = mmap(nullptr, sizeof(Header), PROT_READ, MAP_SHARED, fd, 0);
    if (p != MAP_FAILED) {
      const auto* h = static_cast<const Header*>(p);
      if (__atomic_load_n(&h->magic, __ATOMIC_ACQUIRE) != kMagic) {
        owner = "it is not a facecap segment";
      } else {
        const int64_t age_ns = monotonic_now_ns() - h->heartbeat_ns.load(std::memory_order_acquire);
        const bool stopped = h->writer_state.load(std::memory_order_acquire) == kWriterStopped;
        if (!stopped && age_ns < kStaleWriterNs && process_alive(h->writer_pid))
          owner = fmt::format("facecapd pid {} is writing it (last heartbeat {:.2f} s ago)", h->writer_pid,
                              double(age_ns) / kNsPerSecond);
      }
      munmap(p, sizeof(Header));
    }
  } else if (std::size_t(st.st_size) < sizeof(Header)) {
    owner = "it is not a facecap segment";
  }
  close(fd);
  return owner;
}

}  // namespace

std::string shm_object_name(const std::string& name) {
  if (!shm::valid_name(name)) throw Error(fmt::format("shared-memory name '{}' must be 1 to 200 letters, digits, '-', '_' or '.'", name));
  return name[0] == '/' ? name : "/" + name;
}

ShmWriter::ShmWriter(const ShmOutputSpec& spec) : name_(shm_object_name(spec.name)) {
  if (spec.slot_count < 2 || spec.slot_count > kMaxSlots)
    throw Error(fmt::format("shared memory needs 2 to {} slots, {} given", kMaxSlots, spec.slot_count));
  if (spec.shape_names.size() > kMaxShapes || spec.vertex_count > kMaxVertices)
    throw Error(fmt::format("rig too large for the shared-memory layout ({} shapes, {} vertices; at most {} and {})",
                            spec.shape_names.size(), spec.vertex_count, kMaxShapes, kMaxVertices));
  const uint32_t shape_count = uint32_t(spec.shape_names.size());
  const Geometry geometry = compute_geometry(shape_count, spec.vertex_count, spec.slot_count);

  int fd = shm_open(name_.c_str(), O_CREAT | O_EXCL | O_RDWR, kSegmentMode);
  if (fd < 0 && errno == EEXIST) {
    if (const std::string owner = existing_segment_owner(name_); !owner.empty())
      throw Error(fmt::format("shared memory {} already exists and {}; choose another outputs.shm.name or stop that "
                              "writer (remove /dev/shm{} if it is stale)", name_, owner, name_));
    spdlog::warn("removing stale shared memory {} left by a writer that is gone", name_);
    shm_unlink(name_.c_str());
    fd = shm_open(name_.c_str(), O_CREAT | O_EXCL | O_RDWR, kSegmentMode);
  }
  if (fd < 0) throw Error(fmt::format("cannot create shared memory {}: {}", name_, std::strerror(errno)));
  // The umask may have narrowed the mode; readers in the group need exactly 0640.
  const bool sized = fchmod(fd, kSegmentMode) == 0 && ftruncate(fd, off_t(geometry.total_bytes)) == 0;
  if (struct stat st {}; fstat(fd, &st) == 0) {
    device_ = st.st_dev;
    inode_ = st.st_ino;
  }
  void* p = sized ? mmap(nullptr, geometry.total_bytes, PROT_READ | PROT_WRITE, MAP_SHARED, fd, 0) : MAP_FAILED;
  const int saved_errno = errno;
  close(fd);
  if (p == MAP_FAILED) {
    shm_unlink(name_.c_str());
    throw Error(fmt::format("cannot size or map shared memory {} ({} bytes): {}", name_, geometry.total_bytes,
                            std::strerror(saved_errno)));
  }
  base_ = static_cast<unsigned char*>(p);
  size_ = geometry.total_bytes;
  std::memset(base_, 0, size_);  // also faults every page in now rather than on the solve thread

  header_ = new (base_) Header{};
  header_->layout_version = kLayoutVersion;
  header_->header_bytes = sizeof(Header);
  header_->total_bytes = geometry.total_bytes;
  header_->slot_count = spec.slot_count;
  header_->slot_bytes = geometry.slot_bytes;
  header_->shape_count = shape_count;
  header_->vertex_count = spec.vertex_count;
  header_->shape_name_bytes = kShapeNameBytes;
  header_->slot_weights_offset = geometry.slot_weights_offset;
  header_->slot_vertices_offset = geometry.slot_vertices_offset;
  header_->shape_names_offset = geometry.shape_names_offset;
  header_->arkit_names_offset = geometry.arkit_names_offset;
  header_->slots_offset = geometry.slots_offset;
  header_->writer_pid = ::getpid();
  header_->writer_generation = (uint64_t(std::random_device{}()) << 32) ^ std::random_device{}() ^ uint64_t(monotonic_now_ns());
  header_->writer_start_ns = monotonic_now_ns();
  header_->nominal_rate_hz = spec.nominal_rate_hz;
  header_->rig_hash = spec.rig_hash;
  std::snprintf(header_->rig_name, kRigNameBytes, "%s", spec.rig_name.c_str());
  header_->heartbeat_ns.store(monotonic_now_ns(), std::memory_order_relaxed);
  for (uint32_t i = 0; i < shape_count; ++i) {
    char* text = reinterpret_cast<char*>(base_ + geometry.shape_names_offset + uint64_t(i) * kShapeNameBytes);
    std::snprintf(text, kShapeNameBytes, "%s", spec.shape_names[i].c_str());
    char* arkit = reinterpret_cast<char*>(base_ + geometry.arkit_names_offset + uint64_t(i) * kShapeNameBytes);
    std::snprintf(arkit, kShapeNameBytes, "%s", i < spec.arkit_names.size() ? spec.arkit_names[i].c_str() : "");
  }
  for (uint32_t s = 0; s < spec.slot_count; ++s) new (base_ + geometry.slots_offset + uint64_t(s) * geometry.slot_bytes) SlotHeader{};
  // Last: a reader that sees the magic sees every field above.
  __atomic_store_n(&header_->magic, kMagic, __ATOMIC_RELEASE);
}

ShmWriter::~ShmWriter() {
  if (!base_) return;
  mark_stopped();
  munmap(base_, size_);
  const int fd = shm_open(name_.c_str(), O_RDONLY, 0);
  if (fd < 0) return;
  struct stat st {};
  const bool still_ours = fstat(fd, &st) == 0 && st.st_dev == device_ && st.st_ino == inode_;
  close(fd);
  if (still_ours) shm_unlink(name_.c_str());
}

shm::SlotHeader& ShmWriter::slot_for(uint64_t sequence) noexcept {
  return *reinterpret_cast<SlotHeader*>(base_ + header_->slots_offset + ((sequence - 1) % header_->slot_count) * header_->slot_bytes);
}

int64_t ShmWriter::publish(const SolvedFrame& frame) noexcept {
  const uint64_t sequence = published_ + 1;
  SlotHeader& slot = slot_for(sequence);
  unsigned char* slot_base = reinterpret_cast<unsigned char*>(&slot);
  const uint64_t lock = slot.seqlock.load(std::memory_order_relaxed);
  slot.seqlock.store(lock + 1, std::memory_order_relaxed);
  // Orders the odd value before every store into the slot (a real fence: readers run on
  // other cores).
  std::atomic_thread_fence(std::memory_order_release);

  slot.sequence = sequence;
  slot.frame_no = frame.frame_no;
  slot.source_time_ns = frame.source_time_ns;
  slot.receive_time_ns = frame.receive_time_ns;
  slot.solve_start_ns = frame.solve_start_ns;
  slot.solve_end_ns = frame.solve_end_ns;
  slot.head_rotation_wxyz[0] = float(frame.head_rotation.w());
  slot.head_rotation_wxyz[1] = float(frame.head_rotation.x());
  slot.head_rotation_wxyz[2] = float(frame.head_rotation.y());
  slot.head_rotation_wxyz[3] = float(frame.head_rotation.z());
  for (int k = 0; k < 3; ++k) slot.head_translation[k] = float(frame.head_translation[k]);
  slot.flags = frame.flags;
  slot.markers_used = frame.markers_used;
  slot.collision_constraints = frame.collision_constraints;
  slot.timecode_hours = frame.timecode.hours;
  slot.timecode_minutes = frame.timecode.minutes;
  slot.timecode_seconds = frame.timecode.seconds;
  slot.timecode_frames = frame.timecode.frames;
  slot.timecode_rate_hz = frame.timecode.rate_hz;
  slot.timecode_subframe = frame.timecode.subframe;
  for (std::size_t s = 0; s < kStageCount && s < frame.stage_ns.size(); ++s) slot.stage_ns[s] = frame.stage_ns[s];

  const std::size_t shapes = std::min<std::size_t>(header_->shape_count, std::size_t(frame.weights.size()));
  std::memcpy(slot_base + header_->slot_weights_offset, frame.weights.data(), shapes * sizeof(float));
  const std::size_t vertices = std::min<std::size_t>(header_->vertex_count, std::size_t(frame.vertices.cols()));
  if (vertices > 0)
    std::memcpy(slot_base + header_->slot_vertices_offset, frame.vertices.data(), vertices * 3 * sizeof(float));

  const int64_t publish_ns = monotonic_now_ns();
  slot.publish_time_ns = publish_ns;
  slot.seqlock.store(lock + 2, std::memory_order_release);
  header_->last_published.store(sequence, std::memory_order_release);
  header_->heartbeat_ns.store(publish_ns, std::memory_order_release);
  if (published_ == 0) header_->writer_state.store(kWriterRunning, std::memory_order_release);
  published_ = sequence;
  return publish_ns;
}

void ShmWriter::beat(int64_t now_ns) noexcept { header_->heartbeat_ns.store(now_ns, std::memory_order_release); }

void ShmWriter::mark_stopped() noexcept { header_->writer_state.store(kWriterStopped, std::memory_order_release); }

}  // namespace facecap::outputs
