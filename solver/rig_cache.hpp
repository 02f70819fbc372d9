#pragma once
// The binary rig cache: loading a rig again skips parsing. One file per rig source,
// named by a key over the input files' paths, sizes and modification times, so an
// edited OBJ is a new key. Versioned and checksummed; a damaged or stale entry is
// ignored (with a warning) and rebuilt.
#include <cstdint>
#include <filesystem>
#include <optional>
#include <vector>

#include "solver/rig.hpp"

namespace facecap {

inline constexpr uint32_t kRigCacheVersion = 3;  // 2: Rig::hinged; 3: Rig::file_vertex_of

struct RigCacheKey {
  uint64_t value = 0;
};

RigCacheKey make_rig_cache_key(const char* loader, const std::vector<std::filesystem::path>& inputs);

// Serialised rig (for the cache and tests). Throws Error on a damaged buffer.
std::vector<char> serialize_rig(const Rig& rig, RigCacheKey key);
Rig deserialize_rig(const std::vector<char>& bytes, RigCacheKey expected_key, const std::string& name_for_errors);

// nullopt when absent, stale or damaged. cache_file receives the entry's path.
std::optional<Rig> read_rig_cache(RigCacheKey key, const std::optional<std::filesystem::path>& cache_dir,
                                  std::filesystem::path* cache_file = nullptr);
// Returns the file written, or empty when the cache directory is not writable.
std::filesystem::path write_rig_cache(RigCacheKey key, const Rig& rig,
                                      const std::optional<std::filesystem::path>& cache_dir);

}  // namespace facecap
