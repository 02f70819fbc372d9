#include "outputs/shm/shm_writer.hpp"

#include <algorithm>
#include <cerrno>
#include <cstring>
#include <random>

#include <fcntl.h>
#include <fmt/format.h>
#include <sys/mman.h>
#include <sys/stat.h>
#include <unistd.h>

#include "client/facecap_shm_lock.hpp"
#include "core/error.hpp"
#include "core/log.hpp"
#include "core/time.hpp"

namespace facecap::outputs {
namespace {

using namespace facecap::shm;

// A writer that holds its lock but has not beaten for this long is reported as stalled.
constexpr int64_t kStalledWriterNs = 2 * kNsPerSecond;
constexpr mode_t kSegmentMode = 0640;  // owner writes, the facecap group reads
// A name freed by removing a stale segment can be taken by another writer before ours is
// created; after this many rounds we give up and say so.
constexpr int kCreateAttempts = 4;
// Someone inspecting our new segment holds a lock on it for a moment; a read lock held
// longer (a reader that opened it between its creation and our lock) makes us give up.
constexpr int64_t kLockWaitNs = kNsPerSecond;

// Whether the name still refers to the segment open on `fd`.
bool names_segment(const std::string& name, int fd) {
  const int now = shm_open(name.c_str(), O_RDONLY, 0);
  if (now < 0) return false;
  struct stat ours {}, named {};
  const bool same = fstat(fd, &ours) == 0 && fstat(now, &named) == 0 && ours.st_dev == named.st_dev &&
                    ours.st_ino == named.st_ino;
  close(now);
  return same;
}

// Takes the writer lock on our new segment, waiting up to kLockWaitNs. False, errno set,
// when it could not.
bool take_writer_lock(int fd) {
  const int64_t give_up = monotonic_now_ns() + kLockWaitNs;
  while (!try_writer_lock(fd)) {
    if ((errno != EAGAIN && errno != EACCES && errno != EINTR) || monotonic_now_ns() >= give_up) return false;
    timespec pause{0, long(kNsPerMs)};
    nanosleep(&pause, nullptr);
  }
  return true;
}

// Removes the segment `name` when its writer is gone (nobody holds the writer lock) and
// returns empty; otherwise explains who holds it and leaves it alone.
std::string remove_if_stale(const std::string& name) {
  int fd = shm_open(name.c_str(), O_RDWR, 0);
  const bool can_take = fd >= 0;
  if (fd < 0) fd = shm_open(name.c_str(), O_RDONLY, 0);
  if (fd < 0) return errno == ENOENT ? std::string() : fmt::format("it cannot be opened ({})", std::strerror(errno));
  // Held from here to the unlink, so that nobody else judges the same segment meanwhile.
  const bool locked = can_take && try_writer_lock(fd);
  std::string owner;
  struct stat st {};
  const Header* h = nullptr;
  void* p = MAP_FAILED;
  if (fstat(fd, &st) == 0 && std::size_t(st.st_size) >= sizeof(Header)) {
    p = mmap(nullptr, sizeof(Header), PROT_READ, MAP_SHARED, fd, 0);
    if (p != MAP_FAILED && __atomic_load_n(&static_cast<const Header*>(p)->magic, __ATOMIC_ACQUIRE) == kMagic)
      h = static_cast<const Header*>(p);
  }
  if (!locked && writer_lock_held(fd)) {
    if (!h) {
      owner = "another writer is creating it";
    } else {
      const int64_t age_ns = monotonic_now_ns() - h->heartbeat_ns.load(std::memory_order_acquire);
      owner = age_ns < kStalledWriterNs
                  ? fmt::format("facecapd pid {} is writing it (last heartbeat {:.2f} s ago)", h->writer_pid,
                                double(age_ns) / kNsPerSecond)
                  : fmt::format("facecapd pid {} still holds it but is stalled (no heartbeat for {:.1f} s: stopped "
                                "or hung, not dead)", h->writer_pid, double(age_ns) / kNsPerSecond);
    }
  } else if (!h) {
    owner = "it is not a facecap segment";
  } else if (!can_take) {
    owner = "its writer is gone but this user may not remove it";
  } else if (locked || names_segment(name, fd)) {
    // Without our lock (a reader holds a read lock, which does not keep a writer's name),
    // the name is checked to still be this segment, so that a writer that took it over
    // meanwhile keeps its new one.
    spdlog::warn("taking over shared memory {}: its writer (facecapd pid {}) is gone{}", name, h->writer_pid,
                 locked ? ", nothing holds its lock" : "; a reader's read lock on it is left with the old segment");
    shm_unlink(name.c_str());
  }
  if (p != MAP_FAILED) munmap(p, sizeof(Header));
  close(fd);  // drops our lock, after the unlink
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

  int fd = -1;
  for (int attempt = 0; fd < 0 && attempt < kCreateAttempts; ++attempt) {
    fd = shm_open(name_.c_str(), O_CREAT | O_EXCL | O_RDWR, kSegmentMode);
    if (fd >= 0 || errno != EEXIST) break;
    if (const std::string owner = remove_if_stale(name_); !owner.empty())
      throw Error(fmt::format("shared memory {} already exists and {}; choose another outputs.shm.name or stop that "
                              "writer", name_, owner));
  }
  if (fd < 0) throw Error(fmt::format("cannot create shared memory {}: {}", name_, std::strerror(errno)));
  // Before anything else: a segment whose lock is free counts as stale.
  if (!take_writer_lock(fd)) {
    const int saved_errno = errno;
    close(fd);
    shm_unlink(name_.c_str());
    throw Error(fmt::format("cannot lock shared memory {} within {} s (another process holds a lock on it): {}", name_,
                            kLockWaitNs / kNsPerSecond, std::strerror(saved_errno)));
  }
  // The umask may have narrowed the mode; readers in the group need exactly 0640.
  const bool sized = fchmod(fd, kSegmentMode) == 0 && ftruncate(fd, off_t(geometry.total_bytes)) == 0;
  if (struct stat st {}; fstat(fd, &st) == 0) {
    device_ = st.st_dev;
    inode_ = st.st_ino;
  }
  void* p = sized ? mmap(nullptr, geometry.total_bytes, PROT_READ | PROT_WRITE, MAP_SHARED, fd, 0) : MAP_FAILED;
  const int saved_errno = errno;
  if (p == MAP_FAILED) {
    shm_unlink(name_.c_str());
    close(fd);
    throw Error(fmt::format("cannot size or map shared memory {} ({} bytes): {}", name_, geometry.total_bytes,
                            std::strerror(saved_errno)));
  }
  lock_fd_ = fd;
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
  close(lock_fd_);  // releases the writer lock, after the unlink
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
