// Test support for the command-line tests (cli_test.cpp, cli_outputs_test.cpp): an
// `omnitwin` (or any program) child process started with posix_spawn, its output captured to
// files, and a fixture with a temp work dir. A header, so no test binary is built from it.
#pragma once

#include <gtest/gtest.h>
#include <nlohmann/json.hpp>

#include <fcntl.h>
#include <signal.h>
#include <spawn.h>
#include <stdlib.h>
#include <sys/wait.h>
#include <unistd.h>

#include <algorithm>
#include <chrono>
#include <cstring>
#include <filesystem>
#include <regex>
#include <string>
#include <thread>
#include <vector>

#include "tests/support/mujoco_fixture.hpp"
#include "tests/support/temp_dir.hpp"
#include "twin/process_tree.hpp"

extern char** environ;

namespace omnitwin::twin::cli {

namespace fs = std::filesystem;
using namespace std::chrono_literals;
using omnitwin::testing::binary_path;
using omnitwin::testing::read_bytes;
using omnitwin::testing::source_path;
using omnitwin::testing::TempDir;

// ---------------------------------------------------------------------------------------
// Helpers: files

inline std::string test_scenario(const std::string& name) { return source_path("tests/data/scenarios/" + name); }

inline bool contains(const std::string& text, const std::string& part) { return text.find(part) != std::string::npos; }

inline std::size_t count_char(const std::string& text, char c) { return std::count(text.begin(), text.end(), c); }

// ---------------------------------------------------------------------------------------
// Helpers: the child process

inline std::string omnitwin_binary() { return binary_path("twin/omnitwin"); }

// One `omnitwin` child: started with posix_spawn in `cwd`, stdin from /dev/null, stdout
// and stderr into files under `io`. The destructor kills and reaps it if still running.
class Child {
 public:
  Child(const std::vector<std::string>& args, const fs::path& cwd, const fs::path& io)
      : Child(omnitwin_binary(), args, cwd, io, "") {}
  // Any program; `tag` keeps its captured output apart from another child's. `own_group`: the
  // child leads a process group of its own, as a shell's foreground job does, so that
  // signal_group() reaches it and everything it started, as a Ctrl-C at a terminal does.
  Child(const std::string& program, const std::vector<std::string>& args, const fs::path& cwd, const fs::path& io,
        const std::string& tag, bool own_group = false)
      : out_(io / (tag + "stdout")), err_(io / (tag + "stderr")) {
    std::vector<std::string> argv_s{program};
    argv_s.insert(argv_s.end(), args.begin(), args.end());
    std::vector<char*> argv;
    for (auto& a : argv_s) argv.push_back(a.data());
    argv.push_back(nullptr);
    // Redirections and working directory.
    posix_spawn_file_actions_t fa;
    posix_spawn_file_actions_init(&fa);
    posix_spawn_file_actions_addopen(&fa, 0, "/dev/null", O_RDONLY, 0);
    posix_spawn_file_actions_addopen(&fa, 1, out_.c_str(), O_WRONLY | O_CREAT | O_TRUNC, 0644);
    posix_spawn_file_actions_addopen(&fa, 2, err_.c_str(), O_WRONLY | O_CREAT | O_TRUNC, 0644);
    posix_spawn_file_actions_addchdir_np(&fa, cwd.c_str());
    // Default dispositions and an empty mask, whatever the test runner inherited.
    posix_spawnattr_t at;
    posix_spawnattr_init(&at);
    sigset_t none, defaults;
    sigemptyset(&none);
    sigemptyset(&defaults);
    sigaddset(&defaults, SIGINT);
    sigaddset(&defaults, SIGTERM);
    posix_spawnattr_setsigmask(&at, &none);
    posix_spawnattr_setsigdefault(&at, &defaults);
    posix_spawnattr_setpgroup(&at, 0);
    posix_spawnattr_setflags(&at, static_cast<short>(POSIX_SPAWN_SETSIGMASK | POSIX_SPAWN_SETSIGDEF |
                                                     (own_group ? POSIX_SPAWN_SETPGROUP : 0)));
    const int rc = posix_spawn(&pid_, argv[0], &fa, &at, argv.data(), environ);
    posix_spawn_file_actions_destroy(&fa);
    posix_spawnattr_destroy(&at);
    if (rc != 0) throw std::runtime_error("posix_spawn " + argv_s[0] + ": " + std::strerror(rc));
  }
  ~Child() {
    if (pid_ <= 0) return;
    ::kill(pid_, SIGKILL);
    ::waitpid(pid_, nullptr, 0);
  }
  Child(const Child&) = delete;
  Child& operator=(const Child&) = delete;

  bool running() { return pid_ > 0 && !reap(WNOHANG); }
  void signal(int sig) const {
    if (pid_ > 0) ::kill(pid_, sig);
  }
  pid_t pid() const { return pid_; }
  // The whole process group (a child started with own_group).
  void signal_group(int sig) const {
    if (pid_ > 0) ::kill(-pid_, sig);
  }

  // Waits up to `limit` for the exit. Returns the exit code, 128 + N if killed by signal
  // N, or -1 on timeout (the child is then killed by the destructor).
  int wait(std::chrono::milliseconds limit) {
    const auto deadline = std::chrono::steady_clock::now() + limit;
    while (pid_ > 0 && !reap(WNOHANG)) {
      if (std::chrono::steady_clock::now() > deadline) return -1;
      std::this_thread::sleep_for(10ms);
    }
    return code_;
  }

  std::string out() const { return read_bytes(out_); }
  std::string err() const { return read_bytes(err_); }

  // Waits up to `limit` until stdout holds `text` (e.g. the twin's "waiting for a master"
  // line), or the child ends. Returns whether stdout holds it.
  bool wait_for_output(const std::string& text, std::chrono::milliseconds limit = std::chrono::seconds(20)) {
    const auto deadline = std::chrono::steady_clock::now() + limit;
    while (out().find(text) == std::string::npos && running() && std::chrono::steady_clock::now() < deadline)
      std::this_thread::sleep_for(20ms);
    return out().find(text) != std::string::npos;
  }

 private:
  // Collects the child if it has ended; keeps its exit code (128 + N for signal N).
  bool reap(int flags) {
    int status = 0;
    if (::waitpid(pid_, &status, flags) != pid_) return false;
    code_ = WIFEXITED(status) ? WEXITSTATUS(status) : 128 + WTERMSIG(status);
    pid_ = 0;
    return true;
  }

  pid_t pid_ = 0;
  int code_ = -1;
  fs::path out_, err_;
};

struct Finished {
  int code;
  std::string out, err;
};

// Base for every CLI test: a temp dir (work/ is the child's cwd, io/ its captured output).
// Checks first that the omnitwin binary exists: the build makes it before twin_tests, so its
// absence is a broken build and a hard failure (the test body then does not run), not a skip.
class CliTest : public ::testing::Test {
 public:
  // A run directory's metrics.json.
  static nlohmann::json metrics(const fs::path& run_dir) {
    return nlohmann::json::parse(read_bytes(run_dir / "metrics.json"));
  }

 protected:
  void SetUp() override {
    if (!fs::is_regular_file(omnitwin_binary()))
      FAIL() << "omnitwin binary missing at " << omnitwin_binary()
             << " (twin_tests depends on the omnitwin target; build it)";
    fs::create_directories(work());
    fs::create_directories(io());
  }
  fs::path work() const { return dir_ / "work"; }
  fs::path io() const { return dir_ / "io"; }

  // Runs omnitwin to completion (limit 120 s) and returns its exit code and output.
  Finished run(const std::vector<std::string>& args) {
    Child c(args, work(), io());
    const int code = c.wait(120s);
    EXPECT_NE(code, -1) << "omnitwin did not finish within 120 s";
    return {code, c.out(), c.err()};
  }
  // `omnitwin run tests/data/scenarios/NAME --out OUT --no-progress --set S…`.
  Finished run_test_scenario(const std::string& name, const fs::path& out, const std::vector<std::string>& sets = {}) {
    std::vector<std::string> args{"run", test_scenario(name), "--out", out.string(), "--no-progress"};
    for (const auto& s : sets) args.insert(args.end(), {"--set", s});
    return run(args);
  }

  TempDir dir_{"omnitwin-cli"};
};

// Copies files into a fresh directory `name` under the temp dir; returns it.
inline fs::path scenario_dir(const TempDir& dir, const std::string& name, const std::vector<std::string>& files) {
  const fs::path d = dir / name;
  fs::create_directories(d);
  for (const auto& f : files) fs::copy_file(test_scenario(f), d / f);
  return d;
}

// ---------------------------------------------------------------------------------------
// Helpers: a run's records and processes (cli_trust_test.cpp, cli_signals_slow_test.cpp)

// A realtime CAN run keeps the scenario's bus (python-can's group and port, for anyone to
// join); tests that run side by side under ctest -j take a free port each instead, or one
// run's master keeps the other's supervision content.
inline const char* const kOwnCanBus = "bus.transport=udp:239.74.163.2:0";

// Files of the run directory left under a temporary name only.
inline std::vector<std::string> part_files(const fs::path& dir) {
  std::vector<std::string> parts;
  if (!fs::exists(dir)) return parts;
  for (const auto& e : fs::recursive_directory_iterator(dir))
    if (e.path().filename().string().ends_with(".part")) parts.push_back(e.path().filename().string());
  return parts;
}

// ffmpeg decodes every frame of `file` without an error.
inline bool video_decodes(const fs::path& file) {
  const std::string cmd = "ffmpeg -v error -xerror -i '" + file.string() + "' -f null - >/dev/null 2>&1";
  return std::system(cmd.c_str()) == 0;
}

// tshark reads the capture to its end.
inline bool capture_reads(const fs::path& file) {
  const std::string cmd = "tshark -r '" + file.string() + "' >/dev/null 2>&1";
  return std::system(cmd.c_str()) == 0;
}

// Waits until `file` holds `text` (or the child ends / 60 s pass).
inline bool wait_for_text(const fs::path& file, const std::string& text, Child& c) {
  for (int i = 0; i < 6000; ++i) {
    if (contains(read_bytes(file), text)) return true;
    if (!c.running()) return contains(read_bytes(file), text);
    std::this_thread::sleep_for(10ms);
  }
  return false;
}

// The CPU time a process has used (user and system, all its threads) [s]; -1 once it is gone.
inline double cpu_seconds(pid_t pid) {
  const auto p = omnitwin::twin::process_entry(pid);
  return p ? static_cast<double>(p->cpu) / static_cast<double>(::sysconf(_SC_CLK_TCK)) : -1;
}

// Waits until the child has used `more` seconds of CPU beyond what it had used when called
// (or it ends, or 60 s of wall time pass): a point in its work that a loaded machine moves in
// wall time but not in CPU time (e.g. the first frames of a video rendered).
inline bool wait_for_cpu(Child& c, double more) {
  const double from = cpu_seconds(c.pid());
  for (int i = 0; i < 6000 && c.running(); ++i) {
    if (cpu_seconds(c.pid()) >= from + more) return true;
    std::this_thread::sleep_for(10ms);
  }
  return false;
}

// The master's pid, from the run's event log while it is written (.events.log.part); -1
// unless it names a child of the twin `c` (a signal to any other process would test nothing).
inline pid_t master_pid(const fs::path& run_dir, Child& c) {
  const fs::path log = run_dir / ".events.log.part";
  if (!wait_for_text(log, "started (pid ", c)) return -1;
  std::smatch m;
  const std::string text = read_bytes(log);
  if (!std::regex_search(text, m, std::regex("started \\(pid ([0-9]+)"))) return -1;
  const auto pid = static_cast<pid_t>(std::stol(m[1]));
  const auto entry = omnitwin::twin::process_entry(pid);
  return entry && entry->ppid == c.pid() ? pid : -1;
}

}  // namespace omnitwin::twin::cli
