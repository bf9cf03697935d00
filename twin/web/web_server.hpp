// twin/web — the HTTP server of the browser view (cpp-httplib, Debian's libcpp-httplib-dev):
// the page and its libraries (media/web, three.js and uPlot from npm), the platform's scene,
// and the run's data. A live run streams as Server-Sent Events on /api/stream: every message
// is kept in a history that each new page gets first, so a page opened mid-run (or after a
// reconnect) draws the run from its start. A recorded run (`omnitwin view`) is one JSON
// document on /api/run, with the run directory's own files (its video) under /run/.
//
// The server runs on its own threads (httplib's pool of 32); nothing here is called from a
// run's cyclic path: the live observer (web_observer) decimates and batches on its own thread.
// No client holds the pool or the process: at most max_streams event streams are open (one
// more is answered 503), a request must arrive whole within request_timeout_s, an idle
// connection closes after keep_alive_timeout_s, and the destructor shuts every connection down.
// URLs and messages: docs/web-view.md.
#pragma once

#include <atomic>
#include <condition_variable>
#include <cstdint>
#include <deque>
#include <memory>
#include <mutex>
#include <string>
#include <thread>
#include <vector>

#include <nlohmann/json.hpp>

namespace omnitwin::twin {

struct WebSettings {
  std::string host = "127.0.0.1";  // loopback unless the user names another address
  int port = 0;                    // 0: the system picks a free port (printed in url())
  std::string assets_dir;          // media/web: index.html, view.js, node_modules/
  // The live history a page opened late gets [bytes of SSE text]: over it the oldest messages
  // but the first (the run's info) are dropped, and such a page starts after the gap. 256 MiB
  // is hours of a run at 20 samples per second (about 1.5 kB per sample).
  std::size_t history_cap_bytes = 256u << 20;
  // Event streams open at once (each holds one of the pool's 32 workers while open): one more
  // is answered 503, so that the other workers always answer the pages' other requests.
  int max_streams = 16;
  // A request's line and headers must arrive whole within this [s] of its first byte, and a
  // kept-alive connection idle this long is closed: a client that trickles its request or
  // keeps idle connections frees its worker within seconds.
  double request_timeout_s = 2.0;
  double keep_alive_timeout_s = 2.0;
};

// "[ADDR:]PORT" (e.g. "8080", "0.0.0.0:8080", "127.0.0.1:0"), with the assets directory filled
// from default_web_assets_dir(). Throws std::invalid_argument saying what is wrong.
WebSettings parse_web_address(const std::string& spec);

// $OMNITWIN_WEB_DIR, else the source tree's media/web.
std::string default_web_assets_dir();

class WebServer {
 public:
  // Checks the assets (index.html and the npm libraries: run `scripts/bootstrap build`) and
  // binds (url() is then known); start() serves. Throws std::runtime_error saying which asset
  // is missing or why the address cannot be bound.
  WebServer(const WebSettings& settings, nlohmann::json scene);
  void start();
  ~WebServer();
  WebServer(const WebServer&) = delete;
  WebServer& operator=(const WebServer&) = delete;

  // "http://HOST:PORT/".
  std::string url() const;

  // Live mode: what /api/info answers (a live run's info; "started" false until it runs).
  void set_info(nlohmann::json info);
  // Appends one SSE message (event name, JSON data) to the history and wakes the streams.
  // Thread-safe; allocates (never call it from a run's cyclic path).
  void publish(const std::string& event, const nlohmann::json& data);
  // No more messages: each stream ends once it has sent the whole history.
  void close_streams();
  // Waits until every open stream has sent the whole history, or timeout_s passed.
  void wait_streams_drained(double timeout_s);
  // Blocks until a page has opened /api/stream (true: a GET began receiving it; a HEAD does
  // not count), or *interrupt is set (false).
  bool wait_for_client(const std::atomic<bool>* interrupt);

  // Recorded mode: /api/run answers `run` and /run/ serves the run directory (the video): its
  // regular files whose real path lies inside the run directory's, none named with a dot (a
  // symbolic link out of it, or the .omnitwin-run marker, is 404). /api/stream sends the
  // run's info and end, then ends. Before start().
  void serve_recorded(nlohmann::json run, const std::string& run_dir);

  struct Stats {
    std::uint64_t messages = 0;      // published
    std::uint64_t bytes = 0;         // published (SSE text)
    std::uint64_t streams_opened = 0;   // GETs of /api/stream that began receiving it
    std::uint64_t streams_refused = 0;  // answered 503: max_streams were open
    std::uint64_t history_dropped = 0;  // oldest messages dropped over the history cap
  };
  Stats stats() const;

 private:
  bool stream_chunk(std::uint64_t& cursor, std::string& out);
  void add_routes();

  WebSettings settings_;
  class Http;  // httplib::Server with bounded connections (web_server.cpp)
  std::unique_ptr<Http> http_;
  std::thread listener_;
  std::atomic<bool> listener_done_{false};  // listen_after_bind() returned
  int port_ = 0;

  mutable std::mutex mu_;
  std::condition_variable changed_;
  nlohmann::json info_ = nlohmann::json::object();
  std::string scene_;                // serialized once
  std::string recorded_;             // /api/run, serialized once
  // Messages are numbered from 0 in publishing order; a stream's cursor is such a number.
  std::string first_;                 // message 0 (the run's info), never dropped
  std::deque<std::string> history_;   // messages base_ … total_ - 1
  std::uint64_t base_ = 1;
  std::uint64_t total_ = 0;           // messages published
  std::size_t history_bytes_ = 0;     // in history_
  bool closed_ = false;
  bool stopping_ = false;
  int open_streams_ = 0;
  Stats stats_;
};

}  // namespace omnitwin::twin
