// twin/web — the live run observer of the browser view (see web_observer.hpp).
#include "twin/web/web_observer.hpp"

#include <chrono>

#include "twin/web/web_samples.hpp"

namespace omnitwin::twin {

namespace {
// A few seconds of samples at any realistic rate: the pump empties it every 100 ms.
constexpr std::size_t kRingCapacity = 4096;
constexpr auto kPumpPeriod = std::chrono::milliseconds(100);
}  // namespace

WebRunObserver::WebRunObserver(WebServer& server, double rate_hz)
    : server_(server), decimator_(rate_hz), ring_(kRingCapacity) {}

WebRunObserver::~WebRunObserver() {
  stop_.store(true);
  if (pump_.joinable()) pump_.join();
}

void WebRunObserver::on_start(const RunInfo& info) {
  nlohmann::json j = info_json(info, true);
  server_.set_info(j);
  server_.publish("info", j);
  if (!pump_.joinable()) pump_ = std::thread([this] { pump(); });
}

void WebRunObserver::on_state(const StateSample& s) {
  if (!decimator_.take(s.t_ns)) return;
  if (!ring_.push(s)) ring_full_.fetch_add(1, std::memory_order_relaxed);
}

void WebRunObserver::on_event(const RunEvent& e) {
  std::lock_guard<std::mutex> lk(events_mu_);
  events_.push_back(e);
}

void WebRunObserver::on_end(const nlohmann::json& metrics) {
  stop_.store(true);
  if (pump_.joinable()) pump_.join();
  flush();
  server_.publish("end", end_json(metrics, std::nullopt));
  server_.close_streams();
}

void WebRunObserver::pump() {
  while (!stop_.load()) {
    std::this_thread::sleep_for(kPumpPeriod);
    flush();
  }
}

// What arrived since the last flush, as one "samples" and one "log" message.
void WebRunObserver::flush() {
  nlohmann::json batch = nlohmann::json::array();
  StateSample s;
  while (ring_.pop(s)) batch.push_back(sample_json(s));
  if (!batch.empty()) {
    published_.fetch_add(batch.size(), std::memory_order_relaxed);
    server_.publish("samples", batch);
  }
  std::vector<RunEvent> events;
  {
    std::lock_guard<std::mutex> lk(events_mu_);
    events.swap(events_);
  }
  if (events.empty()) return;
  nlohmann::json log = nlohmann::json::array();
  for (const RunEvent& e : events) log.push_back(event_json(e));
  server_.publish("log", log);
}

WebRunObserver::Stats WebRunObserver::stats() const {
  return {published_.load(), ring_full_.load()};
}

}  // namespace omnitwin::twin
