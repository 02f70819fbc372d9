#include "drivers/registry.hpp"

#include <array>

#include <fmt/format.h>

#include "core/error.hpp"
#include "drivers/replay/replay_source.hpp"
#include "drivers/sim/sim_source.hpp"

namespace facecap::drivers {
namespace {

std::unique_ptr<MarkerSource> make_sim(const SourceConfig& config, const SourceContext& context) {
  return std::make_unique<SimSource>(config.sim, context.rig, *context.markers);
}

std::unique_ptr<MarkerSource> make_replay(const SourceConfig& config, const SourceContext&) {
  return std::make_unique<ReplaySource>(config.replay);
}

const std::array kDrivers = {
    DriverEntry{"sim", "simulated capture of the rig: built-in motion, noise, dropouts, head sway", false, &make_sim},
    DriverEntry{"replay", "a recorded take: C3D, TRC or a facecapd recording (.fcrec)", true, &make_replay},
};

}  // namespace

std::span<const DriverEntry> driver_table() noexcept { return kDrivers; }

const DriverEntry* find_driver(std::string_view name) noexcept {
  for (const DriverEntry& entry : kDrivers)
    if (entry.name == name) return &entry;
  return nullptr;
}

std::unique_ptr<MarkerSource> make_source(const SourceConfig& config, const SourceContext& context) {
  const DriverEntry* entry = find_driver(config.driver);
  if (!entry) throw Error(fmt::format("unknown marker source driver '{}'", config.driver));
  if (!context.rig || !context.markers) throw Error("marker source created without a rig and marker set");
  return entry->make(config, context);
}

}  // namespace facecap::drivers
