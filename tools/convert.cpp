// facecap convert: marker takes between C3D, TRC and .fcrec recordings, and a
// recording's solved weights to a Live Link Face CSV.
#include <chrono>
#include <filesystem>

#include <fmt/format.h>

#include "core/error.hpp"
#include "formats/arkit.hpp"
#include "formats/livelinkface.hpp"
#include "formats/recording.hpp"
#include "formats/take.hpp"
#include "tools/commands.hpp"
#include "tools/progress.hpp"
#include "tools/tool_support.hpp"

namespace facecap::tools {
namespace {

// A recording's solved frames as Live Link Face rows (ARKit names matched to the
// header's shape names). Throws Error when the recording has no solved frames.
formats::FaceTake solved_weights_of(const std::filesystem::path& input, ProgressBar& bar) {
  if (formats::detect_file_format(input) != formats::TakeFormat::kRecording)
    throw file_error(input.string(), "a Live Link Face CSV is written from a .fcrec recording's solved frames");
  const formats::RecordingReader reader(input);
  if (reader.solved_frame_count() == 0)
    throw file_error(input.string(), "the recording has no solved frames (record from facecapd or facecap solve -o x.fcrec)");
  if (const std::string damage = reader.damage_summary(); !damage.empty())
    fmt::print(stderr, "facecap: warning: {}: damaged: {}; converting the frames read\n", input.string(), damage);
  const formats::ArkitWeights arkit(reader.header().shape_names);
  formats::FaceTake face;
  face.rate_hz = reader.header().rate_hz;
  SolvedFrame solved;
  for (std::size_t i = 0; i < reader.solved_frame_count(); ++i) {
    read_solved_frame_checked(reader, i, solved);
    face.frames.push_back(formats::face_frame_from_solved(solved, arkit));
    bar.update(i + 1, reader.solved_frame_count());
  }
  return face;
}

}  // namespace

// Takes this long get a progress bar on a terminal without asking.
constexpr std::size_t kLongTakeFrames = 1000;

void add_convert_command(CLI::App& app, int& exit_code) {
  struct Options {
    std::string input;
    std::string output;
    bool progress = false;
    bool force = false;
  };
  auto opts = std::make_shared<Options>();
  auto* cmd = app.add_subcommand("convert", "Convert marker takes between C3D, TRC and .fcrec recordings, or a "
                                            "recording's solved weights to a Live Link Face CSV");
  cmd->add_option("in", opts->input, "Input take (.c3d, .trc, .fcrec)")->required()->check(CLI::ExistingFile);
  cmd->add_option("out", opts->output, "Output file; its extension picks the format (.c3d, .trc, .fcrec; .csv: the "
                                       "solved weights of a .fcrec as Live Link Face)")->required();
  cmd->add_flag("--progress", opts->progress, "Show progress on stderr (default: on a terminal, for long takes)");
  cmd->add_flag("--force", opts->force, "Replace the output file if it exists");
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
      ProgressBar bar(fmt::format("writing {}", output.filename().string()), opts->progress);
      const formats::FaceTake face = solved_weights_of(input, bar);
      write_live_link_csv(output, face);
      bar.finish();
      const double seconds = std::chrono::duration<double>(std::chrono::steady_clock::now() - start).count();
      fmt::print("{} (solved weights) -> {} (Live Link Face): {} frames, {:.3f} s\n", input.string(), output.string(),
                 face.frames.size(), seconds);
      exit_code = 0;
      return;
    }
    const formats::MarkerTake take = formats::read_take(input);
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
