#include "core/units.hpp"

#include <cctype>
#include <cmath>

#include <fmt/format.h>

namespace facecap {

std::optional<double> millimetres_per_unit(std::string_view units) {
  std::string u;
  for (char c : units)
    if (!std::isspace(static_cast<unsigned char>(c))) u += char(std::tolower(static_cast<unsigned char>(c)));
  if (u == "mm" || u == "millimeter" || u == "millimeters" || u == "millimetre" || u == "millimetres") return 1.0;
  if (u == "cm" || u == "centimeter" || u == "centimeters" || u == "centimetre" || u == "centimetres") return 10.0;
  if (u == "m" || u == "meter" || u == "meters" || u == "metre" || u == "metres") return 1000.0;
  return std::nullopt;
}

std::string unit_name(double mm_per_unit) {
  if (std::abs(mm_per_unit - 1.0) < 1e-9) return "mm";
  if (std::abs(mm_per_unit - 10.0) < 1e-9) return "cm";
  if (std::abs(mm_per_unit - 1000.0) < 1e-9) return "m";
  return fmt::format("{}mm", mm_per_unit);
}

}  // namespace facecap
