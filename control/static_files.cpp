#include "control/static_files.hpp"

#include <filesystem>
#include <fstream>
#include <sstream>

#include <boost/beast/http/field.hpp>
#include <fmt/format.h>

namespace facecap::control {
namespace fs = std::filesystem;
namespace http = boost::beast::http;

namespace {

// Files larger than this are not served (the dashboard's largest is well under it).
constexpr std::uintmax_t kMaxStaticFileBytes = 16u << 20;

std::optional<std::string> percent_decode(std::string_view text) {
  std::string out;
  out.reserve(text.size());
  for (std::size_t i = 0; i < text.size(); ++i) {
    if (text[i] != '%') {
      out.push_back(text[i]);
      continue;
    }
    if (i + 2 >= text.size()) return std::nullopt;
    auto hex = [](char c) -> int {
      if (c >= '0' && c <= '9') return c - '0';
      if (c >= 'a' && c <= 'f') return c - 'a' + 10;
      if (c >= 'A' && c <= 'F') return c - 'A' + 10;
      return -1;
    };
    const int high = hex(text[i + 1]), low = hex(text[i + 2]);
    if (high < 0 || low < 0) return std::nullopt;
    out.push_back(char(high * 16 + low));
    i += 2;
  }
  return out;
}

std::string_view media_type(const fs::path& file) {
  const std::string extension = file.extension().string();
  if (extension == ".html") return "text/html; charset=utf-8";
  if (extension == ".js" || extension == ".mjs") return "text/javascript; charset=utf-8";
  if (extension == ".css") return "text/css; charset=utf-8";
  if (extension == ".json" || extension == ".map") return "application/json";
  if (extension == ".svg") return "image/svg+xml";
  if (extension == ".png") return "image/png";
  if (extension == ".ico") return "image/x-icon";
  if (extension == ".woff2") return "font/woff2";
  return "application/octet-stream";
}

std::string escape_html(std::string_view text) {
  std::string out;
  for (const char c : text) {
    if (c == '<') out += "&lt;";
    else if (c == '>') out += "&gt;";
    else if (c == '&') out += "&amp;";
    else if (c == '"') out += "&quot;";
    else out.push_back(c);
  }
  return out;
}

HttpResponse html_response(const HttpRequest& request, http::status status, std::string body, std::string_view server) {
  HttpResponse response{status, request.version()};
  response.set(http::field::server, std::string(server));
  response.set(http::field::content_type, "text/html; charset=utf-8");
  response.body() = std::move(body);
  response.keep_alive(request.keep_alive());
  response.prepare_payload();
  return response;
}

HttpResponse not_found(const HttpRequest& request, std::string_view title, std::string_view detail, std::string_view server) {
  return html_response(request, http::status::not_found,
                       fmt::format("<!doctype html>\n<html><head><meta charset=\"utf-8\"><title>facecapd: {0}</title></head>\n"
                                   "<body><h1>{0}</h1>\n<p>{1}</p>\n<p>The control API's routes are listed in "
                                   "docs/control-api.md; the dashboard in docs/dashboard.md.</p></body></html>\n",
                                   escape_html(title), escape_html(detail)),
                       server);
}

}  // namespace

std::string resolve_static_path(std::string_view path, const std::string& directory) {
  if (directory.empty() || path.empty() || path.front() != '/') return {};
  const std::optional<std::string> decoded = percent_decode(path);
  if (!decoded || decoded->find('\0') != std::string::npos || decoded->find('\\') != std::string::npos) return {};
  std::string relative = decoded->substr(1);
  if (relative.empty() || relative.back() == '/') relative += "index.html";
  std::size_t start = 0;
  while (start <= relative.size()) {
    const std::size_t end = std::min(relative.find('/', start), relative.size());
    const std::string_view segment = std::string_view(relative).substr(start, end - start);
    if (segment == "." || segment == ".." || (segment.empty() && end != relative.size())) return {};
    start = end + 1;
  }
  std::error_code ec;
  const fs::path root = fs::canonical(directory, ec);
  if (ec) return {};
  const fs::path file = fs::weakly_canonical(root / relative, ec);
  if (ec) return {};
  // Symbolic links resolved: the file must still be under the root.
  const auto [root_end, file_at] = std::mismatch(root.begin(), root.end(), file.begin(), file.end());
  if (root_end != root.end()) return {};
  return file.string();
}

HttpResponse serve_static_file(const HttpRequest& request, std::string_view path, const std::string& directory,
                               std::string_view server) {
  std::error_code ec;
  if (directory.empty() || !fs::is_directory(directory, ec))
    return not_found(request, "The dashboard is not installed",
                     directory.empty() ? std::string("This facecapd has no dashboard directory (control.http.dashboard_dir).")
                                       : fmt::format("{} does not exist: build the dashboard (it needs Node.js and npm) "
                                                     "or set control.http.dashboard_dir.",
                                                     directory),
                     server);
  const std::string file = resolve_static_path(path, directory);
  if (file.empty() || !fs::is_regular_file(file, ec))
    return not_found(request, "Not found", fmt::format("No file {} in the dashboard.", path), server);
  const std::uintmax_t size = fs::file_size(file, ec);
  if (ec || size > kMaxStaticFileBytes)
    return not_found(request, "Not found", fmt::format("{} cannot be served.", path), server);
  std::ifstream in(file, std::ios::binary);
  std::ostringstream bytes;
  bytes << in.rdbuf();
  if (!in) return not_found(request, "Not found", fmt::format("{} cannot be read.", path), server);
  HttpResponse response{http::status::ok, request.version()};
  response.set(http::field::server, std::string(server));
  response.set(http::field::content_type, std::string(media_type(file)));
  // Vite names its bundles by content hash; the pages themselves are re-read each time.
  response.set(http::field::cache_control, path.starts_with("/assets/") ? "max-age=31536000, immutable" : "no-cache");
  response.body() = std::move(bytes).str();
  response.keep_alive(request.keep_alive());
  response.prepare_payload();
  return response;
}

}  // namespace facecap::control
