#include "config/config_file.hpp"

#include <algorithm>
#include <cmath>
#include <filesystem>
#include <set>
#include <tuple>

#include <arpa/inet.h>
#include <sys/stat.h>
#include <fmt/format.h>
#include <net/if.h>
#include <netinet/in.h>
#include <toml++/toml.h>

#include "client/facecap_shm_layout.hpp"
#include "core/text_list.hpp"
#include "core/toml_reader.hpp"

namespace facecap::config {
namespace fs = std::filesystem;

namespace {

std::size_t key_index(const KeySpec& key) { return std::size_t(&key - config_schema().data()); }

// Line and column only where they mean something (not for --set overrides).
ErrorLocation location_of(const toml::node& node, const std::string& file, std::string_view key_path) {
  const auto& begin = node.source().begin;
  const bool positioned = file != "--set" && begin.line > 0;
  return ErrorLocation{.file = file, .line = positioned ? int64_t(begin.line) : -1,
                       .column = positioned ? int64_t(begin.column) : -1, .key = std::string(key_path)};
}

// "string \"fast\"", "integer 5", ... for messages.
std::string describe_node(const toml::node& node) {
  if (auto s = node.value<std::string>()) return fmt::format("string \"{}\"", *s);
  if (node.is_integer()) return fmt::format("integer {}", node.as_integer()->get());
  if (node.is_floating_point()) return fmt::format("number {}", node.as_floating_point()->get());
  if (node.is_boolean()) return fmt::format("boolean {}", node.as_boolean()->get());
  if (node.is_array()) return "an array";
  if (node.is_table()) return "a table";
  return "a date or time";
}

// Sections that moved: the old path is still read, with a warning.
struct RenamedSection {
  std::string_view old_path, new_path;
};
constexpr RenamedSection kRenamedSections[] = {{"recording", "outputs.recording"}};

// Parent sections of every key ("outputs", "outputs.shm", ...).
const std::set<std::string, std::less<>>& section_paths() {
  static const std::set<std::string, std::less<>> sections = [] {
    std::set<std::string, std::less<>> out;
    for (const KeySpec& key : config_schema())
      for (std::string_view s = key.section(); !s.empty();) {
        out.emplace(s);
        const auto dot = s.rfind('.');
        s = dot == std::string_view::npos ? std::string_view() : s.substr(0, dot);
      }
    return out;
  }();
  return sections;
}

// Whether an IP address literal is loopback (127.0.0.0/8, ::1); nullopt when it is not one.
std::optional<bool> is_loopback_address(const std::string& address) {
  in_addr v4{};
  if (inet_pton(AF_INET, address.c_str(), &v4) == 1) return (ntohl(v4.s_addr) >> 24) == 127;
  in6_addr v6{};
  if (inet_pton(AF_INET6, address.c_str(), &v6) == 1) return IN6_IS_ADDR_LOOPBACK(&v6) != 0;
  return std::nullopt;
}

std::size_t edit_distance(std::string_view a, std::string_view b) {
  std::vector<std::size_t> row(b.size() + 1);
  for (std::size_t j = 0; j <= b.size(); ++j) row[j] = j;
  for (std::size_t i = 1; i <= a.size(); ++i) {
    std::size_t diagonal = row[0];
    row[0] = i;
    for (std::size_t j = 1; j <= b.size(); ++j) {
      const std::size_t substitution = diagonal + (a[i - 1] == b[j - 1] ? 0 : 1);
      diagonal = row[j];
      row[j] = std::min({row[j] + 1, row[j - 1] + 1, substitution});
    }
  }
  return row[b.size()];
}

class Loader {
 public:
  explicit Loader(LoadedConfig& out) : out_(out) {}

  void apply_table(const toml::table& table, const std::string& prefix, Origin origin, const std::string& file,
                   const fs::path& base_dir) {
    for (const auto& [name, node] : table) {
      const std::string path = prefix.empty() ? std::string(name.str()) : prefix + "." + std::string(name.str());
      const ErrorLocation where = location_of(node, file, path);
      const auto renamed = std::find_if(std::begin(kRenamedSections), std::end(kRenamedSections),
                                        [&](const RenamedSection& r) { return r.old_path == path; });
      if (renamed != std::end(kRenamedSections) && node.is_table()) {
        out_.warnings.push_back(fmt::format("{}: [{}] is now [{}]; the old name still works but is deprecated",
                                            where.to_string(), renamed->old_path, renamed->new_path));
        apply_table(*node.as_table(), std::string(renamed->new_path), origin, file, base_dir);
        continue;
      }
      if (const KeySpec* key = find_key(path)) {
        apply_value(*key, node, origin, where, base_dir);
      } else if (section_paths().count(path)) {
        if (const toml::table* sub = node.as_table()) apply_table(*sub, path, origin, file, base_dir);
        else problem(where, fmt::format("[{}] is a section and must be a table, not {}", path, describe_node(node)));
      } else {
        unknown_key(path, prefix, std::string(name.str()), where);
      }
    }
  }

  // Every input file named must exist (checked even when other keys have problems).
  void check_input_files() {
    for (const KeySpec& key : config_schema()) {
      if (!key.names_input_file) continue;
      const std::string value = std::get<std::string>(get_value(key, out_.values));
      if (value.empty() || value == "builtin") continue;
      std::error_code ec;
      if (!fs::exists(value, ec)) problem(where(key), fmt::format("\"{}\" does not exist", value));
    }
    // Secrets, like ssh's keys: refused when others may read them.
    const HttpSection& http = out_.values.control.http;
    const struct {
      const char* key;
      const std::string* path;
      const char* holds;
    } secrets[] = {{"control.http.token_file", &http.token_file, "a token"},
                   {"control.http.viewer_token_file", &http.viewer_token_file, "a token"},
                   {"control.http.tls_key", http.enabled && http.tls ? &http.tls_key : nullptr, "the TLS private key"}};
    for (const auto& secret : secrets) {
      struct stat info {};
      if (!secret.path || secret.path->empty() || ::stat(secret.path->c_str(), &info) != 0 || (info.st_mode & 077) == 0) continue;
      problem(where(secret.key), fmt::format("\"{}\" holds {} but group or others may access it (mode {:04o}): chmod 600 it",
                                             *secret.path, secret.holds, info.st_mode & 07777));
    }
    if (http.enabled && http.tls) {
      std::error_code ec;
      const bool certificate = fs::exists(http.tls_certificate, ec), key = fs::exists(http.tls_key, ec);
      if (certificate != key)
        problem(where(certificate ? "control.http.tls_key" : "control.http.tls_certificate"),
                fmt::format("\"{}\" does not exist but \"{}\" does: give both, or remove both to have a new pair made at start",
                            certificate ? http.tls_key : http.tls_certificate, certificate ? http.tls_certificate : http.tls_key));
    }
  }

  // Rules that involve more than one key.
  void check_across_keys() {
    const DaemonConfig& c = out_.values;
    if (!drivers::driver_built(c.source.driver))
      problem(where("source.driver"), fmt::format("the {} driver is not built into this facecapd", drivers::kDriverIds.name(c.source.driver)));
    if (c.source.driver == drivers::DriverId::kReplay && c.source.replay.file.empty())
      problem(where("source.replay.file"), "source.driver is \"replay\" but no file is given");
    if (c.source.driver == drivers::DriverId::kV4l2 && c.source.v4l2.calibration.empty())
      problem(where("source.v4l2.calibration"), "source.driver is \"v4l2\" but no camera calibration is given");
    if (c.source.driver == drivers::DriverId::kV4l2 && c.source.v4l2.devices.empty())
      problem(where("source.v4l2.devices"), "source.driver is \"v4l2\" but no camera devices are named");
    if (c.source.v4l2.min_blob_area_px > c.source.v4l2.max_blob_area_px)
      problem(where("source.v4l2.min_blob_area_px"),
              fmt::format("{} is above source.v4l2.max_blob_area_px ({})", c.source.v4l2.min_blob_area_px,
                          c.source.v4l2.max_blob_area_px));
    if (c.source.replay.end_s != 0.0 && c.source.replay.end_s <= c.source.replay.start_s)
      problem(where("source.replay.end_s"),
              fmt::format("{} must be after source.replay.start_s ({}) or 0 for the end of the take",
                          format_value(c.source.replay.end_s), format_value(c.source.replay.start_s)));
    const drivers::NatNetOptions& natnet = c.source.natnet;
    for (const auto& [key, value] : {std::pair{"source.natnet.server_address", natnet.server_address},
                                     std::pair{"source.natnet.discovery_address", natnet.discovery_address},
                                     std::pair{"source.natnet.multicast_group", natnet.multicast_group}}) {
      in_addr address{};
      if (!value.empty() && inet_pton(AF_INET, value.c_str(), &address) != 1)
        problem(where(key), fmt::format("\"{}\" is not an IPv4 address (like 10.0.0.5)", value));
      else if (!value.empty() && std::string_view(key) == "source.natnet.multicast_group" && !IN_MULTICAST(ntohl(address.s_addr)))
        problem(where(key), fmt::format("\"{}\" is not a multicast address (224.0.0.0 to 239.255.255.255)", value));
    }
    if (c.source.driver == drivers::DriverId::kNatNet && natnet.marker_set.empty() && natnet.unlabelled_markers == 0)
      problem(where("source.natnet.marker_set"), "the natnet driver needs a marker set to take, or unlabelled points "
                                                 "(source.natnet.unlabelled_markers > 0)");
    if (c.loop.mode == LoopMode::kLockstep && !drivers::supports_lockstep(c.source.driver))
      problem(where("loop.mode"), fmt::format("lockstep needs a source that can hand every frame on request; the {} "
                                              "driver runs on its own clock (use mode = \"fixed\")",
                                              drivers::kDriverIds.name(c.source.driver)));
    if (!solver_method_is_realtime(c.solver.method) && c.loop.mode == LoopMode::kFixed)
      problem(where("solver.method"),
              fmt::format("{0} is an offline baseline that takes seconds a frame and cannot keep a fixed-rate loop: use "
                          "\"nonlinear\" live, or {0} with loop.mode = \"lockstep\" and a replay (or `facecap solve "
                          "--set solver.method={0}`)", kSolverMethods.name(c.solver.method)));
    if (c.calibration.file.empty() && (c.calibration.head_markers == 1 || c.calibration.head_markers == 2))
      problem(where("calibration.head_markers"),
              fmt::format("{} head markers cannot fix a rigid pose: use 0 (no stabilisation) or at least 3",
                          c.calibration.head_markers));
    if (c.outputs.shm.enabled && !shm::valid_name(c.outputs.shm.name))
      problem(where("outputs.shm.name"), fmt::format("\"{}\" is not a valid name (1 to 200 of A-Z a-z 0-9 - _ .)",
                                                     c.outputs.shm.name));
    if (c.outputs.recording.enabled && c.outputs.recording.directory.empty())
      problem(where("outputs.recording.directory"), "recording is enabled but no directory is given");
    check_network_output("udp", c.outputs.udp);
    check_network_output("vmc", c.outputs.vmc);
    check_network_output("livelink", c.outputs.livelink);
    if (c.outputs.udp.enabled && !c.outputs.udp.multicast_interface.empty() &&
        if_nametoindex(c.outputs.udp.multicast_interface.c_str()) == 0)
      problem(where("outputs.udp.multicast_interface"),
              fmt::format("this machine has no network interface \"{}\"", c.outputs.udp.multicast_interface));
    if (c.outputs.vmc.enabled && c.outputs.vmc.names == VmcNames::kMap && c.outputs.vmc.map_file.empty())
      problem(where("outputs.vmc.map_file"), "outputs.vmc.names is \"map\" but no map file is given");
    if (c.outputs.livelink.enabled && (c.outputs.livelink.subject_name.empty() || c.outputs.livelink.subject_name.size() > 255))
      problem(where("outputs.livelink.subject_name"), "the subject name must be 1 to 255 bytes");
    if (c.outputs.livelink.enabled && c.outputs.livelink.device_id.size() > 255)
      problem(where("outputs.livelink.device_id"), "the device id must be at most 255 bytes");
    if (c.control.http.enabled) {
      const std::optional<bool> loopback = is_loopback_address(c.control.http.address);
      if (!loopback)
        problem(where("control.http.address"),
                fmt::format("\"{}\" is not an IPv4 or IPv6 address", c.control.http.address));
      else if (!*loopback && c.control.http.token_file.empty())
        problem(where("control.http.token_file"),
                fmt::format("the control API listens on {}, which is not loopback: a bearer token is required "
                            "(set control.http.token_file)", c.control.http.address));
      if (!c.control.http.viewer_token_file.empty() && c.control.http.token_file.empty())
        problem(where("control.http.viewer_token_file"),
                "a viewer's token needs the operator's (control.http.token_file): without it every client is the operator");
      for (const std::string& origin : split_list(c.control.http.allowed_origins, kListSeparators))
        if (!(origin.starts_with("http://") || origin.starts_with("https://")) ||
            origin.find('/', origin.find("//") + 2) != std::string::npos)
          problem(where("control.http.allowed_origins"),
                  fmt::format("\"{}\" is not an origin (scheme://host[:port], no path, as in http://tablet.lan:8080)", origin));
      for (const std::string& host : split_list(c.control.http.allowed_hosts, kListSeparators))
        if (host.find_first_of(":/[]@") != std::string::npos)
          problem(where("control.http.allowed_hosts"),
                  fmt::format("\"{}\" is not a host name (no port, scheme or path: stage-box.local)", host));
    }
    const QualitySection& q = c.quality;
    if (q.markers_used_bad > q.markers_used_degraded)
      problem(where("quality.markers_used_bad"), "must not be above quality.markers_used_degraded");
    if (q.head_held_bad < q.head_held_degraded)
      problem(where("quality.head_held_bad"), "must not be below quality.head_held_degraded");
    if (q.residual_p95_bad_mm < q.residual_p95_degraded_mm)
      problem(where("quality.residual_p95_bad_mm"), "must not be below quality.residual_p95_degraded_mm");
  }

  // An enabled network output needs an address it can send to.
  void check_network_output(std::string_view name, const NetworkOutput& output) {
    if (!output.enabled) return;
    unsigned char parsed[sizeof(in6_addr)];
    if (inet_pton(AF_INET, output.address.c_str(), parsed) != 1 && inet_pton(AF_INET6, output.address.c_str(), parsed) != 1)
      problem(where(fmt::format("outputs.{}.address", name)),
              fmt::format("\"{}\" is not a numeric IPv4 or IPv6 address", output.address));
  }

  void problem(ErrorLocation where, std::string what) { problems_.emplace_back(std::move(what), std::move(where)); }
  std::vector<Error>& problems() { return problems_; }

 private:
  ErrorLocation where(const KeySpec& key) const {
    ErrorLocation loc = out_.origins[key_index(key)].where;
    loc.key = std::string(key.path);
    if (loc.file.empty()) loc.file = out_.file.empty() ? "defaults" : out_.file + " (default)";
    return loc;
  }
  ErrorLocation where(std::string_view path) const { return where(*find_key(path)); }

  void unknown_key(const std::string& path, const std::string& prefix, const std::string& name, ErrorLocation where) {
    // Siblings first (a typo inside the right section), then every key and section path.
    std::vector<std::string> siblings, everything;
    for (const KeySpec& key : config_schema()) {
      if (key.section() == prefix) siblings.emplace_back(key.name());
      everything.emplace_back(key.path);
    }
    for (const auto& s : section_paths()) {
      everything.push_back(s);
      const auto dot = s.rfind('.');
      if ((dot == std::string::npos ? std::string() : s.substr(0, dot)) == prefix)
        siblings.push_back(dot == std::string::npos ? s : s.substr(dot + 1));
    }
    const std::string where_text = prefix.empty() ? "at the top level" : fmt::format("in [{}]", prefix);
    std::string hint;
    if (auto near = closest_match(name, siblings); !near.empty()) hint = fmt::format("; did you mean '{}'?", near);
    else if (auto near_path = closest_match(path, everything); !near_path.empty())
      hint = fmt::format("; did you mean '{}'?", near_path);
    problem(std::move(where), fmt::format("unknown key '{}' {}{}", name, where_text, hint));
  }

  void apply_value(const KeySpec& key, const toml::node& node, Origin origin, const ErrorLocation& where,
                   const fs::path& base_dir) {
    std::optional<Value> value = convert(key, node, where);
    if (!value) return;
    if (key.names_input_file && origin == Origin::kFile) {
      auto& text = std::get<std::string>(*value);
      if (!text.empty() && text != "builtin" && fs::path(text).is_relative()) text = (base_dir / text).lexically_normal().string();
    }
    set_value(key, out_.values, *value);
    out_.origins[key_index(key)] = KeyOrigin{origin, where};
  }

  std::optional<Value> convert(const KeySpec& key, const toml::node& node, const ErrorLocation& where) {
    auto wrong_type = [&] {
      const std::string_view type = value_type_name(key.type());
      const char* article = type.front() == 'a' || type.front() == 'i' ? "an" : "a";
      problem(where, fmt::format("expected {} {}, got {}", article, type, describe_node(node)));
      return std::nullopt;
    };
    switch (key.type()) {
      case ValueType::kBool:
        if (auto v = node.value_exact<bool>()) return Value(*v);
        return wrong_type();
      case ValueType::kInt:
        if (auto v = node.value_exact<int64_t>()) {
          if (!check_range(key, double(*v), fmt::format("{}", *v), where)) return std::nullopt;
          return Value(*v);
        }
        return wrong_type();
      case ValueType::kFloat: {
        std::optional<double> v;
        if (node.is_floating_point()) v = node.as_floating_point()->get();
        else if (node.is_integer()) v = double(node.as_integer()->get());  // `rate_hz = 120` is fine
        if (!v) return wrong_type();
        if (!std::isfinite(*v)) {
          problem(where, fmt::format("{} is not a finite number (allowed: {})", *v, allowed_range(key)));
          return std::nullopt;
        }
        if (!check_range(key, *v, format_value(*v), where)) return std::nullopt;
        return Value(*v);
      }
      case ValueType::kString: {
        auto v = node.value_exact<std::string>();
        if (!v) return wrong_type();
        return Value(*v);
      }
      case ValueType::kChoice: {
        auto v = node.value_exact<std::string>();
        if (!v) return wrong_type();
        std::vector<std::string> names;
        for (const Choice& c : key.choices()) names.emplace_back(c.name);
        if (std::find(names.begin(), names.end(), *v) == names.end()) {
          const std::string near = closest_match(*v, names);
          problem(where, fmt::format("\"{}\" is not allowed (allowed: {}){}", *v, allowed_range(key),
                                     near.empty() ? "" : fmt::format("; did you mean \"{}\"?", near)));
          return std::nullopt;
        }
        return Value(*v);
      }
      case ValueType::kIntList: {
        const toml::array* array = node.as_array();
        if (!array) return wrong_type();
        std::vector<int64_t> out;
        for (const toml::node& element : *array) {
          auto v = element.value_exact<int64_t>();
          if (!v) {
            problem(location_of(element, where.file, where.key),
                    fmt::format("expected an integer in the array, got {}", describe_node(element)));
            return std::nullopt;
          }
          if (!check_range(key, double(*v), fmt::format("{}", *v), location_of(element, where.file, where.key)))
            return std::nullopt;
          out.push_back(*v);
        }
        return Value(std::move(out));
      }
    }
    return std::nullopt;
  }

  bool check_range(const KeySpec& key, double v, const std::string& text, const ErrorLocation& where) {
    if (v >= key.min && v <= key.max) return true;
    problem(where, fmt::format("{} is out of range (allowed: {})", text, allowed_range(key)));
    return false;
  }

  LoadedConfig& out_;
  std::vector<Error> problems_;
};

std::string compose(const std::vector<Error>& problems) {
  std::string text;
  for (const Error& e : problems) text += (text.empty() ? "" : "\n") + std::string(e.what());
  return text;
}

// A --set override as TOML ("loop.rate_hz=240"); a string key's value may lack quotes.
toml::table parse_override(const std::string& text, Loader& loader) {
  const auto eq = text.find('=');
  if (eq == std::string::npos) {
    loader.problem({.file = "--set"}, fmt::format("override \"{}\" must look like key=value", text));
    return {};
  }
  std::string key = text.substr(0, eq), value = text.substr(eq + 1);
  auto trim = [](std::string& s) {
    s.erase(0, s.find_first_not_of(" \t"));
    s.erase(s.find_last_not_of(" \t") + 1);
  };
  trim(key);
  trim(value);
  try {
    return toml::parse(std::string_view(key + " = " + value), std::string_view("--set"));
  } catch (const toml::parse_error&) {
    const KeySpec* spec = find_key(key);
    if (spec && (spec->type() == ValueType::kString || spec->type() == ValueType::kChoice)) {
      // The same nesting TOML gives a dotted key.
      toml::table table;
      toml::table* at = &table;
      std::size_t start = 0;
      for (std::size_t dot = key.find('.'); dot != std::string::npos; start = dot + 1, dot = key.find('.', start))
        at = at->emplace<toml::table>(key.substr(start, dot - start)).first->second.as_table();
      at->insert_or_assign(key.substr(start), value);
      return table;
    }
    loader.problem({.file = "--set", .key = key}, fmt::format("cannot parse the value of override \"{}\"", text));
    return {};
  }
}

}  // namespace

const KeyOrigin& LoadedConfig::origin_of(std::string_view key_path) const {
  const KeySpec* key = find_key(key_path);
  if (!key) throw Error(fmt::format("no config key '{}'", key_path));
  return origins.at(key_index(*key));
}

ConfigError::ConfigError(std::vector<Error> problems) : Error(compose(problems)), problems_(std::move(problems)) {}

std::string closest_match(std::string_view word, const std::vector<std::string>& candidates) {
  std::string best;
  std::size_t best_distance = std::string::npos;
  for (const auto& c : candidates) {
    const std::size_t d = edit_distance(word, c);
    if (d < best_distance) {
      best_distance = d;
      best = c;
    }
  }
  // Close enough to be a typo: at most a third of the word, and at least 1 edit allowed.
  const std::size_t limit = std::max<std::size_t>(1, (word.size() + 2) / 3);
  return best_distance <= limit ? best : std::string();
}

namespace {

// Defaults, then `read` (which applies a file or text, or nothing), then the overrides,
// then the checks. Throws ConfigError with every problem.
template <typename Read>
LoadedConfig load(const std::string& name, const std::vector<std::string>& overrides, Checks checks, Read&& read) {
  LoadedConfig out;
  out.values = default_config();
  out.origins.resize(config_schema().size());
  out.file = name;
  Loader loader(out);
  read(loader);
  for (const std::string& text : overrides)
    loader.apply_table(parse_override(text, loader), "", Origin::kCommandLine, "--set", fs::current_path());
  if (checks == Checks::kAll) {
    loader.check_input_files();
    if (loader.problems().empty()) loader.check_across_keys();
  }
  if (!loader.problems().empty()) {
    auto& problems = loader.problems();
    std::stable_sort(problems.begin(), problems.end(), [](const Error& a, const Error& b) {
      return std::tie(a.where().file, a.where().line) < std::tie(b.where().file, b.where().line);
    });
    throw ConfigError(std::move(problems));
  }
  return out;
}

}  // namespace

LoadedConfig load_config(const std::string& file, const std::vector<std::string>& overrides, Checks checks) {
  return load(file, overrides, checks, [&](Loader& loader) {
    if (file.empty()) return;
    try {
      const toml::table table = parse_toml_file(file);
      loader.apply_table(table, "", Origin::kFile, file, fs::path(file).parent_path());
    } catch (const Error& e) {
      loader.problem(e.where(), e.message());
    }
  });
}

LoadedConfig load_config_text(std::string_view text, const std::string& name, const std::vector<std::string>& overrides,
                              Checks checks) {
  return load(name, overrides, checks, [&](Loader& loader) {
    try {
      const toml::table table = parse_toml(text, name);
      loader.apply_table(table, "", Origin::kFile, name, fs::current_path());
    } catch (const Error& e) {
      loader.problem(e.where(), e.message());
    }
  });
}


namespace {

// Comment lines of at most `width` columns.
std::string comment_block(std::string_view text, std::size_t width = 88) {
  std::string out, line = "#";
  std::size_t start = 0;
  while (start < text.size()) {
    std::size_t end = text.find(' ', start);
    if (end == std::string_view::npos) end = text.size();
    const std::string_view word = text.substr(start, end - start);
    if (line.size() + 1 + word.size() > width && line != "#") {
      out += line + "\n";
      line = "#";
    }
    line += " ";
    line += word;
    start = end + 1;
  }
  return out + line + "\n";
}

// The description, then one line with the allowed values and what SIGHUP does.
std::string key_notes(const KeySpec& key) {
  std::string facts;
  if (const std::string range = allowed_range(key); !range.empty()) facts = fmt::format("Allowed: {}.", range);
  else if (!key.unit.empty()) facts = fmt::format("Unit: {}.", key.unit);
  switch (key.reload) {
    case Reload::kLive: facts += " SIGHUP applies a change at once."; break;
    case Reload::kRebuild: facts += " SIGHUP rebuilds the solver with a change."; break;
    case Reload::kRestart: break;
  }
  std::string out = comment_block(key.description);
  for (const Choice& c : key.choices())
    if (!c.description.empty()) out += comment_block(fmt::format("  {}: {}.", c.name, c.description));
  if (!facts.empty()) out += comment_block(facts.front() == ' ' ? facts.substr(1) : facts);
  return out;
}

std::string_view section_description(std::string_view path) {
  for (const SectionSpec& s : config_sections())
    if (s.path == path) return s.description;
  return {};
}

}  // namespace

std::string render_documented_defaults() {
  std::string out =
      "# facecapd configuration: every key at its default, with what it does.\n"
      "# Generated from the schema in config/schema.cpp by `facecapd --print-default-config`;\n"
      "# tests check that this file matches it. Keys marked \"SIGHUP ...\" can change while\n"
      "# running (systemctl reload facecapd); any other change needs a restart.\n"
      "# Check a file with `facecapd --check-config FILE`; see its effective values with\n"
      "# `facecapd --config FILE --print-config`.\n";
  const DaemonConfig defaults = default_config();
  std::string_view section = "\x01";
  for (const KeySpec& key : config_schema()) {
    if (key.section() != section) {
      section = key.section();
      out += "\n";
      if (!section.empty()) out += comment_block(section_description(section)) + fmt::format("[{}]\n", section);
    }
    out += key_notes(key);
    out += fmt::format("{} = {}\n", key.name(), format_value(get_value(key, defaults)));
  }
  return out;
}

std::string render_effective_config(const LoadedConfig& config) {
  std::string out = fmt::format("# facecapd effective configuration{}\n",
                                config.file.empty() ? " (defaults only)" : fmt::format(" from {}", config.file));
  std::string_view section = "\x01";
  for (const KeySpec& key : config_schema()) {
    if (key.section() != section) {
      section = key.section();
      if (!section.empty()) out += fmt::format("\n[{}]\n", section);
    }
    const KeyOrigin& origin = config.origins[key_index(key)];
    std::string from = "default";
    if (origin.origin == Origin::kFile) from = fmt::format("file {}:{}", origin.where.file, origin.where.line);
    if (origin.origin == Origin::kCommandLine) from = "--set";
    const std::string line = fmt::format("{} = {}", key.name(), format_value(get_value(key, config.values)));
    out += fmt::format("{:<48} # {}\n", line, from);
  }
  return out;
}

std::string render_markdown_reference() {
  auto cell = [](std::string text) {
    for (std::size_t at = text.find('|'); at != std::string::npos; at = text.find('|', at + 2)) text.replace(at, 1, "\\|");
    return text;
  };
  std::string out;
  std::string_view section = "\x01";
  for (const KeySpec& key : config_schema()) {
    if (key.section() != section) {
      section = key.section();
      out += fmt::format("\n### {}\n\n", section.empty() ? "top level" : fmt::format("[{}]", section));
      if (const auto d = section_description(section); !d.empty()) out += fmt::format("{}\n\n", d);
      out += "| key | type | default | allowed | SIGHUP | description |\n|---|---|---|---|---|---|\n";
    }
    std::string allowed = allowed_range(key);
    if (allowed.empty() && !key.unit.empty()) allowed = std::string(key.unit);
    const char* reload = key.reload == Reload::kLive ? "applied" : key.reload == Reload::kRebuild ? "rebuilds solver" : "restart";
    std::string description(key.description);
    for (const Choice& c : key.choices())
      if (!c.description.empty()) description += fmt::format("<br>`{}`: {}.", c.name, c.description);
    out += fmt::format("| `{}` | {} | `{}` | {} | {} | {} |\n", key.name(), value_type_name(key.type()),
                       cell(format_value(key.default_value)), cell(allowed), reload, cell(description));
  }
  return out;
}

std::vector<const KeySpec*> changed_keys(const DaemonConfig& before, const DaemonConfig& after) {
  std::vector<const KeySpec*> changed;
  for (const KeySpec& key : config_schema())
    if (get_value(key, before) != get_value(key, after)) changed.push_back(&key);
  return changed;
}

}  // namespace facecap::config
