#pragma once
// The one ordered table of the marker source drivers this build contains. Adding a driver
// is a row here, an id in drivers/api/driver_id.hpp, its options in
// drivers/api/source_config.hpp and config/schema.cpp, and its own target under drivers/
// (docs/architecture.md, "Adding a driver"); nothing registers itself.
#include <memory>
#include <span>
#include <string>
#include <string_view>

#include "drivers/api/driver_id.hpp"
#include "drivers/api/marker_source.hpp"
#include "drivers/api/source_config.hpp"
#include "solver/marker_layout.hpp"
#include "solver/rig.hpp"

namespace facecap::drivers {

// What a driver may use besides its own options: the rig being solved and the markers the
// calibration expects (the sim samples them on the posed rig; other drivers ignore them).
struct SourceContext {
  std::shared_ptr<const Rig> rig;
  MarkerSet markers;
};

struct DriverEntry {
  DriverId id;
  std::string_view needs;  // what it needs to run, for --list-drivers and its errors
  std::unique_ptr<MarkerSource> (*make)(const SourceConfig& config, const SourceContext& context);
  // Reads the files the driver would read when opened (facecapd --check-config); null when
  // it reads none. Returns what it found; throws Error.
  std::string (*check_files)(const SourceConfig& config) = nullptr;

  std::string_view name() const noexcept { return kDriverIds.name(id); }
};

// The built drivers, in the order of kDriverIds.
std::span<const DriverEntry> driver_table() noexcept;

// nullptr when the driver is not built.
const DriverEntry* find_driver(DriverId id) noexcept;

// Creates (does not open) the configured source. Throws Error for a driver this build
// lacks.
// The configured driver's check_files ("" when it reads no files). Throws Error.
std::string check_source_files(const SourceConfig& config);

std::unique_ptr<MarkerSource> make_source(const SourceConfig& config, const SourceContext& context);

}  // namespace facecap::drivers
