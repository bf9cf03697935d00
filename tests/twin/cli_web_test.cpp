// Tests the CLI's browser view (twin/main.cpp: --web, --web-wait, `omnitwin view`) through the
// real program and real HTTP on loopback: bad addresses and flags refused with exit 2, the
// twin for an external master streaming its run (info, samples with the drives' protocol
// states, the end) to a page, `omnitwin view` serving a recorded run until SIGTERM (exit 0),
// and clients that trickle requests neither holding the program at its end nor, with a HEAD,
// starting a --web-wait run. The page itself is tested in a browser (tests/media/web).
#include <arpa/inet.h>
#include <gtest/gtest.h>
#include <httplib.h>
#include <netinet/in.h>
#include <sys/socket.h>

#include <atomic>
#include <csignal>
#include <memory>
#include <regex>

#include "tests/twin/cli_support.hpp"

namespace omnitwin::twin {
namespace {

using namespace omnitwin::twin::cli;  // Child, CliTest, fs, the path helpers

// Clients that connected to 127.0.0.1:`port`, began a request and add a byte to its headers
// every 200 ms until stop().
class Tricklers {
 public:
  Tricklers(int port, int n) {
    for (int k = 0; k < n; ++k) {
      const int fd = ::socket(AF_INET, SOCK_STREAM, 0);
      sockaddr_in a{};
      a.sin_family = AF_INET;
      a.sin_port = htons(static_cast<std::uint16_t>(port));
      a.sin_addr.s_addr = htonl(INADDR_LOOPBACK);
      if (fd < 0 || ::connect(fd, reinterpret_cast<sockaddr*>(&a), sizeof a) != 0) {
        if (fd >= 0) ::close(fd);
        throw std::runtime_error("cannot connect to port " + std::to_string(port));
      }
      fds_.push_back(fd);
      send(fd, "GET /api/info HTTP/1.1\r\nHost: x\r\nX-a: ");
    }
    thread_ = std::thread([this] {
      while (!stop_) {
        for (const int fd : fds_) send(fd, "a");
        std::this_thread::sleep_for(200ms);
      }
    });
  }
  ~Tricklers() { stop(); }
  void stop() {
    stop_ = true;
    if (thread_.joinable()) thread_.join();
    for (const int fd : fds_) ::close(fd);
    fds_.clear();
  }

 private:
  static void send(int fd, const std::string& s) { (void)::send(fd, s.data(), s.size(), MSG_NOSIGNAL); }
  std::vector<int> fds_;
  std::atomic<bool> stop_{false};
  std::thread thread_;
};

class CliWeb : public CliTest {
 protected:
  // A recorded run of a still platform, `duration` seconds on bus direct: its directory, or
  // "" (with a test failure) when the run failed.
  fs::path recorded_run(const std::string& duration) {
    const fs::path out = dir_ / "rec", scenario = dir_ / "still.yaml";
    std::ofstream(scenario) << "name: still\nplatform: {variant: capsule}\nduration: " << duration << "\n";
    const Finished f = run({"run", scenario.string(), "--bus", "direct", "--out", out.string(), "--no-progress",
                            "--no-video", "--no-report"});
    EXPECT_EQ(f.code, 0) << f.out << f.err;
    return f.code == 0 ? out : fs::path();
  }

  // The port of the "web view: http://127.0.0.1:PORT/" line on the child's stderr (0: none
  // within 20 s).
  static int web_port(Child& c) {
    const std::regex line(R"(web view: http://127\.0\.0\.1:(\d+)/)");
    for (int i = 0; i < 1000 && c.running(); ++i) {
      std::smatch m;
      const std::string err = c.err();
      if (std::regex_search(err, m, line)) return std::stoi(m[1]);
      std::this_thread::sleep_for(20ms);
    }
    return 0;
  }
};

TEST_F(CliWeb, RefusesBadAddressesAndAWaitWithoutAView) {
  const std::string scenario = source_path("models/scenarios/thesis_line.yaml");
  Finished f = run({"run", scenario, "--web", "localhost:http", "--no-progress"});
  EXPECT_EQ(f.code, 2) << f.err;
  EXPECT_TRUE(contains(f.err, "want [ADDR:]PORT")) << f.err;
  f = run({"run", scenario, "--web-wait", "--no-progress"});
  EXPECT_EQ(f.code, 2) << f.err;
  EXPECT_TRUE(contains(f.err, "--web-wait needs --web")) << f.err;
  f = run({"view", work().string()});
  EXPECT_EQ(f.code, 2) << f.err;
  EXPECT_TRUE(contains(f.err, "not a run directory")) << f.err;
  EXPECT_FALSE(fs::exists(work() / "out"));  // nothing was run
}

// The twin waits for an external master (none comes); a page that opens mid-run gets the run
// from its start, the drives in the protocol's words, and the end with the verdict.
TEST_F(CliWeb, TwinStreamsItsRunToAPage) {
  const fs::path out = dir_ / "twin", scenario = dir_ / "bare.yaml";
  std::ofstream(scenario) << "name: bare\nplatform: {variant: capsule}\n";
  Child c({"twin", scenario.string(), "--bus", "canopen", "--set", "bus.transport=udp:239.74.163.2:47613", "--duration",
           "1.5", "--out", out.string(), "--no-progress", "--no-video", "--no-report", "--web", "127.0.0.1:0"},
          work(), io());
  const int port = web_port(c);
  ASSERT_GT(port, 0) << c.err();
  httplib::Client http("127.0.0.1", port);
  http.set_read_timeout(20, 0);
  std::string stream;
  auto r = http.Get("/api/stream", [&](const char* d, std::size_t n) {
    stream.append(d, n);
    return true;
  });
  ASSERT_TRUE(r) << httplib::to_string(r.error());
  EXPECT_EQ(c.wait(30s), 1) << c.out() << c.err();  // no master connected
  EXPECT_TRUE(contains(stream, "event: info\ndata: {")) << stream.substr(0, 300);
  EXPECT_TRUE(contains(stream, R"("started":true)"));
  EXPECT_TRUE(contains(stream, R"("bus":"canopen")"));
  EXPECT_TRUE(contains(stream, "event: samples\ndata: [{"));
  EXPECT_TRUE(contains(stream, R"("t":0.0,)")) << "the page got the run from its start";
  EXPECT_TRUE(contains(stream, R"("comm":"pre_operational")")) << "CANopen drives wait in NMT pre-operational";
  EXPECT_TRUE(contains(stream, "event: end\ndata: {"));
  EXPECT_TRUE(contains(stream, R"("passed":false)"));
  EXPECT_TRUE(contains(stream, "no master connected"));
  EXPECT_TRUE(contains(c.out(), "web view: ")) << c.out();
}

TEST_F(CliWeb, ViewServesARecordedRunUntilSigterm) {
  const fs::path out = recorded_run("2");
  ASSERT_FALSE(out.empty());
  Child c({"view", out.string(), "--web", "127.0.0.1:0"}, work(), io());
  const int port = web_port(c);
  ASSERT_GT(port, 0) << c.err();
  httplib::Client http("127.0.0.1", port);
  auto r = http.Get("/api/run");
  ASSERT_TRUE(r);
  const nlohmann::json run = nlohmann::json::parse(r->body);
  EXPECT_EQ(run["info"]["mode"], "recorded");
  EXPECT_TRUE(run["info"]["video"].is_null());  // this run has none
  EXPECT_GE(run["samples"].size(), 50u);        // 2 s at 25 samples per second
  EXPECT_EQ(run["end"]["passed"], true);
  r = http.Get("/api/scene");
  ASSERT_TRUE(r);
  EXPECT_GT(nlohmann::json::parse(r->body)["geoms"].size(), 10u);
  c.signal(SIGTERM);
  EXPECT_EQ(c.wait(10s), 0) << c.err();
}

// `omnitwin view`: a page's event stream of the recorded run ends (it sent ": idle" for ever),
// and Ctrl-C ends the program at once although two clients trickle requests and one is idle
// (found in review: 20 s, the server's workers waiting for the trickling clients).
TEST_F(CliWeb, ViewsStreamEndsAndCtrlCEndsItWhateverClientsDo) {
  const fs::path out = recorded_run("0.5");
  ASSERT_FALSE(out.empty());
  Child c({"view", out.string(), "--web", "127.0.0.1:0"}, work(), io());
  const int port = web_port(c);
  ASSERT_GT(port, 0) << c.err();
  httplib::Client http("127.0.0.1", port);
  std::string stream;
  const auto t0 = std::chrono::steady_clock::now();
  auto r = http.Get("/api/stream", [&](const char* d, std::size_t n) {
    stream.append(d, n);
    return std::chrono::steady_clock::now() - t0 < 3s;  // an endless stream: give up
  });
  EXPECT_TRUE(r) << httplib::to_string(r.error()) << "\n" << stream.substr(0, 300);
  EXPECT_TRUE(contains(stream, "event: info\ndata: {")) << stream.substr(0, 300);
  EXPECT_TRUE(contains(stream, R"("mode":"recorded")"));
  EXPECT_TRUE(contains(stream, "event: end\ndata: {"));
  Tricklers slow(port, 2);
  httplib::Client idle("127.0.0.1", port);
  idle.set_keep_alive(true);
  ASSERT_TRUE(idle.Get("/api/info"));  // its connection stays open, idle
  std::this_thread::sleep_for(300ms);
  c.signal(SIGINT);
  const int code = c.wait(2s);
  slow.stop();  // lets a program that waited for them end
  EXPECT_EQ(code, 0) << "not ended 2 s after Ctrl-C\n" << c.err();
}

// `run --web-wait`: a HEAD of the stream is no page (it started the run), the page's GET is;
// and the finished run ends at once although a client trickles a request (found in review:
// it ended only when the client stopped).
TEST_F(CliWeb, RunWaitsForAPageNotAHeadAndEndsWhateverClientsDo) {
  const fs::path out = dir_ / "live", scenario = dir_ / "still.yaml";
  std::ofstream(scenario) << "name: still\nplatform: {variant: capsule}\nduration: 0.5\n";
  Child c({"run", scenario.string(), "--bus", "direct", "--out", out.string(), "--no-progress", "--no-video",
           "--no-report", "--web", "127.0.0.1:0", "--web-wait"},
          work(), io());
  const int port = web_port(c);
  ASSERT_GT(port, 0) << c.err();
  httplib::Client http("127.0.0.1", port);
  http.set_read_timeout(20, 0);
  auto r = http.Head("/api/stream");
  ASSERT_TRUE(r) << httplib::to_string(r.error());
  std::this_thread::sleep_for(500ms);
  EXPECT_FALSE(fs::exists(out)) << "a HEAD started the run";
  ASSERT_TRUE(c.running()) << c.out() << c.err();
  Tricklers slow(port, 1);
  std::string stream;
  r = http.Get("/api/stream", [&](const char* d, std::size_t n) {
    stream.append(d, n);
    return true;
  });
  ASSERT_TRUE(r) << httplib::to_string(r.error());
  EXPECT_TRUE(contains(stream, "event: end\ndata: {")) << stream.substr(0, 300);
  const int code = c.wait(5s);
  slow.stop();
  EXPECT_EQ(code, 0) << "not ended 5 s after its page's stream\n" << c.out() << c.err();
  EXPECT_TRUE(contains(c.out(), "1 page opened")) << c.out();
}

}  // namespace
}  // namespace omnitwin::twin
