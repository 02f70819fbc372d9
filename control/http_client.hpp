#pragma once
// A small blocking HTTP/1.1 client (plain or TLS) for the control API: `facecap ctl`, the load benchmark
// and the tests. One kept-alive connection, opened again when the server closed it.
// Not real-time code.
#include <cstdint>
#include <memory>
#include <string>
#include <string_view>

namespace facecap::control {

struct HttpResult {
  int status = 0;
  std::string body;
  std::string content_type;
};

class HttpClient {
 public:
  // token: sent as "Authorization: Bearer <token>" when not empty. timeout_s bounds each
  // request (a calibration takes as long as its capture and then some). tls_ca_file: speak
  // HTTPS, trusting the certificates in that PEM file (facecapd's own certificate, for a
  // self-signed one), and check that the certificate names `address`.
  HttpClient(std::string address, uint16_t port, std::string token = {}, double timeout_s = 120.0, std::string tls_ca_file = {});
  ~HttpClient();
  HttpClient(const HttpClient&) = delete;
  HttpClient& operator=(const HttpClient&) = delete;

  // Throws Error naming the address when it cannot connect, send or read a response.
  HttpResult request(std::string_view method, std::string_view target, std::string_view json_body = {});

 private:
  struct Connection;
  std::string address_;
  uint16_t port_;
  std::string token_;
  double timeout_s_;
  std::string tls_ca_file_;
  std::unique_ptr<Connection> connection_;
};

}  // namespace facecap::control
