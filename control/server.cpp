#include "control/server.hpp"

#include <chrono>
#include <future>
#include <optional>
#include <set>
#include <unordered_map>

#include <boost/asio/ip/tcp.hpp>
#include <boost/asio/post.hpp>
#include <boost/asio/ssl/context.hpp>
#include <boost/asio/steady_timer.hpp>
#include <boost/beast/core.hpp>
#include <boost/beast/core/detect_ssl.hpp>
#include <boost/beast/ssl/ssl_stream.hpp>
#include <boost/beast/http.hpp>
#include <boost/beast/websocket.hpp>
#include <boost/beast/websocket/ssl.hpp>
#include <fmt/format.h>

#include "core/error.hpp"
#include "core/log.hpp"
#include "core/time.hpp"
#include "control/tls.hpp"

namespace facecap::control {
namespace net = boost::asio;
namespace beast = boost::beast;
namespace http = beast::http;
namespace websocket = beast::websocket;
using tcp = net::ip::tcp;
using TlsStream = beast::ssl_stream<beast::tcp_stream>;

namespace {

// A new connection has this long to send its request's whole header (slowloris), and a
// kept-alive one this long to send the next; a body and an answer this long each.
constexpr auto kHeaderTimeout = std::chrono::seconds(5);
constexpr auto kKeepAliveTimeout = std::chrono::seconds(15);
constexpr auto kBodyTimeout = std::chrono::seconds(10);
constexpr auto kWriteTimeout = std::chrono::seconds(10);
// A stream client that has answered no ping for this long is closed (Beast pings at half
// of it), and so is one whose last message has not gone out for kStalledWriteTimeout.
constexpr auto kStreamIdleTimeout = std::chrono::seconds(20);
constexpr int64_t kStalledWriteTimeoutNs = 10 * kNsPerSecond;
// The stream's I/O-thread pump: how often it drains the sink, and status messages.
constexpr auto kPumpInterval = std::chrono::milliseconds(5);
constexpr int64_t kStatusMessageIntervalNs = kNsPerSecond;

}  // namespace

class StreamClient;

// What the server can close to make room: an HTTP session or a stream client.
class Connection {
 public:
  virtual ~Connection() = default;
  virtual void abort() = 0;
};

struct ControlServer::Impl : std::enable_shared_from_this<ControlServer::Impl> {
  Impl(net::io_context& io, ServerOptions o, const StatusBoard& board, CommandQueue& commands, StreamSink* sink)
      : acceptor(io), accept_timer(io), pump_timer(io), options(std::move(o)),
        context{board, commands, options.version, options.dashboard_dir, options.access}, stream(sink),
        table(options.limits) {}

  void accept();
  void accept_failed(const beast::error_code& ec);
  void forget(ConnectionTable::Id id) {
    table.remove(id);
    live.erase(id);
  }
  void add_client(const std::shared_ptr<StreamClient>& client);
  void remove_client(const std::shared_ptr<StreamClient>& client);
  void update_stream_rate();
  void pump();
  void close_all();

  tcp::acceptor acceptor;
  net::steady_timer accept_timer;
  net::steady_timer pump_timer;
  ServerOptions options;
  ApiContext context;
  StreamSink* stream;
  ConnectionTable table;
  std::unordered_map<ConnectionTable::Id, std::weak_ptr<Connection>> live;  // to abort the evicted
  AcceptBackoff accept_backoff;
  std::set<std::shared_ptr<StreamClient>> clients;
  std::shared_ptr<net::ssl::context> tls;  // null: plain HTTP
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

// A /stream client: which frames are due for it and whether its last message has gone,
// whatever it is carried over (StreamSession below).
class StreamClient : public Connection {
 public:
  explicit StreamClient(StreamRequest request) : request_(request) {}
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
  // Whether its last message has waited too long to go out (a client that does not read).
  bool stalled(int64_t now_ns) const noexcept { return writing_ && now_ns - write_started_ns_ > kStalledWriteTimeoutNs; }
  void send(std::string text) {
    if (writing_) return;
    writing_ = true;
    write_started_ns_ = monotonic_now_ns();
    out_ = std::move(text);
    write_out();
  }
  virtual void close() = 0;
  void abort() override { close(); }

 protected:
  // Writes out_ and then calls written().
  virtual void write_out() = 0;
  void written() noexcept { writing_ = false; }

  StreamRequest request_;
  std::string out_;

 private:
  bool writing_ = false;
  int64_t write_started_ns_ = 0;
  int64_t next_due_ns_ = 0;
  int64_t next_status_ns_ = 0;
};

// A WebSocket /stream client over `Stream` (plain TCP or TLS).
template <class Stream>
class StreamSession : public StreamClient, public std::enable_shared_from_this<StreamSession<Stream>> {
 public:
  StreamSession(Stream&& stream, StreamRequest request, std::shared_ptr<ControlServer::Impl> server, ConnectionTable::Id id)
      : StreamClient(request), ws_(std::move(stream)), server_(std::move(server)), id_(id) {}
  ~StreamSession() override { server_->forget(id_); }

  void start(HttpRequest upgrade) {
    server_->live[id_] = this->weak_from_this();
    beast::get_lowest_layer(ws_).expires_never();
    websocket::stream_base::timeout timeout;
    timeout.handshake_timeout = kWriteTimeout;
    timeout.idle_timeout = kStreamIdleTimeout;
    timeout.keep_alive_pings = true;
    ws_.set_option(timeout);
    ws_.async_accept(upgrade, [self = this->shared_from_this()](beast::error_code ec) {
      if (ec) return;
      // The schema first: frames and status messages only follow it.
      self->send(schema_message(self->server_->stream->schema(), self->request_.rate_hz, self->request_.vertices).dump());
      self->server_->add_client(self);
      self->read();
    });
  }
  void close() override {
    beast::error_code ec;
    beast::get_lowest_layer(ws_).socket().close(ec);
  }

 private:
  void write_out() override {
    ws_.text(true);
    ws_.async_write(net::buffer(out_), [self = this->shared_from_this()](beast::error_code ec, std::size_t) {
      self->written();
      if (ec) self->server_->remove_client(self);
    });
  }
  // Reads (and ignores) what the client sends, to see it close.
  void read() {
    ws_.async_read(in_, [self = this->shared_from_this()](beast::error_code ec, std::size_t) {
      if (ec) {
        self->server_->remove_client(self);
        return;
      }
      self->in_.consume(self->in_.size());
      self->read();
    });
  }

  websocket::stream<Stream> ws_;
  std::shared_ptr<ControlServer::Impl> server_;
  beast::flat_buffer in_;
  ConnectionTable::Id id_;
};

namespace {

// Whether a request's Transfer-Encoding is absent or exactly "chunked": anything else
// ("chunked, identity", "gzip") is refused rather than guessed at (request smuggling).
bool acceptable_transfer_encoding(const http::request_parser<http::string_body>& parser) {
  const auto& header = parser.get();
  const auto field = header.find(http::field::transfer_encoding);
  if (field == header.end()) return true;
  return beast::iequals(field->value(), "chunked") && header.count(http::field::transfer_encoding) == 1;
}

// An HTTP/1.1 connection over `Stream`: beast::tcp_stream, or TlsStream when the API
// serves TLS (then the handshake comes first, within the header's time).
template <class Stream>
class HttpSession : public Connection, public std::enable_shared_from_this<HttpSession<Stream>> {
  static constexpr bool kTls = std::is_same_v<Stream, TlsStream>;

 public:
  HttpSession(tcp::socket&& socket, std::shared_ptr<ControlServer::Impl> server, ConnectionTable::Id id)
      : stream_(make_stream(std::move(socket), *server)), server_(std::move(server)), id_(id) {}
  ~HttpSession() override {
    if (!handed_over_) server_->forget(id_);
  }

  void start() {
    server_->live[id_] = this->weak_from_this();
    if constexpr (kTls) {
      lowest().expires_after(kHeaderTimeout);
      beast::async_detect_ssl(lowest(), buffer_, [self = this->shared_from_this()](beast::error_code ec, bool tls) {
        if (ec) return self->abort();
        if (!tls) return self->refuse_plain_http();
        self->stream_.async_handshake(net::ssl::stream_base::server, self->buffer_.data(),
                                      [self](beast::error_code handshake_error, std::size_t used) {
                                        if (handshake_error) return self->abort();
                                        self->buffer_.consume(used);
                                        self->read(kHeaderTimeout);
                                      });
      });
    } else {
      read(kHeaderTimeout);
    }
  }
  void abort() override {
    beast::error_code ec;
    lowest().socket().close(ec);
  }

 private:
  // The next request's header within `header_timeout`, then its body.
  void read(std::chrono::seconds header_timeout) {
    if (server_->closed) return;
    parser_.emplace();
    parser_->header_limit(kMaxHeaderBytes);
    parser_->body_limit(kMaxBodyBytes);
    lowest().expires_after(header_timeout);
    http::async_read_header(stream_, buffer_, *parser_, [self = this->shared_from_this()](beast::error_code ec, std::size_t) {
      if (ec) return self->on_read(ec);
      if (!acceptable_transfer_encoding(*self->parser_))
        return self->write(unreadable_request(400, "Transfer-Encoding must be absent or exactly \"chunked\"",
                                              self->server_->options.version));
      self->lowest().expires_after(kBodyTimeout);
      http::async_read(self->stream_, self->buffer_, *self->parser_,
                       [self](beast::error_code ec, std::size_t) { self->on_read(ec); });
    });
  }

  void on_read(beast::error_code ec) {
    if (ec == http::error::end_of_stream || ec == net::error::operation_aborted || ec == beast::error::timeout ||
        ec == net::error::connection_reset || ec == net::ssl::error::stream_truncated || server_->closed)
      return close();
    if (ec == http::error::body_limit)
      return write(unreadable_request(413, fmt::format("the body is larger than {} bytes", kMaxBodyBytes), server_->options.version));
    if (ec == http::error::header_limit)
      return write(unreadable_request(431, fmt::format("the header is larger than {} bytes", kMaxHeaderBytes), server_->options.version));
    if (ec) return write(unreadable_request(400, fmt::format("malformed HTTP request: {}", ec.message()), server_->options.version));

    HttpRequest request = parser_->release();
    if (request_authenticated(request, server_->context)) server_->table.authenticated(id_);
    if (websocket::is_upgrade(request) && target_path(std::string_view(request.target().data(), request.target().size())) == "/stream") {
      if (!server_->stream) return write(make_response(request, error_reply(404, "no stream in this facecapd"), server_->options.version));
      auto accepted = accept_stream(request, server_->context, peer_address());
      if (auto* refused = std::get_if<HttpResponse>(&accepted)) return write(std::move(*refused));
      if (!server_->table.become_stream_client(id_)) {
        Reply full = error_reply(503, fmt::format("{} stream clients are connected already (control.http.max_stream_clients)",
                                                  server_->table.stream_clients()));
        full.retry_after_s = 5;
        return write(make_response(request, full, server_->options.version));
      }
      handed_over_ = true;
      std::make_shared<StreamSession<Stream>>(std::move(stream_), std::get<StreamRequest>(accepted), server_, id_)
          ->start(std::move(request));
      return;
    }
    auto respond = [self = this->shared_from_this(), executor = stream_.get_executor()](HttpResponse response) {
      net::post(executor, [self, response = std::move(response)]() mutable { self->write(std::move(response)); });
    };
    if (auto immediate = handle_request(request, server_->context, std::move(respond), peer_address())) write(std::move(*immediate));
  }

  static Stream make_stream(tcp::socket&& socket, ControlServer::Impl& server) {
    if constexpr (kTls)
      return Stream(std::move(socket), *server.tls);
    else
      return Stream(std::move(socket));
  }
  beast::tcp_stream& lowest() { return beast::get_lowest_layer(stream_); }

  std::string peer_address() {
    beast::error_code ec;
    const tcp::endpoint peer = lowest().socket().remote_endpoint(ec);
    return ec ? std::string() : peer.address().to_string();
  }

  // Plain HTTP sent to the TLS port: a short answer a person can read, then closed.
  void refuse_plain_http() {
    const auto& o = server_->options;
    const std::string body = fmt::format("This facecapd's control API speaks HTTPS only: https://{}:{}/\n",
                                         o.address.find(':') == std::string::npos ? o.address : "[" + o.address + "]",
                                         server_->context.access.port);
    plain_answer_ = fmt::format("HTTP/1.1 400 Bad Request\r\nContent-Type: text/plain; charset=utf-8\r\nContent-Length: {}\r\n"
                                "Connection: close\r\n\r\n{}", body.size(), body);
    lowest().expires_after(kWriteTimeout);
    net::async_write(lowest(), net::buffer(plain_answer_), [self = this->shared_from_this()](beast::error_code, std::size_t) {
      beast::error_code ignored;
      self->lowest().socket().shutdown(tcp::socket::shutdown_send, ignored);
    });
  }

  void write(HttpResponse response) {
    response_ = std::move(response);
    lowest().expires_after(kWriteTimeout);
    http::async_write(stream_, response_, [self = this->shared_from_this()](beast::error_code ec, std::size_t) {
      if (ec || !self->response_.keep_alive()) return self->close();
      self->response_ = {};  // an answer of a recording's frames can be megabytes
      self->read(kKeepAliveTimeout);
    });
  }

  void close() {
    if constexpr (kTls) {
      // close_notify, then the socket; a peer that never answers it is cut at the timeout.
      lowest().expires_after(kWriteTimeout);
      stream_.async_shutdown([self = this->shared_from_this()](beast::error_code) { self->abort(); });
    } else {
      beast::error_code ec;
      lowest().socket().shutdown(tcp::socket::shutdown_send, ec);
    }
  }

  Stream stream_;
  std::shared_ptr<ControlServer::Impl> server_;
  ConnectionTable::Id id_;
  bool handed_over_ = false;  // to a StreamSession, with its id
  beast::flat_buffer buffer_;
  std::optional<http::request_parser<http::string_body>> parser_;
  HttpResponse response_;
  std::string plain_answer_;
};

}  // namespace

void ControlServer::Impl::accept() {
  acceptor.async_accept([self = shared_from_this()](beast::error_code ec, tcp::socket socket) {
    if (self->closed || ec == net::error::operation_aborted) return;
    if (ec) return self->accept_failed(ec);
    self->accept_backoff.succeeded();
    beast::error_code peer_error;
    const tcp::endpoint peer = socket.remote_endpoint(peer_error);
    const ConnectionTable::Admission admission =
        self->table.admit(peer_error ? std::string("?") : peer.address().to_string());
    if (admission.evicted) {
      const auto evicted = self->live.find(*admission.evicted);
      if (evicted != self->live.end()) {
        if (const auto connection = evicted->second.lock()) connection->abort();
        self->live.erase(evicted);
      }
    }
    if (admission.admitted && self->tls) {
      std::make_shared<HttpSession<TlsStream>>(std::move(socket), self, *admission.admitted)->start();
    } else if (admission.admitted) {
      std::make_shared<HttpSession<beast::tcp_stream>>(std::move(socket), self, *admission.admitted)->start();
    } else {
      beast::error_code ignored;
      socket.close(ignored);
    }
    self->accept();
  });
}

// Out of descriptors (EMFILE) or memory, accept() would fail again at once: wait, and warn
// once in a while with the count instead of at every failure.
void ControlServer::Impl::accept_failed(const beast::error_code& ec) {
  const AcceptBackoff::Step step = accept_backoff.failed(monotonic_now_ns());
  if (step.warn_with_count > 0)
    spdlog::warn("control API: accepting a connection failed {} time(s) since the last warning: {}; next try in {} ms "
                 "({} connections open)", step.warn_with_count, ec.message(), step.delay_ns / kNsPerMs, table.connections());
  accept_timer.expires_after(std::chrono::nanoseconds(step.delay_ns));
  accept_timer.async_wait([self = shared_from_this()](beast::error_code wait_error) {
    if (!wait_error && !self->closed) self->accept();
  });
}

void ControlServer::Impl::add_client(const std::shared_ptr<StreamClient>& client) {
  if (closed) return client->close();
  clients.insert(client);
  update_stream_rate();
  if (!pumping) {
    pumping = true;
    pump();
  }
}

void ControlServer::Impl::remove_client(const std::shared_ptr<StreamClient>& client) {
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
  // Each client's status once a second, when its last message has gone; a client that
  // reads nothing is closed (its pending write then fails and removes it).
  const int64_t now = monotonic_now_ns();
  for (const auto& client : clients)
    if (client->stalled(now)) client->close();
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
  accept_timer.cancel();
  pump_timer.cancel();
  for (const auto& [id, connection] : live)
    if (const auto alive = connection.lock()) alive->abort();
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
  std::shared_ptr<net::ssl::context> tls = options.tls ? make_tls_server_context(*options.tls) : nullptr;
  options.access.tls = tls != nullptr;
  impl_ = std::make_shared<Impl>(io, std::move(options), board, commands, stream);
  impl_->tls = std::move(tls);
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
