// facecap convert: marker takes between C3D, TRC and .fcrec recordings, and a
// recording's solved weights to a Live Link Face CSV.
#include <chrono>
#include <filesystem>

#include <fmt/format.h>

#include "core/error.hpp"
#include "formats/recording.hpp"
#include "formats/take.hpp"
#include "tools/commands.hpp"
#include "tools/export.hpp"
#include "tools/progress.hpp"
#include "tools/tool_support.hpp"

namespace facecap::tools {

// Takes this long get a progress bar on a terminal without asking.
constexpr std::size_t kLongTakeFrames = 1000;

void add_convert_command(CLI::App& app, int& exit_code) {
  struct Options {
    std::string input;
    std::string output;
    bool progress = false;
    bool force = false;
    bool salvage = false;
  };
  auto opts = std::make_shared<Options>();
  auto* cmd = app.add_subcommand("convert", "Convert marker takes between C3D, TRC and .fcrec recordings, or a "
                                            "recording's solved weights to a Live Link Face CSV (facecap export writes every other format)");
  cmd->add_option("in", opts->input, "Input take (.c3d, .trc, .fcrec)")->required()->check(CLI::ExistingFile);
  cmd->add_option("out", opts->output, "Output file; its extension picks the format (.c3d, .trc, .fcrec; .csv: the "
                                       "solved weights of a .fcrec as Live Link Face)")->required();
  cmd->add_flag("--progress", opts->progress, "Show progress on stderr (default: on a terminal, for long takes)");
  cmd->add_flag("--force", opts->force, "Replace the output file if it exists");
  cmd->add_flag("--salvage", opts->salvage,
                "Read a recording whose HEAD is damaged and has no intact copy (as facecap inspect --salvage)");
  cmd->callback([opts, &exit_code] {
    const std::filesystem::path input(opts->input), output(opts->output);
    std::error_code ec;
    if (std::filesystem::equivalent(input, output, ec)) throw file_error(output.string(), "output is the input file");
    if (!opts->force && std::filesystem::exists(output)) {
      throw file_error(output.string(), "exists; pass --force to replace it");
    }
    const auto format = formats::format_from_extension(output);
    if (!format) throw file_error(output.string(), "output must end in .c3d, .trc, .fcrec or .csv");
    const auto start = std::chrono::steady_clock::now();
    if (*format == formats::TakeFormat::kLiveLinkFace) {
      // facecap export's own path (its --map and --rig-names options are there).
      export_weights_csv({.input = input, .output = output, .progress = opts->progress});
      exit_code = 0;
      return;
    }
    const formats::MarkerTake take = formats::read_take(input, {.salvage_recording = opts->salvage});
    for (const auto& warning : take.warnings) fmt::print(stderr, "facecap: warning: {}\n", warning);
    const bool show = opts->progress || (stderr_is_terminal() && take.frames.size() >= kLongTakeFrames);
    ProgressBar bar(fmt::format("writing {}", output.filename().string()), show);
    formats::write_take(output, take, [&bar](std::size_t done, std::size_t total) { bar.update(done, total); });
    bar.finish();
    const double seconds = std::chrono::duration<double>(std::chrono::steady_clock::now() - start).count();
    fmt::print("{} ({}) -> {} ({}): {} frames, {} markers, {:.3f} s\n", input.string(),
               formats::format_name(take.format), output.string(),
               formats::format_name(*formats::format_from_extension(output)), take.frames.size(), take.marker_count(),
               seconds);
    exit_code = 0;
  });
}

}  // namespace facecap::tools
