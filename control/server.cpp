#include "control/server.hpp"

#include <chrono>
#include <future>
#include <optional>
#include <set>

#include <boost/asio/ip/tcp.hpp>
#include <boost/asio/post.hpp>
#include <boost/asio/steady_timer.hpp>
#include <boost/beast/core.hpp>
#include <boost/beast/http.hpp>
#include <boost/beast/websocket.hpp>
#include <fmt/format.h>

#include "core/error.hpp"
#include "core/log.hpp"
#include "core/time.hpp"

namespace facecap::control {
namespace net = boost::asio;
namespace beast = boost::beast;
namespace http = beast::http;
namespace websocket = beast::websocket;
using tcp = net::ip::tcp;

namespace {

// An idle HTTP connection is closed after this long.
constexpr auto kIdleTimeout = std::chrono::seconds(30);
// Connections beyond this are closed at once: a client opening sockets in a loop
// cannot exhaust the process's descriptors.
constexpr std::size_t kMaxSessions = 64;
// The stream's I/O-thread pump: how often it drains the sink, and status messages.
constexpr auto kPumpInterval = std::chrono::milliseconds(5);
constexpr int64_t kStatusMessageIntervalNs = kNsPerSecond;

}  // namespace

class StreamSession;

struct ControlServer::Impl : std::enable_shared_from_this<ControlServer::Impl> {
  Impl(net::io_context& io, ServerOptions o, const StatusBoard& board, CommandQueue& commands, StreamSink* sink)
      : acceptor(io), pump_timer(io), options(std::move(o)), context{board, commands, options.version, options.dashboard_dir, options.access},
        stream(sink) {}

  void accept();
  void add_client(const std::shared_ptr<StreamSession>& client);
  void remove_client(const std::shared_ptr<StreamSession>& client);
  void update_stream_rate();
  void pump();
  void close_all();

  tcp::acceptor acceptor;
  net::steady_timer pump_timer;
  ServerOptions options;
  ApiContext context;
  StreamSink* stream;
  std::size_t sessions = 0;
  std::set<std::shared_ptr<StreamSession>> clients;
  bool pumping = false;
  bool closed = false;
};

namespace {

// A response to a request that could not be read whole; the connection closes after it.
HttpResponse unreadable_request(int status, std::string what, const std::string& server) {
  HttpRequest shape;
  shape.version(11);
  shape.keep_alive(false);
  return make_response(shape, error_reply(status, std::move(what)), server);
}

}  // namespace

class StreamSession : public std::enable_shared_from_this<StreamSession> {
 public:
  StreamSession(beast::tcp_stream&& stream, StreamRequest request, std::shared_ptr<ControlServer::Impl> server)
      : ws_(std::move(stream)), request_(request), server_(std::move(server)) {}

  void start(HttpRequest upgrade) {
    beast::get_lowest_layer(ws_).expires_never();
    ws_.set_option(websocket::stream_base::timeout::suggested(beast::role_type::server));
    ws_.async_accept(upgrade, [self = shared_from_this()](beast::error_code ec) {
      if (ec) return;
      // The schema first: frames and status messages only follow it.
      self->send(schema_message(self->server_->stream->schema(), self->request_.rate_hz, self->request_.vertices).dump());
      self->server_->add_client(self);
      self->read();
    });
  }
  // Whether the frame at time_ns is due for this client and the last message has gone.
  bool wants(int64_t time_ns) const noexcept { return !writing_ && time_ns >= next_due_ns_; }
  bool due(int64_t time_ns) const noexcept { return time_ns >= next_due_ns_; }
  void sent_frame(int64_t time_ns) noexcept {
    next_due_ns_ = time_ns + int64_t(1e9 / request_.rate_hz) - int64_t(1e9 / request_.rate_hz) / 8;
  }
  bool status_due(int64_t now_ns) const noexcept { return !writing_ && now_ns >= next_status_ns_; }
  void sent_status(int64_t now_ns) noexcept { next_status_ns_ = now_ns + kStatusMessageIntervalNs; }
  bool vertices() const noexcept { return request_.vertices; }
  double rate_hz() const noexcept { return request_.rate_hz; }
  void send(std::string text) {
    if (writing_) return;
    writing_ = true;
    out_ = std::move(text);
    ws_.text(true);
    ws_.async_write(net::buffer(out_), [self = shared_from_this()](beast::error_code ec, std::size_t) {
      self->writing_ = false;
      if (ec) self->server_->remove_client(self);
    });
  }
  void close() {
    beast::error_code ec;
    beast::get_lowest_layer(ws_).socket().close(ec);
  }

 private:
  // Reads (and ignores) what the client sends, to see it close.
  void read() {
    ws_.async_read(in_, [self = shared_from_this()](beast::error_code ec, std::size_t) {
      if (ec) {
        self->server_->remove_client(self);
        return;
      }
      self->in_.consume(self->in_.size());
      self->read();
    });
  }

  websocket::stream<beast::tcp_stream> ws_;
  StreamRequest request_;
  std::shared_ptr<ControlServer::Impl> server_;
  beast::flat_buffer in_;
  std::string out_;
  bool writing_ = false;
  int64_t next_due_ns_ = 0;
  int64_t next_status_ns_ = 0;
};

namespace {

class HttpSession : public std::enable_shared_from_this<HttpSession> {
 public:
  HttpSession(tcp::socket&& socket, std::shared_ptr<ControlServer::Impl> server)
      : stream_(std::move(socket)), server_(std::move(server)) {
    ++server_->sessions;
  }
  ~HttpSession() { --server_->sessions; }

  void read() {
    if (server_->closed) return;
    parser_.emplace();
    parser_->header_limit(kMaxHeaderBytes);
    parser_->body_limit(kMaxBodyBytes);
    stream_.expires_after(kIdleTimeout);
    http::async_read(stream_, buffer_, *parser_, [self = shared_from_this()](beast::error_code ec, std::size_t) {
      self->on_read(ec);
    });
  }

 private:
  void on_read(beast::error_code ec) {
    if (ec == http::error::end_of_stream || ec == net::error::operation_aborted || ec == beast::error::timeout ||
        ec == net::error::connection_reset || server_->closed)
      return close();
    if (ec == http::error::body_limit)
      return write(unreadable_request(413, fmt::format("the body is larger than {} bytes", kMaxBodyBytes), server_->options.version));
    if (ec == http::error::header_limit)
      return write(unreadable_request(431, fmt::format("the header is larger than {} bytes", kMaxHeaderBytes), server_->options.version));
    if (ec) return write(unreadable_request(400, fmt::format("malformed HTTP request: {}", ec.message()), server_->options.version));

    HttpRequest request = parser_->release();
    if (websocket::is_upgrade(request) && target_path(std::string_view(request.target().data(), request.target().size())) == "/stream") {
      if (!server_->stream) return write(make_response(request, error_reply(404, "no stream in this facecapd"), server_->options.version));
      auto accepted = accept_stream(request, server_->context, peer_address());
      if (auto* refused = std::get_if<HttpResponse>(&accepted)) return write(std::move(*refused));
      std::make_shared<StreamSession>(std::move(stream_), std::get<StreamRequest>(accepted), server_)->start(std::move(request));
      return;
    }
    auto respond = [self = shared_from_this(), executor = stream_.get_executor()](HttpResponse response) {
      net::post(executor, [self, response = std::move(response)]() mutable { self->write(std::move(response)); });
    };
    if (auto immediate = handle_request(request, server_->context, std::move(respond), peer_address())) write(std::move(*immediate));
  }

  std::string peer_address() const {
    beast::error_code ec;
    const tcp::endpoint peer = stream_.socket().remote_endpoint(ec);
    return ec ? std::string() : peer.address().to_string();
  }

  void write(HttpResponse response) {
    response_ = std::move(response);
    stream_.expires_after(kIdleTimeout);
    http::async_write(stream_, response_, [self = shared_from_this()](beast::error_code ec, std::size_t) {
      if (ec || !self->response_.keep_alive()) return self->close();
      self->read();
    });
  }

  void close() {
    beast::error_code ec;
    stream_.socket().shutdown(tcp::socket::shutdown_send, ec);
  }

  beast::tcp_stream stream_;
  std::shared_ptr<ControlServer::Impl> server_;
  beast::flat_buffer buffer_;
  std::optional<http::request_parser<http::string_body>> parser_;
  HttpResponse response_;
};

}  // namespace

void ControlServer::Impl::accept() {
  acceptor.async_accept([self = shared_from_this()](beast::error_code ec, tcp::socket socket) {
    if (self->closed) return;
    if (!ec) {
      if (self->sessions >= kMaxSessions) {
        beast::error_code ignored;
        socket.close(ignored);
      } else {
        std::make_shared<HttpSession>(std::move(socket), self)->read();
      }
    } else if (ec != net::error::operation_aborted) {
      spdlog::warn("control API: accepting a connection failed: {}", ec.message());
    }
    self->accept();
  });
}

void ControlServer::Impl::add_client(const std::shared_ptr<StreamSession>& client) {
  if (closed) return client->close();
  clients.insert(client);
  update_stream_rate();
  if (!pumping) {
    pumping = true;
    pump();
  }
}

void ControlServer::Impl::remove_client(const std::shared_ptr<StreamSession>& client) {
  clients.erase(client);
  update_stream_rate();
}

void ControlServer::Impl::update_stream_rate() {
  double fastest = 0.0;
  for (const auto& client : clients) fastest = std::max(fastest, client->rate_hz());
  stream->set_rate(fastest);
}

// Drains the stream's queue into the clients due a frame, and sends the status once a
// second; runs while any client listens.
void ControlServer::Impl::pump() {
  if (clients.empty() || closed) {
    pumping = false;
    while (stream->front()) stream->pop();
    return;
  }
  while (StreamSink::Entry* entry = stream->front()) {
    const int64_t time_ns = entry->solved.receive_time_ns;
    std::string plain, with_vertices;
    bool undelivered = false;
    for (const auto& client : clients) {
      if (!client->due(time_ns)) continue;
      if (!client->wants(time_ns)) {
        undelivered = true;
        continue;
      }
      std::string& text = client->vertices() ? with_vertices : plain;
      if (text.empty()) text = frame_message(*entry, stream->schema(), client->vertices()).dump();
      client->send(text);
      client->sent_frame(time_ns);
    }
    if (undelivered) stream->count_undelivered();
    stream->pop();
  }
  // Each client's status once a second, when its last message has gone.
  const int64_t now = monotonic_now_ns();
  std::string status;
  for (const auto& client : clients) {
    if (!client->status_due(now)) continue;
    if (status.empty()) status = "{\"type\":\"status\",\"status\":" + context.board.latest()->status_json + "}";
    client->send(status);
    client->sent_status(now);
  }
  pump_timer.expires_after(kPumpInterval);
  pump_timer.async_wait([self = shared_from_this()](beast::error_code ec) {
    if (!ec) self->pump();
  });
}

void ControlServer::Impl::close_all() {
  closed = true;
  beast::error_code ec;
  acceptor.close(ec);
  pump_timer.cancel();
  for (const auto& client : clients) client->close();
  clients.clear();
  if (stream) stream->set_rate(0);
}

ControlServer::ControlServer(net::io_context& io, ServerOptions options, const StatusBoard& board, CommandQueue& commands,
                             StreamSink* stream) {
  const std::string where = fmt::format("{}:{}", options.address, options.port);
  beast::error_code ec;
  const net::ip::address address = net::ip::make_address(options.address, ec);
  if (ec) throw Error(fmt::format("control API: \"{}\" is not an IP address", options.address));
  const tcp::endpoint endpoint(address, options.port);
  impl_ = std::make_shared<Impl>(io, std::move(options), board, commands, stream);
  tcp::acceptor& acceptor = impl_->acceptor;
  acceptor.open(endpoint.protocol(), ec);
  if (!ec) acceptor.set_option(net::socket_base::reuse_address(true), ec);
  if (!ec) acceptor.bind(endpoint, ec);
  if (!ec) acceptor.listen(net::socket_base::max_listen_connections, ec);
  if (ec) throw Error(fmt::format("control API cannot listen on {}: {}", where, ec.message()));
  port_ = acceptor.local_endpoint().port();
  impl_->context.access.address = impl_->options.address;
  impl_->context.access.port = port_;
  impl_->accept();
}

ControlServer::~ControlServer() { stop(); }

void ControlServer::stop() {
  if (stopped_) return;
  stopped_ = true;
  auto done = std::make_shared<std::promise<void>>();
  net::post(impl_->acceptor.get_executor(), [impl = impl_, done] {
    impl->close_all();
    done->set_value();
  });
  if (done->get_future().wait_for(std::chrono::seconds(1)) != std::future_status::ready)
    spdlog::warn("control API: the I/O thread did not close the server within a second");
}

}  // namespace facecap::control
