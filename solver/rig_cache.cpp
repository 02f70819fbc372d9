#include "solver/rig_cache.hpp"

#include <cstring>
#include <set>

#include <fmt/format.h>
#include <spdlog/spdlog.h>

#include "core/error.hpp"
#include "core/io.hpp"

namespace facecap {
namespace fs = std::filesystem;
namespace {

constexpr char kMagic[8] = {'F', 'C', 'R', 'I', 'G', '\0', '\r', '\n'};

// Header, little-endian as written by this machine (the cache is per machine).
struct CacheHeader {
  char magic[8];
  uint32_t version;
  uint32_t header_size;
  uint64_t key;
  uint64_t payload_size;
  uint64_t payload_checksum;
};
static_assert(sizeof(CacheHeader) == 40);

class Writer {
 public:
  template <typename T>
  void value(const T& v) { raw(&v, sizeof(T)); }
  void raw(const void* p, std::size_t n) {
    const auto* c = static_cast<const char*>(p);
    bytes_.insert(bytes_.end(), c, c + n);
  }
  void string(const std::string& s) { value<uint64_t>(s.size()); raw(s.data(), s.size()); }
  std::vector<char>& bytes() { return bytes_; }

 private:
  std::vector<char> bytes_;
};

class Reader {
 public:
  Reader(const char* data, std::size_t size, const std::string& name) : data_(data), size_(size), name_(name) {}
  template <typename T>
  T value() { T v; raw(&v, sizeof(T)); return v; }
  void raw(void* p, std::size_t n) {
    if (n > size_ - pos_) throw offset_error(name_, int64_t(pos_), fmt::format("truncated: needs {} more bytes", n));
    if (n == 0) return;  // p may be an empty matrix's null data(), which memcpy must not get
    std::memcpy(p, data_ + pos_, n);
    pos_ += n;
  }
  std::string string() {
    const auto n = value<uint64_t>();
    if (n > size_ - pos_) throw offset_error(name_, int64_t(pos_), "string length past the end");
    std::string s(data_ + pos_, n);
    pos_ += n;
    return s;
  }
  // Count of items of item_size bytes that must still fit in the buffer.
  uint64_t count(std::size_t item_size) {
    const auto n = value<uint64_t>();
    if (item_size && n > (size_ - pos_) / item_size) throw offset_error(name_, int64_t(pos_), "count past the end");
    return n;
  }
  bool at_end() const { return pos_ == size_; }
  std::size_t remaining() const { return size_ - pos_; }

 private:
  const char* data_;
  std::size_t size_;
  std::size_t pos_ = 0;
  const std::string& name_;
};

fs::path cache_path(RigCacheKey key, const std::optional<fs::path>& cache_dir) {
  const fs::path dir = cache_dir ? *cache_dir : user_cache_dir() / "rigs";
  return dir / fmt::format("{:016x}.fcrig", key.value);
}

}  // namespace

RigCacheKey make_rig_cache_key(const char* loader, const std::vector<fs::path>& inputs) {
  Fnv1a64 h;
  h.add_value(kRigCacheVersion);
  h.add_string(loader);
  for (const auto& p : inputs) {
    std::error_code ec;
    h.add_string(fs::absolute(p, ec).lexically_normal().string());
    h.add_value(uint64_t(fs::file_size(p, ec)));
    h.add_value(int64_t(fs::last_write_time(p, ec).time_since_epoch().count()));
  }
  return {h.digest()};
}

std::vector<char> serialize_rig(const Rig& rig, RigCacheKey key) {
  Writer w;
  w.string(rig.name);
  w.string(rig.source);
  w.value<uint8_t>(rig.hinged ? 1 : 0);
  w.value<uint64_t>(uint64_t(rig.neutral.cols()));
  w.raw(rig.neutral.data(), sizeof(double) * std::size_t(rig.neutral.size()));
  w.value<uint64_t>(uint64_t(rig.triangles.cols()));
  w.raw(rig.triangles.data(), sizeof(int) * std::size_t(rig.triangles.size()));
  w.value<uint64_t>(rig.shape_names.size());
  for (const auto& n : rig.shape_names) w.string(n);
  w.raw(rig.deltas.data(), sizeof(double) * std::size_t(rig.deltas.size()));
  w.value<uint64_t>(rig.file_vertex_of.size());
  w.raw(rig.file_vertex_of.data(), sizeof(int) * rig.file_vertex_of.size());

  Fnv1a64 checksum;
  checksum.add(w.bytes().data(), w.bytes().size());
  CacheHeader header{};
  std::memcpy(header.magic, kMagic, sizeof kMagic);
  header.version = kRigCacheVersion;
  header.header_size = sizeof(CacheHeader);
  header.key = key.value;
  header.payload_size = w.bytes().size();
  header.payload_checksum = checksum.digest();
  std::vector<char> out(sizeof header);
  std::memcpy(out.data(), &header, sizeof header);
  out.insert(out.end(), w.bytes().begin(), w.bytes().end());
  return out;
}

Rig deserialize_rig(const std::vector<char>& bytes, RigCacheKey expected_key, const std::string& name) {
  CacheHeader header{};
  if (bytes.size() < sizeof header) throw offset_error(name, 0, "shorter than the cache header");
  std::memcpy(&header, bytes.data(), sizeof header);
  if (std::memcmp(header.magic, kMagic, sizeof kMagic) != 0) throw offset_error(name, 0, "not a facecap rig cache (bad magic)");
  if (header.version != kRigCacheVersion)
    throw offset_error(name, 8, fmt::format("cache version {}, this build reads {}", header.version, kRigCacheVersion));
  if (header.key != expected_key.value) throw offset_error(name, 16, "cache key does not match the rig's files");
  if (header.payload_size != bytes.size() - sizeof header)
    throw offset_error(name, 24, fmt::format("payload is {} bytes, header says {}", bytes.size() - sizeof header,
                                             header.payload_size));
  Fnv1a64 checksum;
  checksum.add(bytes.data() + sizeof header, bytes.size() - sizeof header);
#ifndef FUZZING_BUILD_MODE_UNSAFE_FOR_PRODUCTION  // fuzzers reach the payload checks past the checksum
  if (checksum.digest() != header.payload_checksum) throw offset_error(name, 32, "checksum mismatch (damaged file)");
#endif

  Reader r(bytes.data() + sizeof header, bytes.size() - sizeof header, name);
  Rig rig;
  rig.name = r.string();
  rig.source = r.string();
  const auto hinged = r.value<uint8_t>();
  if (hinged > 1) throw Error(fmt::format("hinged flag is {}, not 0 or 1", hinged), ErrorLocation{.file = name});
  rig.hinged = hinged == 1;
  const auto n = r.count(3 * sizeof(double));
  rig.neutral.resize(3, Eigen::Index(n));
  r.raw(rig.neutral.data(), sizeof(double) * std::size_t(rig.neutral.size()));
  const auto t = r.count(3 * sizeof(int));
  rig.triangles.resize(3, Eigen::Index(t));
  r.raw(rig.triangles.data(), sizeof(int) * std::size_t(rig.triangles.size()));
  const auto m = r.count(sizeof(uint64_t));
  std::set<std::string> names;
  for (uint64_t i = 0; i < m; ++i) {
    rig.shape_names.push_back(r.string());
    if (!names.insert(rig.shape_names.back()).second)
      throw Error(fmt::format("shape name '{}' appears twice", rig.shape_names.back()), ErrorLocation{.file = name});
  }
  // n and m are each bounded by the payload, their product only here.
  if (n != 0 && m > r.remaining() / (3 * sizeof(double) * n))
    throw Error(fmt::format("{} shapes of {} vertices do not fit in the {} bytes left", m, n, r.remaining()),
                ErrorLocation{.file = name});
  rig.deltas.resize(3 * Eigen::Index(n), Eigen::Index(m));
  r.raw(rig.deltas.data(), sizeof(double) * std::size_t(rig.deltas.size()));
  rig.file_vertex_of.resize(r.count(sizeof(int)));
  r.raw(rig.file_vertex_of.data(), sizeof(int) * rig.file_vertex_of.size());
  if (!r.at_end()) throw offset_error(name, int64_t(bytes.size()), "trailing bytes after the rig");
  // The solver indexes vertices by these without checks: a cache is trusted no further
  // than the files it replaces.
  if (rig.triangles.size() > 0 && (rig.triangles.minCoeff() < 0 || rig.triangles.maxCoeff() >= Eigen::Index(n)))
    throw Error(fmt::format("a triangle indexes a vertex outside 0..{}", Eigen::Index(n) - 1), ErrorLocation{.file = name});
  for (const int v : rig.file_vertex_of)
    if (v < 0 || v >= Eigen::Index(n))
      throw Error(fmt::format("the file's vertex map names vertex {} outside 0..{}", v, Eigen::Index(n) - 1),
                  ErrorLocation{.file = name});
  if (!rig.neutral.allFinite() || !rig.deltas.allFinite())
    throw Error("vertex positions are not all finite", ErrorLocation{.file = name});
  return rig;
}

std::optional<Rig> read_rig_cache(RigCacheKey key, const std::optional<fs::path>& cache_dir, fs::path* cache_file) {
  const fs::path path = cache_path(key, cache_dir);
  if (cache_file) *cache_file = path;
  std::error_code ec;
  if (!fs::exists(path, ec)) return std::nullopt;
  try {
    return deserialize_rig(read_file_bytes(path), key, path.string());
  } catch (const Error& e) {
    spdlog::warn("ignoring rig cache entry: {}; rebuilding it", e.what());
    return std::nullopt;
  }
}

fs::path write_rig_cache(RigCacheKey key, const Rig& rig, const std::optional<fs::path>& cache_dir) {
  const fs::path path = cache_path(key, cache_dir);
  try {
    std::error_code ec;
    fs::create_directories(path.parent_path(), ec);
    const auto bytes = serialize_rig(rig, key);
    write_file_atomically(path, bytes);
    return path;
  } catch (const Error& e) {
    spdlog::warn("rig cache not written ({}); loading will parse the files next time too", e.what());
    return {};
  }
}

}  // namespace facecap
