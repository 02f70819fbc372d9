#pragma once
// TRC (Motion Analysis track row column) marker reader and writer.
//
// Reads PathFileType 3 and 4, fields separated by tabs (empty cells allowed) or by
// spaces, any of LF, CRLF, CR CR LF or CR line endings. The five header lines give
// rate, NumMarkers, Units and the labels; data rows are `Frame# Time X1 Y1 Z1 ...`.
// A marker is missing when its three cells are empty, absent (short row) or NaN.
// Columns past NumMarkers (unlabelled extras some exporters add) are ignored with a
// warning; a NumFrames that disagrees with the rows present is a warning, not an error.
#include <string>
#include <string_view>

#include "formats/take.hpp"

namespace facecap::formats {

// Parses TRC text; `name` labels errors ("name:line:column: what"). Throws Error.
MarkerTake read_trc(std::string_view text, const std::string& name);

// Writes PathFileType 4, tab-separated, LF endings, missing markers as empty cells.
// Coordinates are written as the shortest text that reads back to the same float32;
// `file_name` goes into the first header line.
std::string write_trc(const MarkerTake& take, std::string_view file_name, const ProgressFn& progress = {});

}  // namespace facecap::formats
