#pragma once
// The operator dashboard's files (docs/dashboard.md), served by the control API at `/`
// from one directory: a request path is percent-decoded and refused (404) when any of
// its segments is "." or "..", holds a NUL or a backslash, or when the file it names,
// symbolic links resolved, is not inside the directory. Not real-time code (the I/O
// thread reads the file).
#include <string>
#include <string_view>

#include "control/api.hpp"

namespace facecap::control {

// The response to a GET of `path` (without its query) under `directory`: the
// file with its media type, `index.html` for a path ending in '/', or a 404 HTML page
// saying what is missing (the whole dashboard when `directory` is empty or absent).
HttpResponse serve_static_file(const HttpRequest& request, std::string_view path, const std::string& directory,
                               std::string_view server);

// The file a request path names under `directory` ("" when it names none: a ".." or "."
// segment, a NUL, a backslash, bad percent-encoding, or a place outside the directory).
std::string resolve_static_path(std::string_view path, const std::string& directory);

}  // namespace facecap::control
