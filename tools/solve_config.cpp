#include "tools/solve_config.hpp"

#include <fmt/format.h>

#include "config/config_file.hpp"
#include "core/error.hpp"
#include "pipeline/settings.hpp"

namespace facecap::tools {

void add_solve_config_options(CLI::App& command, SolveConfigOptions& options) {
  command.add_option("--config", options.file, "facecapd configuration whose [solver] and [filter] sections (and "
                                               "calibration.stabilise_head) to solve with")
      ->check(CLI::ExistingFile);
  command.add_option("--set", options.sets, "Override one solve setting, e.g. --set solver.alpha=0.2 (repeatable)");
}

SolveConfig load_solve_config(const SolveConfigOptions& options, const std::optional<std::string>& stored,
                              const std::string& stored_name) {
  for (const std::string& set : options.sets) {
    const std::string key = set.substr(0, set.find('='));
    if (!pipeline::is_solve_setting(key.substr(0, key.find_last_not_of(" \t") + 1)))
      throw Error(fmt::format("--set {}: only the [solver] and [filter] keys and calibration.stabilise_head, label_markers and max_marker_speed_mm_s affect a solve", set));
  }
  SolveConfig out;
  const std::string with_sets = options.sets.empty() ? "" : " with --set";
  if (!options.file.empty()) {
    out.values = config::load_config(options.file, options.sets, config::Checks::kValues).values;
    out.origin = options.file + with_sets;
  } else if (stored) {
    out.values = config::load_config_text(*stored, stored_name, options.sets, config::Checks::kValues).values;
    out.origin = "the recording's stored settings" + with_sets;
  } else {
    out.values = config::load_config("", options.sets, config::Checks::kValues).values;
    out.origin = "defaults" + with_sets;
  }
  return out;
}

}  // namespace facecap::tools
