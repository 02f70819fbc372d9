#include "core/io.hpp"

#include <cerrno>
#include <cstdlib>
#include <cstring>
#include <fstream>

#include <fcntl.h>
#include <fmt/format.h>
#include <sys/stat.h>
#include <unistd.h>

#include "core/error.hpp"

namespace facecap {

std::vector<char> read_file_bytes(const std::filesystem::path& path) {
  // open + fstat rather than an ifstream's seek/tell: a directory opens as a stream whose
  // "size" is 2^63, which would be allocated before the read failed.
  const int fd = ::open(path.c_str(), O_RDONLY | O_CLOEXEC);
  if (fd < 0) throw file_error(path.string(), fmt::format("cannot open: {}", std::strerror(errno)));
  struct stat st {};
  if (::fstat(fd, &st) != 0 || !S_ISREG(st.st_mode)) {
    const bool directory = S_ISDIR(st.st_mode);
    ::close(fd);
    throw file_error(path.string(), directory ? "is a directory, not a file" : "not a regular file");
  }
  std::vector<char> bytes(static_cast<std::size_t>(st.st_size));
  std::size_t done = 0;
  while (done < bytes.size()) {
    const ssize_t n = ::read(fd, bytes.data() + done, bytes.size() - done);
    if (n < 0 && errno == EINTR) continue;
    if (n <= 0) {
      const int err = n < 0 ? errno : 0;
      ::close(fd);
      throw file_error(path.string(), err ? fmt::format("read failed: {}", std::strerror(err))
                                          : fmt::format("file shrank while being read ({} of {} bytes)", done, bytes.size()));
    }
    done += std::size_t(n);
  }
  ::close(fd);
  return bytes;
}

void write_file_atomically(const std::filesystem::path& path, std::span<const char> bytes) {
  const auto tmp = path.string() + fmt::format(".tmp.{}", ::getpid());
  {
    std::ofstream out(tmp, std::ios::binary | std::ios::trunc);
    if (!out) throw file_error(tmp, fmt::format("cannot create: {}", std::strerror(errno)));
    out.write(bytes.data(), static_cast<std::streamsize>(bytes.size()));
    if (!out.flush()) throw file_error(tmp, "write failed (disk full?)");
  }
  std::error_code ec;
  std::filesystem::rename(tmp, path, ec);
  if (ec) {
    std::filesystem::remove(tmp, ec);
    throw file_error(path.string(), "cannot rename temporary file into place");
  }
}

std::filesystem::path user_cache_dir() {
  if (const char* dir = std::getenv("FACECAP_CACHE_DIR"); dir && *dir) return dir;
  if (const char* xdg = std::getenv("XDG_CACHE_HOME"); xdg && *xdg) return std::filesystem::path(xdg) / "facecap";
  if (const char* home = std::getenv("HOME"); home && *home) return std::filesystem::path(home) / ".cache" / "facecap";
  return std::filesystem::temp_directory_path() / "facecap-cache";
}

}  // namespace facecap
