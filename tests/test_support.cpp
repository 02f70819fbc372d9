#include "tests/test_support.hpp"

#include <cstdio>
#include <cstdlib>
#include <fstream>
#include <sstream>

#include <sys/wait.h>

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

std::string slurp(const std::filesystem::path& path) {
  std::ifstream in(path, std::ios::binary);
  std::stringstream s;
  s << in.rdbuf();
  return s.str();
}

std::string run_and_capture(const std::string& command, int* status) {
  std::string out;
  FILE* pipe = popen(command.c_str(), "r");
  char buffer[4096];
  while (std::size_t n = fread(buffer, 1, sizeof buffer, pipe)) out.append(buffer, n);
  *status = pclose(pipe);
  return out;
}

Run run_built(const std::string& program, const std::filesystem::path& dir, const std::vector<std::string>& args) {
  std::string command = std::string("'") + FACECAP_BINARY_DIR + "/" + program + "'";
  for (const auto& a : args) command += " '" + a + "'";
  command += " >'" + (dir / "stdout").string() + "' 2>'" + (dir / "stderr").string() + "' </dev/null";
  const int status = std::system(command.c_str());
  Run run;
  run.exit_code = WIFEXITED(status) ? WEXITSTATUS(status) : -1;
  run.out = slurp(dir / "stdout");
  run.err = slurp(dir / "stderr");
  return run;
}

}  // namespace facecap::test
