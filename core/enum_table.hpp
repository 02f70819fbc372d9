#pragma once
// A closed set of choices (solver method, collision region, loop mode, source driver, ...)
// declared once as a table of (value, name, description) rows. Parsing, printing, the
// configuration schema's list of allowed values and the documentation all read the same
// rows, so a choice cannot be accepted in one place and unknown in another.
//
//   enum class LoopMode : uint8_t { kFixed, kLockstep };
//   inline constexpr EnumTable kLoopModes{std::array{
//       EnumEntry{LoopMode::kFixed, "fixed", "solve the newest frame at every tick"},
//       EnumEntry{LoopMode::kLockstep, "lockstep", "solve every frame in order"}}};
//   kLoopModes.parse("fixed") == LoopMode::kFixed; kLoopModes.name(LoopMode::kLockstep) == "lockstep"
#include <array>
#include <cstddef>
#include <optional>
#include <span>
#include <string_view>
#include <vector>

namespace facecap {

template <typename E>
struct EnumEntry {
  E value;
  std::string_view name;         // as written in config files and on command lines
  std::string_view description;  // one sentence for --help, the schema and docs
};

// Spelled out for compilers without aggregate deduction (clang before 17).
template <typename E>
EnumEntry(E, std::string_view, std::string_view) -> EnumEntry<E>;

// A row without its type, for the config schema and documentation.
struct Choice {
  std::string_view name;
  std::string_view description;
};

template <typename E, std::size_t N>
class EnumTable {
 public:
  constexpr explicit EnumTable(std::array<EnumEntry<E>, N> entries) noexcept : entries_(entries) {}

  // The value named `name` (exact, case-sensitive), or nullopt. RT-safe.
  constexpr std::optional<E> parse(std::string_view name) const noexcept {
    for (const auto& entry : entries_)
      if (entry.name == name) return entry.value;
    return std::nullopt;
  }
  // The name of `value`; "?" for a value outside the table. RT-safe.
  constexpr std::string_view name(E value) const noexcept {
    for (const auto& entry : entries_)
      if (entry.value == value) return entry.name;
    return "?";
  }
  constexpr std::string_view description(E value) const noexcept {
    for (const auto& entry : entries_)
      if (entry.value == value) return entry.description;
    return {};
  }
  constexpr std::span<const EnumEntry<E>> entries() const noexcept { return entries_; }
  constexpr std::size_t size() const noexcept { return N; }

  // The rows' names in table order ("nonlinear, linear, dt"), for messages. Not RT-safe.
  std::vector<std::string_view> names() const {
    std::vector<std::string_view> out;
    for (const auto& entry : entries_) out.push_back(entry.name);
    return out;
  }
  std::vector<Choice> choices() const {
    std::vector<Choice> out;
    for (const auto& entry : entries_) out.push_back({entry.name, entry.description});
    return out;
  }

 private:
  std::array<EnumEntry<E>, N> entries_;
};

}  // namespace facecap
