#pragma once
// SolvePipeline::State as bytes: the payload of a recording's STAT chunk (layout and
// versions: docs/recording-format.md).
#include <cstdint>
#include <span>
#include <string_view>
#include <vector>

#include "pipeline/solve_pipeline.hpp"

namespace facecap::pipeline {

// 1: the first layout.
inline constexpr uint32_t kPipelineStateVersion = 1;

// Replaces `out` with the state's bytes. RT-safe when out's capacity holds them (an
// earlier encoding of the same pipeline's state: its sizes do not change).
void encode_pipeline_state(const SolvePipeline::State& state, std::vector<char>& out) noexcept;
// Not RT-safe. Throws Error naming `name` (the file) on another version, or a payload cut short,
// too long or with sizes past its end.
SolvePipeline::State decode_pipeline_state(std::span<const char> bytes, std::string_view name);

}  // namespace facecap::pipeline
