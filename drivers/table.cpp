#include "drivers/table.hpp"

#include <cctype>
#include <string>

#include <fmt/format.h>

#include "core/error.hpp"
#if FACECAP_WITH_NATNET
#include "drivers/natnet/natnet_source.hpp"
#endif
#if FACECAP_WITH_REPLAY
#include "drivers/replay/replay_source.hpp"
#endif
#if FACECAP_WITH_SIM
#include "drivers/sim/sim_source.hpp"
#endif

namespace facecap::drivers {
namespace {

#if FACECAP_WITH_SIM
std::unique_ptr<MarkerSource> make_sim(const SourceConfig& config, const SourceContext& context) {
  if (!context.rig) throw Error("the sim source needs the rig being solved");
  return std::make_unique<SimSource>(config.sim, context.rig, context.markers);
}
#endif

#if FACECAP_WITH_REPLAY
std::unique_ptr<MarkerSource> make_replay(const SourceConfig& config, const SourceContext&) {
  return std::make_unique<ReplaySource>(config.replay, config.natnet);
}
#endif

#if FACECAP_WITH_NATNET
std::unique_ptr<MarkerSource> make_natnet(const SourceConfig& config, const SourceContext&) {
  return std::make_unique<NatNetSource>(config.natnet);
}
#endif

const DriverEntry kDrivers[] = {
#if FACECAP_WITH_SIM
    {DriverId::kSim, "nothing: it samples the rig being solved", &make_sim},
#endif
#if FACECAP_WITH_REPLAY
    {DriverId::kReplay, "a take file (source.replay.file)", &make_replay},
#endif
#if FACECAP_WITH_NATNET
    {DriverId::kNatNet, "a NatNet server on the network (source.natnet.server_address, or discovery)", &make_natnet},
#endif
};

}  // namespace

std::span<const DriverEntry> driver_table() noexcept { return kDrivers; }

const DriverEntry* find_driver(DriverId id) noexcept {
  for (const DriverEntry& entry : kDrivers)
    if (entry.id == id) return &entry;
  return nullptr;
}

std::unique_ptr<MarkerSource> make_source(const SourceConfig& config, const SourceContext& context) {
  const DriverEntry* entry = find_driver(config.driver);
  if (!entry) {
    std::string option(kDriverIds.name(config.driver));
    for (char& c : option) c = char(std::toupper(static_cast<unsigned char>(c)));
    throw Error(fmt::format("the {} driver is not built into this facecapd (configure with -DFACECAP_WITH_{}=ON)",
                            kDriverIds.name(config.driver), option));
  }
  return entry->make(config, context);
}

}  // namespace facecap::drivers
