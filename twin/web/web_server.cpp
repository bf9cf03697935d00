// twin/web — the view's HTTP server (see web_server.hpp).
#include "twin/web/web_server.hpp"

#include <httplib.h>
#include <netdb.h>
#include <poll.h>
#include <sys/socket.h>
#include <unistd.h>

#include <algorithm>
#include <cerrno>
#include <chrono>
#include <cmath>
#include <cstdlib>
#include <cstring>
#include <filesystem>
#include <fstream>
#include <iterator>
#include <set>
#include <stdexcept>

namespace omnitwin::twin {
namespace {

namespace fs = std::filesystem;
using nlohmann::json;

// The page and its libraries; a missing library means `npm ci` did not run.
void check_assets(const std::string& dir) {
  for (const char* f : {"index.html", "view.js", "node_modules/three/build/three.module.js",
                        "node_modules/uplot/dist/uPlot.esm.js"}) {
    if (!fs::exists(fs::path(dir) / f))
      throw std::runtime_error("web view: " + (fs::path(dir) / f).string() +
                               " is missing (scripts/bootstrap build installs the page's libraries)");
  }
}

std::string sse_message(const std::string& event, const json& data) {
  return "event: " + event + "\ndata: " + data.dump(-1, ' ', false, json::error_handler_t::replace) + "\n\n";
}

// The file /run/`sub` names in the run directory `root` (canonical): a regular file whose real
// path (symbolic links resolved) lies inside `root`, named by no part that starts with a dot,
// before or after resolving. Else empty: a link to /etc/passwd, a link to a directory outside,
// the .omnitwin-run marker, a directory.
fs::path run_file(const fs::path& root, const std::string& sub) {
  const auto dotted = [](const fs::path& p) {
    for (const auto& part : p)
      if (!part.empty() && part.string()[0] == '.') return true;
    return false;
  };
  const fs::path rel = fs::path(sub).relative_path();
  if (rel.empty() || dotted(rel)) return {};
  std::error_code ec;
  const fs::path real = fs::canonical(root / rel, ec);
  if (ec || !fs::is_regular_file(real, ec)) return {};
  const auto [in_root, in_real] = std::mismatch(root.begin(), root.end(), real.begin(), real.end());
  if (in_root != root.end() || dotted(real.lexically_relative(root))) return {};
  return real;
}

const char* content_type(const fs::path& file) {
  const std::string ext = file.extension().string();
  if (ext == ".mp4") return "video/mp4";
  if (ext == ".json") return "application/json";
  if (ext == ".csv") return "text/csv";
  if (ext == ".png") return "image/png";
  if (ext == ".html") return "text/html; charset=utf-8";
  if (ext == ".xml") return "application/xml";
  if (ext == ".yaml" || ext == ".log" || ext == ".txt") return "text/plain; charset=utf-8";
  return "application/octet-stream";
}

using Clock = std::chrono::steady_clock;

// Set by a handler whose answer ends its connection (a refused stream): its client would
// otherwise keep the connection, and a worker with it, for the keep-alive time.
thread_local bool t_close_connection = false;

// Waits until `sock` has `events` (POLLIN, POLLOUT) or `until` passed (false).
bool wait_socket(socket_t sock, short events, Clock::time_point until) {
  for (;;) {
    const auto left = std::chrono::duration_cast<std::chrono::milliseconds>(until - Clock::now()).count();
    pollfd p{sock, events, 0};
    const int n = ::poll(&p, 1, static_cast<int>(std::clamp<long long>(left, 0, 1000)));
    if (n > 0) return true;
    if (n < 0 && errno != EINTR) return false;
    if (n == 0 && left <= 1000) return false;
  }
}

// A connection's stream for one request, as httplib's SocketStream but with a deadline for the
// whole of the request's reading (its line and headers) instead of one per byte: a client
// trickling a byte a second kept a worker for ever.
class ConnectionStream final : public httplib::Stream {
 public:
  ConnectionStream(socket_t sock, Clock::time_point read_deadline, Clock::duration write_timeout)
      : sock_(sock), read_deadline_(read_deadline), write_timeout_(write_timeout) {}

  bool is_readable() const override {
    if (wait_socket(sock_, POLLIN, read_deadline_)) return true;
    timed_out_ = true;
    return false;
  }
  // A read found the deadline passed: the connection is to be closed (its client trickles).
  bool timed_out() const { return timed_out_; }
  bool is_writable() const override {
    if (!wait_socket(sock_, POLLOUT, Clock::now() + write_timeout_)) return false;
    // Gone when readable with nothing to read (the page closed its end).
    pollfd p{sock_, POLLIN, 0};
    if (::poll(&p, 1, 0) <= 0) return true;
    char c;
    return ::recv(sock_, &c, 1, MSG_PEEK | MSG_DONTWAIT) > 0;
  }
  ssize_t read(char* ptr, std::size_t size) override {
    if (off_ < len_) {
      const std::size_t n = std::min(size, len_ - off_);
      std::memcpy(ptr, buf_ + off_, n);
      off_ += n;
      return static_cast<ssize_t>(n);
    }
    if (!is_readable()) return -1;
    if (size >= sizeof buf_) return ::recv(sock_, ptr, size, 0);
    const ssize_t got = ::recv(sock_, buf_, sizeof buf_, 0);
    if (got <= 0) return got;
    len_ = static_cast<std::size_t>(got);
    off_ = std::min(size, len_);
    std::memcpy(ptr, buf_, off_);
    return static_cast<ssize_t>(off_);
  }
  ssize_t write(const char* ptr, std::size_t size) override {
    if (!is_writable()) return -1;
    return ::send(sock_, ptr, size, MSG_NOSIGNAL);
  }
  void get_remote_ip_and_port(std::string& ip, int& port) const override { address(true, ip, port); }
  void get_local_ip_and_port(std::string& ip, int& port) const override { address(false, ip, port); }
  socket_t socket() const override { return sock_; }

 private:
  void address(bool remote, std::string& ip, int& port) const {
    sockaddr_storage a{};
    socklen_t len = sizeof a;
    auto* sa = reinterpret_cast<sockaddr*>(&a);
    if ((remote ? ::getpeername(sock_, sa, &len) : ::getsockname(sock_, sa, &len)) != 0) return;
    char host[NI_MAXHOST], serv[NI_MAXSERV];
    if (::getnameinfo(sa, len, host, sizeof host, serv, sizeof serv, NI_NUMERICHOST | NI_NUMERICSERV) != 0) return;
    ip = host;
    port = std::atoi(serv);
  }

  socket_t sock_;
  Clock::time_point read_deadline_;
  Clock::duration write_timeout_;
  char buf_[4096];
  std::size_t off_ = 0, len_ = 0;
  mutable bool timed_out_ = false;
};

}  // namespace

// httplib's server with its connections under our control: httplib 0.11.4 reads a request
// with a timeout per byte and keeps a connection for as long as its client sends, and its
// stop() joins every worker, so clients trickling requests held all 32 workers (no page
// loaded) and kept the process from exiting (found in review: 20 s after Ctrl-C). Here each
// connection has a deadline per request and an idle timeout, and close_connections() shuts
// them all down, so that stop() finds every worker ending.
class WebServer::Http : public httplib::Server {
 public:
  Http(double request_timeout_s, double keep_alive_timeout_s)
      : request_timeout_(std::chrono::duration_cast<Clock::duration>(std::chrono::duration<double>(request_timeout_s))),
        keep_alive_timeout_(
            std::chrono::duration_cast<Clock::duration>(std::chrono::duration<double>(keep_alive_timeout_s))) {}

  // Reads and writes on every connection fail from now on, and new ones are closed at once.
  void close_connections() {
    std::lock_guard<std::mutex> lk(mu_);
    closing_ = true;
    for (const socket_t s : open_) ::shutdown(s, SHUT_RDWR);
  }

 private:
  // Overrides httplib's (the same loop: up to keep_alive_max_count_ requests on a connection).
  bool process_and_close_socket(socket_t sock) override {
    {
      std::lock_guard<std::mutex> lk(mu_);
      if (closing_) {
        ::close(sock);
        return false;
      }
      open_.insert(sock);
    }
    bool ok = false;
    for (std::size_t left = keep_alive_max_count_; left > 0 && !closing_ && svr_sock_ != INVALID_SOCKET; --left) {
      if (!wait_socket(sock, POLLIN, Clock::now() + keep_alive_timeout_)) break;  // idle
      if (closing_) break;
      ConnectionStream strm(sock, Clock::now() + request_timeout_, std::chrono::seconds(5));
      bool closed = false;
      t_close_connection = false;
      ok = process_request(strm, left == 1, closed, nullptr);
      if (!ok || closed || strm.timed_out() || t_close_connection) break;
    }
    {
      std::lock_guard<std::mutex> lk(mu_);
      open_.erase(sock);  // under the lock: close_connections() never shuts a reused number
    }
    ::shutdown(sock, SHUT_RDWR);
    ::close(sock);
    return ok;
  }

  const Clock::duration request_timeout_, keep_alive_timeout_;
  std::mutex mu_;
  std::set<socket_t> open_;
  std::atomic<bool> closing_{false};
};

WebSettings parse_web_address(const std::string& spec) {
  WebSettings s;
  s.assets_dir = default_web_assets_dir();
  std::string port = spec;
  if (const auto colon = spec.rfind(':'); colon != std::string::npos) {
    s.host = spec.substr(0, colon);
    port = spec.substr(colon + 1);
    if (s.host.empty()) throw std::invalid_argument("--web '" + spec + "': the address before ':' is empty");
  }
  char* end = nullptr;
  const long p = std::strtol(port.c_str(), &end, 10);
  if (port.empty() || *end != '\0' || p < 0 || p > 65535)
    throw std::invalid_argument("--web '" + spec + "': want [ADDR:]PORT with PORT 0..65535");
  s.port = static_cast<int>(p);
  return s;
}

std::string default_web_assets_dir() {
  if (const char* d = std::getenv("OMNITWIN_WEB_DIR"); d && *d) return d;
  return std::string(OMNITWIN_SOURCE_DIR) + "/media/web";
}

WebServer::WebServer(const WebSettings& settings, json scene)
    : settings_(settings),
      http_(std::make_unique<Http>(settings.request_timeout_s, settings.keep_alive_timeout_s)),
      scene_(scene.dump()) {
  check_assets(settings_.assets_dir);
  // Each open page holds a worker with its event stream and a few with keep-alive
  // connections: more workers than httplib's default (8) so that several pages fit.
  http_->new_task_queue = [] { return new httplib::ThreadPool(32); };
  // What the Keep-Alive header announces (Http closes idle connections itself).
  http_->set_keep_alive_timeout(static_cast<time_t>(std::ceil(settings_.keep_alive_timeout_s)));
  // SO_REUSEADDR only: httplib's default adds SO_REUSEPORT, with which a second view on a port
  // in use would bind too and share the connections instead of failing.
  http_->set_socket_options([](socket_t sock) {
    int yes = 1;
    ::setsockopt(sock, SOL_SOCKET, SO_REUSEADDR, &yes, sizeof yes);
  });
  add_routes();
  port_ = settings_.port == 0 ? http_->bind_to_any_port(settings_.host) : settings_.port;
  if (settings_.port != 0 && !http_->bind_to_port(settings_.host, settings_.port)) port_ = -1;
  if (port_ < 0)
    throw std::runtime_error("web view: cannot listen on " + settings_.host + ":" + std::to_string(settings_.port));
}

void WebServer::start() {
  if (listener_.joinable()) return;
  listener_ = std::thread([this] {
    http_->listen_after_bind();
    listener_done_ = true;
  });
  // httplib's stop() does nothing until the listener runs, and a listener that starts after it
  // never ends: a Ctrl-C right after start() hung the destructor's join. So wait for it here.
  while (!http_->is_running() && !listener_done_) std::this_thread::sleep_for(std::chrono::milliseconds(1));
}

WebServer::~WebServer() {
  {
    std::lock_guard<std::mutex> lk(mu_);
    stopping_ = true;
  }
  changed_.notify_all();
  // Shut every connection down first: stop() joins the workers, and one still reading from a
  // client that trickles its request (or writing to one that reads nothing) held the process.
  http_->close_connections();
  http_->stop();
  if (listener_.joinable()) listener_.join();
}

std::string WebServer::url() const { return "http://" + settings_.host + ":" + std::to_string(port_) + "/"; }

void WebServer::add_routes() {
  const fs::path dir(settings_.assets_dir);
  http_->set_mount_point("/static", dir.string());
  http_->set_mount_point("/vendor/three", (dir / "node_modules/three").string());
  http_->set_mount_point("/vendor/uplot", (dir / "node_modules/uplot/dist").string());
  http_->Get("/", [dir](const httplib::Request&, httplib::Response& res) {
    std::ifstream f(dir / "index.html", std::ios::binary);
    res.set_content(std::string(std::istreambuf_iterator<char>(f), {}), "text/html; charset=utf-8");
  });
  http_->Get("/api/scene", [this](const httplib::Request&, httplib::Response& res) {
    res.set_content(scene_, "application/json");
  });
  http_->Get("/api/info", [this](const httplib::Request&, httplib::Response& res) {
    std::lock_guard<std::mutex> lk(mu_);
    res.set_content(info_.dump(), "application/json");
  });
  http_->Get("/api/run", [this](const httplib::Request&, httplib::Response& res) {
    std::lock_guard<std::mutex> lk(mu_);
    if (recorded_.empty()) {
      res.status = 404;
      res.set_content("{\"error\": \"a live run: read /api/stream\"}", "application/json");
      return;
    }
    res.set_content(recorded_, "application/json");
  });
  http_->Get("/api/stream", [this](const httplib::Request&, httplib::Response& res) {
    res.set_header("Cache-Control", "no-cache");
    {
      std::lock_guard<std::mutex> lk(mu_);
      // Each open stream holds a worker: past the cap the pool would have none left for the
      // pages' other requests (found in review: 32 open streams and /api/info timed out).
      if (open_streams_ >= settings_.max_streams) {
        ++stats_.streams_refused;
        res.status = 503;
        res.set_header("Retry-After", "10");
        res.set_header("Connection", "close");
        res.set_content("{\"error\": \"" + std::to_string(open_streams_) + " event streams are open; close a page\"}",
                        "application/json");
        t_close_connection = true;
        return;
      }
      ++open_streams_;
    }
    struct Stream {
      std::uint64_t cursor = 0;
      bool opened = false;
    };
    auto stream = std::make_shared<Stream>();
    res.set_chunked_content_provider(
        "text/event-stream",
        [this, stream](std::size_t, httplib::DataSink& sink) {
          // A page opened the stream once a GET's content is asked for: a HEAD has none, and
          // counted as a page (found in review: a HEAD started a --web-wait run).
          if (!stream->opened) {
            stream->opened = true;
            {
              std::lock_guard<std::mutex> lk(mu_);
              ++stats_.streams_opened;
            }
            changed_.notify_all();
          }
          std::string out;
          const bool more = stream_chunk(stream->cursor, out);
          if (!out.empty() && !sink.write(out.data(), out.size())) return false;
          if (!more) sink.done();
          return true;
        },
        [this](bool) {
          std::lock_guard<std::mutex> lk(mu_);
          --open_streams_;
          changed_.notify_all();
        });
  });
}

// The next messages for one stream after `cursor` (waits up to a second for some, then sends a
// comment line so that a vanished page is noticed). False once the stream is complete.
bool WebServer::stream_chunk(std::uint64_t& cursor, std::string& out) {
  std::unique_lock<std::mutex> lk(mu_);
  if (cursor >= total_ && !closed_ && !stopping_)
    changed_.wait_for(lk, std::chrono::seconds(1), [&] { return cursor < total_ || closed_ || stopping_; });
  if (cursor == 0 && total_ > 0) out += first_, cursor = 1;
  if (cursor < base_) cursor = base_;  // dropped over the cap while this page was away
  for (; cursor < total_ && out.size() < (1u << 20); ++cursor) out += history_[cursor - base_];
  if (out.empty() && !closed_ && !stopping_) out = ": idle\n\n";
  return !(stopping_ || (closed_ && cursor >= total_));
}

void WebServer::set_info(json info) {
  std::lock_guard<std::mutex> lk(mu_);
  info_ = std::move(info);
}

void WebServer::publish(const std::string& event, const json& data) {
  std::string msg = sse_message(event, data);
  {
    std::lock_guard<std::mutex> lk(mu_);
    ++stats_.messages;
    stats_.bytes += msg.size();
    if (total_++ == 0) {
      first_ = std::move(msg);  // the run's info: every page gets it
    } else {
      history_bytes_ += msg.size();
      history_.push_back(std::move(msg));
    }
    // Over the cap: drop the oldest (not the newest, which open pages may still need).
    while (history_bytes_ > settings_.history_cap_bytes && history_.size() > 1) {
      history_bytes_ -= history_.front().size();
      history_.pop_front();
      ++base_;
      ++stats_.history_dropped;
    }
  }
  changed_.notify_all();
}

void WebServer::close_streams() {
  {
    std::lock_guard<std::mutex> lk(mu_);
    closed_ = true;
  }
  changed_.notify_all();
}

void WebServer::wait_streams_drained(double timeout_s) {
  std::unique_lock<std::mutex> lk(mu_);
  changed_.wait_for(lk, std::chrono::duration<double>(timeout_s), [this] { return open_streams_ <= 0; });
}

bool WebServer::wait_for_client(const std::atomic<bool>* interrupt) {
  std::unique_lock<std::mutex> lk(mu_);
  while (stats_.streams_opened == 0) {
    if (interrupt && interrupt->load()) return false;
    changed_.wait_for(lk, std::chrono::milliseconds(100));
  }
  return true;
}

void WebServer::serve_recorded(json run, const std::string& run_dir) {
  {
    std::lock_guard<std::mutex> lk(mu_);
    info_ = run["info"];
    recorded_ = run.dump(-1, ' ', false, json::error_handler_t::replace);
  }
  // /run/ before any route: httplib's mount point followed symbolic links (found in review:
  // /run/pw with pw -> /etc/passwd served it) and served dotfiles.
  std::error_code ec;
  fs::path root = fs::canonical(run_dir, ec);
  if (ec) root = fs::absolute(run_dir).lexically_normal();
  http_->set_pre_routing_handler([root](const httplib::Request& req, httplib::Response& res) {
    if (req.path != "/run" && req.path.rfind("/run/", 0) != 0) return httplib::Server::HandlerResponse::Unhandled;
    const fs::path file =
        (req.method == "GET" || req.method == "HEAD") ? run_file(root, req.path.substr(4)) : fs::path();
    std::ifstream f(file, std::ios::binary);
    if (file.empty() || !f) {
      res.status = 404;
      return httplib::Server::HandlerResponse::Handled;
    }
    // The status (200, or 206 with the byte ranges asked for) is httplib's, as for its files.
    res.set_content(std::string(std::istreambuf_iterator<char>(f), {}), content_type(file));
    return httplib::Server::HandlerResponse::Handled;
  });
  // The page reads /api/run; a stream gets the run's info and end and ends. Nothing closed it
  // before: it sent ": idle" for ever and held its worker (found in review).
  publish("info", run["info"]);
  if (run.contains("end") && !run["end"].is_null()) publish("end", run["end"]);
  close_streams();
}

WebServer::Stats WebServer::stats() const {
  std::lock_guard<std::mutex> lk(mu_);
  return stats_;
}

}  // namespace omnitwin::twin
