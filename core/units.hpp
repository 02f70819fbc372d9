#pragma once
// Length units of takes, sources and rigs: "mm", "cm" or "m" (the only ones capture
// systems use for faces), converted through millimetres.
#include <optional>
#include <string>
#include <string_view>

namespace facecap {

// Millimetres per unit for "mm", "cm", "m" (and their spelled-out forms, any case, spaces
// ignored); nullopt for anything else, the empty string included.
std::optional<double> millimetres_per_unit(std::string_view units);

// The canonical name of a unit size: "mm", "cm", "m", or "<n>mm" for any other size.
std::string unit_name(double mm_per_unit);

}  // namespace facecap
