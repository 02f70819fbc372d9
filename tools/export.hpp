#pragma once
// What facecap export shares with facecap convert: a recording's solved weights as CSV.
#include <filesystem>

namespace facecap::tools {

struct WeightsCsvOptions {
  std::filesystem::path input;   // a .fcrec with solved frames
  std::filesystem::path output;
  std::filesystem::path map;     // rig shape -> ARKit name (shape_map.hpp); empty: by name
  bool rig_names = false;        // the rig's own names instead of a Live Link Face CSV
  bool progress = false;
};

// Writes a Live Link Face CSV (ARKit names, matched by name or through the map) or, with
// rig_names, Timecode, Seconds and one column per rig shape. Throws Error naming why when
// the file would animate nothing: no shape maps to ARKit, or every weight stays 0.
void export_weights_csv(const WeightsCsvOptions& options);

}  // namespace facecap::tools
