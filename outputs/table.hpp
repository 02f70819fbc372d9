#pragma once
// The one ordered table of outputs. Each row is a sink configured by its own section,
// [outputs.<name>]; the solve loop offers every solved frame to each enabled sink in this
// order. Adding an output is a row here, its section in config/schema.cpp and its own
// folder under outputs/ (docs/architecture.md, "Adding a sink"); nothing registers itself.
#include <memory>
#include <span>
#include <string_view>
#include <vector>

#include "config/daemon_config.hpp"
#include "outputs/api/sink.hpp"
#include "outputs/api/sink_context.hpp"
#include "outputs/recording/recorder.hpp"

namespace facecap::outputs {

struct OutputEntry {
  std::string_view name;  // its section is [outputs.<name>]
  std::string_view summary;
  // The sink its section configures, or nullptr when the section disables it. Not
  // RT-safe; throws Error.
  std::unique_ptr<OutputSink> (*make)(const config::DaemonConfig& config, const SinkContext& context);
};

std::span<const OutputEntry> output_table() noexcept;

// Every enabled output, in table order. Throws Error naming the output that failed.
std::vector<std::unique_ptr<OutputSink>> make_outputs(const config::DaemonConfig& config, const SinkContext& context);

// A take's recorder options from [outputs.recording]: what to record, the queue, the file.
RecorderOptions take_options(const config::DaemonConfig& config, formats::RecordingHeader header,
                             std::filesystem::path file);

}  // namespace facecap::outputs
