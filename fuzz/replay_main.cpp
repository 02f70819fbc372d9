// The fuzz targets without libFuzzer (GCC builds): every file named on the command line,
// or found under a directory named there, goes once through LLVMFuzzerTestOneInput. A
// crash or an exception other than facecap::Error ends the run, and the test fails: the
// seed corpora and saved findings replayed as regression inputs.
#include <algorithm>
#include <cstdint>
#include <cstdio>
#include <filesystem>
#include <fstream>
#include <iterator>
#include <vector>

extern "C" int LLVMFuzzerTestOneInput(const uint8_t* data, size_t size);

int main(int argc, char** argv) {
  namespace fs = std::filesystem;
  std::vector<fs::path> inputs;
  for (int i = 1; i < argc; ++i) {
    const fs::path arg(argv[i]);
    if (fs::is_directory(arg)) {
      for (const auto& entry : fs::recursive_directory_iterator(arg))
        if (entry.is_regular_file()) inputs.push_back(entry.path());
    } else if (fs::is_regular_file(arg)) {
      inputs.push_back(arg);
    }
  }
  std::sort(inputs.begin(), inputs.end());
  uint64_t bytes = 0;
  for (const fs::path& path : inputs) {
    std::ifstream file(path, std::ios::binary);  // not core/io.hpp: some targets link only the client
    const std::vector<char> input((std::istreambuf_iterator<char>(file)), std::istreambuf_iterator<char>());
    bytes += input.size();
    LLVMFuzzerTestOneInput(reinterpret_cast<const uint8_t*>(input.data()), input.size());
  }
  std::printf("replayed %zu inputs (%llu bytes) through %s\n", inputs.size(), static_cast<unsigned long long>(bytes),
              argc > 0 ? argv[0] : "the target");
  return inputs.empty() ? 1 : 0;  // no input at all: the corpus is missing, not passed
}
