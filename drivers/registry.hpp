#pragma once
// The one ordered table of marker sources. Adding a driver is adding a row here (and its
// options to drivers/source_config.hpp and config/schema.cpp); nothing registers itself.
#include <memory>
#include <span>
#include <string_view>

#include "drivers/marker_set.hpp"
#include "drivers/marker_source.hpp"
#include "drivers/source_config.hpp"
#include "solver/rig.hpp"

namespace facecap::drivers {

// What a driver may use besides its own options.
struct SourceContext {
  std::shared_ptr<const Rig> rig;  // the rig being solved (the sim drives it)
  const MarkerSet* markers = nullptr;  // the marker set the solver expects
};

struct DriverEntry {
  std::string_view name;
  std::string_view summary;
  bool supports_lockstep;  // can hand every frame in order as fast as the loop asks
  std::unique_ptr<MarkerSource> (*make)(const SourceConfig& config, const SourceContext& context);
};

// In the order `facecapd --list-drivers` and the config documentation show them.
std::span<const DriverEntry> driver_table() noexcept;

// nullptr when no driver has that name.
const DriverEntry* find_driver(std::string_view name) noexcept;

// Creates (does not open) the configured source. Throws Error for an unknown driver.
std::unique_ptr<MarkerSource> make_source(const SourceConfig& config, const SourceContext& context);

}  // namespace facecap::drivers
