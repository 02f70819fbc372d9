// The control API's request handling on bytes: Beast's HTTP parser with the server's
// limits, then authorisation, routing, JSON bodies and the stream's query, as the I/O
// thread runs them (control/api.hpp). A queued command is answered at once, as the
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
  control::ApiContext context{board, queue, (size % 2) ? "s3cret" : "", "fuzz"};
  std::optional<control::HttpResponse> later;
  const auto response = control::handle_request(request, context, [&](control::HttpResponse r) { later = std::move(r); });
  if (!response) {
    std::optional<control::Command> command = queue.pop();
    if (command) command->reply({200, {{"ok", true}}});
  }
  if (control::target_path({request.target().data(), request.target().size()}) == "/stream")
    control::accept_stream(request, context);
  return 0;
}
