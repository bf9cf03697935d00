// media layer — the run report and check index through their Python scripts; see run_report.hpp.
#include "media/run_report.hpp"

#include <fcntl.h>
#include <poll.h>
#include <signal.h>
#include <spawn.h>
#include <sys/wait.h>
#include <unistd.h>

#include <algorithm>
#include <cerrno>
#include <chrono>
#include <cstring>
#include <filesystem>
#include <fstream>
#include <string>
#include <vector>

#include <nlohmann/json.hpp>

extern char** environ;

namespace omnitwin::media {
namespace {

namespace fs = std::filesystem;
using Clock = std::chrono::steady_clock;

constexpr std::size_t kMaxStderrBytes = 64 * 1024;  // what a script may say before we stop keeping it

// What became of one child process.
struct ProcessOutcome {
  std::string start_error;  // non-empty: it never ran (posix_spawn failed)
  bool timed_out = false;
  int exit_code = -1;       // valid when exited
  bool exited = false;
  int signal = 0;           // when killed by a signal
  std::string stderr_text;  // the first kMaxStderrBytes of its stderr
};

// Closes a file descriptor if open and marks it closed.
void close_fd(int& fd) {
  if (fd >= 0) ::close(fd);
  fd = -1;
}

// Reads the child's stderr until EOF or the deadline. Returns false on timeout (or if the
// pipe cannot be polled: the caller then kills the child rather than wait on it blind).
bool drain(int fd, Clock::time_point deadline, std::string& out) {
  char buf[4096];
  while (true) {
    const auto left = std::chrono::duration_cast<std::chrono::milliseconds>(deadline - Clock::now()).count();
    if (left <= 0) return false;
    pollfd p{fd, POLLIN, 0};
    const int n = ::poll(&p, 1, static_cast<int>(std::min<long long>(left, 1000)));
    if (n < 0 && errno == EINTR) continue;
    if (n < 0) return false;
    if (n == 0) continue;  // this slice timed out; the deadline decides
    const ssize_t got = ::read(fd, buf, sizeof buf);
    if (got < 0 && (errno == EINTR || errno == EAGAIN)) continue;
    if (got <= 0) return true;  // EOF: the child closed stderr (normally: it exited)
    if (out.size() < kMaxStderrBytes) out.append(buf, static_cast<std::size_t>(std::min<ssize_t>(got, kMaxStderrBytes)));
  }
}

// Waits for pid, retrying on EINTR; fills the exit status.
void reap(pid_t pid, ProcessOutcome& o) {
  int status = 0;
  pid_t r;
  do {
    r = ::waitpid(pid, &status, 0);
  } while (r < 0 && errno == EINTR);
  if (r < 0) return;
  if (WIFEXITED(status)) {
    o.exited = true;
    o.exit_code = WEXITSTATUS(status);
  } else if (WIFSIGNALED(status)) {
    o.signal = WTERMSIG(status);
  }
}

// Runs argv[0] with argv (no shell, no PATH search): stdin and stdout on /dev/null, stderr
// captured. Kills it after timeout_s.
ProcessOutcome run_process(const std::vector<std::string>& argv, double timeout_s) {
  ProcessOutcome o;
  int fds[2] = {-1, -1};
  if (::pipe2(fds, O_CLOEXEC) != 0) {
    o.start_error = std::string("pipe: ") + std::strerror(errno);
    return o;
  }
  std::vector<char*> args;
  for (const auto& a : argv) args.push_back(const_cast<char*>(a.c_str()));
  args.push_back(nullptr);
  posix_spawn_file_actions_t fa;
  posix_spawn_file_actions_init(&fa);
  posix_spawn_file_actions_addopen(&fa, 0, "/dev/null", O_RDONLY, 0);
  posix_spawn_file_actions_addopen(&fa, 1, "/dev/null", O_WRONLY, 0);
  posix_spawn_file_actions_adddup2(&fa, fds[1], 2);
  pid_t pid = -1;
  const int rc = ::posix_spawn(&pid, args[0], &fa, nullptr, args.data(), environ);
  posix_spawn_file_actions_destroy(&fa);
  close_fd(fds[1]);
  if (rc != 0) {
    close_fd(fds[0]);
    o.start_error = std::strerror(rc);
    return o;
  }
  const auto deadline = Clock::now() + std::chrono::duration_cast<Clock::duration>(
                                           std::chrono::duration<double>(std::max(0.0, timeout_s)));
  if (!drain(fds[0], deadline, o.stderr_text)) {
    o.timed_out = true;
    ::kill(pid, SIGKILL);
  }
  close_fd(fds[0]);
  reap(pid, o);
  return o;
}

// The last non-empty line of a text (a Python traceback ends with the exception).
std::string last_line(const std::string& text) {
  const std::size_t end = text.find_last_not_of(" \t\r\n");
  if (end == std::string::npos) return "";
  const std::size_t newline = text.rfind('\n', end);
  const std::size_t begin = newline == std::string::npos ? 0 : newline + 1;
  return text.substr(begin, end + 1 - begin);
}

// The one-line reason a script run failed, or "" if it succeeded.
std::string failure_of(const ProcessOutcome& o, const ReportTools& tools, const std::string& script) {
  if (!o.start_error.empty())
    return "cannot run " + tools.python + ": " + o.start_error + " (Debian: python3, python3-matplotlib)";
  if (o.timed_out) return script + " did not finish within " + std::to_string(static_cast<int>(tools.timeout_s)) + " s";
  if (o.exited && o.exit_code == 0) return "";
  const std::string said = last_line(o.stderr_text);
  const std::string how = o.exited ? "exit " + std::to_string(o.exit_code)
                                   : "killed by signal " + std::to_string(o.signal);
  return script + " failed (" + how + ")" + (said.empty() ? "" : ": " + said);
}

// Checks that the interpreter and the script exist; "" or why not.
std::string check_tools(const ReportTools& tools, const std::string& script_path) {
  if (::access(tools.python.c_str(), X_OK) != 0)
    return "cannot run " + tools.python + ": " + std::strerror(errno) + " (Debian: python3, python3-matplotlib)";
  std::error_code ec;
  if (tools.scripts_dir.empty()) return "no report scripts directory given";
  if (!fs::is_regular_file(script_path, ec)) return "report script not found: " + script_path;
  return "";
}

// Runs one script with its arguments; fills ok/error of r.
void run_script(const ReportTools& tools, const std::string& script, const std::vector<std::string>& args,
                ReportResult& r) {
  const std::string path = (fs::path(tools.scripts_dir) / script).string();
  if (std::string why = check_tools(tools, path); !why.empty()) {
    r.error = why;
    return;
  }
  std::vector<std::string> argv = {tools.python, path};
  argv.insert(argv.end(), args.begin(), args.end());
  r.error = failure_of(run_process(argv, tools.timeout_s), tools, script);
  r.ok = r.error.empty();
}

double seconds_since(Clock::time_point t0) { return std::chrono::duration<double>(Clock::now() - t0).count(); }

// Writes the summary for check_index.py next to the page; "" or why not.
std::string write_summary(const fs::path& file, const nlohmann::json& summary) {
  std::ofstream f(file, std::ios::binary | std::ios::trunc);
  if (!f) return "cannot write " + file.string() + ": " + std::strerror(errno);
  // Invalid UTF-8 in a message must not throw: replace it.
  f << summary.dump(1, ' ', false, nlohmann::json::error_handler_t::replace) << "\n";
  f.close();
  if (!f) return "cannot write " + file.string();
  return "";
}

}  // namespace

ReportResult write_run_report(const std::string& run_dir, const ReportTools& tools, const std::string& video,
                              const std::string& renderer) {
  const auto t0 = Clock::now();
  ReportResult r;
  try {
    std::error_code ec;
    if (!fs::is_directory(run_dir, ec)) {
      r.error = "run directory '" + run_dir + "' does not exist";
    } else {
      std::vector<std::string> args{run_dir};
      if (!video.empty()) args.insert(args.end(), {"--video", video});
      if (!renderer.empty()) args.insert(args.end(), {"--renderer", renderer});
      run_script(tools, "run_report.py", args, r);
      if (r.ok) r.path = (fs::path(run_dir) / "report.html").string();
    }
  } catch (const std::exception& e) {
    r.ok = false;
    r.error = std::string("report: ") + e.what();
  }
  r.seconds = seconds_since(t0);
  return r;
}

ReportResult write_check_index(const std::string& out_html, const nlohmann::json& summary, const ReportTools& tools) {
  const auto t0 = Clock::now();
  ReportResult r;
  try {
    const fs::path out = fs::absolute(out_html);
    std::error_code ec;
    fs::create_directories(out.parent_path(), ec);
    const fs::path temp = out.parent_path() / ("." + out.filename().string() + ".summary.json");
    r.error = write_summary(temp, summary);
    if (r.error.empty()) {
      run_script(tools, "check_index.py", {out.string(), temp.string()}, r);
      if (r.ok) r.path = out.string();
    }
    fs::remove(temp, ec);
  } catch (const std::exception& e) {
    r.ok = false;
    r.error = std::string("check index: ") + e.what();
  }
  r.seconds = seconds_since(t0);
  return r;
}

ReportResult write_sweep_plot(const std::string& csv, const std::string& png, const std::string& x,
                              const std::string& y, const std::vector<std::string>& params, const ReportTools& tools) {
  const auto t0 = Clock::now();
  ReportResult r;
  try {
    std::vector<std::string> args = {csv, png, x, y};
    args.insert(args.end(), params.begin(), params.end());
    run_script(tools, "sweep_plot.py", args, r);
    if (r.ok) r.path = png;
  } catch (const std::exception& e) {
    r.ok = false;
    r.error = std::string("sweep plot: ") + e.what();
  }
  r.seconds = seconds_since(t0);
  return r;
}

}  // namespace omnitwin::media
