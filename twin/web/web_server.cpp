// twin/web — the view's HTTP server (see web_server.hpp).
#include "twin/web/web_server.hpp"

#include <httplib.h>

#include <chrono>
#include <cstdlib>
#include <filesystem>
#include <fstream>
#include <iterator>
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

}  // namespace

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
    : settings_(settings), http_(std::make_unique<httplib::Server>()), scene_(scene.dump()) {
  check_assets(settings_.assets_dir);
  // Each open page holds a worker with its event stream and a few with keep-alive
  // connections: more workers than httplib's default (8) so that several pages fit.
  http_->new_task_queue = [] { return new httplib::ThreadPool(32); };
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
      ++open_streams_;
      ++stats_.streams_opened;
    }
    changed_.notify_all();
    auto cursor = std::make_shared<std::uint64_t>(0);
    res.set_chunked_content_provider(
        "text/event-stream",
        [this, cursor](std::size_t, httplib::DataSink& sink) {
          std::string out;
          const bool more = stream_chunk(*cursor, out);
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
  std::lock_guard<std::mutex> lk(mu_);
  info_ = run["info"];
  recorded_ = run.dump(-1, ' ', false, json::error_handler_t::replace);
  http_->set_mount_point("/run", run_dir);
}

WebServer::Stats WebServer::stats() const {
  std::lock_guard<std::mutex> lk(mu_);
  return stats_;
}

}  // namespace omnitwin::twin
