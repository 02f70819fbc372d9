// The subscriber side of the shared-memory ring. Everything here is allocation-free
// after facecap_client_open(); reads copy one slot under its seqlock and never write to
// the segment (it is mapped PROT_READ).
#include "client/facecap_client.h"

#include <cerrno>
#include <cstring>
#include <ctime>
#include <memory>
#include <string>
#include <vector>

#include <fcntl.h>
#include <sys/mman.h>
#include <sys/stat.h>
#include <unistd.h>

#include "client/facecap_shm_layout.hpp"
#include "client/facecap_shm_lock.hpp"

namespace {

using namespace facecap::shm;

// A reader that loses this many races in a row is being lapped continuously.
constexpr int kMaxReadAttempts = 64;
constexpr int64_t kPollIntervalNs = 200'000;
constexpr int64_t kWriterCheckIntervalNs = 100'000'000;
constexpr int64_t kDefaultStaleNs = 1'000'000'000;

int64_t now_ns() noexcept {
  timespec ts{};
  clock_gettime(CLOCK_MONOTONIC, &ts);
  return int64_t(ts.tv_sec) * 1'000'000'000 + ts.tv_nsec;
}

void sleep_ns(int64_t ns) noexcept {
  timespec ts{time_t(ns / 1'000'000'000), long(ns % 1'000'000'000)};
  while (nanosleep(&ts, &ts) != 0 && errno == EINTR) {}
}

std::string normalised_name(const char* name) { return name[0] == '/' ? std::string(name) : "/" + std::string(name); }

// One read-only mapping of a segment, validated, and the descriptor kept open to test the
// writer's lock.
struct Mapping {
  const unsigned char* base = nullptr;
  std::size_t size = 0;
  dev_t device = 0;
  ino_t inode = 0;
  int fd = -1;

  const Header& header() const noexcept { return *reinterpret_cast<const Header*>(base); }
  const SlotHeader& slot(uint64_t sequence) const noexcept {
    const Header& h = header();
    return *reinterpret_cast<const SlotHeader*>(base + h.slots_offset + ((sequence - 1) % h.slot_count) * h.slot_bytes);
  }
  void unmap() noexcept {
    if (base) munmap(const_cast<unsigned char*>(base), size);
    if (fd >= 0) close(fd);
    base = nullptr;
    fd = -1;
  }
};

int map_segment(const std::string& name, Mapping& out) {
  const int fd = shm_open(name.c_str(), O_RDONLY, 0);
  if (fd < 0) return errno == ENOENT ? FACECAP_ERR_NOT_FOUND : errno == EACCES ? FACECAP_ERR_ACCESS : FACECAP_ERR_SYSTEM;
  struct stat st {};
  if (fstat(fd, &st) != 0) {
    close(fd);
    return FACECAP_ERR_SYSTEM;
  }
  // A writer still sizing its segment, or something that is not ours.
  if (std::size_t(st.st_size) < sizeof(Header)) {
    close(fd);
    return FACECAP_ERR_LAYOUT;
  }
  void* p = mmap(nullptr, std::size_t(st.st_size), PROT_READ, MAP_SHARED, fd, 0);
  if (p == MAP_FAILED) {
    const int status = errno == EACCES ? FACECAP_ERR_ACCESS : FACECAP_ERR_SYSTEM;
    close(fd);
    return status;
  }
  Mapping m{static_cast<const unsigned char*>(p), std::size_t(st.st_size), st.st_dev, st.st_ino, fd};
  const Header& h = m.header();
  // The writer stores the magic last (release) once every other header field is set.
  if (__atomic_load_n(&h.magic, __ATOMIC_ACQUIRE) != kMagic) {
    m.unmap();
    return FACECAP_ERR_LAYOUT;
  }
  // Never trust sizes from a segment before checking them against what it can hold.
  const bool plausible = h.layout_version == kLayoutVersion && h.header_bytes == sizeof(Header) &&
                         h.shape_name_bytes == kShapeNameBytes && h.slot_count > 0 && h.slot_count <= kMaxSlots &&
                         h.shape_count <= kMaxShapes && h.vertex_count <= kMaxVertices;
  if (!plausible) {
    m.unmap();
    return FACECAP_ERR_LAYOUT;
  }
  const Geometry g = compute_geometry(h.shape_count, h.vertex_count, h.slot_count);
  if (g.total_bytes != h.total_bytes || h.total_bytes > m.size || g.slot_bytes != h.slot_bytes ||
      g.slots_offset != h.slots_offset || g.shape_names_offset != h.shape_names_offset ||
      g.slot_weights_offset != h.slot_weights_offset || g.slot_vertices_offset != h.slot_vertices_offset) {
    m.unmap();
    return FACECAP_ERR_LAYOUT;
  }
  out = m;
  return FACECAP_OK;
}

}  // namespace

struct facecap_client {
  std::string name;
  Mapping mapping;
  std::vector<float> weights;
  std::vector<float> vertices;
  std::vector<std::string> shape_names;
  std::string rig_name;
  uint64_t last_sequence = 0;  // of the frame last returned
  uint64_t generation = 0;
  int64_t last_writer_check_ns = 0;

  void adopt(const Mapping& m) {
    mapping = m;
    const Header& h = m.header();
    weights.assign(h.shape_count, 0.0f);
    vertices.assign(std::size_t(h.vertex_count) * 3, 0.0f);
    shape_names.clear();
    for (uint32_t i = 0; i < h.shape_count; ++i) {
      const char* text = reinterpret_cast<const char*>(m.base + h.shape_names_offset + uint64_t(i) * kShapeNameBytes);
      shape_names.emplace_back(text, strnlen(text, kShapeNameBytes));
    }
    rig_name.assign(h.rig_name, strnlen(h.rig_name, kRigNameBytes));
    generation = h.writer_generation;
    // A new subscriber (or one that followed a restart) starts with the next frame.
    last_sequence = h.last_published.load(std::memory_order_acquire);
  }

  // Copies the slot holding `sequence`. FACECAP_OK with *found set to the sequence the
  // slot really held (a newer one when the writer lapped us).
  int copy_slot(uint64_t sequence, facecap_frame& out, uint64_t& found) noexcept {
    const Header& h = mapping.header();
    const SlotHeader& slot = mapping.slot(sequence);
    const unsigned char* slot_base = reinterpret_cast<const unsigned char*>(&slot);
    for (int attempt = 0; attempt < kMaxReadAttempts; ++attempt) {
      const uint64_t before = slot.seqlock.load(std::memory_order_acquire);
      if (before & 1u) {
        sched_yield_hint(attempt);
        continue;
      }
      SlotHeader copy_of_header;
      // Plain copies of memory the writer may be changing: only kept when the seqlock
      // shows it did not (the fence orders these loads before the second seqlock load).
      std::memcpy(static_cast<void*>(&copy_of_header), &slot, sizeof(SlotHeader));
      std::memcpy(weights.data(), slot_base + h.slot_weights_offset, weights.size() * sizeof(float));
      if (!vertices.empty())
        std::memcpy(vertices.data(), slot_base + h.slot_vertices_offset, vertices.size() * sizeof(float));
      std::atomic_thread_fence(std::memory_order_acquire);
      const uint64_t after = slot.seqlock.load(std::memory_order_relaxed);
      if (before != after) continue;
      found = copy_of_header.sequence;
      out.sequence = copy_of_header.sequence;
      out.frame_no = copy_of_header.frame_no;
      out.source_time_ns = copy_of_header.source_time_ns;
      out.receive_time_ns = copy_of_header.receive_time_ns;
      out.solve_start_ns = copy_of_header.solve_start_ns;
      out.solve_end_ns = copy_of_header.solve_end_ns;
      out.publish_time_ns = copy_of_header.publish_time_ns;
      std::memcpy(out.head_rotation_wxyz, copy_of_header.head_rotation_wxyz, sizeof out.head_rotation_wxyz);
      std::memcpy(out.head_translation, copy_of_header.head_translation, sizeof out.head_translation);
      out.flags = copy_of_header.flags;
      out.markers_used = copy_of_header.markers_used;
      out.shape_count = uint32_t(weights.size());
      out.vertex_count = uint32_t(vertices.size() / 3);
      out.weights = weights.data();
      out.vertices = vertices.empty() ? nullptr : vertices.data();
      return FACECAP_OK;
    }
    return FACECAP_ERR_CONTENDED;
  }

  static void sched_yield_hint(int attempt) noexcept {
    if (attempt > 8) sleep_ns(1'000);
  }

  // Reads `wanted`, or the oldest frame still in the ring when it was overwritten.
  int read_from(uint64_t wanted, facecap_frame& out) noexcept {
    const Header& h = mapping.header();
    for (int attempt = 0; attempt < kMaxReadAttempts; ++attempt) {
      uint64_t found = 0;
      const int status = copy_slot(wanted, out, found);
      if (status != FACECAP_OK) return status;
      if (found == wanted) {
        out.dropped = wanted - last_sequence - 1;
        last_sequence = wanted;
        return FACECAP_OK;
      }
      // Lapped: jump to the oldest slot the writer is not about to reuse.
      const uint64_t newest = h.last_published.load(std::memory_order_acquire);
      const uint64_t keep = h.slot_count > 1 ? h.slot_count - 1 : 1;
      wanted = newest > keep ? newest - keep + 1 : 1;
      if (wanted <= last_sequence) wanted = last_sequence + 1;
    }
    return FACECAP_ERR_CONTENDED;
  }
};

extern "C" {

int facecap_client_open(const char* name, facecap_client** out_client) {
  if (!name || !*name || !out_client) return FACECAP_ERR_ARGUMENT;
  *out_client = nullptr;
  try {
    auto client = std::make_unique<facecap_client>();
    client->name = normalised_name(name);
    Mapping m;
    if (const int status = map_segment(client->name, m); status != FACECAP_OK) return status;
    client->adopt(m);
    *out_client = client.release();
    return FACECAP_OK;
  } catch (...) {
    return FACECAP_ERR_SYSTEM;  // out of memory: C callers get a status, never an exception
  }
}

void facecap_client_close(facecap_client* client) {
  if (!client) return;
  client->mapping.unmap();
  delete client;
}

uint32_t facecap_client_shape_count(const facecap_client* client) { return client ? uint32_t(client->shape_names.size()) : 0; }

const char* facecap_client_shape_name(const facecap_client* client, uint32_t index) {
  if (!client || index >= client->shape_names.size()) return nullptr;
  return client->shape_names[index].c_str();
}

uint32_t facecap_client_vertex_count(const facecap_client* client) { return client ? uint32_t(client->vertices.size() / 3) : 0; }
double facecap_client_nominal_rate_hz(const facecap_client* client) {
  return client ? client->mapping.header().nominal_rate_hz : 0.0;
}
const char* facecap_client_rig_name(const facecap_client* client) { return client ? client->rig_name.c_str() : nullptr; }
int32_t facecap_client_writer_pid(const facecap_client* client) { return client ? client->mapping.header().writer_pid : 0; }

int facecap_client_read_latest(facecap_client* client, facecap_frame* out_frame) {
  if (!client || !out_frame) return FACECAP_ERR_ARGUMENT;
  const uint64_t newest = client->mapping.header().last_published.load(std::memory_order_acquire);
  if (newest == 0) return FACECAP_NO_FRAME;
  const uint64_t previous = client->last_sequence;
  uint64_t found = 0;
  const int status = client->copy_slot(newest, *out_frame, found);
  if (status != FACECAP_OK) return status;
  // The writer may have moved on while we copied; what we hold is still one whole frame.
  out_frame->dropped = found > previous + 1 ? found - previous - 1 : 0;
  if (found > client->last_sequence) client->last_sequence = found;
  return FACECAP_OK;
}

int facecap_client_read_next(facecap_client* client, facecap_frame* out_frame) {
  if (!client || !out_frame) return FACECAP_ERR_ARGUMENT;
  const uint64_t newest = client->mapping.header().last_published.load(std::memory_order_acquire);
  if (newest <= client->last_sequence) return FACECAP_NO_FRAME;
  return client->read_from(client->last_sequence + 1, *out_frame);
}

int facecap_client_check_writer(facecap_client* client, int64_t stale_after_ns) {
  if (!client) return FACECAP_ERR_ARGUMENT;
  const Header& h = client->mapping.header();
  const uint32_t state = h.writer_state.load(std::memory_order_acquire);
  const int64_t heartbeat = h.heartbeat_ns.load(std::memory_order_acquire);
  const bool beating = now_ns() - heartbeat < stale_after_ns;
  if (state != kWriterStopped && beating) return FACECAP_OK;
  // Not beating, yet its process still holds the writer lock: stopped or hung, not gone.
  if (state != kWriterStopped && writer_lock_held(client->mapping.fd)) return FACECAP_WRITER_STALLED;
  // The writer is gone; has a new one created a segment under the same name?
  Mapping fresh;
  if (map_segment(client->name, fresh) != FACECAP_OK) return FACECAP_ERR_WRITER_GONE;
  const bool same = fresh.inode == client->mapping.inode && fresh.device == client->mapping.device &&
                    fresh.header().writer_generation == client->generation;
  if (same) {
    fresh.unmap();
    return FACECAP_ERR_WRITER_GONE;
  }
  try {
    Mapping old = client->mapping;
    client->adopt(fresh);
    old.unmap();
  } catch (...) {
    fresh.unmap();
    return FACECAP_ERR_SYSTEM;
  }
  return FACECAP_RESTARTED;
}

int facecap_client_wait_next(facecap_client* client, facecap_frame* out_frame, int64_t timeout_ns) {
  if (!client || !out_frame) return FACECAP_ERR_ARGUMENT;
  const int64_t start = now_ns();
  for (;;) {
    const int status = facecap_client_read_next(client, out_frame);
    if (status != FACECAP_NO_FRAME) return status;
    const int64_t now = now_ns();
    if (now - client->last_writer_check_ns >= kWriterCheckIntervalNs) {
      client->last_writer_check_ns = now;
      const int writer = facecap_client_check_writer(client, kDefaultStaleNs);
      if (writer != FACECAP_OK) return writer;
    }
    if (now - start >= timeout_ns) return FACECAP_NO_FRAME;
    sleep_ns(kPollIntervalNs);
  }
}

const char* facecap_status_string(int status) {
  switch (status) {
    case FACECAP_OK: return "ok";
    case FACECAP_NO_FRAME: return "no new frame";
    case FACECAP_RESTARTED: return "the writer restarted (shapes may have changed)";
    case FACECAP_WRITER_STALLED: return "the writer is alive but has stopped beating (stopped or hung)";
    case FACECAP_ERR_ARGUMENT: return "invalid argument";
    case FACECAP_ERR_NOT_FOUND: return "no such shared-memory segment (is facecapd running?)";
    case FACECAP_ERR_ACCESS: return "permission denied (is this user in the facecap group?)";
    case FACECAP_ERR_LAYOUT: return "not a facecap segment, or an unsupported layout version";
    case FACECAP_ERR_WRITER_GONE: return "the writer stopped";
    case FACECAP_ERR_CONTENDED: return "the frame kept changing while being read";
    case FACECAP_ERR_SYSTEM: return "system error";
    default: return "unknown status";
  }
}

}  // extern "C"
