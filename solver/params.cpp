#include "solver/params.hpp"

#include <fmt/format.h>

#include "core/error.hpp"

namespace facecap {
namespace {

template <typename E, std::size_t N>
E parse_or_throw(const EnumTable<E, N>& table, std::string_view name, std::string_view what) {
  if (const auto value = table.parse(name)) return *value;
  throw Error(fmt::format("unknown {} '{}': choose {}", what, name, fmt::join(table.names(), ", ")));
}

}  // namespace

SolverMethod parse_solver_method(std::string_view name) { return parse_or_throw(kSolverMethods, name, "solver"); }

CollisionRegion parse_collision_region(std::string_view name) {
  return parse_or_throw(kCollisionRegions, name, "collision region");
}

}  // namespace facecap
