#include "tools/shape_map.hpp"

#include <algorithm>

#include <fmt/format.h>

#include "core/error.hpp"
#include "core/io.hpp"
#include "core/toml_reader.hpp"

namespace facecap::tools {
namespace {

// Levenshtein distance, for "did you mean" hints.
std::size_t edit_distance(std::string_view a, std::string_view b) {
  std::vector<std::size_t> row(b.size() + 1);
  for (std::size_t j = 0; j <= b.size(); ++j) row[j] = j;
  for (std::size_t i = 1; i <= a.size(); ++i) {
    std::size_t diagonal = row[0];
    row[0] = i;
    for (std::size_t j = 1; j <= b.size(); ++j) {
      const std::size_t above = row[j];
      row[j] = std::min({row[j] + 1, row[j - 1] + 1, diagonal + (a[i - 1] == b[j - 1] ? 0 : 1)});
      diagonal = above;
    }
  }
  return row[b.size()];
}

template <typename Names>
std::string closest(std::string_view name, const Names& candidates) {
  std::string best;
  std::size_t best_distance = std::string::npos;
  for (const auto& candidate : candidates) {
    const std::size_t d = edit_distance(name, candidate);
    if (d < best_distance) {
      best_distance = d;
      best = std::string(candidate);
    }
  }
  return best;
}

}  // namespace

ShapeMap parse_shape_map(std::string_view text, const std::string& name) {
  const toml::table table = parse_toml(text, name);
  ShapeMap map{.file = name, .entries = {}};
  std::vector<std::string_view> arkit_names;
  for (const auto& shape : formats::kArkitShapes) arkit_names.push_back(shape.arkit);
  for (const auto& entry : table) {
    const auto& key = entry.first;  // not a structured binding: clang 14 cannot capture one
    const auto& value = entry.second;
    const auto& at = value.source().begin;
    auto fail = [&](std::string what) {
      return Error(std::move(what), ErrorLocation{.file = name, .line = at.line, .column = at.column,
                                                  .key = std::string(key.str())});
    };
    if (key.str().empty()) throw fail("a rig shape name is empty");
    const auto* arkit = value.as_string();
    if (!arkit) throw fail("the value must be an ARKit shape name in quotes (\"JawOpen\")");
    const auto index = formats::arkit_shape_index(arkit->get());
    if (!index)
      throw fail(fmt::format("'{}' is not an ARKit shape name (did you mean '{}'?)", arkit->get(),
                             closest(arkit->get(), arkit_names)));
    map.entries.push_back({std::string(key.str()), *index, at.line, at.column});
  }
  if (map.entries.empty()) throw Error("the map names no shapes (lines like \"Jaw_Open\" = \"JawOpen\")", ErrorLocation{.file = name});
  return map;
}

ShapeMap read_shape_map(const std::filesystem::path& path) {
  const std::vector<char> bytes = read_file_bytes(path);
  return parse_shape_map(std::string_view(bytes.data(), bytes.size()), path.string());
}

std::array<std::vector<std::size_t>, formats::kArkitShapeCount> bind_shape_map(
    const ShapeMap& map, std::span<const std::string> rig_shape_names) {
  std::array<std::vector<std::size_t>, formats::kArkitShapeCount> binding;
  for (const ShapeMapEntry& entry : map.entries) {
    const auto it = std::find(rig_shape_names.begin(), rig_shape_names.end(), entry.rig_shape);
    if (it == rig_shape_names.end())
      throw Error(fmt::format("the rig has no shape '{}' (did you mean '{}'?)", entry.rig_shape,
                              closest(entry.rig_shape, rig_shape_names)),
                  ErrorLocation{.file = map.file, .line = entry.line, .column = entry.column, .key = entry.rig_shape});
    binding[entry.arkit_index].push_back(std::size_t(it - rig_shape_names.begin()));
  }
  return binding;
}

}  // namespace facecap::tools
