// controller layer — the sim-clock channel: how the twin lends its simulated time to a master
// process in lockstep (DESIGN section 4; protocol in docs/protocols/sim-clock.md).
//
// The twin owns time (the ROS 2 /clock idea). Each control tick k it GRANTs the master the
// instant t_k together with, per bus, the number of frames it has put on that bus's transport
// since the run began; the master first drains its transport until it has received that many
// frames (so it never runs a tick without frames the twin already delivered), runs tick k, sends
// its frames, and answers DONE with the number of frames it has sent per bus since the run began
// (so the twin waits for exactly those frames before it simulates [t_k, t_k+1)). END ends the
// run. Frames still travel over the real transport; only time and counts use this channel.
// A master on a polling bus (M-III) also exchanges SENT/HORIZON inside a tick: each frame it
// sends is reported with its simulated send time, and the twin answers what reached the
// master and when, so the master's response timeouts pass in simulated time.
//
// Wire: a Unix-domain SOCK_SEQPACKET connection (message boundaries, ordered, and the peer's
// death is seen as end of stream), address "unix:PATH". The twin listens, the master connects.
// Every message is a fixed 96-byte little-endian record (encode()/decode() below); the codec is
// pure and fuzzed. Frame counts are cumulative and 64-bit, so a lost message cannot go unnoticed.
//
// Both ends live here (the master links the client, the twin links the server); neither end
// depends on anything else in the project.
#pragma once

#include <array>
#include <atomic>
#include <chrono>
#include <cstddef>
#include <cstdint>
#include <limits>
#include <optional>
#include <stdexcept>
#include <string>
#include <string_view>
#include <variant>

namespace omnitwin::simclock {

inline constexpr std::uint32_t kMagic = 0x4353544fu;  // "OTSC" little-endian
inline constexpr std::uint16_t kVersion = 2;  // 2: Grant.stop
inline constexpr std::size_t kMaxBuses = 4;           // per-bus counts carried per message
inline constexpr std::size_t kMessageSize = 96;       // bytes on the wire, every message

// Why a master is where it is; carried in DONE so the twin can record the master's reaction
// (scenario expectations use it). Values are part of the wire protocol.
enum class MasterState : std::uint8_t {
  waiting = 0,    // waiting for a start (from the PC node) before detecting
  detecting = 1,  // start-up: looking for its slaves
  running = 2,    // slaves started, commands every tick
  stopped = 3,    // it stopped the slaves (see StopReason) and holds
  finished = 4,   // path done, slaves stopped normally
};
enum class StopReason : std::uint8_t {
  none = 0,
  node_missing = 1,    // a slave did not answer node detection (node in `node`)
  feedback_missing = 2,// a slave's feedback stayed away (node in `node`)
  nmt_stop = 3,        // an NMT stop from the bus (PC node or another participant)
  startup_timeout = 4, // not every slave answered detection at start-up
  bus_error = 5,       // its transport refused frames
  drive_fault = 6,     // a drive reported a fault (CANopen EMCY; node in `node`)
  config_failed = 7,   // a slave's configuration failed at start-up: an SDO aborted, a wrong
                       // device type or identity (node in `node`); or the configuration does
                       // not fit the line (M-III: a transmission cycle too short)
};
const char* to_string(MasterState s);
const char* to_string(StopReason r);

// The master's report with each DONE: state, and what it sees (for records and metrics; the
// twin never feeds these back into the simulation). The poses travel as f32 (about 1 µm at
// 10 m) so that DONE fits kMessageSize; a decoded report holds them widened back to double.
struct MasterReport {
  MasterState state = MasterState::waiting;
  StopReason reason = StopReason::none;
  std::uint8_t node = 0;            // the node a reason names (0 = none)
  std::int64_t path_origin_ns = -1; // tick time at which its path time was 0; -1 = not started
  std::array<double, 3> reference{};  // planned pose x [m], y [m], phi [rad]
  std::array<double, 3> odometry{};   // its odometry pose x [m], y [m], phi [rad]
  bool operator==(const MasterReport&) const = default;
};

struct Hello {  // master → twin, once after connecting
  std::uint32_t pid = 0;
  bool operator==(const Hello&) const = default;
};
struct Grant {  // twin → master: run tick `tick` at `t_ns`
  std::uint64_t tick = 0;
  std::int64_t t_ns = 0;                       // simulated time of the tick [ns]
  std::array<std::uint64_t, kMaxBuses> frames{};  // frames the twin has sent per bus, cumulative
  // The run has reached its end: the master runs its end sequence from this tick on, as at a
  // SIGTERM on the wall clock, and exits when it is done (the twin keeps granting; every later
  // grant has it too). In simulated time, so the shutdown is the same every run.
  bool stop = false;
  bool operator==(const Grant&) const = default;
};
struct Done {  // master → twin: tick `tick` ran
  std::uint64_t tick = 0;
  std::array<std::uint64_t, kMaxBuses> frames{};  // frames the master has sent per bus, cumulative
  MasterReport report;
  // This tick ended the master's end sequence (after a Grant with stop, or a signal): it leaves
  // now, so the twin knows its end at this tick, not one grant later.
  bool last = false;
  bool operator==(const Done&) const = default;
};
struct End {  // twin → master: the run is over; exit
  std::int64_t t_ns = 0;
  bool operator==(const End&) const = default;
};
// Exchange-level lockstep, for a master that needs answers inside a tick (a polling bus such
// as MECHATROLINK-III): within tick `tick` the master reports each frame it sends (SENT) and
// the twin answers with HORIZON before the master reads its clock again.
inline constexpr std::int64_t kQuietForever = std::numeric_limits<std::int64_t>::max();
struct Sent {  // master → twin: frames sent so far (cumulative per bus), the last starting at t_ns
  std::uint64_t tick = 0;
  std::int64_t t_ns = 0;
  std::array<std::uint64_t, kMaxBuses> frames{};
  bool operator==(const Sent&) const = default;
};
struct Horizon {  // twin → master: what reached the master, and how long nothing else will
  std::uint64_t tick = 0;
  std::int64_t arrival_ns = -1;  // when the last frame counted in `frames` reached the master; -1: none new
  std::array<std::uint64_t, kMaxBuses> frames{};  // frames the twin has sent per bus, cumulative
  std::int64_t quiet_until_ns = kQuietForever;    // no other frame reaches the master before this
  bool operator==(const Horizon&) const = default;
};
using Message = std::variant<Hello, Grant, Done, End, Sent, Horizon>;

enum class DecodeError : std::uint8_t { wrong_size, bad_magic, bad_version, unknown_type, bad_value };
const char* to_string(DecodeError e);

// Pure codec. encode() always yields kMessageSize bytes; decode() accepts exactly that size
// and rejects unknown types and out-of-range enum values. Real-time safe, never throws.
std::array<std::uint8_t, kMessageSize> encode(const Message& m) noexcept;
std::variant<Message, DecodeError> decode(const std::uint8_t* data, std::size_t size) noexcept;

// Set-up failures (bad address, socket cannot be created/bound/connected).
class ChannelError : public std::runtime_error {
 public:
  using std::runtime_error::runtime_error;
};

// Outcome of a blocking wait on the channel.
enum class WaitStatus : std::uint8_t {
  ok,
  timeout,    // nothing within the time limit
  closed,     // the peer closed the connection (or died)
  protocol,   // a message that does not decode, or of a type not expected here
};
const char* to_string(WaitStatus s);

// "unix:PATH" → PATH; throws ChannelError for anything else. PATH "@NAME" is NAME in Linux's
// abstract socket namespace: no file, so it works wherever the file system cannot hold a
// socket (a 9p or FUSE /tmp) and leaves nothing behind.
std::string parse_address(std::string_view address);

// Twin end. Creates the listening socket at construction (removing a stale socket file at
// PATH first) and removes it again in the destructor (nothing to remove for "@NAME").
class Server {
 public:
  explicit Server(std::string_view address);  // throws ChannelError
  ~Server();
  Server(const Server&) = delete;
  Server& operator=(const Server&) = delete;

  // Waits for the master to connect and say Hello (a message other than Hello is protocol and
  // drops the connection). A master that connected but has not said Hello by the timeout stays
  // connected: the next call waits on for its Hello, so short calls in a loop never cut a slow
  // master off. Not real-time safe; throws ChannelError only when accept() itself fails (no
  // descriptors left).
  WaitStatus accept(std::chrono::milliseconds timeout, Hello* hello = nullptr);
  // One tick: sends the grant and waits for the matching Done (a Done for another tick is a
  // protocol error). Real-time safe apart from the system calls.
  WaitStatus grant(const Grant& g, Done& done, std::chrono::milliseconds timeout);
  // The same for a master in exchange-level lockstep: every SENT of this tick is answered with
  // the HORIZON `on_sent` returns before the Done is awaited again (a SENT for another tick is
  // a protocol error). The handler runs on the calling thread; real-time safe if it is.
  using OnSent = Horizon (*)(void* context, const Sent& sent);
  WaitStatus grant(const Grant& g, Done& done, std::chrono::milliseconds timeout, OnSent on_sent, void* context);
  // The twin's interrupt flag (SIGINT/SIGTERM), or nullptr: when it is set while a grant waits
  // for its Done, the wait lasts at most 1 s more (then timeout), whatever its own timeout; a
  // grant sent with it set already waits its whole timeout. Set-up only.
  void set_stop_flag(const std::atomic<bool>* stop) { stop_ = stop; }
  // Tells the master the run is over (best effort; a closed peer is fine).
  void end(std::int64_t t_ns);
  const std::string& address() const { return address_; }
  int fd() const { return conn_fd_; }

 private:
  std::string address_;
  std::string path_;
  int listen_fd_ = -1;
  int conn_fd_ = -1;
  int pending_fd_ = -1;  // accepted, Hello not yet read (accept() timed out waiting for it)
  std::int64_t rcvtimeo_us_ = 0;  // SO_RCVTIMEO now set on conn_fd_ [µs]; 0 = none
  const std::atomic<bool>* stop_ = nullptr;  // set_stop_flag()
  const std::atomic<bool>* stop_for_grant() const;
};

// Master end.
class Client {
 public:
  // Connects (retrying until `timeout` while the twin has not yet created the socket) and
  // sends Hello. Throws ChannelError when it cannot. With `stop_fd` >= 0 (the program's
  // signalfd) the wait also ends when that fd becomes readable: no connection, stopped() true
  // (the fd is only polled; the signal stays there to be read). Without it a Ctrl-C waited up
  // to `timeout` (found in review).
  Client(std::string_view address, std::chrono::milliseconds timeout, int stop_fd = -1);
  ~Client();
  Client(const Client&) = delete;
  Client& operator=(const Client&) = delete;

  // Waits for the next Grant (ok) or End (closed, with *end set when given).
  WaitStatus next(Grant& grant, std::chrono::milliseconds timeout, End* end = nullptr);
  bool done(const Done& d);  // false when the twin is gone
  // Exchange-level lockstep: reports frames sent inside the current tick and waits for the
  // twin's HORIZON (ok), End or the twin's death (closed), or anything else (protocol).
  WaitStatus exchange(const Sent& sent, Horizon& horizon, std::chrono::milliseconds timeout);
  int fd() const { return fd_; }
  // The connect wait ended on `stop_fd` (then fd() is -1).
  bool stopped() const { return stopped_; }

 private:
  int fd_ = -1;
  bool stopped_ = false;
};

}  // namespace omnitwin::simclock
