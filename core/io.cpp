#include "core/io.hpp"

#include <cerrno>
#include <cstdlib>
#include <cstring>
#include <utility>

#include <fcntl.h>
#include <fmt/format.h>
#include <sys/mman.h>
#include <sys/stat.h>
#include <unistd.h>

#include "core/error.hpp"

namespace facecap {

namespace {

const char* file_kind(mode_t mode) {
  if (S_ISDIR(mode)) return "a directory";
  if (S_ISFIFO(mode)) return "a FIFO (named pipe)";
  if (S_ISCHR(mode)) return "a character device";
  if (S_ISBLK(mode)) return "a block device";
  if (S_ISSOCK(mode)) return "a socket";
  return "not a regular file";
}

std::size_t regular_file_size(int fd) {
  struct stat st {};
  if (::fstat(fd, &st) != 0) return 0;
  return std::size_t(st.st_size);
}

}  // namespace

int open_regular_file(const std::filesystem::path& path, bool no_follow) {
  // O_NONBLOCK: opening a FIFO for reading would otherwise wait for a writer forever.
  // O_NOFOLLOW fails with ELOOP on a symlink, said as such below.
  const int fd = ::open(path.c_str(), O_RDONLY | O_CLOEXEC | O_NONBLOCK | O_NOCTTY | (no_follow ? O_NOFOLLOW : 0));
  if (fd < 0) {
    if (no_follow && errno == ELOOP) throw file_error(path.string(), "is a symbolic link, which is not followed here");
    throw file_error(path.string(), fmt::format("cannot open: {}", std::strerror(errno)));
  }
  struct stat st {};
  if (::fstat(fd, &st) != 0) {
    const int err = errno;
    ::close(fd);
    throw file_error(path.string(), fmt::format("cannot stat: {}", std::strerror(err)));
  }
  if (!S_ISREG(st.st_mode)) {
    ::close(fd);
    throw file_error(path.string(), fmt::format("is {}, not a regular file", file_kind(st.st_mode)));
  }
  const int flags = ::fcntl(fd, F_GETFL);
  if (flags >= 0) ::fcntl(fd, F_SETFL, flags & ~O_NONBLOCK);
  return fd;
}

MappedFile::MappedFile(const std::filesystem::path& path, bool no_follow) {
  const int fd = open_regular_file(path, no_follow);
  size_ = regular_file_size(fd);
  if (size_ > 0) {
    void* address = ::mmap(nullptr, size_, PROT_READ, MAP_PRIVATE, fd, 0);
    if (address == MAP_FAILED) {
      const int err = errno;
      ::close(fd);
      throw file_error(path.string(), fmt::format("cannot map: {}", std::strerror(err)));
    }
    address_ = address;
  }
  ::close(fd);
}

MappedFile::~MappedFile() {
  if (address_) ::munmap(address_, size_);
}

MappedFile::MappedFile(MappedFile&& other) noexcept
    : address_(std::exchange(other.address_, nullptr)), size_(std::exchange(other.size_, 0)) {}

MappedFile& MappedFile::operator=(MappedFile&& other) noexcept {
  if (this != &other) {
    if (address_) ::munmap(address_, size_);
    address_ = std::exchange(other.address_, nullptr);
    size_ = std::exchange(other.size_, 0);
  }
  return *this;
}

std::vector<char> read_file_bytes(const std::filesystem::path& path) {
  // open + fstat rather than an ifstream's seek/tell: a directory opens as a stream whose
  // "size" is 2^63, which would be allocated before the read failed.
  const int fd = open_regular_file(path);
  std::vector<char> bytes(regular_file_size(fd));
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

void write_file_atomically(const std::filesystem::path& path, std::span<const char> bytes, unsigned mode) {
  const auto tmp = path.string() + fmt::format(".tmp.{}", ::getpid());
  const int fd = ::open(tmp.c_str(), O_WRONLY | O_CREAT | O_TRUNC | O_CLOEXEC, mode_t(mode));
  if (fd < 0) throw file_error(tmp, fmt::format("cannot create: {}", std::strerror(errno)));
  std::size_t written = 0;
  while (written < bytes.size()) {
    const ssize_t n = ::write(fd, bytes.data() + written, bytes.size() - written);
    if (n < 0 && errno == EINTR) continue;
    if (n <= 0) {
      const int error = errno;
      ::close(fd);
      ::unlink(tmp.c_str());
      throw file_error(tmp, fmt::format("write failed: {}", std::strerror(error)));
    }
    written += std::size_t(n);
  }
  ::close(fd);
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
