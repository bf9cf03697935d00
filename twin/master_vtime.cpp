// twin layer — the twin's end of the virtual-time channel and its pacer; see master_vtime.hpp.
#include "twin/master_vtime.hpp"

#include <elf.h>
#include <poll.h>
#include <sys/socket.h>
#include <sys/un.h>
#include <unistd.h>

#include <atomic>
#include <cerrno>
#include <cstring>
#include <filesystem>
#include <fstream>
#include <stdexcept>

#include <fmt/format.h>

#include "twin/bus_network.hpp"
#include "twin/master_process.hpp"

namespace omnitwin::twin {

namespace fs = std::filesystem;
using vtime::Record;
using vtime::Type;

namespace {

std::int64_t wall_ms_left(std::chrono::steady_clock::time_point deadline) {
  return std::chrono::duration_cast<std::chrono::milliseconds>(deadline - std::chrono::steady_clock::now()).count();
}

// One record from `fd` within the deadline; closed on end of stream, protocol on garbage. A
// record already waiting is taken with one system call; poll() only when none is.
VtimeServer::Status read_record(int fd, Record& r, std::chrono::steady_clock::time_point deadline) {
  for (;;) {
    std::uint8_t b[vtime::kRecordSize + 1];
    const ssize_t n = ::recv(fd, b, sizeof b, MSG_DONTWAIT);
    if (n < 0 && (errno == EINTR || errno == EAGAIN)) {
      pollfd p{fd, POLLIN, 0};
      const std::int64_t left = wall_ms_left(deadline);
      if (left < 0) return VtimeServer::Status::timeout;
      const int pr = ::poll(&p, 1, static_cast<int>(left));
      if (pr == 0) return VtimeServer::Status::timeout;
      continue;
    }
    if (n <= 0) return VtimeServer::Status::closed;
    const auto rec = vtime::decode(b, static_cast<std::size_t>(n));
    if (!rec) return VtimeServer::Status::protocol;
    r = *rec;
    return VtimeServer::Status::ok;
  }
}

}  // namespace

const char* to_string(VtimeServer::Status s) {
  switch (s) {
    case VtimeServer::Status::ok: return "ok";
    case VtimeServer::Status::timeout: return "timeout";
    case VtimeServer::Status::closed: return "closed";
    case VtimeServer::Status::protocol: return "protocol error";
    case VtimeServer::Status::second_process: return "a second process";
  }
  return "?";
}

VtimeServer::VtimeServer() {
  static std::atomic<int> serial{0};
  name_ = fmt::format("@omnitwin-vtime-{}-{}", ::getpid(), serial++);
  listen_fd_ = ::socket(AF_UNIX, SOCK_SEQPACKET | SOCK_CLOEXEC, 0);
  if (listen_fd_ < 0) throw std::runtime_error(fmt::format("vtime channel: socket: {}", std::strerror(errno)));
  sockaddr_un a{};
  a.sun_family = AF_UNIX;
  std::memcpy(a.sun_path, name_.data(), name_.size());
  a.sun_path[0] = '\0';  // abstract: no file, nothing to clean up, no /tmp needed
  const auto len = static_cast<socklen_t>(offsetof(sockaddr_un, sun_path) + name_.size());
  if (::bind(listen_fd_, reinterpret_cast<sockaddr*>(&a), len) != 0 || ::listen(listen_fd_, 4) != 0) {
    const std::string why = std::strerror(errno);
    ::close(listen_fd_);
    throw std::runtime_error(fmt::format("vtime channel: cannot listen on {}: {}", name_, why));
  }
}

VtimeServer::~VtimeServer() {
  if (conn_fd_ >= 0) ::close(conn_fd_);
  if (listen_fd_ >= 0) ::close(listen_fd_);
}

std::vector<std::string> VtimeServer::environment(const std::string& library, const std::string& bus) const {
  return {"LD_PRELOAD=" + library, fmt::format("{}={}", vtime::kEnvChannel, name_),
          fmt::format("{}={}", vtime::kEnvBus, bus), fmt::format("{}=1767225600", vtime::kEnvEpoch)};
}

bool VtimeServer::send(const Record& r) {
  const auto b = vtime::encode(r);
  return conn_fd_ >= 0 && ::send(conn_fd_, b.data(), b.size(), MSG_NOSIGNAL) == static_cast<ssize_t>(b.size());
}

// A connection waiting on the listening socket: the master (first, or the same pid after an
// exec) is welcomed; anyone else is refused.
VtimeServer::Status VtimeServer::take_connection(SimTime now, bool first) {
  const int fd = ::accept4(listen_fd_, nullptr, nullptr, SOCK_CLOEXEC);
  if (fd < 0) return Status::timeout;
  Record h;
  const Status st = read_record(fd, h, std::chrono::steady_clock::now() + std::chrono::seconds(5));
  if (st != Status::ok || h.type != Type::hello) {
    ::close(fd);
    return st == Status::ok ? Status::protocol : st;
  }
  const auto pid = static_cast<pid_t>(h.pid);
  if (!first && (pid != pid_ || conn_fd_ >= 0)) {
    Record no;
    no.type = Type::refuse;
    no.code = 1;
    const auto b = vtime::encode(no);
    (void)!::send(fd, b.data(), b.size(), MSG_NOSIGNAL);
    ::close(fd);
    other_pid_ = pid;
    return Status::second_process;
  }
  if (conn_fd_ >= 0) ::close(conn_fd_);
  conn_fd_ = fd;
  pid_ = pid;
  Record w;
  w.type = Type::welcome;
  w.now = now;
  return send(w) ? Status::ok : Status::closed;
}

VtimeServer::Status VtimeServer::accept(std::chrono::milliseconds timeout, SimTime now) {
  pollfd p{listen_fd_, POLLIN, 0};
  const int pr = ::poll(&p, 1, static_cast<int>(timeout.count()));
  if (pr <= 0) return Status::timeout;
  return take_connection(now, true);
}

VtimeServer::Status VtimeServer::next_wait(Record& w, std::chrono::milliseconds timeout, SimTime now) {
  const auto deadline = std::chrono::steady_clock::now() + timeout;
  for (;;) {
    pollfd p[2] = {{conn_fd_, POLLIN, 0}, {listen_fd_, POLLIN, 0}};
    const std::int64_t left = wall_ms_left(deadline);
    if (left < 0) return Status::timeout;
    const int pr = ::poll(p, 2, static_cast<int>(left));
    if (pr < 0 && errno == EINTR) continue;
    if (pr == 0) return Status::timeout;
    if (p[1].revents & POLLIN) {
      const Status st = take_connection(now, false);
      if (st == Status::second_process) return st;
      continue;
    }
    if (conn_fd_ < 0) continue;  // between an exec's close and its new connection
    const Status st = read_record(conn_fd_, w, deadline);
    if (st == Status::closed) {
      // The process ended, or exec()ed: its new image connects again within the watchdog.
      ::close(conn_fd_);
      conn_fd_ = -1;
      pollfd l{listen_fd_, POLLIN, 0};
      if (::poll(&l, 1, 200) <= 0) return Status::closed;
      continue;
    }
    if (st != Status::ok) return st;
    if (w.type != Type::wait) return Status::protocol;
    ++waits_;
    return Status::ok;
  }
}

bool VtimeServer::wake(std::uint64_t seq, SimTime now, std::uint64_t frames, int signal) {
  Record r;
  r.type = Type::wake;
  r.seq = seq;
  r.now = now;
  r.frames = frames;
  r.code = static_cast<std::uint32_t>(signal);
  return send(r);
}

void VtimeServer::end(SimTime now) {
  Record r;
  r.type = Type::end;
  r.now = now;
  send(r);
}

// ---- the pacer ----------------------------------------------------------------------------

VtimePacer::VtimePacer(VtimeServer& server, BusNetwork& net, Scheduler& sched, std::chrono::milliseconds watchdog,
                       FailFn fail, std::function<std::string()> master_status)
    : server_(server),
      net_(net),
      sched_(sched),
      watchdog_(watchdog),
      fail_(std::move(fail)),
      master_status_(std::move(master_status)) {}

void VtimePacer::failure(std::string why, bool gone) {
  failed_ = true;
  fail_(std::move(why), gone);
}

// The master's next wait: its frames enter the network at the wait's instant.
bool VtimePacer::take_wait() {
  const VtimeServer::Status st = server_.next_wait(wait_, watchdog_, now_);
  if (st == VtimeServer::Status::closed && expect_end_) {
    ended_ = true;  // it exited after the SIGTERM of the run's end, as asked
    return false;
  }
  if (st != VtimeServer::Status::ok) {
    if (st == VtimeServer::Status::second_process)
      failure(fmt::format("master: a second process (pid {}) started under the virtual clock: it serves one "
                          "process (a master that forks or runs other programs needs --clock realtime)",
                          server_.other_pid()));
    else if (st == VtimeServer::Status::timeout)
      failure(fmt::format("master: it neither waited nor ended for {:.0f} s of wall time at t = {:.6f} s (a loop "
                          "without any clock read, sleep, poll or receive the virtual clock sees?); {}",
                          watchdog_.count() / 1e3, ns_to_seconds(now_), master_status_()));
    else  // ended or killed mid-run: a lost master (master.lost), as in realtime (found in review)
      failure(fmt::format("the master process left the virtual clock at t = {:.6f} s ({}; {})",
                          ns_to_seconds(now_), to_string(st), master_status_()),
              true);
    return false;
  }
  if (wait_.now != now_) {
    failure(fmt::format("master: a wait at {} ns while the clock is at {} ns", wait_.now, now_));
    return false;
  }
  if (!net_.drain_transport(wait_.frames, now_, watchdog_)) {
    failure(fmt::format("master: said {} frames sent, {} arrived on {}", wait_.frames, net_.frames_from_transport(),
                        net_.master_iface()));
    return false;
  }
  have_wait_ = true;
  delivered_at_wait_ = net_.frames_to_transport();
  return true;
}

void VtimePacer::expect_end(int signal) {
  expect_end_ = true;
  if (have_wait_ && !failed_ && !ended_) wake_at(std::max(sched_.now(), now_), signal);
}

bool VtimePacer::wake_at(SimTime t, int signal) {
  now_ = t;
  have_wait_ = false;
  ++wakes_;
  if (!server_.wake(wait_.seq, now_, net_.frames_to_transport(), signal)) {
    if (expect_end_) {
      ended_ = true;
      return false;
    }
    failure(fmt::format("master: gone at t = {:.6f} s ({})", ns_to_seconds(now_), master_status_()));
    return false;
  }
  return true;
}

void VtimePacer::wait_until(SimTime t) {
  if (ended_) return;  // the master has ended at the run's end: time runs free (the last record)
  while (!failed_ && !ended_) {
    if (!have_wait_) {
      if (!take_wait()) break;
      continue;
    }
    const SimTime deadline = std::max(wait_.deadline, now_);
    // A frame the last instant's events put on the master's transport wakes it then.
    if (wait_.wake_on_frame && net_.frames_to_transport() != delivered_at_wait_) {
      ++frame_wakes_;
      if (!wake_at(std::max(sched_.now(), now_))) break;
      continue;
    }
    // The network's own next step (a frame entering, completing or due back) before t and
    // before the deadline: run it, and wake the master if it put a frame on its transport.
    const SimTime x = std::max(net_.next_master_event(), now_);
    if (x <= t && x <= deadline) {
      net_.advance(x);
      net_.release_due(x);
      if (wait_.wake_on_frame && net_.frames_to_transport() != delivered_at_wait_) {
        ++frame_wakes_;
        if (!wake_at(x)) break;
        continue;
      }
      if (std::max(net_.next_master_event(), now_) > x) continue;  // else: nothing more there
    }
    if (deadline <= t) {
      net_.advance(deadline);
      net_.release_due(deadline);
      if (!wake_at(deadline)) break;
      continue;
    }
    return;  // instant t comes first
  }
  if (failed_ || ended_) sched_.stop();
}

// ---- finding things -------------------------------------------------------------------------

std::string find_vtime_library() {
  // Build tree (build/twin/vtime/), an install beside the executable or in ../lib, this build.
  std::string dir;
  const std::string found =
      find_beside_executable({"vtime/libomnitwin_vtime.so", "libomnitwin_vtime.so", "../lib/libomnitwin_vtime.so"},
                             OMNITWIN_BINARY_DIR "/twin/vtime/libomnitwin_vtime.so", R_OK, dir);
  if (!found.empty()) return fs::absolute(found).string();  // LD_PRELOAD resolves it in another cwd
  throw std::runtime_error(fmt::format("libomnitwin_vtime.so was not found beside {} (build target omnitwin_vtime)", dir));
}

std::string preload_obstacle(const std::string& program) {
  if (const std::string why = program_problem(program); !why.empty()) return why;
  const std::string path = program_path(program);
  std::ifstream f(path, std::ios::binary);
  Elf64_Ehdr eh{};
  if (!f.read(reinterpret_cast<char*>(&eh), sizeof eh) || std::memcmp(eh.e_ident, ELFMAG, SELFMAG) != 0)
    return "not an ELF program (a script? name its interpreter's program, or the binary itself)";
  if (eh.e_ident[EI_CLASS] != ELFCLASS64) return "not a 64-bit ELF program";
  for (int i = 0; i < eh.e_phnum; ++i) {
    Elf64_Phdr ph{};
    f.seekg(static_cast<std::streamoff>(eh.e_phoff + static_cast<std::uint64_t>(i) * eh.e_phentsize));
    if (!f.read(reinterpret_cast<char*>(&ph), sizeof ph)) break;
    if (ph.p_type == PT_INTERP) return "";
  }
  return "statically linked (LD_PRELOAD cannot reach it)";
}


}  // namespace omnitwin::twin
