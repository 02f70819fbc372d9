// The subscriber side of facecapd's outputs: the shared-memory ring and the UDP stream.
// Shared memory: everything is allocation-free after facecap_client_open(); reads copy one
// slot under its seqlock and never write to the segment (it is mapped PROT_READ). UDP:
// datagrams are reassembled (udp_stream_reader.hpp) into frames of the same type.
#include "facecap_client.h"

#include <cerrno>
#include <cstddef>
#include <cstring>
#include <ctime>
#include <memory>
#include <string>
#include <vector>

#include <arpa/inet.h>
#include <fcntl.h>
#include <net/if.h>
#include <netdb.h>
#include <netinet/in.h>
#include <poll.h>
#include <sys/mman.h>
#include <sys/socket.h>
#include <sys/stat.h>
#include <unistd.h>

#include "facecap_shm_layout.hpp"
#include "udp_stream_reader.hpp"

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

std::string normalised_name(const char* name) {
  std::string out = name[0] == '/' ? "" : "/";
  return out.append(name);
}

std::string fixed_text(const char* text, std::size_t capacity) { return std::string(text, strnlen(text, capacity)); }

// The frame fields both transports fill alike, from a layout's header (SlotHeader or
// udp::FrameHeader: the same names).
template <typename LayoutHeader>
void copy_frame_fields(const LayoutHeader& h, facecap_frame& out) noexcept {
  out.frame_no = h.frame_no;
  out.source_time_ns = h.source_time_ns;
  out.receive_time_ns = h.receive_time_ns;
  out.solve_start_ns = h.solve_start_ns;
  out.solve_end_ns = h.solve_end_ns;
  out.publish_time_ns = h.publish_time_ns;
  std::memcpy(out.head_rotation_wxyz, h.head_rotation_wxyz, sizeof out.head_rotation_wxyz);
  std::memcpy(out.head_translation, h.head_translation, sizeof out.head_translation);
  out.flags = h.flags;
  out.markers_used = h.markers_used;
  out.timecode_hours = h.timecode_hours;
  out.timecode_minutes = h.timecode_minutes;
  out.timecode_seconds = h.timecode_seconds;
  out.timecode_frames = h.timecode_frames;
  out.timecode_rate_hz = h.timecode_rate_hz;
  out.timecode_subframe = h.timecode_subframe;
}

// One read-only mapping of a segment, validated.
struct Mapping {
  const unsigned char* base = nullptr;
  std::size_t size = 0;
  dev_t device = 0;
  ino_t inode = 0;

  const Header& header() const noexcept { return *reinterpret_cast<const Header*>(base); }
  const SlotHeader& slot(uint64_t sequence) const noexcept {
    const Header& h = header();
    return *reinterpret_cast<const SlotHeader*>(base + h.slots_offset + ((sequence - 1) % h.slot_count) * h.slot_bytes);
  }
  void unmap() noexcept {
    if (base) munmap(const_cast<unsigned char*>(base), size);
    base = nullptr;
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
  close(fd);
  if (p == MAP_FAILED) return errno == EACCES ? FACECAP_ERR_ACCESS : FACECAP_ERR_SYSTEM;
  Mapping m{static_cast<const unsigned char*>(p), std::size_t(st.st_size), st.st_dev, st.st_ino};
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
      g.arkit_names_offset != h.arkit_names_offset ||
      g.slot_weights_offset != h.slot_weights_offset || g.slot_vertices_offset != h.slot_vertices_offset) {
    m.unmap();
    return FACECAP_ERR_LAYOUT;
  }
  out = m;
  return FACECAP_OK;
}

using facecap::udp::Message;

// The frame's layout as bindings in other languages mirror it (docs/subscribers.md).
static_assert(offsetof(facecap_frame, frame_no) == 16 && offsetof(facecap_frame, head_rotation_wxyz) == 64 &&
              offsetof(facecap_frame, flags) == 92 && offsetof(facecap_frame, timecode_hours) == 108 &&
              offsetof(facecap_frame, timecode_rate_hz) == 112 && offsetof(facecap_frame, rig_hash) == 120 &&
              offsetof(facecap_frame, weights) == 128 && sizeof(facecap_frame) == 144);

// What a client shows of its writer, whichever the transport.
struct Schema {
  std::vector<std::string> shape_names;
  std::vector<std::string> arkit_names;
  std::string rig_name;
  uint64_t rig_hash = 0;
  uint32_t vertex_count = 0;
  double nominal_rate_hz = 0.0;
};

// The shared-memory side: one mapped segment, followed to a new one when its writer restarts.
struct ShmReader {
  std::string name;
  Mapping mapping;
  uint64_t generation = 0;

  ~ShmReader() { mapping.unmap(); }
};

// The UDP side: one socket, reassembly, and the schema the frames follow.
struct UdpReader {
  int fd = -1;
  facecap::udp::Reassembler reassembler;
  std::vector<unsigned char> datagram = std::vector<unsigned char>(facecap::udp::kMaxDatagramBytes + 1);
  bool have_schema = false;
  bool stopped = false;   // the sender said it stops
  uint32_t stream_id = 0;
  uint32_t schema_id = 0;
  uint32_t interval_ms = 1000;
  int64_t last_heard_ns = 0;

  ~UdpReader() {
    if (fd >= 0) close(fd);
  }
};

}  // namespace

struct facecap_client {
  std::unique_ptr<ShmReader> shm;
  std::unique_ptr<UdpReader> udp;
  Schema schema;
  std::vector<float> weights;
  std::vector<float> vertices;
  uint64_t last_sequence = 0;  // of the frame last returned
  int64_t last_writer_check_ns = 0;

  void size_frames() {
    weights.assign(schema.shape_names.size(), 0.0f);
    vertices.assign(std::size_t(schema.vertex_count) * 3, 0.0f);
  }

  // ---- shared memory ----

  void adopt(const Mapping& m) {
    shm->mapping = m;
    const Header& h = m.header();
    schema.shape_names.clear();
    schema.arkit_names.clear();
    for (uint32_t i = 0; i < h.shape_count; ++i) {
      const auto* names = reinterpret_cast<const char*>(m.base);
      schema.shape_names.push_back(fixed_text(names + h.shape_names_offset + uint64_t(i) * kShapeNameBytes, kShapeNameBytes));
      schema.arkit_names.push_back(fixed_text(names + h.arkit_names_offset + uint64_t(i) * kShapeNameBytes, kShapeNameBytes));
    }
    schema.rig_name = fixed_text(h.rig_name, kRigNameBytes);
    schema.rig_hash = h.rig_hash;
    schema.vertex_count = h.vertex_count;
    schema.nominal_rate_hz = h.nominal_rate_hz;
    size_frames();
    shm->generation = h.writer_generation;
    // A new subscriber (or one that followed a restart) starts with the next frame.
    last_sequence = h.last_published.load(std::memory_order_acquire);
  }

  // Copies the slot holding `sequence`. FACECAP_OK with *found set to the sequence the
  // slot really held (a newer one when the writer lapped us).
  int copy_slot(uint64_t sequence, facecap_frame& out, uint64_t& found) noexcept {
    const Header& h = shm->mapping.header();
    const SlotHeader& slot = shm->mapping.slot(sequence);
    const unsigned char* slot_base = reinterpret_cast<const unsigned char*>(&slot);
    for (int attempt = 0; attempt < kMaxReadAttempts; ++attempt) {
      const uint64_t before = slot.seqlock.load(std::memory_order_acquire);
      if (before & 1u) {
        if (attempt > 8) sleep_ns(1'000);
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
      copy_frame_fields(copy_of_header, out);
      fill_views(out);
      return FACECAP_OK;
    }
    return FACECAP_ERR_CONTENDED;
  }

  void fill_views(facecap_frame& out) const noexcept {
    out.rig_hash = schema.rig_hash;
    out.shape_count = uint32_t(weights.size());
    out.vertex_count = uint32_t(vertices.size() / 3);
    out.weights = weights.data();
    out.vertices = vertices.empty() ? nullptr : vertices.data();
  }

  // Reads `wanted`, or the oldest frame still in the ring when it was overwritten.
  int read_from(uint64_t wanted, facecap_frame& out) noexcept {
    const Header& h = shm->mapping.header();
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

  int shm_read_latest(facecap_frame& out) noexcept {
    const uint64_t newest = shm->mapping.header().last_published.load(std::memory_order_acquire);
    if (newest == 0) return FACECAP_NO_FRAME;
    const uint64_t previous = last_sequence;
    uint64_t found = 0;
    const int status = copy_slot(newest, out, found);
    if (status != FACECAP_OK) return status;
    // The writer may have moved on while we copied; what we hold is still one whole frame.
    out.dropped = found > previous + 1 ? found - previous - 1 : 0;
    if (found > last_sequence) last_sequence = found;
    return FACECAP_OK;
  }

  int shm_read_next(facecap_frame& out) noexcept {
    const uint64_t newest = shm->mapping.header().last_published.load(std::memory_order_acquire);
    if (newest <= last_sequence) return FACECAP_NO_FRAME;
    return read_from(last_sequence + 1, out);
  }

  int shm_check_writer(int64_t stale_after_ns) noexcept {
    const Header& h = shm->mapping.header();
    const uint32_t state = h.writer_state.load(std::memory_order_acquire);
    const int64_t heartbeat = h.heartbeat_ns.load(std::memory_order_acquire);
    const bool beating = now_ns() - heartbeat < stale_after_ns;
    if (state != kWriterStopped && beating) return FACECAP_OK;
    // The writer is gone; has a new one created a segment under the same name?
    Mapping fresh;
    if (map_segment(shm->name, fresh) != FACECAP_OK) return FACECAP_ERR_WRITER_GONE;
    const bool same = fresh.inode == shm->mapping.inode && fresh.device == shm->mapping.device &&
                      fresh.header().writer_generation == shm->generation;
    if (same) {
      fresh.unmap();
      return FACECAP_ERR_WRITER_GONE;
    }
    try {
      Mapping old = shm->mapping;
      adopt(fresh);
      old.unmap();
    } catch (...) {
      fresh.unmap();
      return FACECAP_ERR_SYSTEM;
    }
    return FACECAP_RESTARTED;
  }

  // ---- UDP ----

  // Takes a schema; FACECAP_RESTARTED when it is a new one (first, new sender, changed).
  int udp_adopt_schema(const Message& message) {
    facecap::udp::SchemaView view;
    if (!facecap::udp::read_schema(message.bytes, view)) return FACECAP_NO_FRAME;
    const facecap::udp::SchemaHeader& h = view.header;
    UdpReader& u = *udp;
    const bool same = u.have_schema && message.stream_id == u.stream_id && h.schema_id == u.schema_id;
    if (h.flags & facecap::udp::kSchemaStopping) {
      if (!same) return FACECAP_NO_FRAME;  // another sender's goodbye
      u.stopped = true;
      return FACECAP_ERR_WRITER_GONE;
    }
    u.interval_ms = h.interval_ms > 0 ? h.interval_ms : 1000;
    if (same) return FACECAP_NO_FRAME;
    schema = Schema{};
    for (uint32_t i = 0; i < h.shape_count; ++i) {
      facecap::udp::ShapeName names;
      std::memcpy(&names, view.names + std::size_t(i) * sizeof names, sizeof names);
      schema.shape_names.push_back(fixed_text(names.rig, facecap::udp::kNameBytes));
      schema.arkit_names.push_back(fixed_text(names.arkit, facecap::udp::kNameBytes));
    }
    schema.rig_name = fixed_text(h.rig_name, facecap::udp::kNameBytes);
    schema.rig_hash = h.rig_hash;
    schema.vertex_count = h.vertex_count;
    schema.nominal_rate_hz = h.frame_rate_hz;
    size_frames();
    u.have_schema = true;
    u.stopped = false;
    u.stream_id = message.stream_id;
    u.schema_id = h.schema_id;
    last_sequence = 0;
    return FACECAP_RESTARTED;
  }

  // A frame of the current schema into the client's storage; false for any other.
  bool udp_take_frame(const Message& message, facecap_frame& out) noexcept {
    facecap::udp::FrameView view;
    const UdpReader& u = *udp;
    if (!u.have_schema || message.stream_id != u.stream_id || !facecap::udp::read_frame(message.bytes, view)) return false;
    const facecap::udp::FrameHeader& h = view.header;
    if (h.schema_id != u.schema_id || h.shape_count != weights.size() || uint64_t(h.vertex_count) * 3 != vertices.size())
      return false;
    std::memcpy(weights.data(), view.weights, weights.size() * sizeof(float));
    if (view.vertices) std::memcpy(vertices.data(), view.vertices, vertices.size() * sizeof(float));
    out.sequence = message.sequence;
    out.dropped = last_sequence > 0 && message.sequence > last_sequence ? message.sequence - last_sequence - 1 : 0;
    last_sequence = message.sequence;
    copy_frame_fields(h, out);
    fill_views(out);
    out.rig_hash = h.rig_hash;
    return true;
  }

  // Takes datagrams until a frame is whole (FACECAP_OK), the schema changes
  // (FACECAP_RESTARTED), the sender says it stops (FACECAP_ERR_WRITER_GONE), or none is
  // waiting (FACECAP_NO_FRAME).
  int udp_read_next(facecap_frame& out) noexcept {
    UdpReader& u = *udp;
    for (;;) {
      const ssize_t n = recv(u.fd, u.datagram.data(), u.datagram.size(), MSG_DONTWAIT);
      if (n < 0) {
        if (errno == EINTR) continue;
        return errno == EAGAIN || errno == EWOULDBLOCK ? FACECAP_NO_FRAME : FACECAP_ERR_SYSTEM;
      }
      u.last_heard_ns = now_ns();
      try {
        const std::optional<Message> message = u.reassembler.add({u.datagram.data(), std::size_t(n)});
        if (!message) continue;
        if (message->kind == facecap::udp::kSchemaMessage) {
          if (const int status = udp_adopt_schema(*message); status != FACECAP_NO_FRAME) return status;
        } else if (udp_take_frame(*message, out)) {
          return FACECAP_OK;
        }
      } catch (...) {
        return FACECAP_ERR_SYSTEM;  // out of memory for a message: C callers get a status
      }
    }
  }

  int udp_read_latest(facecap_frame& out) noexcept {
    uint64_t dropped = 0;
    bool any = false;
    for (;;) {
      const int status = udp_read_next(out);
      if (status == FACECAP_OK) {
        dropped += out.dropped + (any ? 1 : 0);  // frames passed over on the way to the newest
        any = true;
        continue;
      }
      if (status != FACECAP_NO_FRAME) return status;
      if (any) out.dropped = dropped;
      return any ? FACECAP_OK : FACECAP_NO_FRAME;
    }
  }

  int udp_check_writer() const noexcept {
    const UdpReader& u = *udp;
    if (u.stopped) return FACECAP_ERR_WRITER_GONE;
    if (u.have_schema && now_ns() - u.last_heard_ns > 3 * int64_t(u.interval_ms) * 1'000'000) return FACECAP_ERR_WRITER_GONE;
    return FACECAP_OK;
  }

  // Sleeps until a datagram arrives or timeout_ns passes.
  void wait_readable(int64_t timeout_ns) const noexcept {
    if (!udp) {
      sleep_ns(std::min(timeout_ns, kPollIntervalNs));
      return;
    }
    pollfd p{udp->fd, POLLIN, 0};
    poll(&p, 1, int((timeout_ns + 999'999) / 1'000'000));
  }
};

namespace {

// "host:port" or "[v6 host]:port" as a numeric address.
bool parse_address(const char* text, sockaddr_storage& out, socklen_t& length) {
  std::string s(text);
  const auto colon = s.rfind(':');
  if (colon == std::string::npos || colon + 1 >= s.size()) return false;
  std::string host = s.substr(0, colon);
  const std::string port = s.substr(colon + 1);
  if (host.size() >= 2 && host.front() == '[' && host.back() == ']') host = host.substr(1, host.size() - 2);
  addrinfo hints{};
  hints.ai_family = AF_UNSPEC;
  hints.ai_socktype = SOCK_DGRAM;
  hints.ai_flags = AI_NUMERICHOST | AI_NUMERICSERV | AI_PASSIVE;
  addrinfo* found = nullptr;
  if (getaddrinfo(host.c_str(), port.c_str(), &hints, &found) != 0 || !found) return false;
  std::memcpy(&out, found->ai_addr, found->ai_addrlen);
  length = found->ai_addrlen;
  freeaddrinfo(found);
  return true;
}

bool is_multicast(const sockaddr_storage& address) {
  if (address.ss_family == AF_INET)
    return IN_MULTICAST(ntohl(reinterpret_cast<const sockaddr_in&>(address).sin_addr.s_addr));
  return IN6_IS_ADDR_MULTICAST(&reinterpret_cast<const sockaddr_in6&>(address).sin6_addr);
}

// Opens, binds and (for a group) joins. FACECAP_OK with the socket in *fd.
int open_udp_socket(const char* address, const char* interface_name, int& fd) {
  sockaddr_storage where{};
  socklen_t length = 0;
  if (!parse_address(address, where, length)) return FACECAP_ERR_ARGUMENT;
  unsigned interface_index = 0;
  if (interface_name && *interface_name && (interface_index = if_nametoindex(interface_name)) == 0) return FACECAP_ERR_ADDRESS;
  fd = socket(where.ss_family, SOCK_DGRAM | SOCK_CLOEXEC, 0);
  if (fd < 0) return FACECAP_ERR_SYSTEM;
  // A frame with vertices is dozens of datagrams: room for several frames while the
  // reader is not looking (the kernel caps this at net.core.rmem_max).
  const int buffer_bytes = 8 << 20;
  setsockopt(fd, SOL_SOCKET, SO_RCVBUF, &buffer_bytes, sizeof buffer_bytes);
  const bool group = is_multicast(where);
  if (group) {
    const int yes = 1;  // several receivers of one group on this machine
    setsockopt(fd, SOL_SOCKET, SO_REUSEADDR, &yes, sizeof yes);
  }
  if (bind(fd, reinterpret_cast<const sockaddr*>(&where), length) != 0) return FACECAP_ERR_ADDRESS;
  if (!group) return FACECAP_OK;
  int joined = -1;
  if (where.ss_family == AF_INET) {
    ip_mreqn request{};
    request.imr_multiaddr = reinterpret_cast<const sockaddr_in&>(where).sin_addr;
    request.imr_ifindex = int(interface_index);
    joined = setsockopt(fd, IPPROTO_IP, IP_ADD_MEMBERSHIP, &request, sizeof request);
  } else {
    ipv6_mreq request{};
    request.ipv6mr_multiaddr = reinterpret_cast<const sockaddr_in6&>(where).sin6_addr;
    request.ipv6mr_interface = interface_index;
    joined = setsockopt(fd, IPPROTO_IPV6, IPV6_JOIN_GROUP, &request, sizeof request);
  }
  return joined == 0 ? FACECAP_OK : FACECAP_ERR_ADDRESS;
}

}  // namespace

extern "C" {

int facecap_client_open(const char* name, facecap_client** out_client) {
  if (!name || !*name || !out_client) return FACECAP_ERR_ARGUMENT;
  *out_client = nullptr;
  try {
    auto client = std::make_unique<facecap_client>();
    client->shm = std::make_unique<ShmReader>();
    client->shm->name = normalised_name(name);
    Mapping m;
    if (const int status = map_segment(client->shm->name, m); status != FACECAP_OK) return status;
    client->adopt(m);
    *out_client = client.release();
    return FACECAP_OK;
  } catch (...) {
    return FACECAP_ERR_SYSTEM;  // out of memory: C callers get a status, never an exception
  }
}

int facecap_client_open_udp(const char* address, const char* interface_name, facecap_client** out_client) {
  if (!address || !*address || !out_client) return FACECAP_ERR_ARGUMENT;
  *out_client = nullptr;
  try {
    auto client = std::make_unique<facecap_client>();
    client->udp = std::make_unique<UdpReader>();
    if (const int status = open_udp_socket(address, interface_name, client->udp->fd); status != FACECAP_OK) return status;
    *out_client = client.release();
    return FACECAP_OK;
  } catch (...) {
    return FACECAP_ERR_SYSTEM;
  }
}

void facecap_client_close(facecap_client* client) { delete client; }

uint32_t facecap_client_shape_count(const facecap_client* client) {
  return client ? uint32_t(client->schema.shape_names.size()) : 0;
}

const char* facecap_client_shape_name(const facecap_client* client, uint32_t index) {
  if (!client || index >= client->schema.shape_names.size()) return nullptr;
  return client->schema.shape_names[index].c_str();
}

const char* facecap_client_arkit_name(const facecap_client* client, uint32_t index) {
  if (!client || index >= client->schema.arkit_names.size()) return nullptr;
  return client->schema.arkit_names[index].c_str();
}

uint32_t facecap_client_vertex_count(const facecap_client* client) { return client ? client->schema.vertex_count : 0; }
double facecap_client_nominal_rate_hz(const facecap_client* client) { return client ? client->schema.nominal_rate_hz : 0.0; }
const char* facecap_client_rig_name(const facecap_client* client) { return client ? client->schema.rig_name.c_str() : nullptr; }
uint64_t facecap_client_rig_hash(const facecap_client* client) { return client ? client->schema.rig_hash : 0; }
int32_t facecap_client_writer_pid(const facecap_client* client) {
  return client && client->shm ? client->shm->mapping.header().writer_pid : 0;
}
uint64_t facecap_client_incomplete_frames(const facecap_client* client) {
  // Schemas are a datagram or a few and repeat: what is given up is, in practice, frames.
  return client && client->udp ? client->udp->reassembler.counters().incomplete : 0;
}

int facecap_client_read_latest(facecap_client* client, facecap_frame* out_frame) {
  if (!client || !out_frame) return FACECAP_ERR_ARGUMENT;
  return client->udp ? client->udp_read_latest(*out_frame) : client->shm_read_latest(*out_frame);
}

int facecap_client_read_next(facecap_client* client, facecap_frame* out_frame) {
  if (!client || !out_frame) return FACECAP_ERR_ARGUMENT;
  return client->udp ? client->udp_read_next(*out_frame) : client->shm_read_next(*out_frame);
}

int facecap_client_check_writer(facecap_client* client, int64_t stale_after_ns) {
  if (!client) return FACECAP_ERR_ARGUMENT;
  return client->udp ? client->udp_check_writer() : client->shm_check_writer(stale_after_ns);
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
    client->wait_readable(std::min(start + timeout_ns - now, kWriterCheckIntervalNs));
  }
}

const char* facecap_status_string(int status) {
  switch (status) {
    case FACECAP_OK: return "ok";
    case FACECAP_NO_FRAME: return "no new frame";
    case FACECAP_RESTARTED: return "the writer restarted or its schema arrived (shapes may have changed)";
    case FACECAP_ERR_ARGUMENT: return "invalid argument";
    case FACECAP_ERR_NOT_FOUND: return "no such shared-memory segment (is facecapd running?)";
    case FACECAP_ERR_ACCESS: return "permission denied (is this user in the facecap group?)";
    case FACECAP_ERR_LAYOUT: return "not a facecap segment, or an unsupported layout version";
    case FACECAP_ERR_WRITER_GONE: return "the writer stopped";
    case FACECAP_ERR_CONTENDED: return "the frame kept changing while being read";
    case FACECAP_ERR_SYSTEM: return "system error";
    case FACECAP_ERR_ADDRESS: return "cannot receive on that address (in use, not of this machine, or no such interface)";
    default: return "unknown status";
  }
}

}  // extern "C"
