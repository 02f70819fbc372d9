#pragma once
// The one way facecap reads TOML (facecapd config, calibration files and profiles, rig
// manifests): the text is checked to be UTF-8 first, because toml++ 3.3 reaches undefined
// behaviour on some invalid sequences, and every failure becomes an Error at file:line:col.
// Not real-time.
#include <filesystem>
#include <string>
#include <string_view>

#include <toml++/toml.h>

namespace facecap {

// Throws Error at file:line:col (column in characters) of the first byte that does not
// belong to well-formed UTF-8 (RFC 3629: no overlong forms, surrogates or values past
// U+10FFFF).
void check_utf8(std::string_view text, const std::string& name);

// Parses TOML text; `name` labels errors. Throws Error, also for a non-ASCII character
// outside strings and comments (invalid TOML, on which toml++ 3.3 reaches undefined
// behaviour).
toml::table parse_toml(std::string_view text, const std::string& name);
// Reads and parses a file (read_file_bytes: a directory or unreadable file is an Error).
toml::table parse_toml_file(const std::filesystem::path& path);

}  // namespace facecap
