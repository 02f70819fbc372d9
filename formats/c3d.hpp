#pragma once
// C3D (c3d.org) marker reader and writer.
//
// Reads Intel, DEC (VAX floats) and MIPS (big-endian) files with integer or float point
// storage. Parameters win over the header where both exist (POINT:USED, SCALE, RATE,
// DATA_START; TRIAL:ACTUAL_START_FIELD / ACTUAL_END_FIELD for long takes); the header
// fills in what the parameters lack, so files without parameters still read. Analog
// samples are skipped. A point whose fourth word (residual and camera mask) is negative
// is missing. A parameter section damaged after the entries we need is tolerated with a
// warning in MarkerTake::warnings.
#include <span>
#include <string>
#include <vector>

#include "formats/take.hpp"

namespace facecap::formats {

// Parses a whole C3D file held in memory; `name` labels errors. Throws Error naming the
// byte offset and what was wrong.
MarkerTake read_c3d(std::span<const char> bytes, const std::string& name);

// Encodes a take as an Intel, float-storage C3D file: POINT, ANALOG (empty) and TRIAL
// parameters, LABELS2... groups past 255 markers, missing points as residual -1.
// Throws Error when the take cannot be represented (inconsistent frames, > 65535 markers).
std::vector<char> write_c3d(const MarkerTake& take, const ProgressFn& progress = {});

}  // namespace facecap::formats
