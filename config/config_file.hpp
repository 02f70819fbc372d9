#pragma once
// Reading facecapd.toml against the schema: every problem in the file is collected and
// reported together (file:line:col, key path, bad value, allowed range), and nothing is
// returned unless the whole configuration is valid. Not real-time code.
#include <string>
#include <string_view>
#include <vector>

#include "config/daemon_config.hpp"
#include "config/schema.hpp"
#include "core/error.hpp"

namespace facecap::config {

enum class Origin : uint8_t { kDefault, kFile, kCommandLine };

struct KeyOrigin {
  Origin origin = Origin::kDefault;
  ErrorLocation where;  // file:line:col of the value, or "--set"
};

struct LoadedConfig {
  DaemonConfig values;
  std::vector<KeyOrigin> origins;  // parallel to config_schema()
  std::string file;                // the file read, empty for defaults only
  std::vector<std::string> warnings;  // deprecated names used, for the log

  const KeyOrigin& origin_of(std::string_view key_path) const;
};

// All problems of one configuration; what() lists them one per line.
class ConfigError : public Error {
 public:
  explicit ConfigError(std::vector<Error> problems);
  const std::vector<Error>& problems() const noexcept { return problems_; }

 private:
  std::vector<Error> problems_;
};

// What a load checks besides each value's type, range and choices and unknown keys:
// kAll (facecapd) adds the rules across keys and that every input file named exists;
// kValues is for tools that read only some sections (the solve settings).
enum class Checks : uint8_t { kAll, kValues };

// Defaults, then the file (when not empty), then overrides ("loop.rate_hz=240", a string
// may be given without quotes). Input-file paths in the file are relative to the file's
// directory. Checks types, ranges, choices, unknown keys (with a "did you mean"), and with
// kAll the rules across keys and that every input file named exists. Throws ConfigError.
LoadedConfig load_config(const std::string& file, const std::vector<std::string>& overrides = {},
                         Checks checks = Checks::kAll);

// The same from TOML text (a recording's stored settings); `name` labels errors, relative
// input paths are relative to the working directory.
LoadedConfig load_config_text(std::string_view text, const std::string& name,
                              const std::vector<std::string>& overrides = {}, Checks checks = Checks::kAll);

// `--print-config`: every effective value and where it came from, as TOML.
std::string render_effective_config(const LoadedConfig& config);

// The shipped config/facecapd.toml: every key at its default with its documentation.
std::string render_documented_defaults();

// The key reference of docs/config.md: one Markdown table per section.
std::string render_markdown_reference();

// The keys whose values differ.
std::vector<const KeySpec*> changed_keys(const DaemonConfig& before, const DaemonConfig& after);

// What separates the entries of a list setting (split_list): commas or spaces ("a, b c").
inline constexpr std::string_view kListSeparators = ", \t";

// The closest of `candidates` to `word` when it is close enough to be a likely typo.
std::string closest_match(std::string_view word, const std::vector<std::string>& candidates);

}  // namespace facecap::config
