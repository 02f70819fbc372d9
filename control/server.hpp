#pragma once
// The control API's sockets: an HTTP/1.1 listener and its sessions, and the WebSocket
// /stream, plain or over TLS, all asynchronous on facecapd's one I/O thread (daemon/io_thread.hpp), so a slow
// or malicious client never holds up anything but itself. What each request means is
// control/api.hpp. Not real-time code.
#include <cstdint>
#include <memory>
#include <optional>
#include <string>

#include "control/api.hpp"
#include "control/connection_limits.hpp"
#include "control/stream_sink.hpp"
#include "control/tls.hpp"

namespace boost::asio {
class io_context;
}

namespace facecap::control {

struct ServerOptions {
  std::string address = "127.0.0.1";
  uint16_t port = 0;    // 0: any free port
  AccessOptions access;  // tokens, allow-lists (its address and port are set from the above)
  std::string version;  // "facecapd 0.1.0 (git ...)", for the Server header
  std::string dashboard_dir;  // the dashboard's files, served at "/"; "": none (a 404 page says so)
  ConnectionLimits limits;     // control.http.max_connections and the like
  std::optional<TlsFiles> tls;  // HTTPS and WSS only, with this certificate (control.http.tls)
};

class ControlServer {
 public:
  // Listens at once (so that a taken port fails the start) and accepts on `io` once it
  // runs. The board, the queue and the stream (may be null) must outlive the server.
  // Throws Error naming the address when it cannot listen, or the file when options.tls's
  // certificate or key cannot be used.
  ControlServer(boost::asio::io_context& io, ServerOptions options, const StatusBoard& board, CommandQueue& commands,
                StreamSink* stream);
  // stop().
  ~ControlServer();
  ControlServer(const ControlServer&) = delete;
  ControlServer& operator=(const ControlServer&) = delete;

  // The port listened on (the one picked when options.port was 0).
  uint16_t port() const noexcept { return port_; }
  // Closes the listener and every connection, on the I/O thread, and waits up to a second
  // for it. Idempotent; call it while the I/O thread runs.
  void stop();

  struct Impl;  // server.cpp: the listener, the sessions' shared state, the stream's clients

 private:
  std::shared_ptr<Impl> impl_;
  uint16_t port_ = 0;
  bool stopped_ = false;
};

}  // namespace facecap::control
