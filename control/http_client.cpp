#include "control/http_client.hpp"

#include <sys/socket.h>
#include <sys/time.h>

#include <boost/asio/connect.hpp>
#include <boost/asio/io_context.hpp>
#include <boost/asio/ip/tcp.hpp>
#include <boost/asio/ssl.hpp>
#include <boost/beast/core.hpp>
#include <boost/beast/http.hpp>
#include <fmt/format.h>

#include "core/error.hpp"

namespace facecap::control {
namespace net = boost::asio;
namespace beast = boost::beast;
namespace http = beast::http;
using tcp = net::ip::tcp;

struct HttpClient::Connection {
  net::io_context io;
  net::ssl::context tls_context{net::ssl::context::tls_client};
  net::ssl::stream<tcp::socket> stream{io, tls_context};
  bool tls = false;
  beast::flat_buffer buffer;

  tcp::socket& socket() { return stream.next_layer(); }
  // One request and its response, over TLS or not.
  void exchange(const http::request<http::string_body>& request, http::response_parser<http::string_body>& parser,
                beast::error_code& ec) {
    auto run = [&](auto& s) {
      http::write(s, request, ec);
      if (!ec) http::read(s, buffer, parser, ec);
    };
    if (tls)
      run(stream);
    else
      run(socket());
  }
};

HttpClient::HttpClient(std::string address, uint16_t port, std::string token, double timeout_s, std::string tls_ca_file)
    : address_(std::move(address)), port_(port), token_(std::move(token)), timeout_s_(timeout_s),
      tls_ca_file_(std::move(tls_ca_file)) {}

HttpClient::~HttpClient() = default;

HttpResult HttpClient::request(std::string_view method, std::string_view target, std::string_view json_body) {
  const std::string where = fmt::format("{}://{}:{}{}", tls_ca_file_.empty() ? "http" : "https", address_, port_, target);
  http::request<http::string_body> request{http::string_to_verb(beast::string_view(method.data(), method.size())),
                                           beast::string_view(target.data(), target.size()), 11};
  request.set(http::field::host, fmt::format("{}:{}", address_.find(':') == std::string::npos ? address_ : "[" + address_ + "]", port_));
  request.set(http::field::user_agent, "facecap-ctl");
  if (!token_.empty()) request.set(http::field::authorization, "Bearer " + token_);
  // facecapd refuses a POST of any other type (docs/control-api.md#access).
  if (request.method() == http::verb::post) request.set(http::field::content_type, "application/json");
  request.body() = std::string(json_body);
  request.keep_alive(true);
  request.prepare_payload();
  // A kept-alive connection the server has since closed fails on first use: try once more
  // on a new one.
  for (int attempt = 0;; ++attempt) {
    beast::error_code ec;
    const bool fresh = !connection_;
    if (fresh) {
      connection_ = std::make_unique<Connection>();
      const tcp::endpoint endpoint(net::ip::make_address(address_, ec), port_);
      if (!ec) connection_->socket().connect(endpoint, ec);
      if (ec) {
        connection_.reset();
        throw Error(fmt::format("cannot connect to {}: {}", where, ec.message()));
      }
      const timeval timeout{time_t(timeout_s_), suseconds_t((timeout_s_ - double(time_t(timeout_s_))) * 1e6)};
      setsockopt(connection_->socket().native_handle(), SOL_SOCKET, SO_RCVTIMEO, &timeout, sizeof timeout);
      setsockopt(connection_->socket().native_handle(), SOL_SOCKET, SO_SNDTIMEO, &timeout, sizeof timeout);
      if (!tls_ca_file_.empty()) {
        Connection& c = *connection_;
        c.tls = true;
        c.tls_context.load_verify_file(tls_ca_file_, ec);
        if (ec) {
          connection_.reset();
          throw Error(fmt::format("{}: cannot read the certificate to trust: {}", tls_ca_file_, ec.message()));
        }
        c.stream.set_verify_mode(net::ssl::verify_peer);
        c.stream.set_verify_callback(net::ssl::rfc2818_verification(address_));
        c.stream.handshake(net::ssl::stream_base::client, ec);
        if (ec) {
          connection_.reset();
          throw Error(fmt::format("TLS with {} failed: {} (is {} facecapd's certificate, and control.http.tls on?)", where,
                                  ec.message(), tls_ca_file_));
        }
      }
    }
    http::response_parser<http::string_body> parser;
    parser.body_limit(std::uint64_t(1) << 30);
    connection_->exchange(request, parser, ec);
    if (ec) {
      connection_.reset();
      if (!fresh && attempt == 0) continue;
      throw Error(fmt::format("{}: {}", where, ec == net::error::would_block || ec == net::error::try_again
                                                   ? std::string("no response in time")
                                                   : ec.message()));
    }
    auto response = parser.release();
    HttpResult result;
    result.status = int(response.result_int());
    result.body = std::move(response.body());
    result.content_type = std::string(response[http::field::content_type]);
    if (!response.keep_alive()) connection_.reset();
    return result;
  }
}

}  // namespace facecap::control
