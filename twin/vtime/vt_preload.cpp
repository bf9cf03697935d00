// twin layer — libomnitwin_vtime.so: the twin's simulated clock inside a master program we did
// not write (LD_PRELOAD). docs/protocols/vtime.md is the reference; in short:
//
//  - Clock reads (clock_gettime on the monotonic, boot and realtime clocks, gettimeofday, time,
//    timespec_get) answer simulated time: monotonic = 1000 s + t, realtime = EPOCH + t.
//  - Every wait (sleeps, poll/select/epoll, blocking receives, timerfds, condition variables,
//    pthread_join) becomes a wait on the twin. Simulated time moves only when every thread of
//    the process waits: then the last thread to wait (the leader) ends the waits whose
//    descriptors the process itself made ready, or if there are none sends Wait{earliest deadline,
//    wake on a frame?, bus frames sent} and the twin runs to the earlier of that deadline and
//    the next frame reaching the master's socket, and answers Wake{now}. The leader then wakes
//    every waiter whose deadline passed, whose descriptors became ready, or whose thread ran a
//    signal handler of the program's (EINTR, as the kernel; sigaction, signal and siginterrupt
//    are wrapped to see it, and a signal the process sends itself is waited for; see "Signals"
//    in the docs).
//  - Busy polling: a thread that makes kSpinLimit calls in a row that neither wait nor find
//    anything (clock reads, empty non-blocking receives, zero-timeout polls, sleeps already
//    over) waits one quantum (1 µs) of simulated time, woken early by a frame. So a spinning
//    master advances, and deterministically: the count of its own calls decides, never the
//    wall clock.
//  - Every wait on the twin has a wall-clock watchdog (OMNITWIN_VTIME_WATCHDOG, default 60 s).
//  - After the twin's End (or if the twin disappears) time continues on the wall clock from
//    where it stopped and every call goes to the kernel.
// Without OMNITWIN_VTIME in the environment the library passes every call straight through.
//
// Shape: one process-wide state under one mutex; waiters live on their threads' stacks in a
// list. The real functions come from dlsym(RTLD_NEXT); the library never calls an intercepted
// name for its own work. Written without exceptions or iostreams: it runs inside foreign code.
#include <dlfcn.h>
#include <errno.h>
#include <fcntl.h>
#include <poll.h>
#include <pthread.h>
#include <signal.h>
#include <stdarg.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <sys/epoll.h>
#include <sys/eventfd.h>
#include <sys/select.h>
#include <sys/socket.h>
#include <sys/stat.h>
#include <sys/syscall.h>
#include <sys/time.h>
#include <sys/timerfd.h>
#include <sys/un.h>
#include <netinet/in.h>
#include <netinet/udp.h>
#include <time.h>
#include <unistd.h>

#include <cstdint>

#include "twin/vtime/vt_protocol.hpp"

#ifndef UDP_SEGMENT
#define UDP_SEGMENT 103
#endif

namespace {

using ns_t = std::int64_t;
namespace vt = omnitwin::vtime;

constexpr ns_t kNs = 1'000'000'000;
constexpr ns_t kMonoBase = 1000 * kNs;     // CLOCK_MONOTONIC at t = 0 (a machine up 1000 s)
constexpr ns_t kQuantum = 1000;            // the busy-poll rule's step [ns]
constexpr int kSpinLimit = 64;             // calls in a row that find nothing before a quantum passes
constexpr ns_t kGraceNs = 20'000'000;      // how long a woken reader waits for the kernel to deliver [wall ns]
constexpr int kMaxFd = 4096;               // timerfd table

// ---- the real functions ----------------------------------------------------------------
template <class F>
F real(const char* name) {
  return reinterpret_cast<F>(dlsym(RTLD_NEXT, name));
}
#define REAL(name) static auto real_##name = real<decltype(&::name)>(#name)

using cond_wait_fn = int (*)(pthread_cond_t*, pthread_mutex_t*);
using cond_timedwait_fn = int (*)(pthread_cond_t*, pthread_mutex_t*, const timespec*);
using cond_signal_fn = int (*)(pthread_cond_t*);

// The library's own condition variable goes to glibc directly: the names are intercepted below.
void cv_broadcast(pthread_cond_t* c) {
  static auto f = real<cond_signal_fn>("pthread_cond_broadcast");
  f(c);
}
int cv_timedwait(pthread_cond_t* c, pthread_mutex_t* m, const timespec* until) {
  static auto f = real<cond_timedwait_fn>("pthread_cond_timedwait");
  return f(c, m, until);
}

// Saturated at ±kNever: a timeout of 292 years or more (nanosleep({LONG_MAX, 0})) is for ever.
ns_t ts_ns(const timespec& t) {
  if (t.tv_sec >= vt::kNever / kNs) return vt::kNever;
  if (t.tv_sec <= -vt::kNever / kNs) return -vt::kNever;
  return static_cast<ns_t>(t.tv_sec) * kNs + t.tv_nsec;
}
timespec ns_ts(ns_t v) {
  timespec t;
  t.tv_sec = static_cast<time_t>(v / kNs);
  t.tv_nsec = static_cast<long>(v % kNs);
  if (t.tv_nsec < 0) {
    t.tv_nsec += kNs;
    --t.tv_sec;
  }
  return t;
}
// The wall clock, through glibc's real clock_gettime (the vDSO: no system call).
ns_t wall_ns() {
  static auto real_clock = real<int (*)(clockid_t, timespec*)>("clock_gettime");
  timespec t;
  real_clock(CLOCK_MONOTONIC, &t);
  return ts_ns(t);
}
ns_t add_sat(ns_t a, ns_t b) { return (b > 0 && a > vt::kNever - b) ? vt::kNever : a + b; }
// An instant `v` on a clock that reads `base` at t = 0, as simulated time; never stays never.
ns_t minus_base(ns_t v, ns_t base) {
  if (v == vt::kNever) return vt::kNever;
  return v < base - vt::kNever ? -vt::kNever : v - base;
}

void say(const char* fmt, ...) {
  char buf[512];
  va_list ap;
  va_start(ap, fmt);
  int n = vsnprintf(buf, sizeof buf, fmt, ap);
  va_end(ap);
  if (n < 0) return;
  if (n > static_cast<int>(sizeof buf) - 1) n = sizeof buf - 1;
  ssize_t w = syscall(SYS_write, 2, buf, static_cast<size_t>(n));
  (void)w;
}

// ---- state ----------------------------------------------------------------------------------
struct Waiter {
  ns_t deadline = vt::kNever;
  pollfd* fds = nullptr;      // descriptors whose readiness ends the wait
  nfds_t nfds = 0;
  bool any_frame = false;     // a frame reaching the master ends the wait (busy-poll quantum)
  const void* cond = nullptr; // a condition variable's signal ends the wait
  pthread_t join = 0;         // this thread's end ends the wait
  bool joining = false;
  bool satisfied = false;
  bool timed_out = false;
  // A signal handler that ran on the waiting thread ends the wait (EINTR), as on Linux: the
  // thread's count of such handlers, and its value when the wait began. Null: a wait that no
  // signal ends (a condition variable, a join, the busy-poll quantum).
  const std::uint32_t* sigs = nullptr;
  std::uint32_t sigs_at = 0;
  bool interrupted = false;
  Waiter* next = nullptr;
};

// A signal handler the program installed: the library installs its own in its place, which
// runs it and counts it (on_signal), so that a virtual wait the signal interrupts ends.
struct Handler {
  void* fn = nullptr;  // the program's handler; null: the disposition is not a handler of its own
  int flags = 0;       // its sa_flags (SA_SIGINFO, SA_RESTART, SA_RESETHAND …), kept after a reset
  bool reset = false;  // SA_RESETHAND fired: SIG_DFL again, the SA_SIGINFO the library added left
};

// A timerfd, simulated: an eventfd the leader writes expirations into. The eventfd carries the
// program's own O_NONBLOCK (TFD_NONBLOCK, fcntl, FIONBIO); the library reads it only when ready.
struct Timer {
  bool used = false;
  ns_t expiry = vt::kNever;  // simulated time [ns]
  ns_t interval = 0;
  clockid_t clock = CLOCK_MONOTONIC;  // TFD_TIMER_ABSTIME instants are on this clock
};

struct Exited {
  pthread_t id;
  std::uint64_t serial;  // g.exits when it ended: tells a reused id's old entry from the new one's
  Exited* next;
};

struct State {
  pthread_mutex_t mu = PTHREAD_MUTEX_INITIALIZER;
  pthread_cond_t cv = PTHREAD_COND_INITIALIZER;  // waiters wait here (monotonic clock, for the watchdog)
  bool active = false;   // connected and the run not over
  bool ended = false;    // End received (or the twin gone): wall time from end_now on
  int fd = -1;
  ns_t now = 0;          // simulated time [ns]
  ns_t epoch = 1767225600LL * kNs;  // CLOCK_REALTIME at t = 0: 2026-01-01T00:00:00Z
  ns_t end_now = 0, end_wall = 0;
  ns_t watchdog = 60 * kNs;
  std::uint64_t sent = 0;       // bus frames the master sent
  std::uint64_t delivered = 0;  // frames the twin put on the master's transport
  std::uint64_t seq = 0;
  int running = 1;              // threads not waiting (the main thread to begin with)
  bool leading = false;
  std::uint64_t generation = 0;
  Waiter* waiters = nullptr;
  Exited* exited = nullptr;      // ended threads not yet joined
  std::uint64_t exits = 0;      // threads ended so far
  Timer timers[kMaxFd];
  int timers_end = 0;           // 1 + the highest descriptor that was a timerfd: the loops' bound
  bool bus_raw = false;         // OMNITWIN_VTIME_BUS raw:… : packet sockets carry the bus
  int bus_port = -1;            // udp:HOST:PORT : datagrams to PORT carry the bus
  Handler handlers[NSIG];       // the program's own signal handlers (written by sigaction only)
  std::uint64_t handled = 0;    // bit sig−1: a handler of the program's is installed (atomic)
  std::uint64_t no_restart = 0; // bit sig−1: siginterrupt(sig, 1): signal() installs without SA_RESTART
  std::uint32_t sigs = 0;       // handlers run so far, all threads (atomic: written in handlers)
};
constinit State g;  // constant-initialised: ready before any constructor runs
constinit thread_local int t_spin = 0;
// Handlers the program's signals ran on this thread: all of them, and those without SA_RESTART
// (which also end a blocking receive, as the kernel does).
constinit thread_local std::uint32_t t_sigs = 0;
constinit thread_local std::uint32_t t_sigs_norestart = 0;
// Non-zero while this thread takes, holds or waits under g.mu (leading included): a signal
// handler that runs meanwhile must not take the (non-recursive) lock. Its clock reads answer
// without it and its waits go to the kernel.
constinit thread_local int t_held = 0;

void mu_lock() {
  ++t_held;  // before the lock: a signal while it is taken sees it too
  pthread_mutex_lock(&g.mu);
}
void mu_unlock() {
  pthread_mutex_unlock(&g.mu);
  --t_held;
}
struct Lock {
  Lock() { mu_lock(); }
  ~Lock() { mu_unlock(); }
};

bool on() { return g.active && !g.ended && t_held == 0; }
// Clock reads stay on the simulated clock's time line after the end too (continued on the wall).
bool clocked() { return g.active; }

// Simulated now on the monotonic base (or the wall clock's continuation after the end); lock
// held, or inside it on this thread (a signal handler: g.now is read atomically).
ns_t now_locked() {
  if (g.ended) return g.end_now + (wall_ns() - g.end_wall);
  return __atomic_load_n(&g.now, __ATOMIC_RELAXED);
}
// The same from anywhere: takes the lock unless this thread is already inside it.
ns_t now_any() {
  if (t_held > 0) return now_locked();
  Lock l;
  return now_locked();
}

// ---- the channel ----------------------------------------------------------------------------
bool send_record(const vt::Record& r) {
  const auto b = vt::encode(r);
  return syscall(SYS_sendto, g.fd, b.data(), b.size(), MSG_NOSIGNAL, nullptr, 0) == static_cast<long>(b.size());
}

// Receives one record within the watchdog (the channel's SO_RCVTIMEO: one system call per
// record); false when the channel closed or nothing came in time.
bool recv_record(vt::Record& r) {
  std::uint8_t b[vt::kRecordSize + 1];
  ns_t until = 0;
  for (;;) {
    const long n = syscall(SYS_recvfrom, g.fd, b, sizeof b, 0, nullptr, nullptr);
    if (n < 0 && errno == EINTR) {  // a signal: wait on, within the watchdog
      if (until == 0) until = wall_ns() + g.watchdog;
      if (wall_ns() < until) continue;
    }
    if (n <= 0) return false;
    const auto rec = vt::decode(b, static_cast<std::size_t>(n));
    if (!rec) return false;
    r = *rec;
    return true;
  }
}

void go_wall(ns_t at) {
  g.ended = true;
  g.end_now = at;
  g.end_wall = wall_ns();
  cv_broadcast(&g.cv);
}

void connect_channel() {
  const char* name = getenv(vt::kEnvChannel);
  if (!name || !*name) return;
  if (const char* e = getenv(vt::kEnvEpoch)) g.epoch = static_cast<ns_t>(atoll(e)) * kNs;
  if (const char* w = getenv(vt::kEnvWatchdog)) g.watchdog = static_cast<ns_t>(atof(w) * 1e9);
  if (const char* b = getenv(vt::kEnvBus)) {
    if (strncmp(b, "raw:", 4) == 0) g.bus_raw = true;
    if (strncmp(b, "udp:", 4) == 0) {
      const char* colon = strrchr(b, ':');
      if (colon && colon > b + 3) g.bus_port = atoi(colon + 1);
    }
  }
  const int fd = static_cast<int>(syscall(SYS_socket, AF_UNIX, SOCK_SEQPACKET | SOCK_CLOEXEC, 0));
  if (fd < 0) return;
  sockaddr_un a{};
  a.sun_family = AF_UNIX;
  const size_t len = strnlen(name, sizeof a.sun_path - 1);
  memcpy(a.sun_path, name, len);
  if (a.sun_path[0] == '@') a.sun_path[0] = '\0';  // abstract namespace
  const socklen_t alen = static_cast<socklen_t>(offsetof(sockaddr_un, sun_path) + len);
  if (syscall(SYS_connect, fd, reinterpret_cast<sockaddr*>(&a), alen) != 0) {
    say("omnitwin-vtime: cannot reach the twin at %s (%s): this process runs on the wall clock\n", name, strerror(errno));
    syscall(SYS_close, fd);
    return;
  }
  g.fd = fd;
  const timeval limit{static_cast<time_t>(g.watchdog / kNs), static_cast<suseconds_t>((g.watchdog % kNs) / 1000)};
  syscall(SYS_setsockopt, fd, SOL_SOCKET, SO_RCVTIMEO, &limit, sizeof limit);
  vt::Record h;
  h.type = vt::Type::hello;
  h.pid = static_cast<std::uint32_t>(getpid());
  h.ppid = static_cast<std::uint32_t>(getppid());
  vt::Record w;
  if (!send_record(h) || !recv_record(w)) {
    say("omnitwin-vtime: the twin did not welcome process %d: it runs on the wall clock\n", getpid());
    return;
  }
  if (w.type == vt::Type::refuse) {
    say("omnitwin-vtime: the twin refused process %d (only one process lives on the simulated clock): exiting\n", getpid());
    syscall(SYS_exit_group, 3);
  }
  if (w.type != vt::Type::welcome) return;
  g.now = w.now;
  g.active = true;
}

void after_fork_child() {
  // A second process cannot share the first one's clock: say so to the twin, which ends the run.
  if (g.fd >= 0) syscall(SYS_close, g.fd);
  g.fd = -1;
  g.active = false;
  g.running = 1;
  g.waiters = nullptr;
  g.leading = false;
  pthread_mutex_t fresh = PTHREAD_MUTEX_INITIALIZER;
  g.mu = fresh;
  connect_channel();
}

__attribute__((constructor)) void vt_init() {
  pthread_condattr_t a;
  pthread_condattr_init(&a);
  pthread_condattr_setclock(&a, CLOCK_MONOTONIC);
  pthread_cond_init(&g.cv, &a);
  // The clock reads find their real functions now (not active yet: straight through), so that
  // a signal handler's clock read never runs dlsym or a static's first initialisation while
  // the code it interrupted does (recursive_init_error: abort).
  timespec ts;
  timeval tv;
  clock_gettime(CLOCK_MONOTONIC, &ts);
  gettimeofday(&tv, nullptr);
  time(nullptr);
  timespec_get(&ts, TIME_UTC);
  wall_ns();
  connect_channel();
  if (g.active) pthread_atfork(nullptr, nullptr, after_fork_child);
}

// ---- waiting --------------------------------------------------------------------------------
bool has_socket(const Waiter& w) {
  for (nfds_t i = 0; i < w.nfds; ++i) {
    struct stat st;
    if (w.fds[i].fd >= 0 && fstat(w.fds[i].fd, &st) == 0 && S_ISSOCK(st.st_mode)) return true;
  }
  return false;
}

// Polls the waiter's own array, all of it (lock held: its thread waits). Only revents change,
// and every caller asks the kernel again once woken.
bool fds_ready(const Waiter& w, ns_t grace_ns) {
  if (w.nfds == 0) return false;
  timespec ts = ns_ts(grace_ns);
  return syscall(SYS_ppoll, w.fds, w.nfds, &ts, nullptr, 8) > 0;
}

// Simulated timerfds that expired by now: their eventfds count the expirations.
void fire_timers() {
  for (int fd = 0; fd < g.timers_end; ++fd) {
    Timer& t = g.timers[fd];
    if (!t.used || t.expiry > g.now) continue;
    std::uint64_t n = 1;
    if (t.interval > 0) {
      n += static_cast<std::uint64_t>((g.now - t.expiry) / t.interval);
      t.expiry = add_sat(t.expiry, static_cast<ns_t>(n) * t.interval);
    } else {
      t.expiry = vt::kNever;
    }
    ssize_t w = syscall(SYS_write, fd, &n, sizeof n);
    (void)w;
  }
}

// Whether the timerfd `fd` holds expirations (its eventfd is readable).
bool has_expired(int fd) {
  pollfd p{fd, POLLIN, 0};
  const timespec zero{0, 0};
  return syscall(SYS_ppoll, &p, 1, &zero, nullptr, 8) > 0;
}

ns_t earliest_timer() {
  ns_t e = vt::kNever;
  for (int fd = 0; fd < g.timers_end; ++fd)
    if (g.timers[fd].used && g.timers[fd].expiry < e) e = g.timers[fd].expiry;
  return e;
}

void satisfy(Waiter* w) {
  w->satisfied = true;
  ++g.running;
}

// Whether `sig` is pending for the process as a whole (/proc/self/status ShdPnd): sent but not
// yet taken by a thread, i.e. blocked in every thread. Raw system calls: the library's own.
bool pending_for_process(int sig) {
  const long fd = syscall(SYS_openat, AT_FDCWD, "/proc/self/status", O_RDONLY | O_CLOEXEC);
  if (fd < 0) return false;
  char buf[4096];
  const long n = syscall(SYS_read, fd, buf, sizeof buf - 1);
  syscall(SYS_close, fd);
  if (n <= 0) return false;
  buf[n] = 0;
  const char* at = strstr(buf, "ShdPnd:");
  if (!at) return false;
  const unsigned long long set = strtoull(at + 7, nullptr, 16);
  return (set >> (sig - 1)) & 1ULL;
}

// A signal was just sent to the process (`before`: g.sigs then; `handled`: the signals the
// program had handlers for then, since an SA_RESETHAND handler clears its own on delivery). Its
// handler runs on a thread the kernel picks, perhaps still now: wait for it to finish, so that
// the waits it interrupts end at the next lead or wake, the same in every run; for at most
// `limit` [wall ns] while a thread has taken the signal (a slow handler), but no more than 50 ms
// while it stays pending for the process (blocked in every thread: it may never run). None when
// the signal had no handler of the program's. Uses: the SIGTERM of the run's end, which the
// twin names in its Wake (limit: the watchdog), and a signal the process sent itself (100 ms).
void await_handler(int sig, std::uint32_t before, std::uint64_t handled, ns_t limit) {
  if (sig <= 0 || sig >= NSIG || !((handled >> (sig - 1)) & 1ULL)) return;
  const ns_t until = wall_ns() + limit;
  ns_t pending_since = -1;
  while (__atomic_load_n(&g.sigs, __ATOMIC_ACQUIRE) == before && wall_ns() < until) {
    const timespec step{0, 100'000};
    syscall(SYS_nanosleep, &step, nullptr);
    if (!pending_for_process(sig)) {
      pending_since = -1;
    } else if (pending_since < 0) {
      pending_since = wall_ns();
    } else if (wall_ns() - pending_since > 50'000'000) {
      return;
    }
  }
}

// Waiters whose thread ran a handler of the program's since they began end now (EINTR). Lock held.
bool end_interrupted_waits() {
  bool woke = false;
  for (Waiter* w = g.waiters; w; w = w->next)
    if (!w->satisfied && w->sigs && __atomic_load_n(w->sigs, __ATOMIC_ACQUIRE) != w->sigs_at) {
      w->interrupted = true;  // a handler ran on its thread: EINTR, as the kernel ends the call
      satisfy(w);
      woke = true;
    }
  return woke;
}

// The leader's turn (lock held, every thread waiting): one Wait/Wake with the twin, then the
// waiters it ends. Returns false when the twin is gone (time then runs on the wall clock).
bool lead() {
  // First what the process did itself: a descriptor another thread wrote before it waited (a
  // pipe, an eventfd, a loopback socket) ends its waiter now, with no round trip and no time.
  bool woke = false;
  for (Waiter* w = g.waiters; w; w = w->next)
    if (!w->satisfied && w->nfds > 0 && fds_ready(*w, 0)) {
      satisfy(w);
      woke = true;
    }
  // A signal the process sent itself (pthread_kill, raise, kill of its own pid) ran its handler
  // on a waiting thread: that wait ends now too, with no time passing (as the kernel's).
  woke = end_interrupted_waits() || woke;
  if (woke) {
    ++g.generation;
    cv_broadcast(&g.cv);
    return true;
  }
  ns_t deadline = earliest_timer();
  bool frame = false;
  for (Waiter* w = g.waiters; w; w = w->next) {
    if (w->deadline < deadline) deadline = w->deadline;
    frame = frame || w->nfds > 0 || w->any_frame;
  }
  vt::Record r;
  r.type = vt::Type::wait;
  r.seq = ++g.seq;
  r.now = g.now;
  r.deadline = deadline < g.now ? g.now : deadline;
  r.frames = g.sent;
  r.wake_on_frame = frame ? 1 : 0;
  g.leading = true;
  const std::uint32_t sigs_before = __atomic_load_n(&g.sigs, __ATOMIC_ACQUIRE);
  const std::uint64_t handled_before = __atomic_load_n(&g.handled, __ATOMIC_ACQUIRE);
  pthread_mutex_unlock(&g.mu);  // t_held stays set: a signal handler meanwhile stays out of the library
  vt::Record a;
  const bool ok = send_record(r) && recv_record(a);
  if (ok && a.type == vt::Type::wake && a.code > 0)
    await_handler(static_cast<int>(a.code), sigs_before, handled_before, g.watchdog);
  pthread_mutex_lock(&g.mu);
  g.leading = false;
  if (!ok || a.type == vt::Type::end || a.type != vt::Type::wake || a.seq != r.seq) {
    if (!ok) say("omnitwin-vtime: no answer from the twin within %.0f s: continuing on the wall clock\n", g.watchdog * 1e-9);
    go_wall(ok ? a.now : g.now);
    return false;
  }
  const bool new_frames = a.frames != g.delivered;
  __atomic_store_n(&g.now, a.now, __ATOMIC_RELAXED);
  g.delivered = a.frames;
  fire_timers();
  for (Waiter* w = g.waiters; w; w = w->next) {
    if (w->satisfied) continue;
    if (w->deadline <= g.now) {
      w->timed_out = true;
      satisfy(w);
    } else if (w->any_frame && new_frames) {
      satisfy(w);
    } else if (w->nfds > 0 && fds_ready(*w, 0)) {
      satisfy(w);
    } else if (w->nfds > 0 && new_frames && has_socket(*w) && fds_ready(*w, kGraceNs)) {
      satisfy(w);  // the kernel was still delivering the frame
    }
  }
  end_interrupted_waits();  // after a deadline or a descriptor, which win as in the kernel
  ++g.generation;
  cv_broadcast(&g.cv);
  return true;
}

// Blocks the calling thread until `w` is satisfied or the run ends (lock held on entry and
// exit); the caller tells the two apart by w.satisfied.
void wait_virtual(Waiter& w) {
  t_spin = 0;
  w.next = g.waiters;
  g.waiters = &w;
  --g.running;
  while (!w.satisfied && !g.ended) {
    if (g.running == 0 && !g.leading) {
      if (!lead()) break;
      continue;
    }
    const std::uint64_t gen = g.generation;
    timespec until = ns_ts(wall_ns() + g.watchdog);
    while (gen == g.generation && !w.satisfied && !g.ended && !(g.running == 0 && !g.leading)) {
      if (cv_timedwait(&g.cv, &g.mu, &until) == ETIMEDOUT) {
        say("omnitwin-vtime: a thread of process %d waited %.0f s of wall time for simulated time that did not move "
            "(another thread runs or blocks outside the library?): continuing on the wall clock\n",
            getpid(), g.watchdog * 1e-9);
        go_wall(g.now);
        break;
      }
    }
  }
  for (Waiter** p = &g.waiters; *p; p = &(*p)->next)
    if (*p == &w) {
      *p = w.next;
      break;
    }
  if (!w.satisfied) ++g.running;
}

// The busy-poll rule: the kSpinLimit-th call in a row that found nothing lets a quantum pass.
void spun() {
  if (++t_spin < kSpinLimit) return;
  t_spin = 0;
  Lock l;
  if (!g.active || g.ended) return;
  Waiter w;
  w.deadline = g.now + kQuantum;
  w.any_frame = true;
  wait_virtual(w);
}

// A relative timeout as an absolute simulated deadline (negative: never).
ns_t deadline_after(ns_t rel) { return rel < 0 ? vt::kNever : add_sat(g.now, rel); }

// How a virtual wait ended. `timeout` also stands for the run's end (the caller asks the kernel).
enum class Woke { ready, timeout, interrupted };

int eintr() {
  errno = EINTR;
  return -1;
}

// Waits for descriptors or a deadline, or until a handler counted in `sigs` runs. `mask`: the
// thread's signal mask for the wait's length (ppoll, pselect, epoll_pwait), as the kernel sets
// it: a signal it unblocks is taken then and ends the wait.
Woke wait_fds(pollfd* fds, nfds_t n, ns_t deadline, const std::uint32_t* sigs, const sigset_t* mask = nullptr) {
  const std::uint32_t at = sigs ? __atomic_load_n(sigs, __ATOMIC_ACQUIRE) : 0;  // before the mask lets one in
  sigset_t old;
  if (mask) pthread_sigmask(SIG_SETMASK, mask, &old);
  Woke k;
  {
    Lock l;
    Waiter w;
    w.fds = fds;
    w.nfds = n;
    w.deadline = deadline;
    w.sigs = sigs;
    w.sigs_at = at;
    wait_virtual(w);
    k = w.interrupted ? Woke::interrupted : (w.satisfied && !w.timed_out ? Woke::ready : Woke::timeout);
  }
  if (mask) pthread_sigmask(SIG_SETMASK, &old, nullptr);
  return k;
}

// A sleep, which any handler interrupts; true when one did (the time left is the deadline less
// the simulated time now).
bool sleep_until(ns_t deadline) {
  bool over;
  bool interrupted = false;
  {
    Lock l;
    over = deadline <= g.now;
    if (!over) {
      Waiter w;
      w.deadline = deadline;
      w.sigs = &t_sigs;  // any handler on this thread from now on ends it
      w.sigs_at = __atomic_load_n(&t_sigs, __ATOMIC_ACQUIRE);
      wait_virtual(w);
      interrupted = w.interrupted;
    }
  }
  if (over) spun();  // already over (usleep(0) as a yield): a call that found nothing
  return interrupted;
}

// ---- clocks -------------------------------------------------------------------------------
bool is_mono(clockid_t c) {
  return c == CLOCK_MONOTONIC || c == CLOCK_MONOTONIC_RAW || c == CLOCK_MONOTONIC_COARSE || c == CLOCK_BOOTTIME ||
         c == CLOCK_BOOTTIME_ALARM;
}
bool is_real(clockid_t c) {
  return c == CLOCK_REALTIME || c == CLOCK_REALTIME_COARSE || c == CLOCK_TAI || c == CLOCK_REALTIME_ALARM;
}
ns_t base_of(clockid_t c) { return is_mono(c) ? kMonoBase : g.epoch + (c == CLOCK_TAI ? 37 * kNs : 0); }
ns_t clock_now(clockid_t c) { return base_of(c) + now_any(); }

// Socket bookkeeping: a datagram to the bus counts as a frame the twin must receive.
bool is_socket(int fd, int* family = nullptr, int* type = nullptr) {
  int v = 0;
  socklen_t len = sizeof v;
  if (syscall(SYS_getsockopt, fd, SOL_SOCKET, SO_DOMAIN, &v, &len) != 0) return false;
  if (family) *family = v;
  len = sizeof v;
  if (type && syscall(SYS_getsockopt, fd, SOL_SOCKET, SO_TYPE, &v, &len) == 0) *type = v;
  return true;
}

int port_of(const sockaddr* a) {
  if (!a) return -1;
  if (a->sa_family == AF_INET) return ntohs(reinterpret_cast<const sockaddr_in*>(a)->sin_port);
  if (a->sa_family == AF_INET6) return ntohs(reinterpret_cast<const sockaddr_in6*>(a)->sin6_port);
  return -1;
}

// Frames one send carries (0 when it is not bus traffic); `to` null: the connected peer.
std::uint64_t bus_frames(int fd, const sockaddr* to, std::size_t bytes, std::size_t segment) {
  int fam = 0, type = 0;
  if (!is_socket(fd, &fam, &type)) return 0;
  if (fam == AF_PACKET) return g.bus_raw ? 1 : 0;
  if ((fam != AF_INET && fam != AF_INET6) || type != SOCK_DGRAM || g.bus_port < 0) return 0;
  sockaddr_storage peer{};
  if (!to) {
    socklen_t len = sizeof peer;
    if (syscall(SYS_getpeername, fd, &peer, &len) != 0) return 0;
    to = reinterpret_cast<const sockaddr*>(&peer);
  }
  if (port_of(to) != g.bus_port) return 0;
  if (segment == 0) {
    int seg = 0;
    socklen_t len = sizeof seg;
    if (syscall(SYS_getsockopt, fd, SOL_UDP, UDP_SEGMENT, &seg, &len) == 0 && seg > 0) segment = static_cast<std::size_t>(seg);
  }
  if (segment == 0 || bytes <= segment) return 1;
  return (bytes + segment - 1) / segment;  // a GSO send: one datagram per segment
}

void count_sent(std::uint64_t n) {
  if (n == 0) return;
  Lock l;
  g.sent += n;
  t_spin = 0;
}

std::size_t msg_segment(const msghdr* m) {
  if (!m || !m->msg_control) return 0;
  for (cmsghdr* c = CMSG_FIRSTHDR(const_cast<msghdr*>(m)); c; c = CMSG_NXTHDR(const_cast<msghdr*>(m), c))
    if (c->cmsg_level == SOL_UDP && c->cmsg_type == UDP_SEGMENT) {
      std::uint16_t s = 0;
      memcpy(&s, CMSG_DATA(c), sizeof s);
      return s;
    }
  return 0;
}

bool nonblocking(int fd, int flags) {
  if (flags & MSG_DONTWAIT) return true;
  const int fl = static_cast<int>(syscall(SYS_fcntl, fd, F_GETFL));
  return fl >= 0 && (fl & O_NONBLOCK);
}

ns_t rcvtimeo(int fd) {
  timeval tv{};
  socklen_t len = sizeof tv;
  if (syscall(SYS_getsockopt, fd, SOL_SOCKET, SO_RCVTIMEO, &tv, &len) != 0) return -1;
  const ns_t v = static_cast<ns_t>(tv.tv_sec) * kNs + static_cast<ns_t>(tv.tv_usec) * 1000;
  return v == 0 ? -1 : v;
}

constexpr ns_t kNoDeadline = INT64_MIN;  // receive(): the socket's SO_RCVTIMEO from now

// A receive as the kernel would do it on simulated time. `attempt(flags)` is the real call.
template <class Attempt>
ssize_t receive(int fd, int flags, Attempt attempt, ns_t deadline = kNoDeadline) {
  const ssize_t n = attempt(flags | MSG_DONTWAIT);
  if (n >= 0 || (errno != EAGAIN && errno != EWOULDBLOCK)) {
    if (n >= 0) t_spin = 0;
    return n;
  }
  if (nonblocking(fd, flags)) {
    spun();
    return attempt(flags | MSG_DONTWAIT);  // a frame that came meanwhile, or EAGAIN again
  }
  const ns_t timeo = rcvtimeo(fd);
  if (deadline == kNoDeadline) {
    Lock l;
    deadline = deadline_after(timeo);
  }
  // signal(7): a handler with SA_RESTART restarts a blocking receive, unless the socket has a
  // receive timeout; any other handler ends it with EINTR.
  const std::uint32_t* sigs = timeo >= 0 ? &t_sigs : &t_sigs_norestart;
  for (;;) {
    pollfd p{fd, POLLIN, 0};
    const Woke k = wait_fds(&p, 1, deadline, sigs);
    if (k == Woke::interrupted) return eintr();
    if (k == Woke::timeout) {
      bool ended;
      {
        Lock l;
        ended = g.ended;
      }
      if (ended) return attempt(flags);  // the run is over: the kernel decides
      const ssize_t last = attempt(flags | MSG_DONTWAIT);  // data there at the timeout's instant
      if (last >= 0 || (errno != EAGAIN && errno != EWOULDBLOCK)) return last;
      errno = EAGAIN;  // SO_RCVTIMEO passed
      return -1;
    }
    const ssize_t r = attempt(flags | MSG_DONTWAIT);
    if (r >= 0 || (errno != EAGAIN && errno != EWOULDBLOCK)) return r;
  }
}

// MSG_WAITALL on a blocking stream socket: receives until `len` bytes, the end of the stream, an
// error or SO_RCVTIMEO, which bounds the whole call as in the kernel (then what came is
// returned). `chunk(flags, off)` is the real call into the buffer from `off`.
template <class Chunk>
ssize_t receive_all(int fd, int flags, std::size_t len, Chunk chunk) {
  int type = 0;
  if (!(flags & MSG_WAITALL) || (flags & MSG_PEEK) || len == 0 || nonblocking(fd, flags) ||
      !is_socket(fd, nullptr, &type) || type != SOCK_STREAM)
    return receive(fd, flags, [&](int f) { return chunk(f, 0); });
  flags &= ~MSG_WAITALL;
  ns_t deadline;
  {
    Lock l;
    deadline = deadline_after(rcvtimeo(fd));
  }
  std::size_t got = 0;
  while (got < len) {
    const std::size_t off = got;
    const ssize_t n = receive(fd, flags, [&](int f) { return chunk(f, off); }, deadline);
    if (n < 0) return got > 0 ? static_cast<ssize_t>(got) : n;
    if (n == 0) break;  // the end of the stream
    got += static_cast<std::size_t>(n);
  }
  return static_cast<ssize_t>(got);
}

}  // namespace

// =============================================================================================
// The intercepted calls (C linkage, default visibility).
extern "C" {

// ---- clocks ----
int clock_gettime(clockid_t c, timespec* ts) {
  REAL(clock_gettime);
  if (!clocked() || !(is_mono(c) || is_real(c))) return real_clock_gettime(c, ts);
  *ts = ns_ts(clock_now(c));
  if (on()) spun();
  return 0;
}

int gettimeofday(struct timeval* tv, void* tz) {
  REAL(gettimeofday);
  if (!clocked()) return real_gettimeofday(tv, tz);
  asm("" : "+r"(tv));  // glibc declares tv non-null, the kernel takes NULL: keep the check below
  if (tv) {             // NULL: only the (obsolete) timezone is asked for
    const ns_t v = clock_now(CLOCK_REALTIME);
    tv->tv_sec = static_cast<time_t>(v / kNs);
    tv->tv_usec = static_cast<suseconds_t>((v % kNs) / 1000);
  }
  if (tz) memset(tz, 0, sizeof(struct timezone));
  if (on()) spun();
  return 0;
}

time_t time(time_t* out) {
  REAL(time);
  if (!clocked()) return real_time(out);
  const time_t v = static_cast<time_t>(clock_now(CLOCK_REALTIME) / kNs);
  if (out) *out = v;
  if (on()) spun();
  return v;
}

int timespec_get(timespec* ts, int base) {
  REAL(timespec_get);
  if (!clocked() || base != TIME_UTC) return real_timespec_get(ts, base);
  *ts = ns_ts(clock_now(CLOCK_REALTIME));
  if (on()) spun();
  return base;
}

// ---- sleeps ----
int clock_nanosleep(clockid_t c, int flags, const timespec* req, timespec* rem) {
  REAL(clock_nanosleep);
  if (!on()) {
    if (g.ended && (flags & TIMER_ABSTIME) && (is_mono(c) || is_real(c))) {
      // A deadline on the simulated clock, continued on the wall clock.
      const ns_t left = minus_base(ts_ns(*req), base_of(c)) - now_any();
      if (left <= 0) return 0;
      const timespec rel = ns_ts(left);
      return real_clock_nanosleep(CLOCK_MONOTONIC, 0, &rel, rem);
    }
    return real_clock_nanosleep(c, flags, req, rem);
  }
  if (!(is_mono(c) || is_real(c))) return real_clock_nanosleep(c, flags, req, rem);
  if (!req) return EFAULT;
  if (req->tv_nsec < 0 || req->tv_nsec >= kNs || req->tv_sec < 0) return EINVAL;
  ns_t deadline;
  {
    Lock l;
    deadline = (flags & TIMER_ABSTIME) ? minus_base(ts_ns(*req), base_of(c)) : add_sat(g.now, ts_ns(*req));
  }
  if (sleep_until(deadline)) {
    if (rem && !(flags & TIMER_ABSTIME)) *rem = ns_ts(deadline > now_any() ? deadline - now_any() : 0);
    return EINTR;
  }
  if (rem && !(flags & TIMER_ABSTIME)) *rem = timespec{0, 0};
  return 0;
}

int nanosleep(const timespec* req, timespec* rem) {
  REAL(nanosleep);
  if (!on()) return real_nanosleep(req, rem);
  const int e = clock_nanosleep(CLOCK_MONOTONIC, 0, req, rem);
  if (e != 0) {
    errno = e;
    return -1;
  }
  return 0;
}

int usleep(useconds_t us) {
  REAL(usleep);
  if (!on()) return real_usleep(us);
  ns_t d;
  {
    Lock l;
    d = add_sat(g.now, static_cast<ns_t>(us) * 1000);
  }
  return sleep_until(d) ? eintr() : 0;
}

unsigned int sleep(unsigned int s) {
  REAL(sleep);
  if (!on()) return real_sleep(s);
  ns_t d;
  {
    Lock l;
    d = add_sat(g.now, static_cast<ns_t>(s) * kNs);
  }
  if (!sleep_until(d)) return 0;
  const ns_t left = d > now_any() ? d - now_any() : 0;  // interrupted: the whole seconds left, as glibc
  return static_cast<unsigned int>(left / kNs);
}

// ---- descriptor waits ----
int poll(pollfd* fds, nfds_t n, int timeout_ms) {
  REAL(poll);
  if (!on()) return real_poll(fds, n, timeout_ms);
  const int r = real_poll(fds, n, 0);
  if (r != 0) {
    if (r > 0) t_spin = 0;
    return r;
  }
  if (timeout_ms == 0) {
    spun();
    return real_poll(fds, n, 0);
  }
  ns_t deadline;
  {
    Lock l;
    deadline = deadline_after(timeout_ms < 0 ? -1 : static_cast<ns_t>(timeout_ms) * 1'000'000);
  }
  for (;;) {
    // The timeout (or the run's end): the kernel's answer now, so that a descriptor ready at
    // the timeout's instant is reported, not lost.
    const Woke k = wait_fds(fds, n, deadline, &t_sigs);
    if (k == Woke::interrupted) return eintr();
    if (k == Woke::timeout) return real_poll(fds, n, 0);
    const int again = real_poll(fds, n, 0);
    if (again != 0) return again;
  }
}

int ppoll(pollfd* fds, nfds_t n, const timespec* tmo, const sigset_t* mask) {
  REAL(ppoll);
  if (!on()) return real_ppoll(fds, n, tmo, mask);
  if (tmo && (tmo->tv_nsec < 0 || tmo->tv_nsec >= kNs || tmo->tv_sec < 0)) {
    errno = EINVAL;
    return -1;
  }
  const timespec zero{0, 0};
  const int r = real_ppoll(fds, n, &zero, mask);
  if (r != 0) {
    if (r > 0) t_spin = 0;
    return r;
  }
  if (tmo && ts_ns(*tmo) == 0) {
    spun();
    return real_ppoll(fds, n, &zero, mask);
  }
  ns_t deadline;
  {
    Lock l;
    deadline = deadline_after(tmo ? ts_ns(*tmo) : -1);
  }
  for (;;) {
    const Woke k = wait_fds(fds, n, deadline, &t_sigs, mask);
    if (k == Woke::interrupted) return eintr();
    if (k == Woke::timeout) return real_ppoll(fds, n, &zero, mask);  // as in poll
    const int again = real_ppoll(fds, n, &zero, mask);
    if (again != 0) return again;
  }
}

}  // extern "C"

namespace {
// select() as poll: the descriptors of the three sets, waited for with a deadline.
int select_common(int nfds, fd_set* r, fd_set* w, fd_set* e, ns_t rel, const sigset_t* mask, timeval* tv_out) {
  REAL(pselect);
  fd_set r0, w0, e0;
  if (r) r0 = *r;
  if (w) w0 = *w;
  if (e) e0 = *e;
  const timespec zero{0, 0};
  auto attempt = [&]() {
    if (r) *r = r0;
    if (w) *w = w0;
    if (e) *e = e0;
    return real_pselect(nfds, r, w, e, &zero, mask);
  };
  const int first = attempt();
  if (first != 0) return first;
  if (rel == 0) {
    spun();
    return attempt();
  }
  pollfd fds[FD_SETSIZE];
  nfds_t n = 0;
  for (int fd = 0; fd < nfds && fd < FD_SETSIZE; ++fd) {
    short ev = 0;
    if (r && FD_ISSET(fd, &r0)) ev |= POLLIN;
    if (w && FD_ISSET(fd, &w0)) ev |= POLLOUT;
    if (e && FD_ISSET(fd, &e0)) ev |= POLLPRI;
    if (ev) fds[n++] = pollfd{fd, ev, 0};
  }
  ns_t deadline;
  {
    Lock l;
    deadline = deadline_after(rel);
  }
  // select (as Linux does) leaves the time not slept in its timeval.
  auto left = [&]() {
    if (!tv_out || deadline == vt::kNever) return;
    ns_t v = deadline - now_any();
    if (v < 0) v = 0;
    *tv_out = timeval{static_cast<time_t>(v / kNs), static_cast<suseconds_t>((v % kNs) / 1000)};
  };
  for (;;) {
    const Woke k = wait_fds(fds, n, deadline, &t_sigs, mask);
    if (k == Woke::interrupted) {  // the sets as the caller gave them (the kernel leaves them)
      if (r) *r = r0;
      if (w) *w = w0;
      if (e) *e = e0;
      left();
      return eintr();
    }
    if (k == Woke::timeout) {
      const int last = attempt();  // as in poll: ready at the timeout's instant counts
      left();
      return last;
    }
    const int again = attempt();
    if (again != 0) {
      left();
      return again;
    }
  }
}
}  // namespace

extern "C" {

int select(int nfds, fd_set* r, fd_set* w, fd_set* e, timeval* tv) {
  REAL(select);
  if (!on()) return real_select(nfds, r, w, e, tv);
  if (tv && (tv->tv_sec < 0 || tv->tv_usec < 0)) {
    errno = EINVAL;
    return -1;
  }
  ns_t rel = -1;
  if (tv) {  // the kernel takes tv_usec beyond a second too
    const timespec t{tv->tv_sec, 0};
    rel = add_sat(ts_ns(t), static_cast<ns_t>(tv->tv_usec) * 1000);
  }
  return select_common(nfds, r, w, e, rel, nullptr, tv);
}

int pselect(int nfds, fd_set* r, fd_set* w, fd_set* e, const timespec* ts, const sigset_t* mask) {
  REAL(pselect);
  if (!on()) return real_pselect(nfds, r, w, e, ts, mask);
  if (ts && (ts->tv_sec < 0 || ts->tv_nsec < 0 || ts->tv_nsec >= kNs)) {
    errno = EINVAL;
    return -1;
  }
  return select_common(nfds, r, w, e, ts ? ts_ns(*ts) : -1, mask, nullptr);
}

int epoll_pwait(int epfd, epoll_event* ev, int max, int timeout_ms, const sigset_t* mask) {
  REAL(epoll_pwait);
  if (!on()) return real_epoll_pwait(epfd, ev, max, timeout_ms, mask);
  const int r = real_epoll_pwait(epfd, ev, max, 0, mask);
  if (r != 0) {
    if (r > 0) t_spin = 0;
    return r;
  }
  if (timeout_ms == 0) {
    spun();
    return real_epoll_pwait(epfd, ev, max, 0, mask);
  }
  ns_t deadline;
  {
    Lock l;
    deadline = deadline_after(timeout_ms < 0 ? -1 : static_cast<ns_t>(timeout_ms) * 1'000'000);
  }
  pollfd p{epfd, POLLIN, 0};  // an epoll descriptor is readable while an event is ready
  for (;;) {
    const Woke k = wait_fds(&p, 1, deadline, &t_sigs, mask);
    if (k == Woke::interrupted) return eintr();
    if (k == Woke::timeout) return real_epoll_pwait(epfd, ev, max, 0, mask);  // as in poll
    const int again = real_epoll_pwait(epfd, ev, max, 0, mask);
    if (again != 0) return again;
  }
}

int epoll_wait(int epfd, epoll_event* ev, int max, int timeout_ms) {
  REAL(epoll_wait);
  if (!on()) return real_epoll_wait(epfd, ev, max, timeout_ms);
  return epoll_pwait(epfd, ev, max, timeout_ms, nullptr);
}

// ---- receives and sends on sockets ----
ssize_t recv(int fd, void* buf, size_t len, int flags) {
  REAL(recv);
  if (!on()) return real_recv(fd, buf, len, flags);
  return receive_all(fd, flags, len,
                     [&](int f, std::size_t off) { return real_recv(fd, static_cast<char*>(buf) + off, len - off, f); });
}

ssize_t recvfrom(int fd, void* buf, size_t len, int flags, sockaddr* from, socklen_t* fromlen) {
  REAL(recvfrom);
  if (!on()) return real_recvfrom(fd, buf, len, flags, from, fromlen);
  return receive_all(fd, flags, len, [&](int f, std::size_t off) {
    return real_recvfrom(fd, static_cast<char*>(buf) + off, len - off, f, from, fromlen);
  });
}

ssize_t recvmsg(int fd, msghdr* m, int flags) {
  REAL(recvmsg);
  if (!on()) return real_recvmsg(fd, m, flags);
  return receive(fd, flags, [&](int f) { return real_recvmsg(fd, m, f); });
}

int recvmmsg(int fd, mmsghdr* v, unsigned int n, int flags, timespec* tmo) {
  REAL(recvmmsg);
  if (!on()) return real_recvmmsg(fd, v, n, flags, tmo);
  // The timeout (checked by the kernel only between datagrams) is not simulated: see the docs.
  return static_cast<int>(receive(fd, flags, [&](int f) { return static_cast<ssize_t>(real_recvmmsg(fd, v, n, f, nullptr)); }));
}

ssize_t read(int fd, void* buf, size_t len) {
  REAL(read);
  REAL(recv);
  if (!on()) return real_read(fd, buf, len);
  bool timer = false;
  if (fd >= 0 && fd < kMaxFd) {
    Lock l;
    timer = g.timers[fd].used;
  }
  if (!timer && !is_socket(fd)) return real_read(fd, buf, len);
  if (timer) {
    // A timerfd: its eventfd holds the expirations. Read only when there (under the lock: no
    // other reader of the library's takes them meanwhile); else EAGAIN if the descriptor is
    // non-blocking now, or a wait on simulated time for the next expiration.
    if (len < sizeof(std::uint64_t)) {
      errno = EINVAL;
      return -1;
    }
    for (;;) {
      bool nonblock;
      {
        Lock l;
        if (has_expired(fd)) {
          t_spin = 0;
          return static_cast<ssize_t>(syscall(SYS_read, fd, buf, len));
        }
        const long fl = syscall(SYS_fcntl, fd, F_GETFL);
        nonblock = fl >= 0 && (fl & O_NONBLOCK);
      }
      if (nonblock) {
        spun();
        errno = EAGAIN;
        return -1;
      }
      pollfd p{fd, POLLIN, 0};
      const Woke k = wait_fds(&p, 1, vt::kNever, &t_sigs_norestart);  // a slow read: SA_RESTART restarts it
      if (k == Woke::interrupted) return eintr();
      if (k == Woke::timeout) {
        bool ended;
        {
          Lock l;
          ended = g.ended;
        }
        if (ended) return real_read(fd, buf, len);
      }
    }
  }
  return receive(fd, 0, [&](int f) { return real_recv(fd, buf, len, f); });
}

ssize_t send(int fd, const void* buf, size_t len, int flags) {
  REAL(send);
  const ssize_t n = real_send(fd, buf, len, flags);
  if (n >= 0 && on()) count_sent(bus_frames(fd, nullptr, static_cast<std::size_t>(n), 0));
  return n;
}

ssize_t sendto(int fd, const void* buf, size_t len, int flags, const sockaddr* to, socklen_t tolen) {
  REAL(sendto);
  const ssize_t n = real_sendto(fd, buf, len, flags, to, tolen);
  if (n >= 0 && on()) count_sent(bus_frames(fd, to, static_cast<std::size_t>(n), 0));
  return n;
}

ssize_t sendmsg(int fd, const msghdr* m, int flags) {
  REAL(sendmsg);
  const ssize_t n = real_sendmsg(fd, m, flags);
  if (n >= 0 && on())
    count_sent(bus_frames(fd, static_cast<const sockaddr*>(m->msg_name), static_cast<std::size_t>(n), msg_segment(m)));
  return n;
}

int sendmmsg(int fd, mmsghdr* v, unsigned int vlen, int flags) {
  REAL(sendmmsg);
  const int n = real_sendmmsg(fd, v, vlen, flags);
  if (n > 0 && on()) {
    std::uint64_t frames = 0;
    for (int i = 0; i < n; ++i)
      frames += bus_frames(fd, static_cast<const sockaddr*>(v[i].msg_hdr.msg_name), v[i].msg_len, msg_segment(&v[i].msg_hdr));
    count_sent(frames);
  }
  return n;
}

ssize_t write(int fd, const void* buf, size_t len) {
  REAL(write);
  const ssize_t n = real_write(fd, buf, len);
  if (n >= 0 && on() && fd > 2 && is_socket(fd)) count_sent(bus_frames(fd, nullptr, static_cast<std::size_t>(n), 0));
  return n;
}

// ---- timerfds ----
int timerfd_create(int clockid, int flags) {
  REAL(timerfd_create);
  if (!on() || !(is_mono(clockid) || is_real(clockid))) return real_timerfd_create(clockid, flags);
  if (flags & ~(TFD_NONBLOCK | TFD_CLOEXEC)) {
    errno = EINVAL;
    return -1;
  }
  const int fd = eventfd(0, (flags & TFD_NONBLOCK ? EFD_NONBLOCK : 0) | (flags & TFD_CLOEXEC ? EFD_CLOEXEC : 0));
  if (fd < 0) return fd;
  if (fd >= kMaxFd) {
    syscall(SYS_close, fd);
    errno = EMFILE;
    return -1;
  }
  Lock l;
  g.timers[fd] = Timer{true, vt::kNever, 0, clockid};
  if (fd >= g.timers_end) g.timers_end = fd + 1;
  return fd;
}

int timerfd_settime(int fd, int flags, const itimerspec* nv, itimerspec* old) {
  REAL(timerfd_settime);
  bool ours = false;
  if (fd >= 0 && fd < kMaxFd) {
    Lock l;
    ours = g.timers[fd].used;
  }
  if (!ours) return real_timerfd_settime(fd, flags, nv, old);
  if (!nv) {
    errno = EFAULT;
    return -1;
  }
  // As Linux: unknown flags and a negative or denormal value or interval are EINVAL.
  auto bad = [](const timespec& v) { return v.tv_sec < 0 || v.tv_nsec < 0 || v.tv_nsec >= kNs; };
  if ((flags & ~(TFD_TIMER_ABSTIME | TFD_TIMER_CANCEL_ON_SET)) || bad(nv->it_value) || bad(nv->it_interval)) {
    errno = EINVAL;
    return -1;
  }
  Lock l;
  Timer& t = g.timers[fd];
  if (old) {
    old->it_interval = ns_ts(t.interval);
    old->it_value = ns_ts(t.expiry == vt::kNever ? 0 : t.expiry - g.now);
  }
  if (has_expired(fd)) {  // re-arming clears pending expirations
    std::uint64_t drop = 0;
    ssize_t r = syscall(SYS_read, fd, &drop, sizeof drop);
    (void)r;
  }
  const ns_t v = ts_ns(nv->it_value);
  t.interval = ts_ns(nv->it_interval);
  if (v == 0)
    t.expiry = vt::kNever;
  else
    t.expiry = (flags & TFD_TIMER_ABSTIME) ? minus_base(v, base_of(t.clock)) : add_sat(g.now, v);
  if (t.expiry != vt::kNever && t.expiry <= g.now) fire_timers();
  return 0;
}

int timerfd_gettime(int fd, itimerspec* cur) {
  REAL(timerfd_gettime);
  bool ours = false;
  if (fd >= 0 && fd < kMaxFd) {
    Lock l;
    ours = g.timers[fd].used;
  }
  if (!ours) return real_timerfd_gettime(fd, cur);
  Lock l;
  const Timer& t = g.timers[fd];
  cur->it_interval = ns_ts(t.interval);
  cur->it_value = ns_ts(t.expiry == vt::kNever ? 0 : t.expiry - g.now);
  return 0;
}

int close(int fd) {
  REAL(close);
  if (fd >= 0 && fd < kMaxFd && g.active) {
    if (t_held > 0) {  // a signal handler inside the library's lock
      g.timers[fd].used = false;
    } else {
      Lock l;
      g.timers[fd].used = false;
    }
  }
  return real_close(fd);
}

// ---- signals ----
}  // extern "C"

namespace {
using info_handler = void (*)(int, siginfo_t*, void*);

// The library's handler in place of each of the program's: runs the program's, then counts it
// for the thread it ran on (the virtual wait there ends with EINTR at the next wake, lead()).
// Async-signal-safe: atomics and the program's own handler only.
void on_signal(int sig, siginfo_t* si, void* uc) {
  const int saved = errno;
  Handler h;
  h.fn = __atomic_load_n(&g.handlers[sig].fn, __ATOMIC_ACQUIRE);
  h.flags = __atomic_load_n(&g.handlers[sig].flags, __ATOMIC_ACQUIRE);
  // SA_RESETHAND: the kernel has made the disposition SIG_DFL again on delivery.
  if (h.flags & SA_RESETHAND) {
    __atomic_store_n(&g.handlers[sig].fn, nullptr, __ATOMIC_RELEASE);
    __atomic_store_n(&g.handlers[sig].reset, true, __ATOMIC_RELEASE);
    __atomic_and_fetch(&g.handled, ~(1ULL << (sig - 1)), __ATOMIC_RELEASE);
  }
  errno = saved;
  if (h.fn && (h.flags & SA_SIGINFO)) reinterpret_cast<info_handler>(h.fn)(sig, si, uc);
  else if (h.fn) reinterpret_cast<void (*)(int)>(h.fn)(sig);
  ++t_sigs;
  if (!(h.flags & SA_RESTART)) ++t_sigs_norestart;
  __atomic_add_fetch(&g.sigs, 1, __ATOMIC_RELEASE);
}

// A handler of the program's, not a disposition (SIG_DFL, SIG_IGN), whatever SA_SIGINFO says:
// sa_handler and sa_sigaction share their storage.
bool is_handler(const struct sigaction& a) {
  return a.sa_handler != SIG_DFL && a.sa_handler != SIG_IGN;
}

void* handler_of(const struct sigaction& a) {
  return (a.sa_flags & SA_SIGINFO) ? reinterpret_cast<void*>(a.sa_sigaction) : reinterpret_cast<void*>(a.sa_handler);
}

void record(int sig, void* fn, int flags) {
  __atomic_store_n(&g.handlers[sig].flags, flags, __ATOMIC_RELEASE);
  __atomic_store_n(&g.handlers[sig].reset, false, __ATOMIC_RELEASE);
  __atomic_store_n(&g.handlers[sig].fn, fn, __ATOMIC_RELEASE);
  const std::uint64_t bit = 1ULL << (sig - 1);
  if (fn) __atomic_or_fetch(&g.handled, bit, __ATOMIC_RELEASE);
  else __atomic_and_fetch(&g.handled, ~bit, __ATOMIC_RELEASE);
}
}  // namespace

extern "C" {

// The program's handlers are recorded and the library's installed in their place (same mask
// and flags, SA_SIGINFO added); the old action reads as the program set it.
int sigaction(int sig, const struct sigaction* act, struct sigaction* old) {
  REAL(sigaction);
  if (!g.active || sig <= 0 || sig >= NSIG || sig == SIGKILL || sig == SIGSTOP) return real_sigaction(sig, act, old);
  const Handler was{__atomic_load_n(&g.handlers[sig].fn, __ATOMIC_ACQUIRE), g.handlers[sig].flags,
                    __atomic_load_n(&g.handlers[sig].reset, __ATOMIC_ACQUIRE)};
  struct sigaction mine;
  const bool wrap = act && is_handler(*act);
  if (wrap) {
    mine = *act;
    mine.sa_sigaction = on_signal;
    mine.sa_flags = act->sa_flags | SA_SIGINFO;
    record(sig, handler_of(*act), act->sa_flags);  // first: a signal before the kernel's change runs the new one
  }
  const int r = real_sigaction(sig, wrap ? &mine : act, old);
  if (r != 0) {
    if (wrap) {
      record(sig, was.fn, was.flags);
      __atomic_store_n(&g.handlers[sig].reset, was.reset, __ATOMIC_RELEASE);
    }
    return r;
  }
  if (act && !wrap) record(sig, nullptr, act->sa_flags);
  // The old action as the program knows it: its own handler and flags, not the library's
  // (the kernel's own bits, such as SA_RESTORER, kept); after an SA_RESETHAND handler fired,
  // SIG_DFL without the SA_SIGINFO the library had added.
  if (old && ((was.fn && (old->sa_flags & SA_SIGINFO) && old->sa_sigaction == on_signal) || was.reset)) {
    old->sa_flags = (old->sa_flags & ~SA_SIGINFO) | (was.flags & SA_SIGINFO);
    if (was.reset) old->sa_handler = SIG_DFL;
    else if (was.flags & SA_SIGINFO) old->sa_sigaction = reinterpret_cast<info_handler>(was.fn);
    else old->sa_handler = reinterpret_cast<void (*)(int)>(was.fn);
  }
  return 0;
}

// signal() as glibc makes it (BSD semantics: SA_RESTART unless siginterrupt(sig, 1) was called,
// the signal blocked in its handler), through sigaction above.
sighandler_t signal(int sig, sighandler_t h) {
  REAL(signal);
  if (!g.active) return real_signal(sig, h);
  if (h == SIG_ERR || sig <= 0 || sig >= NSIG) {
    errno = EINVAL;
    return SIG_ERR;
  }
  struct sigaction a, o;
  memset(&a, 0, sizeof a);
  a.sa_handler = h;
  sigemptyset(&a.sa_mask);
  sigaddset(&a.sa_mask, sig);
  const bool intr = (__atomic_load_n(&g.no_restart, __ATOMIC_ACQUIRE) >> (sig - 1)) & 1ULL;
  a.sa_flags = intr ? 0 : SA_RESTART;
  if (sigaction(sig, &a, &o) != 0) return SIG_ERR;
  return o.sa_handler;
}

// siginterrupt(): glibc changes the action through its internal sigaction, which the library
// does not see; done here through the one above, so the recorded flags follow.
}  // extern "C"

namespace {
// A signal the process sent itself runs its handler on the thread the kernel picks, perhaps a
// waiting one, at once but asynchronously: the sender waits (at most 100 ms of wall time) until
// the handler has run, so that the wait it interrupts is seen ended at the next lead, the same
// in every run (await_handler).
void await_own_signal(int sig, std::uint32_t before) {
  await_handler(sig, before, __atomic_load_n(&g.handled, __ATOMIC_ACQUIRE), 100'000'000);
}

bool to_self(pid_t pid) { return pid == 0 || pid == getpid() || pid == -getpgrp(); }
}  // namespace

extern "C" {

int pthread_kill(pthread_t t, int sig) {
  REAL(pthread_kill);
  const std::uint32_t before = __atomic_load_n(&g.sigs, __ATOMIC_ACQUIRE);
  const int r = real_pthread_kill(t, sig);
  if (r == 0 && on()) await_own_signal(sig, before);
  return r;
}

int kill(pid_t pid, int sig) {
  REAL(kill);
  const std::uint32_t before = __atomic_load_n(&g.sigs, __ATOMIC_ACQUIRE);
  const int r = real_kill(pid, sig);
  if (r == 0 && on() && to_self(pid)) await_own_signal(sig, before);
  return r;
}

int sigqueue(pid_t pid, int sig, const union sigval value) {
  REAL(sigqueue);
  const std::uint32_t before = __atomic_load_n(&g.sigs, __ATOMIC_ACQUIRE);
  const int r = real_sigqueue(pid, sig, value);
  if (r == 0 && on() && to_self(pid)) await_own_signal(sig, before);
  return r;
}

#pragma GCC diagnostic push
#pragma GCC diagnostic ignored "-Wdeprecated-declarations"  // intercepted as programs still call it
int siginterrupt(int sig, int flag) {
  REAL(siginterrupt);
  if (!g.active) return real_siginterrupt(sig, flag);
  if (sig <= 0 || sig >= NSIG) {
    errno = EINVAL;
    return -1;
  }
  const std::uint64_t bit = 1ULL << (sig - 1);
  if (flag) __atomic_or_fetch(&g.no_restart, bit, __ATOMIC_RELEASE);
  else __atomic_and_fetch(&g.no_restart, ~bit, __ATOMIC_RELEASE);
  struct sigaction a;
  if (sigaction(sig, nullptr, &a) != 0) return -1;
  if (flag) a.sa_flags &= ~SA_RESTART;
  else a.sa_flags |= SA_RESTART;
  return sigaction(sig, &a, nullptr);
}
#pragma GCC diagnostic pop

// ---- threads ----
}  // extern "C"

namespace {
struct Start {
  void* (*fn)(void*);
  void* arg;
};

void thread_ends() {
  Lock l;
  if (!g.active) return;
  --g.running;
  auto* e = static_cast<Exited*>(malloc(sizeof(Exited)));
  if (e) {
    e->id = pthread_self();
    e->serial = ++g.exits;
    e->next = g.exited;
    g.exited = e;
  }
  for (Waiter* w = g.waiters; w; w = w->next)
    if (w->joining && !w->satisfied && pthread_equal(w->join, pthread_self())) satisfy(w);
  cv_broadcast(&g.cv);  // a leader may be due now that one runner fewer is left
}

// Forgets ended threads with id `t` (lock held); only those that ended by `serial` when given:
// glibc reuses a joined or detached thread's id for a new thread.
void forget_exited(pthread_t t, std::uint64_t serial = UINT64_MAX) {
  for (Exited** p = &g.exited; *p;) {
    Exited* e = *p;
    if (pthread_equal(e->id, t) && e->serial <= serial) {
      *p = e->next;
      free(e);
    } else {
      p = &e->next;
    }
  }
}

void* trampoline(void* p) {
  Start s = *static_cast<Start*>(p);
  free(p);
  void* r = s.fn(s.arg);
  thread_ends();
  return r;
}
}  // namespace

extern "C" {

int pthread_create(pthread_t* t, const pthread_attr_t* a, void* (*fn)(void*), void* arg) {
  REAL(pthread_create);
  if (!g.active) return real_pthread_create(t, a, fn, arg);
  auto* s = static_cast<Start*>(malloc(sizeof(Start)));
  if (!s) return EAGAIN;
  *s = Start{fn, arg};
  std::uint64_t before;
  {
    Lock l;
    ++g.running;  // counted before it starts: time cannot move past its first instant
    before = g.exits;
  }
  const int r = real_pthread_create(t, a, trampoline, s);
  Lock l;
  if (r != 0) {
    free(s);
    --g.running;
  } else {
    forget_exited(*t, before);  // an earlier thread's end under the same id (the new one may have ended already)
  }
  return r;
}

void pthread_exit(void* v) {
  static auto real_exit = real<void (*)(void*)>("pthread_exit");
  if (g.active) thread_ends();
  real_exit(v);
  __builtin_unreachable();
}

int pthread_join(pthread_t t, void** ret) {
  REAL(pthread_join);
  if (on()) {
    Lock l;
    bool done = false;
    for (Exited* e = g.exited; e; e = e->next) done = done || pthread_equal(e->id, t);
    if (!done) {
      Waiter w;
      w.joining = true;
      w.join = t;
      wait_virtual(w);
    }
  }
  const int r = real_pthread_join(t, ret);
  if (r == 0 && g.active && t_held == 0) {
    Lock l;
    forget_exited(t);
  }
  return r;
}

// Condition variables: a wait on the simulated clock, ended by a signal or broadcast of the same
// variable or by its deadline (POSIX allows the spurious wake-ups this may add).
}  // extern "C"

namespace {
int cond_wait_virtual(pthread_cond_t* c, pthread_mutex_t* m, ns_t deadline) {
  Waiter w;
  w.cond = c;
  w.deadline = deadline;
  mu_lock();  // registered before the user's mutex is released: no lost signal
  pthread_mutex_unlock(m);
  wait_virtual(w);
  const bool timed_out = w.timed_out;
  mu_unlock();
  pthread_mutex_lock(m);
  return timed_out ? ETIMEDOUT : 0;
}

int cond_wake(pthread_cond_t* c, bool all) {
  bool found = false;
  if (on()) {
    Lock l;
    for (Waiter* w = g.waiters; w; w = w->next) {
      if (w->cond != c || w->satisfied) continue;
      satisfy(w);
      found = true;
      if (!all) break;
    }
    if (found) cv_broadcast(&g.cv);
  }
  static auto real_sig = real<cond_signal_fn>("pthread_cond_signal");
  static auto real_all = real<cond_signal_fn>("pthread_cond_broadcast");
  return all || !found ? (all ? real_all(c) : real_sig(c)) : 0;
}
}  // namespace

extern "C" {

int pthread_cond_wait(pthread_cond_t* c, pthread_mutex_t* m) {
  static auto real_wait = real<cond_wait_fn>("pthread_cond_wait");
  if (!on()) return real_wait(c, m);
  return cond_wait_virtual(c, m, vt::kNever);
}

int pthread_cond_timedwait(pthread_cond_t* c, pthread_mutex_t* m, const timespec* abs) {
  static auto real_wait = real<cond_timedwait_fn>("pthread_cond_timedwait");
  if (!clocked()) return real_wait(c, m, abs);
  if (abs->tv_nsec < 0 || abs->tv_nsec >= kNs) return EINVAL;
  // The variable's clock is not visible: a deadline below 10^9 s is on the monotonic clock.
  const ns_t v = ts_ns(*abs);
  const bool mono = v < 1'000'000'000LL * kNs;
  const ns_t deadline = minus_base(v, mono ? kMonoBase : g.epoch);
  if (on()) return cond_wait_virtual(c, m, deadline);
  // After the end: the same instant on the real clock.
  const ns_t left = deadline - now_any();
  timespec real_now;
  syscall(SYS_clock_gettime, mono ? CLOCK_MONOTONIC : CLOCK_REALTIME, &real_now);
  const timespec until = ns_ts(add_sat(ts_ns(real_now), left > 0 ? left : 0));
  return real_wait(c, m, &until);
}

int pthread_cond_clockwait(pthread_cond_t* c, pthread_mutex_t* m, clockid_t clk, const timespec* abs) {
  static auto real_wait = real<int (*)(pthread_cond_t*, pthread_mutex_t*, clockid_t, const timespec*)>("pthread_cond_clockwait");
  if (!clocked() || !(is_mono(clk) || is_real(clk))) return real_wait(c, m, clk, abs);
  if (abs->tv_nsec < 0 || abs->tv_nsec >= kNs) return EINVAL;
  const ns_t deadline = minus_base(ts_ns(*abs), base_of(clk));
  if (on()) return cond_wait_virtual(c, m, deadline);
  const ns_t left = deadline - now_any();
  timespec real_now;
  syscall(SYS_clock_gettime, clk, &real_now);
  const timespec until = ns_ts(add_sat(ts_ns(real_now), left > 0 ? left : 0));
  return real_wait(c, m, clk, &until);
}

int pthread_cond_signal(pthread_cond_t* c) { return cond_wake(c, false); }
int pthread_cond_broadcast(pthread_cond_t* c) { return cond_wake(c, true); }

}  // extern "C"
