// controller layer — the sim-clock channel; see sim_clock.hpp and docs/protocols/sim-clock.md.
#include "controller/sim_clock.hpp"

#include <poll.h>
#include <sys/socket.h>
#include <sys/stat.h>
#include <sys/time.h>
#include <sys/un.h>
#include <unistd.h>

#include <algorithm>
#include <bit>
#include <cerrno>
#include <cmath>
#include <cstddef>
#include <cstring>
#include <limits>
#include <system_error>
#include <thread>
#include <utility>

namespace omnitwin::simclock {

const char* to_string(MasterState s) {
  switch (s) {
    case MasterState::waiting: return "waiting";
    case MasterState::detecting: return "detecting";
    case MasterState::running: return "running";
    case MasterState::stopped: return "stopped";
    case MasterState::finished: return "finished";
  }
  return "unknown";
}

const char* to_string(StopReason r) {
  switch (r) {
    case StopReason::none: return "none";
    case StopReason::node_missing: return "node_missing";
    case StopReason::feedback_missing: return "feedback_missing";
    case StopReason::nmt_stop: return "nmt_stop";
    case StopReason::startup_timeout: return "startup_timeout";
    case StopReason::bus_error: return "bus_error";
    case StopReason::drive_fault: return "drive_fault";
    case StopReason::config_failed: return "config_failed";
  }
  return "unknown";
}

const char* to_string(DecodeError e) {
  switch (e) {
    case DecodeError::wrong_size: return "wrong_size";
    case DecodeError::bad_magic: return "bad_magic";
    case DecodeError::bad_version: return "bad_version";
    case DecodeError::unknown_type: return "unknown_type";
    case DecodeError::bad_value: return "bad_value";
  }
  return "unknown";
}

const char* to_string(WaitStatus s) {
  switch (s) {
    case WaitStatus::ok: return "ok";
    case WaitStatus::timeout: return "timeout";
    case WaitStatus::closed: return "closed";
    case WaitStatus::protocol: return "protocol";
  }
  return "unknown";
}

// ---------------------------------------------------------------------------------------------
// Codec. Layout (byte offsets, little-endian; docs/protocols/sim-clock.md has the table):
//   0 u32 magic, 4 u16 version, 6 u8 type (1 Hello, 2 Grant, 3 Done, 4 End, 5 Sent,
//   6 Horizon), 7 u8 reserved = 0
//   Hello  8 u32 pid
//   Grant  8 u64 tick, 16 i64 t_ns, 24 4×u64 frames, 56 u8 stop (0/1)
//   Done   8 u64 tick, 16 4×u64 frames, 48 u8 state, 49 u8 reason, 50 u8 node, 51 u8 last (0/1),
//          52 i64 path_origin_ns, 60 3×f32 reference, 72 3×f32 odometry
//   End    8 i64 t_ns
//   Sent   8 u64 tick, 16 i64 t_ns, 24 4×u64 frames
//   Horizon 8 u64 tick, 16 i64 arrival_ns, 24 4×u64 frames, 56 i64 quiet_until_ns
// Every byte after a type's last field is zero. The poses travel as f32 (doubles would make
// Done 108 bytes); NaN travels as the one canonical quiet NaN so that decode∘encode is exact.

namespace {

enum class Type : std::uint8_t { hello = 1, grant = 2, done = 3, end = 4, sent = 5, horizon = 6 };
constexpr std::size_t kHeaderSize = 8;
constexpr std::uint32_t kCanonicalNan = 0x7fc00000u;  // the f32 bits every NaN is sent as

using Bytes = std::array<std::uint8_t, kMessageSize>;

// Sequential little-endian writer into a zeroed record.
class Writer {
 public:
  explicit Writer(Bytes& b) : b_(b) {}
  void u8(std::uint8_t v) { b_[pos_++] = v; }
  void u16(std::uint16_t v) { put(v, 2); }
  void u32(std::uint32_t v) { put(v, 4); }
  void u64(std::uint64_t v) { put(v, 8); }
  void i64(std::int64_t v) { put(static_cast<std::uint64_t>(v), 8); }
  // Narrows to f32: NaN → the canonical NaN, beyond ±FLT_MAX → ±inf (no UB in the cast).
  void f32(double v) {
    constexpr double kMax = std::numeric_limits<float>::max();
    const float inf = std::numeric_limits<float>::infinity();
    const float f = v > kMax ? inf : v < -kMax ? -inf : static_cast<float>(v);
    u32(std::isnan(v) ? kCanonicalNan : std::bit_cast<std::uint32_t>(f));
  }

 private:
  void put(std::uint64_t v, int n) {
    for (int i = 0; i < n; ++i) b_[pos_++] = static_cast<std::uint8_t>(v >> (8 * i));
  }
  Bytes& b_;
  std::size_t pos_ = 0;
};

// Sequential little-endian reader over a record of kMessageSize bytes.
class Reader {
 public:
  explicit Reader(const std::uint8_t* d) : d_(d) {}
  std::uint8_t u8() { return d_[pos_++]; }
  std::uint16_t u16() { return static_cast<std::uint16_t>(get(2)); }
  std::uint32_t u32() { return static_cast<std::uint32_t>(get(4)); }
  std::uint64_t u64() { return get(8); }
  std::int64_t i64() { return static_cast<std::int64_t>(get(8)); }
  // An f32 widened to double; false for a NaN other than the canonical one.
  bool f32(double& out) {
    const std::uint32_t bits = u32();
    const float f = std::bit_cast<float>(bits);
    out = static_cast<double>(f);
    return !std::isnan(f) || bits == kCanonicalNan;
  }
  // True when every byte from the current position to the end is zero.
  bool rest_zero() const {
    for (std::size_t i = pos_; i < kMessageSize; ++i)
      if (d_[i] != 0) return false;
    return true;
  }

 private:
  std::uint64_t get(int n) {
    std::uint64_t v = 0;
    for (int i = 0; i < n; ++i) v |= static_cast<std::uint64_t>(d_[pos_++]) << (8 * i);
    return v;
  }
  const std::uint8_t* d_;
  std::size_t pos_ = 0;
};

void write_header(Writer& w, Type t) {
  w.u32(kMagic);
  w.u16(kVersion);
  w.u8(static_cast<std::uint8_t>(t));
  w.u8(0);  // reserved
}

void write_body(Writer& w, const Hello& h) {
  write_header(w, Type::hello);
  w.u32(h.pid);
}

void write_body(Writer& w, const Grant& g) {
  write_header(w, Type::grant);
  w.u64(g.tick);
  w.i64(g.t_ns);
  for (std::uint64_t f : g.frames) w.u64(f);
  w.u8(g.stop ? 1 : 0);
}

void write_body(Writer& w, const Done& d) {
  write_header(w, Type::done);
  w.u64(d.tick);
  for (std::uint64_t f : d.frames) w.u64(f);
  w.u8(static_cast<std::uint8_t>(d.report.state));
  w.u8(static_cast<std::uint8_t>(d.report.reason));
  w.u8(d.report.node);
  w.u8(d.last ? 1 : 0);
  w.i64(d.report.path_origin_ns);
  for (double v : d.report.reference) w.f32(v);
  for (double v : d.report.odometry) w.f32(v);
}

void write_body(Writer& w, const End& e) {
  write_header(w, Type::end);
  w.i64(e.t_ns);
}

void write_body(Writer& w, const Sent& s) {
  write_header(w, Type::sent);
  w.u64(s.tick);
  w.i64(s.t_ns);
  for (std::uint64_t f : s.frames) w.u64(f);
}

void write_body(Writer& w, const Horizon& h) {
  write_header(w, Type::horizon);
  w.u64(h.tick);
  w.i64(h.arrival_ns);
  for (std::uint64_t f : h.frames) w.u64(f);
  w.i64(h.quiet_until_ns);
}

using Decoded = std::variant<Message, DecodeError>;

// The fields of a Done after its header; bad_value for out-of-range enums or `last`, or NaNs.
Decoded read_done(Reader& r) {
  Done d;
  d.tick = r.u64();
  for (std::uint64_t& f : d.frames) f = r.u64();
  const std::uint8_t state = r.u8(), reason = r.u8();
  d.report.node = r.u8();
  const std::uint8_t last = r.u8();
  d.report.path_origin_ns = r.i64();
  bool floats_ok = true;
  for (double& v : d.report.reference) floats_ok = r.f32(v) && floats_ok;
  for (double& v : d.report.odometry) floats_ok = r.f32(v) && floats_ok;
  if (state > static_cast<std::uint8_t>(MasterState::finished) ||
      reason > static_cast<std::uint8_t>(StopReason::config_failed) || last > 1 || !floats_ok)
    return DecodeError::bad_value;
  d.report.state = static_cast<MasterState>(state);
  d.report.reason = static_cast<StopReason>(reason);
  d.last = last == 1;
  return Message{d};
}

// The body of a message of type `type` (header already checked).
Decoded read_body(Reader& r, std::uint8_t type) {
  switch (static_cast<Type>(type)) {
    case Type::hello: return Message{Hello{r.u32()}};
    case Type::grant: {
      Grant g;
      g.tick = r.u64();
      g.t_ns = r.i64();
      for (std::uint64_t& f : g.frames) f = r.u64();
      const std::uint8_t stop = r.u8();
      if (stop > 1) return DecodeError::bad_value;
      g.stop = stop == 1;
      return Message{g};
    }
    case Type::done: return read_done(r);
    case Type::end: return Message{End{r.i64()}};
    case Type::sent: {
      Sent m;
      m.tick = r.u64();
      m.t_ns = r.i64();
      for (std::uint64_t& f : m.frames) f = r.u64();
      return Message{m};
    }
    case Type::horizon: {
      Horizon h;
      h.tick = r.u64();
      h.arrival_ns = r.i64();
      for (std::uint64_t& f : h.frames) f = r.u64();
      h.quiet_until_ns = r.i64();
      return Message{h};
    }
  }
  return DecodeError::unknown_type;
}

}  // namespace

std::array<std::uint8_t, kMessageSize> encode(const Message& m) noexcept {
  // A zeroed record; the body writer fills the header and the type's fields.
  Bytes out{};
  Writer w(out);
  if (const auto* h = std::get_if<Hello>(&m)) write_body(w, *h);
  else if (const auto* g = std::get_if<Grant>(&m)) write_body(w, *g);
  else if (const auto* d = std::get_if<Done>(&m)) write_body(w, *d);
  else if (const auto* e = std::get_if<End>(&m)) write_body(w, *e);
  else if (const auto* st = std::get_if<Sent>(&m)) write_body(w, *st);
  else if (const auto* hz = std::get_if<Horizon>(&m)) write_body(w, *hz);
  return out;
}

std::variant<Message, DecodeError> decode(const std::uint8_t* data, std::size_t size) noexcept {
  // Header checks, in the order of the DecodeError values.
  if (data == nullptr || size != kMessageSize) return DecodeError::wrong_size;
  Reader r(data);
  if (r.u32() != kMagic) return DecodeError::bad_magic;
  if (r.u16() != kVersion) return DecodeError::bad_version;
  const std::uint8_t type = r.u8();
  if (type < static_cast<std::uint8_t>(Type::hello) || type > static_cast<std::uint8_t>(Type::horizon))
    return DecodeError::unknown_type;
  if (r.u8() != 0) return DecodeError::bad_value;  // reserved
  // The body, then every unused byte must be zero (so re-encoding gives the same bytes).
  Decoded d = read_body(r, type);
  if (std::holds_alternative<Message>(d) && !r.rest_zero()) return DecodeError::bad_value;
  return d;
}

// ---------------------------------------------------------------------------------------------
// Socket helpers: every call retries on EINTR; sends use MSG_NOSIGNAL (a dead peer is a status,
// never a SIGPIPE).

namespace {

using Clock = std::chrono::steady_clock;
constexpr std::chrono::milliseconds kMaxTimeout{365LL * 24 * 3600 * 1000};  // now + this cannot overflow
constexpr std::chrono::milliseconds kConnectRetry{10};                     // between connect tries

// The instant `timeout` from now (negative timeouts count as 0).
Clock::time_point deadline_after(std::chrono::milliseconds timeout) {
  return Clock::now() + std::clamp(timeout, std::chrono::milliseconds{0}, kMaxTimeout);
}

// Milliseconds left until `deadline` for poll(), rounded up; 0 once it has passed.
int remaining_ms(Clock::time_point deadline) {
  const auto left = deadline - Clock::now();
  if (left <= Clock::duration::zero()) return 0;
  const auto ms = std::chrono::ceil<std::chrono::milliseconds>(left).count();
  return static_cast<int>(std::min<std::int64_t>(ms, std::numeric_limits<int>::max()));
}

std::string errno_text(int err) { return std::generic_category().message(err); }

// Waits until fd is readable (ok), the deadline passes (timeout) or poll fails (closed).
WaitStatus wait_readable(int fd, Clock::time_point deadline) {
  for (;;) {
    pollfd p{fd, POLLIN, 0};
    const int r = ::poll(&p, 1, remaining_ms(deadline));
    if (r > 0) return WaitStatus::ok;
    if (r == 0) return WaitStatus::timeout;
    if (errno != EINTR) return WaitStatus::closed;
  }
}

// Sends one encoded message; false when the peer is gone (EPIPE, ECONNRESET, …).
bool send_message(int fd, const Message& m) {
  const Bytes bytes = encode(m);
  for (;;) {
    const ssize_t n = ::send(fd, bytes.data(), bytes.size(), MSG_NOSIGNAL);
    if (n == static_cast<ssize_t>(bytes.size())) return true;
    if (n >= 0 || errno != EINTR) return false;
  }
}

// The result of one received record: ok (decoded into out) or protocol (it does not decode).
WaitStatus decode_into(const std::uint8_t* data, ssize_t n, Message& out) {
  const auto d = decode(data, static_cast<std::size_t>(n));
  if (const auto* m = std::get_if<Message>(&d)) {
    out = *m;
    return WaitStatus::ok;
  }
  return WaitStatus::protocol;
}

// Receives one message by `deadline`: ok (decoded into out), timeout, closed (end of stream or
// a receive error) or protocol (it does not decode). Over-long records read as wrong_size.
// It tries the socket first and polls only when nothing is there: the caller usually knows a
// message is waiting (the master after its poll), so that is one system call, not two.
WaitStatus receive_message(int fd, Clock::time_point deadline, Message& out) {
  std::array<std::uint8_t, kMessageSize + 1> buf;
  for (;;) {
    const ssize_t n = ::recv(fd, buf.data(), buf.size(), MSG_DONTWAIT);
    if (n == 0) return WaitStatus::closed;
    if (n > 0) return decode_into(buf.data(), n, out);
    if (errno == EINTR) continue;
    if (errno != EAGAIN && errno != EWOULDBLOCK) return WaitStatus::closed;
    const WaitStatus w = wait_readable(fd, deadline);
    if (w != WaitStatus::ok) return w;
  }
}

// As receive_message, for a message that is usually not there yet (the twin's Done): waits in
// recv() itself, bounded by SO_RCVTIMEO (set only when the bound changes, cached in
// *timeout_us), so a tick costs one system call instead of a poll and a recv. The descriptor
// must be blocking.
// With `stop` given, the wait is cut into slices of kStopSlice (a signal may land on another
// thread and interrupt nothing here), and once *stop is set the deadline comes at most
// kStopGrace later: a master that does not answer then is not waited for (found in review: a
// Ctrl-C to a twin whose lockstep master hung waited the whole handshake timeout, 10 s).
constexpr std::chrono::milliseconds kStopSlice{100};
constexpr std::chrono::milliseconds kStopGrace{1000};

WaitStatus receive_message_blocking(int fd, Clock::time_point deadline, Message& out, std::int64_t* timeout_us,
                                    const std::atomic<bool>* stop = nullptr) {
  std::array<std::uint8_t, kMessageSize + 1> buf;
  bool stop_seen = false;
  for (;;) {
    if (stop != nullptr && !stop_seen && stop->load()) {
      stop_seen = true;
      deadline = std::min(deadline, Clock::now() + kStopGrace);
    }
    const auto left = deadline - Clock::now();
    if (left <= Clock::duration::zero()) return receive_message(fd, deadline, out);  // one look, no wait
    // Whole milliseconds (as poll() would wait), so the option is set once per distinct bound.
    const auto slice = stop != nullptr && !stop_seen ? std::min<Clock::duration>(left, kStopSlice) : left;
    const std::int64_t us = std::chrono::ceil<std::chrono::milliseconds>(slice).count() * 1000;
    if (us != *timeout_us) {
      const timeval tv{static_cast<time_t>(us / 1'000'000), static_cast<suseconds_t>(us % 1'000'000)};
      if (::setsockopt(fd, SOL_SOCKET, SO_RCVTIMEO, &tv, sizeof tv) != 0) return receive_message(fd, deadline, out);
      *timeout_us = us;
    }
    const ssize_t n = ::recv(fd, buf.data(), buf.size(), 0);
    if (n == 0) return WaitStatus::closed;
    if (n > 0) return decode_into(buf.data(), n, out);
    if (errno == EINTR) continue;
    if (errno == EAGAIN || errno == EWOULDBLOCK) {
      if (Clock::now() >= deadline) return WaitStatus::timeout;
      if (stop != nullptr) continue;  // the end of a slice: look at the flag, wait on
      return receive_message(fd, deadline, out);
    }
    return WaitStatus::closed;
  }
}

// True for an abstract-namespace name ("@NAME": no file, nothing to clean up, no directory
// that must be able to hold a socket).
bool is_abstract(const std::string& path) { return path.front() == '@'; }

// The socket address for `path` with its exact length ("@NAME" in the abstract namespace);
// throws ChannelError when it does not fit sun_path.
struct SocketAddress {
  sockaddr_un sa{};
  socklen_t len = 0;
};
SocketAddress socket_address(const std::string& path) {
  SocketAddress a;
  a.sa.sun_family = AF_UNIX;
  if (path.size() >= sizeof(a.sa.sun_path))
    throw ChannelError("sim-clock socket path is " + std::to_string(path.size()) +
                       " bytes; a Unix socket path holds at most " + std::to_string(sizeof(a.sa.sun_path) - 1) +
                       ": " + path);
  std::memcpy(a.sa.sun_path, path.data(), path.size());
  if (is_abstract(path)) a.sa.sun_path[0] = '\0';  // the abstract name is the bytes after the NUL
  a.len = static_cast<socklen_t>(offsetof(sockaddr_un, sun_path) + path.size() + (is_abstract(path) ? 0 : 1));
  return a;
}

// A new SOCK_SEQPACKET socket; throws ChannelError.
int make_socket(int extra_flags) {
  const int fd = ::socket(AF_UNIX, SOCK_SEQPACKET | SOCK_CLOEXEC | extra_flags, 0);
  if (fd < 0) throw ChannelError("sim-clock: cannot create a Unix socket: " + errno_text(errno));
  return fd;
}

void close_fd(int& fd) {
  if (fd >= 0) ::close(fd);
  fd = -1;
}

// Removes a socket file left at `path` by an earlier run (never a file of another kind).
void remove_stale_socket(const std::string& path) {
  if (is_abstract(path)) return;
  struct stat st{};
  if (::lstat(path.c_str(), &st) == 0 && S_ISSOCK(st.st_mode)) ::unlink(path.c_str());
}

// True for connect() failures that mean "the twin is not listening yet".
bool retry_connect(int err) {
  return err == ENOENT || err == ECONNREFUSED || err == EINTR || err == EAGAIN;
}

// Connects a new socket to `sa`, retrying while the listener is missing until `deadline`;
// -1 when `stop_fd` (>= 0) becomes readable meanwhile.
int connect_until(const SocketAddress& sa, Clock::time_point deadline, const std::string& path, int stop_fd) {
  for (;;) {
    int fd = make_socket(0);
    if (::connect(fd, reinterpret_cast<const sockaddr*>(&sa.sa), sa.len) == 0) return fd;
    const int err = errno;
    close_fd(fd);
    const auto left = deadline - Clock::now();
    if (!retry_connect(err) || left <= Clock::duration::zero())
      throw ChannelError("sim-clock: cannot connect to " + path + ": " + errno_text(err));
    const auto wait = std::min<Clock::duration>(left, kConnectRetry);
    if (stop_fd < 0) {
      std::this_thread::sleep_for(wait);
      continue;
    }
    pollfd p{stop_fd, POLLIN, 0};
    const auto ms = std::chrono::ceil<std::chrono::milliseconds>(wait).count();
    if (::poll(&p, 1, static_cast<int>(ms)) > 0 && (p.revents & POLLIN)) return -1;
  }
}

}  // namespace

std::string parse_address(std::string_view address) {
  // "unix:" followed by a non-empty path without NUL bytes ("@" alone names nothing).
  constexpr std::string_view kScheme = "unix:";
  const bool ok = address.starts_with(kScheme) && address.size() > kScheme.size() &&
                  address.find('\0') == std::string_view::npos && address != "unix:@";
  if (!ok)
    throw ChannelError("sim-clock address '" + std::string(address) + "': expected unix:PATH");
  return std::string(address.substr(kScheme.size()));
}

// ---------------------------------------------------------------------------------------------
// Server (twin end).

Server::Server(std::string_view address) : address_(address), path_(parse_address(address)) {
  // Address first (it may throw), then a non-blocking listener bound in place of a stale file.
  const SocketAddress sa = socket_address(path_);
  remove_stale_socket(path_);
  listen_fd_ = make_socket(SOCK_NONBLOCK);
  if (::bind(listen_fd_, reinterpret_cast<const sockaddr*>(&sa.sa), sa.len) != 0) {
    const int err = errno;
    close_fd(listen_fd_);
    throw ChannelError("sim-clock: cannot bind " + path_ + ": " + errno_text(err));
  }
  if (::listen(listen_fd_, 1) != 0) {
    const int err = errno;
    close_fd(listen_fd_);
    if (!is_abstract(path_)) ::unlink(path_.c_str());
    throw ChannelError("sim-clock: cannot listen on " + path_ + ": " + errno_text(err));
  }
}

Server::~Server() {
  close_fd(pending_fd_);
  close_fd(conn_fd_);
  if (listen_fd_ >= 0 && !is_abstract(path_)) ::unlink(path_.c_str());
  close_fd(listen_fd_);
}

WaitStatus Server::accept(std::chrono::milliseconds timeout, Hello* hello) {
  // A new master replaces any earlier connection; one that connected in an earlier call but
  // has not said Hello yet is still waited for (closing it at the end of a short slice broke a
  // master that was descheduled between connect() and its Hello: "Broken pipe").
  const Clock::time_point deadline = deadline_after(timeout);
  if (pending_fd_ < 0) {
    close_fd(conn_fd_);
    rcvtimeo_us_ = 0;  // a new socket has no receive timeout
  }
  while (pending_fd_ < 0) {
    const WaitStatus w = wait_readable(listen_fd_, deadline);
    if (w != WaitStatus::ok) return w;
    pending_fd_ = ::accept4(listen_fd_, nullptr, nullptr, SOCK_CLOEXEC);
    if (pending_fd_ < 0 && errno != EINTR && errno != EAGAIN && errno != EWOULDBLOCK &&
        errno != ECONNABORTED)
      throw ChannelError("sim-clock: accept on " + path_ + " failed: " + errno_text(errno));
  }
  // Its first message must be Hello; anything else drops the connection.
  Message m;
  WaitStatus w = receive_message(pending_fd_, deadline, m);
  if (w == WaitStatus::timeout) return w;  // still connected: the next call waits on
  if (w == WaitStatus::ok && !std::holds_alternative<Hello>(m)) w = WaitStatus::protocol;
  if (w != WaitStatus::ok) {
    close_fd(pending_fd_);
    return w;
  }
  conn_fd_ = std::exchange(pending_fd_, -1);
  if (hello != nullptr) *hello = std::get<Hello>(m);
  return WaitStatus::ok;
}

// The interrupt flag a grant's waits watch: none when it was set before the grant (the shutdown
// served after an interrupt keeps the whole timeout).
const std::atomic<bool>* Server::stop_for_grant() const { return stop_ != nullptr && !stop_->load() ? stop_ : nullptr; }

WaitStatus Server::grant(const Grant& g, Done& done, std::chrono::milliseconds timeout) {
  // Send the grant, then wait for the Done of this very tick.
  if (conn_fd_ < 0) return WaitStatus::closed;
  const std::atomic<bool>* stop = stop_for_grant();
  const Clock::time_point deadline = deadline_after(timeout);
  if (!send_message(conn_fd_, g)) return WaitStatus::closed;
  Message m;
  const WaitStatus w = receive_message_blocking(conn_fd_, deadline, m, &rcvtimeo_us_, stop);
  if (w != WaitStatus::ok) return w;
  const Done* d = std::get_if<Done>(&m);
  if (d == nullptr || d->tick != g.tick) return WaitStatus::protocol;
  done = *d;
  return WaitStatus::ok;
}

WaitStatus Server::grant(const Grant& g, Done& done, std::chrono::milliseconds timeout, OnSent on_sent,
                         void* context) {
  // Send the grant; answer every SENT of this tick until the Done of this very tick.
  if (conn_fd_ < 0) return WaitStatus::closed;
  const std::atomic<bool>* stop = stop_for_grant();
  const Clock::time_point deadline = deadline_after(timeout);
  if (!send_message(conn_fd_, g)) return WaitStatus::closed;
  for (;;) {
    Message m;
    const WaitStatus w = receive_message_blocking(conn_fd_, deadline, m, &rcvtimeo_us_, stop);
    if (w != WaitStatus::ok) return w;
    if (const Sent* s = std::get_if<Sent>(&m)) {
      if (s->tick != g.tick || on_sent == nullptr) return WaitStatus::protocol;
      if (!send_message(conn_fd_, on_sent(context, *s))) return WaitStatus::closed;
      continue;
    }
    const Done* d = std::get_if<Done>(&m);
    if (d == nullptr || d->tick != g.tick) return WaitStatus::protocol;
    done = *d;
    return WaitStatus::ok;
  }
}

void Server::end(std::int64_t t_ns) {
  // Best effort: a master that is already gone needs no End.
  if (conn_fd_ >= 0) send_message(conn_fd_, End{t_ns});
}

// ---------------------------------------------------------------------------------------------
// Client (master end).

Client::Client(std::string_view address, std::chrono::milliseconds timeout, int stop_fd) {
  // Connect (waiting for the twin's listener), then introduce ourselves.
  const std::string path = parse_address(address);
  const SocketAddress sa = socket_address(path);
  int fd = connect_until(sa, deadline_after(timeout), path, stop_fd);
  if (fd < 0) {
    stopped_ = true;
    return;
  }
  if (!send_message(fd, Hello{static_cast<std::uint32_t>(::getpid())})) {
    const int err = errno;
    close_fd(fd);
    throw ChannelError("sim-clock: cannot send Hello to " + path + ": " + errno_text(err));
  }
  fd_ = fd;
}

Client::~Client() { close_fd(fd_); }

WaitStatus Client::next(Grant& grant, std::chrono::milliseconds timeout, End* end) {
  // A Grant is ok, an End (or the twin's death) closed; anything else is a protocol error.
  if (fd_ < 0) return WaitStatus::closed;
  Message m;
  const WaitStatus w = receive_message(fd_, deadline_after(timeout), m);
  if (w != WaitStatus::ok) return w;
  if (const auto* g = std::get_if<Grant>(&m)) {
    grant = *g;
    return WaitStatus::ok;
  }
  if (const auto* e = std::get_if<End>(&m)) {
    if (end != nullptr) *end = *e;
    return WaitStatus::closed;
  }
  return WaitStatus::protocol;
}

bool Client::done(const Done& d) { return fd_ >= 0 && send_message(fd_, d); }

WaitStatus Client::exchange(const Sent& sent, Horizon& horizon, std::chrono::milliseconds timeout) {
  // Report the frames sent, then wait for the twin's horizon of this tick.
  if (fd_ < 0 || !send_message(fd_, sent)) return WaitStatus::closed;
  Message m;
  const WaitStatus w = receive_message(fd_, deadline_after(timeout), m);
  if (w != WaitStatus::ok) return w;
  if (const auto* h = std::get_if<Horizon>(&m); h != nullptr && h->tick == sent.tick) {
    horizon = *h;
    return WaitStatus::ok;
  }
  return std::holds_alternative<End>(m) ? WaitStatus::closed : WaitStatus::protocol;
}

}  // namespace omnitwin::simclock
