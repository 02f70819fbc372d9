// The control API's request handling on bytes: Beast's HTTP parser with the server's
// limits, then the Host, Origin and Content-Type checks, tokens, login, session cookies
// and logout, routing, JSON bodies and the stream's query, as the I/O thread runs them
// (control/api.hpp, control/access.hpp). A queued command is answered at once, as the
// supervisor would, so that the reply path runs too. Nothing here may throw: the API
// answers every malformed request with a 4xx.
#include <boost/beast/core/flat_buffer.hpp>
#include <boost/beast/http/parser.hpp>

#include "control/api.hpp"
#include "fuzz/fuzz_support.hpp"

extern "C" int LLVMFuzzerTestOneInput(const uint8_t* data, size_t size) {
  using namespace facecap;
  namespace http = boost::beast::http;
  http::request_parser<http::string_body> parser;
  parser.header_limit(control::kMaxHeaderBytes);
  parser.body_limit(control::kMaxBodyBytes);
  parser.eager(true);
  boost::beast::error_code ec;
  parser.put(boost::asio::buffer(data, size), ec);
  if (!ec && !parser.is_done()) parser.put_eof(ec);
  if (ec || !parser.is_done()) return 0;  // the server answers these 400/413/431 and closes
  const control::HttpRequest request = parser.release();

  static control::StatusBoard board;
  static control::CommandQueue queue(1);
  // Inputs of odd length meet the tokens, the login and its sessions; seeds name Host x.
  control::ApiContext context{board, queue, "fuzz"};
  context.access.allowed_hosts = {"x"};
  context.access.allowed_origins = {"http://x"};
  if (size % 2) {
    context.access.operator_token = "s3cret";
    context.access.viewer_token = "v1ewer";
  }
  auto handle = [&](const control::HttpRequest& r) {
    std::optional<control::HttpResponse> later;
    auto response = control::handle_request(r, context, [&](control::HttpResponse answer) { later = std::move(answer); }, "fuzz");
    if (!response) {
      std::optional<control::Command> command = queue.pop();
      if (command) command->reply({200, {{"ok", true}}});
    }
    return response;
  };
  const auto response = handle(request);
  if (control::target_path({request.target().data(), request.target().size()}) == "/stream")
    control::accept_stream(request, context, "fuzz");
  // A login that succeeded: its cookie on the same request again, then on a logout.
  if (response && response->count(http::field::set_cookie) && response->result_int() == 200) {
    const std::string set_cookie((*response)[http::field::set_cookie]);
    control::HttpRequest again = request;
    again.set(http::field::cookie, set_cookie.substr(0, set_cookie.find(';')));
    handle(again);
    again.target("/logout");
    handle(again);
    again.method(http::verb::get);
    again.target("/session");
    handle(again);
  }
  return 0;
}
