// bus_emulators/ethercat/transport — a veth pair (two virtual Ethernet interfaces joined back
// to back) that lives as long as the object: the twin puts its slaves on one end and gives the
// master the other (bus ethercat, transport auto/veth), and raw-socket tests do the same.
//
// Names are unique per process and instance ("ot" + pid + counter + "a"/"b", at most 15
// characters), so tests running in parallel (ctest -j: one process each) never share or delete
// each other's interfaces; a leftover pair with the same names (a crashed earlier process with
// the same pid) is deleted first. The first end carries the alias "omnitwin-pid-NS-PID" (NS:
// the PID namespace's inode); a pair whose process is gone (SIGKILL, a crash: no destructor
// ran) is deleted by the next VethPair made in the same PID namespace (sweep_stale()), so killed
// runs do not pile up interfaces. A pair of another PID namespace (a container sharing the
// host's network) is never judged: its pid means nothing here. Both ends are brought up with IPv6 disabled on them (no router
// solicitations or DAD frames on the wire), and the constructor returns once the kernel has
// them operationally up with their queue discipline (before that, frames sent are dropped). The destructor deletes the pair (deleting one end
// deletes both), also when the test fails, since a failed assertion returns from the test body
// and unwinds the fixture.
//
// Needs root (CAP_NET_ADMIN) and the `ip` tool: callers ask unavailable_reason() first (tests
// call GTEST_SKIP() << *reason when it is set; the twin falls back to EtherCAT over UDP).
// Set-up code only: runs `ip` as child processes.
#pragma once

#include <signal.h>
#include <sys/stat.h>
#include <sys/wait.h>
#include <unistd.h>

#include <cerrno>
#include <filesystem>

#include <array>
#include <atomic>
#include <chrono>
#include <cstdio>
#include <cstdlib>
#include <fstream>
#include <optional>
#include <stdexcept>
#include <string>
#include <thread>

namespace omnitwin::ethercat {

class VethPair {
 public:
  // Why veth pairs cannot be made here (not root, no `ip`, the kernel refuses a probe pair),
  // or nothing when they can. The probe runs once per process.
  static std::optional<std::string> unavailable_reason() {
    static const std::optional<std::string> reason = probe();
    return reason;
  }

  // Creates the pair, both ends up; throws std::runtime_error with `ip`'s message on failure.
  VethPair() {
    static std::atomic<int> counter{0};
    const std::string base = "ot" + std::to_string(::getpid()) + std::to_string(counter++);
    a_ = base + "a";
    b_ = base + "b";
    if (b_.size() > 15) throw std::runtime_error("veth name too long: " + b_);
    sweep_stale();
    run(ip() + " link del " + a_);  // a leftover of a crashed process with the same pid
    if (const auto err = run(ip() + " link add " + a_ + " type veth peer name " + b_))
      throw std::runtime_error("cannot create veth pair " + a_ + "/" + b_ + ": " + *err);
    run(ip() + " link set dev " + a_ + " alias " + alias_prefix() + std::to_string(::getpid()));  // best effort
    for (const std::string& n : {a_, b_}) {
      std::ofstream(std::string("/proc/sys/net/ipv6/conf/") + n + "/disable_ipv6") << "1\n";  // best effort
      if (const auto err = run(ip() + " link set " + n + " up")) {
        run(ip() + " link del " + a_);
        throw std::runtime_error("cannot bring up " + n + ": " + *err);
      }
    }
    if (const auto err = wait_until_ready()) {
      run(ip() + " link del " + a_);
      throw std::runtime_error("veth pair " + a_ + "/" + b_ + " did not come up: " + *err);
    }
  }
  ~VethPair() { run(ip() + " link del " + a_); }
  VethPair(const VethPair&) = delete;
  VethPair& operator=(const VethPair&) = delete;

  const std::string& a() const { return a_; }
  const std::string& b() const { return b_; }

  // Sets the MAC address of one end (e.g. "00:00:5e:00:53:01": the kernel's random veth
  // addresses have bit 1 of the first byte set, which hides the slaves' source marking).
  void set_address(const std::string& ifname, const std::string& mac) const {
    if (const auto err = run(ip() + " link set dev " + ifname + " address " + mac))
      throw std::runtime_error("cannot set the address of " + ifname + ": " + *err);
  }

  // Whether an interface of this name exists now.
  static bool exists(const std::string& ifname) {
    return ::access(("/sys/class/net/" + ifname).c_str(), F_OK) == 0;
  }

  // Deletes every interface whose alias says a VethPair of a process of this PID namespace that
  // no longer exists made it; returns how many. Best effort (another process may delete it
  // first).
  static int sweep_stale() {
    int deleted = 0;
    const std::string prefix = alias_prefix();
    std::error_code ec;
    for (const auto& entry : std::filesystem::directory_iterator("/sys/class/net", ec)) {
      std::ifstream f(entry.path() / "ifalias");
      std::string alias;
      if (!f || !std::getline(f, alias) || alias.rfind(prefix, 0) != 0) continue;
      const std::string digits = alias.substr(prefix.size());
      if (digits.empty() || digits.find_first_not_of("0123456789") != std::string::npos) continue;
      const long pid = std::stol(digits);
      if (pid <= 0 || ::kill(static_cast<pid_t>(pid), 0) == 0 || errno != ESRCH) continue;  // alive (or not ours to judge)
      if (!run(ip() + " link del " + entry.path().filename().string())) ++deleted;
    }
    return deleted;
  }

 private:
  // Waits (up to 5 s) until both ends are operationally up and have their transmit queue
  // discipline. `ip link set up` returns before the kernel's link-watch work has run; until it
  // runs an end keeps the "noop" qdisc, which drops every frame sent through it (a packet socket
  // without qdisc bypass), so a test's or master's first frames could vanish when that work is
  // held up (other processes adding and deleting interfaces under the same lock). Nothing when
  // ready, else what was last seen.
  std::optional<std::string> wait_until_ready() const {
    const auto deadline = std::chrono::steady_clock::now() + std::chrono::seconds(5);
    std::string seen;
    for (;;) {
      seen.clear();
      bool ready = true;
      for (const std::string& n : {a_, b_}) {
        std::string state;
        std::getline(std::ifstream("/sys/class/net/" + n + "/operstate"), state);
        std::string link;
        if (state == "up") capture(ip() + " -o link show dev " + n, link);
        const bool no_qdisc = link.empty() || link.find("qdisc noop") != std::string::npos;
        if (state != "up" || no_qdisc) ready = false;
        seen += n + ": operstate " + (state.empty() ? "?" : state) + (state == "up" && no_qdisc ? ", qdisc noop; " : "; ");
      }
      if (ready) return std::nullopt;
      if (std::chrono::steady_clock::now() > deadline) return seen;
      std::this_thread::sleep_for(std::chrono::milliseconds(1));
    }
  }

  // Runs a shell command (our own names and addresses only: no quoting needed); nothing on
  // success, else its output and exit status.
  static std::optional<std::string> run(const std::string& cmd) {
    std::string out;
    const int status = capture(cmd, out);
    if (status == 0) return std::nullopt;
    while (!out.empty() && (out.back() == '\n' || out.back() == '\r')) out.pop_back();
    return "'" + cmd + "' failed (status " + std::to_string(WIFEXITED(status) ? WEXITSTATUS(status) : -1) + "): " + out;
  }

  // Runs a shell command, its output (stdout and stderr) into `out`; returns pclose's status
  // (-1 when it could not start).
  static int capture(const std::string& cmd, std::string& out) {
    FILE* p = ::popen((cmd + " 2>&1").c_str(), "r");
    if (!p) {
      out = "popen failed for: " + cmd;
      return -1;
    }
    std::array<char, 256> buf{};
    while (std::fgets(buf.data(), static_cast<int>(buf.size()), p)) out += buf.data();
    return ::pclose(p);
  }

  // The `ip` program's path (PATH may lack the sbin folders), "ip" when none was found.
  static const std::string& ip() {
    static const std::string path = [] {
      for (const char* dir : {"/usr/sbin/", "/sbin/", "/usr/bin/", "/bin/"})
        if (::access((std::string(dir) + "ip").c_str(), X_OK) == 0) return std::string(dir) + "ip";
      return std::string("ip");
    }();
    return path;
  }

  static std::optional<std::string> probe() {
    if (::geteuid() != 0) return "veth pairs need root (CAP_NET_ADMIN); run the tests as root, as CI does";
    if (ip() == "ip") return "the `ip` tool (iproute2) is not installed";
    try {
      VethPair probe;
    } catch (const std::exception& e) {
      return std::string("this kernel does not let us create veth pairs: ") + e.what();
    }
    return std::nullopt;
  }

  // "omnitwin-pid-NS-": NS the inode of this process's PID namespace ("0" if unreadable).
  static std::string alias_prefix() {
    struct stat st {};
    const unsigned long long ns = ::stat("/proc/self/ns/pid", &st) == 0 ? static_cast<unsigned long long>(st.st_ino) : 0;
    return "omnitwin-pid-" + std::to_string(ns) + "-";
  }
  std::string a_;
  std::string b_;
};

}  // namespace omnitwin::ethercat
