// facecapd.toml: parsed and validated against the schema. load_config reads a path, so
// the input is written to a memfd once per run and named as /proc/self/fd/N.
#include <sys/mman.h>
#include <unistd.h>

#include <cstdlib>
#include <string>

#include "config/config_file.hpp"
#include "fuzz/fuzz_support.hpp"

extern "C" int LLVMFuzzerTestOneInput(const uint8_t* data, size_t size) {
  using namespace facecap;
  static const int fd = ::memfd_create("facecapd.toml", MFD_CLOEXEC);
  static const std::string path = "/proc/self/fd/" + std::to_string(fd);
  if (fd < 0 || ::ftruncate(fd, 0) != 0 || ::pwrite(fd, data, size, 0) != ssize_t(size)) std::abort();
  return fuzz::parse_refusing_errors([&] { config::load_config(path); });
}
