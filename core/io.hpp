#pragma once
// Small file and hashing helpers shared by loaders, caches and recordings.
#include <cstdint>
#include <filesystem>
#include <span>
#include <string>
#include <vector>

namespace facecap {

// Opens a file for reading only if it is a regular file (following symlinks unless
// no_follow): a FIFO, device, socket or directory named as a file is refused at once,
// never waited on (the open itself does not block on a FIFO). Returns the descriptor
// (O_CLOEXEC, blocking); throws Error naming the path and what it is.
int open_regular_file(const std::filesystem::path& path, bool no_follow = false);

// Whole file into memory; throws Error naming the file on failure (open_regular_file).
std::vector<char> read_file_bytes(const std::filesystem::path& path);

// A regular file mapped read-only (open_regular_file): only the pages read cost memory,
// so a reader that refuses a file from its header never touches the rest.
class MappedFile {
 public:
  explicit MappedFile(const std::filesystem::path& path, bool no_follow = false);
  ~MappedFile();
  MappedFile(MappedFile&& other) noexcept;
  MappedFile& operator=(MappedFile&& other) noexcept;
  std::span<const char> bytes() const noexcept { return {static_cast<const char*>(address_), size_}; }

 private:
  void* address_ = nullptr;
  std::size_t size_ = 0;
};

// Writes via a temporary file and rename, so readers never see a half-written file. The
// file is created with `mode` (less the umask): 0600 for a secret, which is then never
// readable by others, not even for a moment.
void write_file_atomically(const std::filesystem::path& path, std::span<const char> bytes, unsigned mode = 0644);

// 64-bit FNV-1a: stable across runs and machines, used for identities and checksums.
struct Fnv1a64 {
  uint64_t state = 0xcbf29ce484222325ull;
  void add(const void* data, std::size_t size) noexcept {
    const auto* p = static_cast<const unsigned char*>(data);
    for (std::size_t i = 0; i < size; ++i) {
      state ^= p[i];
      state *= 0x100000001b3ull;
    }
  }
  template <typename T>
  void add_value(const T& value) noexcept { add(&value, sizeof(T)); }
  void add_string(const std::string& s) noexcept { add_value(s.size()); add(s.data(), s.size()); }
  uint64_t digest() const noexcept { return state; }
};

// $FACECAP_CACHE_DIR, else $XDG_CACHE_HOME/facecap, else ~/.cache/facecap.
std::filesystem::path user_cache_dir();

}  // namespace facecap
