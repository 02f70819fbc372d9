#pragma once
// The declarative schema of facecapd.toml: one row per key with its type, default, unit,
// range, choices, reload behaviour and description. Validation, `--print-config`, the
// shipped config/facecapd.toml and docs/config.md all come from this one table.
#include <cstdint>
#include <limits>
#include <span>
#include <string>
#include <string_view>
#include <variant>
#include <vector>

#include "config/daemon_config.hpp"

namespace facecap::config {

// A key whose value is one of an enum table's rows (core/enum_table.hpp): written and
// read as the row's name, stored as the enum.
struct ChoiceField {
  std::string_view (*get)(const DaemonConfig&);
  bool (*set)(DaemonConfig&, std::string_view name);  // false: not a row's name
  std::vector<Choice> (*choices)();
};

// The member of DaemonConfig a key sets; its type is the key's type (an int member, as the
// solver's parameters have, is an integer key read and written as int64_t).
using Field = std::variant<bool& (*)(DaemonConfig&), int64_t& (*)(DaemonConfig&), double& (*)(DaemonConfig&),
                           std::string& (*)(DaemonConfig&), std::vector<int64_t>& (*)(DaemonConfig&), ChoiceField,
                           int& (*)(DaemonConfig&)>;
// A choice's value is its name.
using Value = std::variant<bool, int64_t, double, std::string, std::vector<int64_t>>;

enum class ValueType : uint8_t { kBool, kInt, kFloat, kString, kIntList, kChoice };
std::string_view value_type_name(ValueType type) noexcept;  // "boolean", "integer", ...

// What SIGHUP does when the key changed.
enum class Reload : uint8_t {
  kLive,     // applied at once
  kRebuild,  // a new solver is built aside and swapped in between frames
  kRestart,  // kept until facecapd restarts (logged)
};

inline constexpr double kUnbounded = std::numeric_limits<double>::infinity();

struct KeySpec {
  std::string_view path;  // "loop.rate_hz"
  Field field;
  Value default_value;
  std::string_view unit;  // "Hz", "mm", "s", ... or empty
  double min = -kUnbounded;  // numeric keys and list elements
  double max = kUnbounded;
  Reload reload = Reload::kRestart;
  bool names_input_file = false;  // a path that must exist (unless empty or "builtin")
  std::string_view description;

  ValueType type() const noexcept;
  // The rows of a choice key; empty for other keys.
  std::vector<Choice> choices() const;
  std::string_view section() const noexcept;  // "loop" for "loop.rate_hz", "" for "version"
  std::string_view name() const noexcept;     // "rate_hz"
};

struct SectionSpec {
  std::string_view path;  // "outputs.shm"
  std::string_view description;
};

// In file order; keys of one section are contiguous.
std::span<const KeySpec> config_schema();
std::span<const SectionSpec> config_sections();

// nullptr when unknown.
const KeySpec* find_key(std::string_view path) noexcept;

// Every key at its default.
DaemonConfig default_config();

Value get_value(const KeySpec& key, const DaemonConfig& config);
void set_value(const KeySpec& key, DaemonConfig& config, const Value& value);

// The value as TOML text: true, 120, 120.0, "sim", [0, 1].
std::string format_value(const Value& value);

// "1 to 2000 Hz", "one of: sim, replay", "" when unrestricted.
std::string allowed_range(const KeySpec& key);

}  // namespace facecap::config
