// Tests of the DDS echo (twin/dds/dds_echo.hpp), run_echo in a thread against a publisher
// in this process, and once in a child process (this test program re-executed) so that
// discovery and data cross the loopback interface: JSON lines carry the exact values
// offered, --count ends the echo, --timeout ends it with 1 when samples are missing and 0
// when a stream went quiet, the stop flag ends it, unknown topics are refused, and the text
// form is one line per sample.
#include <gtest/gtest.h>
#include <nlohmann/json.hpp>
#include <poll.h>
#include <spawn.h>
#include <sys/wait.h>
#include <unistd.h>

#include <atomic>
#include <cstdlib>
#include <future>
#include <iostream>
#include <sstream>
#include <thread>
#include <vector>

#include "tests/support/temp_dir.hpp"
#include "tests/twin/dds_test_support.hpp"
#include "twin/dds/dds_echo.hpp"
#include "twin/dds/dds_publisher.hpp"

extern char** environ;

namespace omnitwin::twin {
namespace {

using ddstest::make_sample;
using ddstest::test_domain;
using nlohmann::json;
using omnitwin::testing::lines_of;

EchoOptions echo_options(const std::string& topic, std::uint64_t count, double timeout_s, bool json = true) {
  EchoOptions o;
  o.domain = test_domain();
  o.interface = "lo";
  o.topic = topic;
  o.count = count;
  o.timeout_s = timeout_s;
  o.json = json;
  return o;
}

DdsSettings publisher_settings(double rate_hz = 1000) {
  DdsSettings s;
  s.domain = test_domain();
  s.interface = "lo";
  s.rate_hz = rate_hz;
  return s;
}

RunInfo run_info(const std::string& scenario) { return RunInfo{scenario, "direct", "lockstep", "", 0.001, 1}; }

// run_echo on its own thread, its output collected.
struct EchoThread {
  explicit EchoThread(EchoOptions o, const std::atomic<bool>* stop = nullptr)
      : result(std::async(std::launch::async, [this, o, stop] { return run_echo(o, out, stop); })) {}
  std::vector<json> json_lines() const {
    std::vector<json> v;
    for (const std::string& l : lines_of(out.str())) v.push_back(json::parse(l));
    return v;
  }
  std::ostringstream out;
  std::future<int> result;
};

TEST(DdsEcho, PrintsRunEventsAsJsonLinesAndStopsAtCount) {
  DdsPublisher pub(publisher_settings());
  pub.start(run_info("echo-events"));
  pub.event(RunEvent{1'500'000'000, RunEventKind::fault, "fault", "node 3 bus-off"});
  pub.event(RunEvent{1'600'000'000, RunEventKind::info, "master", "more"});  // beyond count
  EchoThread echo(echo_options("events", 2, 5.0));
  ASSERT_EQ(echo.result.get(), kEchoOk);
  const std::vector<json> lines = echo.json_lines();
  ASSERT_EQ(lines.size(), 2u);
  EXPECT_EQ(lines[0]["topic"], "run_events");
  EXPECT_EQ(lines[0]["kind"], "start");
  EXPECT_EQ(lines[0]["scenario"], "echo-events");
  EXPECT_EQ(lines[1]["kind"], "fault");
  EXPECT_EQ(lines[1]["source"], "fault");
  EXPECT_EQ(lines[1]["text"], "node 3 bus-off");
  EXPECT_EQ(lines[1]["t"], 1.5);
  EXPECT_EQ(lines[1]["t_ns"], 1'500'000'000);
}

// A text that is not UTF-8 (a run directory's name can be any bytes) is printed with the
// bad bytes replaced: the JSON form threw and ended the echo with exit 3 (found in review).
TEST(DdsEcho, JsonOfATextThatIsNotUtf8IsPrintedNotThrown) {
  DdsPublisher pub(publisher_settings());
  pub.start(run_info("echo-bytes"));
  pub.event(RunEvent{1'000'000, RunEventKind::info, "twin", "run_dir=/tmp/caf\xe9"});
  EchoThread echo(echo_options("events", 2, 5.0));
  ASSERT_EQ(echo.result.get(), kEchoOk);
  const std::vector<json> lines = echo.json_lines();
  ASSERT_EQ(lines.size(), 2u);
  EXPECT_EQ(lines[1]["text"], "run_dir=/tmp/caf\xef\xbf\xbd");  // U+FFFD
}

TEST(DdsEcho, PlatformStateJsonCarriesTheExactValues) {
  DdsPublisher pub(publisher_settings());
  pub.start(run_info("echo-state"));
  EchoThread echo(echo_options("state", 5, 5.0));
  // Offer until the echo has its five samples (best-effort: it sees those after it matched).
  std::uint64_t i = 0;
  while (echo.result.wait_for(std::chrono::milliseconds(1)) != std::future_status::ready && i < 5000)
    pub.offer(make_sample(i++));
  ASSERT_EQ(echo.result.get(), kEchoOk);
  const std::vector<json> lines = echo.json_lines();
  ASSERT_EQ(lines.size(), 5u);
  for (const json& j : lines) {
    const StateSample s = make_sample(j["seq"].get<std::uint64_t>());
    EXPECT_EQ(j["topic"], "platform_state");
    EXPECT_EQ(j["t_ns"].get<std::int64_t>(), s.t_ns);
    EXPECT_EQ(j["x"].get<double>(), s.x);
    EXPECT_EQ(j["phi"].get<double>(), s.phi);
    EXPECT_EQ(j["cmd_vy"].get<double>(), s.cmd_vy);
    EXPECT_EQ(j["wheel_torque"][3].get<double>(), s.wheel_torque[3]);
    EXPECT_EQ(j["active_faults"].get<std::uint32_t>(), s.active_faults);
  }
  EXPECT_LT(lines[0]["seq"].get<std::uint64_t>(), lines[4]["seq"].get<std::uint64_t>());
}

// ... and says why on stderr (it exited 1 without a word; found by a walkthrough).
TEST(DdsEcho, TimeoutWithNoSampleReturnsOne) {
  std::ostringstream err;
  std::streambuf* const old = std::cerr.rdbuf(err.rdbuf());
  EchoThread echo(echo_options("odom", 0, 0.3));
  const int code = echo.result.get();
  std::cerr.rdbuf(old);
  EXPECT_EQ(code, kEchoTimeout);
  EXPECT_EQ(echo.out.str(), "");
  EXPECT_EQ(err.str(), "omnitwin echo: no sample within 0.3 s\n");
}

TEST(DdsEcho, TimeoutBeforeCountReturnsOneAndAQuietStreamReturnsZero) {
  DdsPublisher pub(publisher_settings());
  pub.start(run_info("quiet"));  // one event: start
  EchoThread short_of_count(echo_options("run_events", 3, 0.5));
  EXPECT_EQ(short_of_count.result.get(), kEchoTimeout);
  EXPECT_EQ(short_of_count.json_lines().size(), 1u);
  EchoThread until_quiet(echo_options("rt/omnitwin/run_events", 0, 0.5));
  EXPECT_EQ(until_quiet.result.get(), kEchoOk);
  EXPECT_EQ(until_quiet.json_lines().size(), 1u);
}

TEST(DdsEcho, StopFlagEndsAnEndlessEcho) {
  std::atomic<bool> stop{false};
  EchoThread echo(echo_options("all", 0, 0), &stop);
  std::this_thread::sleep_for(std::chrono::milliseconds(150));
  stop = true;
  ASSERT_EQ(echo.result.wait_for(std::chrono::seconds(2)), std::future_status::ready);
  EXPECT_EQ(echo.result.get(), kEchoOk);
}

TEST(DdsEcho, UnknownTopicIsRefused) {
  std::ostringstream out;
  EXPECT_THROW(run_echo(echo_options("wheels", 1, 1), out, nullptr), std::invalid_argument);
  EXPECT_TRUE(find_topic("drives") && find_topic("drives")->name == "rt/omnitwin/drive_states");
  EXPECT_TRUE(find_topic("rt/omnitwin/bus_statistics") && find_topic("bus_statistics"));
}

TEST(DdsEcho, TextFormIsOneLinePerSample) {
  DdsPublisher pub(publisher_settings());
  pub.start(run_info("text"));
  pub.event(RunEvent{250'000'000, RunEventKind::expectation, "scenario", "final_error_cm <= 2"});
  EchoThread echo(echo_options("events", 2, 5.0, false));
  ASSERT_EQ(echo.result.get(), kEchoOk);
  const std::vector<std::string> lines = lines_of(echo.out.str());
  ASSERT_EQ(lines.size(), 2u);
  EXPECT_EQ(lines[0].rfind("run_events t=0 kind=start source=twin text=scenario=text", 0), 0u) << lines[0];
  EXPECT_EQ(lines[1], "run_events t=0.25 kind=expectation source=scenario text=final_error_cm <= 2 scenario=text");
}

// The child half of CrossesTheLoopbackInterfaceToAnotherProcess: only runs when that test
// re-executes this program with OMNITWIN_DDS_ECHO_CHILD=<domain>.
TEST(DdsEchoChild, EchoesRunEventsToStdout) {
  const char* domain = std::getenv("OMNITWIN_DDS_ECHO_CHILD");
  if (!domain) GTEST_SKIP() << "the child half of a cross-process test";
  EchoOptions o;
  o.domain = std::atoi(domain);
  o.config_file = ddstest::loopback_config();
  o.topic = "events";
  o.count = 2;
  o.timeout_s = 8;
  o.json = true;
  ASSERT_EQ(run_echo(o, std::cout, nullptr), kEchoOk);
}

// Starts this program as the child echo; returns its pid and the read end of its stdout.
std::pair<pid_t, int> spawn_child_echo(int domain) {
  int fds[2];
  EXPECT_EQ(::pipe(fds), 0);
  posix_spawn_file_actions_t fa;
  posix_spawn_file_actions_init(&fa);
  posix_spawn_file_actions_adddup2(&fa, fds[1], STDOUT_FILENO);
  posix_spawn_file_actions_addclose(&fa, fds[0]);
  std::vector<std::string> env{"OMNITWIN_DDS_ECHO_CHILD=" + std::to_string(domain)};
  for (char** e = environ; *e; ++e) env.emplace_back(*e);
  std::vector<char*> envp;
  for (std::string& e : env) envp.push_back(e.data());
  envp.push_back(nullptr);
  std::string exe = "/proc/self/exe", filter = "--gtest_filter=DdsEchoChild.EchoesRunEventsToStdout";
  char* argv[] = {exe.data(), filter.data(), nullptr};
  pid_t pid = -1;
  EXPECT_EQ(posix_spawn(&pid, exe.c_str(), &fa, nullptr, argv, envp.data()), 0);
  posix_spawn_file_actions_destroy(&fa);
  ::close(fds[1]);
  return {pid, fds[0]};
}

// Everything the child writes until it closes stdout or the deadline passes.
std::string read_until_eof(int fd, double timeout_s) {
  std::string text;
  const auto end = std::chrono::steady_clock::now() + std::chrono::duration<double>(timeout_s);
  char buf[4096];
  while (std::chrono::steady_clock::now() < end) {
    pollfd p{fd, POLLIN, 0};
    if (::poll(&p, 1, 50) <= 0) continue;
    const ssize_t n = ::read(fd, buf, sizeof buf);
    if (n <= 0) break;
    text.append(buf, static_cast<std::size_t>(n));
  }
  ::close(fd);
  return text;
}

TEST(DdsEcho, CrossesTheLoopbackInterfaceToAnotherProcess) {
  DdsSettings s;
  s.domain = test_domain(2);
  s.config_file = ddstest::loopback_config();
  DdsPublisher pub(s);
  pub.start(run_info("cross"));
  pub.event(RunEvent{42, RunEventKind::info, "master", "hello from the parent"});
  auto [pid, fd] = spawn_child_echo(s.domain);
  ASSERT_GT(pid, 0);
  const std::string out = read_until_eof(fd, 10.0);
  int status = 0;
  if (!ddstest::wait_until([&] { return ::waitpid(pid, &status, WNOHANG) == pid; }, 3.0))
    ::kill(pid, SIGKILL), ::waitpid(pid, &status, 0);
  ASSERT_TRUE(WIFEXITED(status) && WEXITSTATUS(status) == 0) << out;
  std::vector<json> events;
  for (const std::string& l : lines_of(out))
    if (!l.empty() && l[0] == '{') events.push_back(json::parse(l));
  ASSERT_EQ(events.size(), 2u) << out;
  EXPECT_EQ(events[0]["kind"], "start");
  EXPECT_EQ(events[1]["text"], "hello from the parent");
  EXPECT_EQ(events[1]["scenario"], "cross");
  pub.finish();
}

}  // namespace
}  // namespace omnitwin::twin
