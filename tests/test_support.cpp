#include "tests/test_support.hpp"

#include <cstdlib>
#include <fstream>

#include <unistd.h>

namespace facecap::test {

std::filesystem::path shared_data_dir() {
  if (const char* env = std::getenv("FACECAP_SHARED_DATA"); env && *env) return env;
  return FACECAP_SHARED_DATA_DIR;
}

std::filesystem::path shared_data(const std::string& relative) {
  auto path = shared_data_dir() / relative;
  return std::filesystem::exists(path) ? path : std::filesystem::path{};
}

std::string missing_shared_data_message(const std::string& relative) {
  return "SKIPPED: shared test data " + (shared_data_dir() / relative).string() +
         " is absent (clone ../shared beside the checkout to run this test)";
}

std::filesystem::path scratch_dir(const std::string& name) {
  auto dir = std::filesystem::temp_directory_path() /
             ("facecap-test-" + std::to_string(::getpid())) / name;
  std::filesystem::remove_all(dir);
  std::filesystem::create_directories(dir);
  return dir;
}

void write_text(const std::filesystem::path& path, const std::string& text) {
  std::filesystem::create_directories(path.parent_path());
  std::ofstream out(path, std::ios::binary | std::ios::trunc);
  out << text;
}

}  // namespace facecap::test
