// twin layer — a scenario: everything one run needs, loaded and validated up front.
//
// A scenario file (YAML, models/scenarios/*.yaml) names the platform parameter file and
// overrides, the bus, the controller settings, the path, faults, the run length and the
// expectations. Loading is all-or-nothing: every key is checked (unknown keys, wrong types,
// out-of-range values) before anything is run or written, and the first problem is
// reported as a ScenarioError naming the file, line and key. The loaded Scenario is fixed
// configuration; nothing in it changes while a run steps.
#pragma once

#include <array>
#include <cstdint>
#include <optional>
#include <stdexcept>
#include <string>
#include <vector>

#include "media/run_video.hpp"
#include "physics/platform_params.hpp"
#include "twin/dds/dds_settings.hpp"

namespace YAML {
class Node;
}

namespace omnitwin::twin {

// A bad scenario (or parameter file, or --set override). what() is one line:
// "FILE:LINE: KEY: MESSAGE" (LINE omitted when unknown, e.g. for a missing file).
class ScenarioError : public std::runtime_error {
 public:
  ScenarioError(std::string file, int line, std::string key, const std::string& message);
  const std::string& file() const { return file_; }
  int line() const { return line_; }  // 1-based; 0 = no line
  const std::string& key() const { return key_; }

 private:
  std::string file_;
  int line_;
  std::string key_;
};

// One piece of the reference path, in world coordinates. Each segment starts where the
// previous one ended (pose and time) and runs the trapezoidal profile of seed 002
// (eq. 4-9 … 4-13) over its own duration unless stated otherwise.
struct PathSegment {
  enum class Kind {
    line,          // straight move by (dx, dy) and turn by dphi, simultaneously
    arc,           // around `center` (relative to the segment's start) by sweep_deg
    rotate,        // turn in place by dphi
    dwell,         // hold the pose
    square,        // 4 lines of `side`, turning left (ccw) or right; duration per side
    circle,        // full circle of `radius`, centre to the left (ccw) or right
    figure_eight,  // two tangent circles of `radius`, one trapezoid over the whole length
  };
  Kind kind = Kind::line;
  double duration = 0;    // [s] (square: per side)
  double dx = 0, dy = 0;  // line [m]
  double dphi_deg = 0;    // line/rotate/arc heading change [deg]
  double cx = 0, cy = 0;  // arc centre relative to the segment start [m]
  double sweep_deg = 0;   // arc sweep, ccw positive [deg]
  double side = 0;        // square [m]
  double radius = 0;      // circle, figure_eight [m]
  bool ccw = true;        // square/circle/figure_eight turning sense (first loop)
  int line = 0;           // line in the scenario file (for messages)
};

struct PathSpec {
  double x0 = 0, y0 = 0, phi0_deg = 0;  // start pose (world) [m, m, deg]
  std::vector<PathSegment> segments;
};

// The platform loop of the master (seed 002, fig. 4-13).
struct ControllerSpec {
  double period = 0.010;                   // master sample period [s]
  double kp[3] = {6.0, 6.0, 6.0};          // PI on x, y [1/s], phi [1/s]
  double ki[3] = {6.0, 6.0, 6.0};          // [1/s²]
  bool feedforward = false;                // add the planned velocity to the PI output
  double max_speed = 0.5;                  // |platform speed command| limit [m/s]
  double max_yaw_rate = 2.0;               // [rad/s]
};

enum class BusKind { direct, can, canopen, ethercat, m3, tml };
enum class ClockMode { lockstep, realtime };

// Settings of the `can` bus: the thesis's Omni nodes on one classic-CAN bus.
struct CanSpec {
  std::int64_t bit_rate = 1'000'000;          // [bit/s], 10 kbit/s … 1 Mbit/s
  // Where the master process and the twin meet (transport.hpp spec). The default is
  // python-can's udp_multicast default, so a python-can script joins without arguments.
  std::string transport = "udp:239.74.163.2:43113";
  double t_pre_us = 0.604;                    // master processing before a frame [µs] (table 2-1)
  double t_post_us = 88.8;                    // slave processing before a frame [µs] (table 2-1)
  // Run time of the slaves' control-step interrupt [µs] (OmniSlaveConfig::isr_ns): 0 = a
  // hardware-reloaded timer; > 0 = reloaded at the routine's end, feedback sent then.
  double isr_us = 0.0;
  std::array<double, 4> drift{3.62e-3, 3.62e-3, 3.62e-3, 3.62e-3};  // slave oscillators [-]
  bool sync = false;                          // synchronisation of 3-2-2
  bool hold_missing_command = false;          // slaves: hold (true) or skip (fig. 4-16) a missing command
  int sync_interval = 20;                     // timer interrupts between resyncs
  // Each slave's timer phase at NMT start, as a fraction of its period [0, 1)
  // (OmniSlaveConfig::start_phase_ns); start_phase_random draws them from `seed` instead.
  std::array<double, 4> start_phase{0.0, 0.0, 0.0, 0.0};
  bool start_phase_random = false;
  int detect_every = 1;                       // master: node detection every N samples (0 off)
  std::string master;                         // master program; "" = omni-master beside omnitwin
  std::uint64_t seed = 1;                     // random faults (frame loss, jitter)
  double handshake_timeout = 10.0;            // [s] the master must answer a tick within
  // Frames from a transport sender other than the first (the master) are always counted
  // (bus.foreign_frames); true also keeps them off the wire (bus.refused_frames). UDP and mem
  // only: SocketCAN names no sender.
  bool refuse_foreign = false;
};

// Settings of the `ethercat` bus: four single-axis CiA 402 drives (one per wheel) on one
// EtherCAT segment, driven by our master in CSV or CSP mode.
struct EthercatSpec {
  // Where the master process and the twin meet: `auto` (a veth pair made for the run when the
  // twin may create one, i.e. as root; EtherCAT over UDP on loopback otherwise), `veth`
  // (always a fresh veth pair), `raw:IFACE` (the twin answers on IFACE; the master is given
  // `master_iface`), `udp:HOST:PORT` (EtherCAT over UDP), or `mem:NAME` (a master in the same
  // process: tests and embedding).
  std::string transport = "auto";
  std::string master_iface;                 // raw: the master's interface (the peer of IFACE)
  std::string esi;                          // device description; "" = models/ethercat/omnitwin_drive.xml
  // Axis cards of seed 001's multi-axis slaves (models/ethercat/omnitwin_multiaxis.xml, 8 per
  // slave, the rest on the last) behind the four wheel drives, each at rest on SYNC0: the
  // seeds' network sizes as a run (issue 17, item 4). 0 = the four drives alone.
  int extra_axes = 0;
  std::string mode = "csv";                 // csv | csp: how the master commands the wheels
  double drive_period = 0.001;              // the drives' own update period [s]
  int counts_per_rev = 131072;              // the drives' motor encoder (17 bit) [counts/rev]
  bool dc = true;                           // distributed clocks: drives run on SYNC0
  std::array<double, 4> drift{20e-6, -15e-6, 35e-6, -30e-6};  // slave oscillators [-]
  double t_pre_us = 5.0;                    // master processing before a frame leaves [µs]
  // Time the master is given to bring the segment to OP (scan, SII, CoE, states) before its
  // path starts; added to the default duration so that the path and settle still fit. [s]
  double startup = 3.0;
  std::string master;                       // master program; "" = omni-master beside omnitwin
  std::uint64_t seed = 1;                   // random faults (frame loss)
  double handshake_timeout = 10.0;          // [s] the master must answer a tick within
  // Frames from a sender other than the first (the master: another source MAC on raw,
  // another address on udp) are always counted (bus.foreign_frames); true also refuses them.
  bool refuse_foreign = false;
};

// Settings of the `canopen` bus: four single-axis CiA 402 drives as CANopen nodes (one per
// wheel) on the simulated CAN wire, driven by our CANopen master (docs/protocols/canopen.md).
// The wire's own settings (bit_rate, transport, t_pre_us, master, seed, handshake_timeout)
// are bus.can's: `bus: {type: canopen, bit_rate: …}` reads them into CanSpec.
struct CanopenSpec {
  std::string eds;                          // device description; "" = models/canopen/omnitwin_drive.eds
  std::string mode = "csv";                 // csv | pv: how the master commands the wheels
  double cycle = 0.001;                     // the SYNC period [s]
  // Who produces SYNC: "master" (one master tick per SYNC) or "drive" (drive 1, 0x1005 gen
  // bit; the master then ticks at the control period and its RPDOs take effect at the next SYNC).
  std::string sync_producer = "master";
  double drive_period = 0.001;              // the drives' own update period [s]
  int counts_per_rev = 131072;              // the drives' motor encoder (17 bit) [counts/rev]
  int heartbeat_ms = 50;                    // the nodes' (and the master's) heartbeat period
  std::array<double, 4> drift{20e-6, -15e-6, 35e-6, -30e-6};  // the drives' oscillators [-]
  // Time the master is given to configure the drives (SDO) and enable them before its path
  // starts; added to the default duration. [s]
  double startup = 1.0;
};

// Settings of the `tml` bus: four Technosoft IDM drives (seed 003; bus_emulators/tml) on the
// simulated CAN wire, driven by our TML master over TMLCAN (29-bit) or TechCAN (11-bit)
// (docs/protocols/tml.md). The wire's own settings are bus.can's, as for canopen.
struct TmlSpec {
  std::string protocol = "tmlcan";          // tmlcan | techcan
  double cycle = 0.002;                     // the master's tick [s]
  double drive_period = 0.001;              // the drives' period = their IU time base [s]
  int counts_per_rev = 131072;              // APOS counts per wheel revolution
  std::array<double, 4> drift{20e-6, -15e-6, 35e-6, -30e-6};  // the drives' oscillators [-]
  double startup = 0.2;                     // added to the default duration [s]
};

// Settings of the `m3` bus: four MECHATROLINK-III standard servos (profile 10h), one per
// wheel, on one line, driven by our C1 master with VELCTRL or INTERPOLATE
// (docs/protocols/mechatrolink3.md).
struct M3Spec {
  // Where the master process and the twin meet: auto (a veth pair as root, else UDP on
  // loopback), veth, raw:IFACE (+ master_iface), udp:HOST:PORT or mem:NAME.
  std::string transport = "auto";
  std::string master_iface;
  double cycle = 0.001;                     // transmission cycle [s]; the master's tick
  int retry_slots = 1;                      // retries inside one cycle
  // cyclic, or event: no SYNC, the servos stay in phase 2, the master asks each one for an
  // exchange (64 bytes, VELCTRL) every `cycle`, within seed 000's 50 ms limit.
  std::string communication = "cyclic";
  int data_bytes = 32;                      // 32 or 48 (subcommands)
  std::string mode = "velctrl";             // velctrl | interpolate: how the wheels are commanded
  std::string topology = "cascade";         // cascade | star
  // Stations on the line, 4..62: the four wheel servos (03h-06h), then servos whose motors
  // turn no wheel (unloaded shafts), started by the master and held at zero speed.
  int stations = 4;
  double cable_m = 1.0;                     // every cable's length [m]
  double response_us = 2.0;                 // each slave's response time [µs]
  // Added to every T_RSP by the master [µs]; < 0: 1 µs in lockstep, 80 µs in realtime. The
  // master's delay measurement already holds the transport's round trip across processes;
  // the margin absorbs its jitter (no real M-III line has either).
  double margin_us = -1;
  double drive_period = 0.001;              // the servos' own update period [s]
  int counts_per_rev = 131072;              // the servos' reference units per wheel revolution
  double startup = 0.5;                     // [s] added to the default duration for the start-up
  std::string master;                       // master program; "" = omni-master beside omnitwin
  std::uint64_t seed = 1;                   // random faults (frame loss, corruption)
  double handshake_timeout = 10.0;          // [s] the master must answer a tick within
  // Frames from a sender other than the first (the master) are always counted
  // (bus.foreign_frames); true also drops them (bus.refused_frames), as on bus ethercat.
  bool refuse_foreign = false;
  double margin(bool realtime) const { return margin_us >= 0 ? margin_us : realtime ? 80.0 : 1.0; }
};

// How a realtime run watches the master process it started (bus.supervision). Lockstep
// needs none of this: there a master that stops answering misses its tick's handshake.
struct SupervisionSpec {
  // The master is lost when its process ends, or when no frame of its has arrived for this
  // many control periods (counted from its first frame; before that, handshake_timeout).
  int silent_periods = 50;
  // fail: a lost master ends the run with exit 3. record: the run goes on to its end with
  // the loss in events.log and metrics.json (master.lost, master.lost_at_s), so a scenario
  // can expect the fault and judge the platform's reaction.
  enum class OnLoss { fail, record } on_master_loss = OnLoss::fail;
};

struct BusSpec {
  BusKind kind = BusKind::direct;
  CanSpec can;
  EthercatSpec ethercat;
  M3Spec m3;
  CanopenSpec canopen;
  TmlSpec tml;
  SupervisionSpec supervision;
};

// A scripted fault. wheel_slip acts on the physics; the others on the bus (bus: can or
// ethercat; bus_off is CAN's, link_break EtherCAT's).
struct FaultSpec {
  enum class Kind {
    wheel_slip,  // the wheel's floor friction scaled by friction_scale
    frame_loss,  // frames to `node` lost with probability `rate`, in bursts of `burst`
    delay,       // frames sent by `node` leave extra_ms (+ uniform jitter_ms) later
    drift,       // the slave's oscillator drift becomes `drift` (back to its setting at the end)
    power_loss,  // the slave loses power (off the bus, drive off) and returns at the end
    bus_off,     // the slave's transmissions are corrupted until it is bus-off; it asks for
                 // recovery at the end (duration 0: never)
    link_break,  // EtherCAT, M-III: the cable after slave `wheel` (0 = between master and slave
                 // 1) is cut; EtherCAT frames return from the last slave still reached (none
                 // for 0), M-III stations behind the cut drop off the line
    corruption,  // M-III: frames to and from `node` get a bad FCS with probability `rate`
    second_master,  // M-III: another C1 master on the line (address 01h too) sends every slave a
                    // command of its own each transmission cycle, its WDT count never advancing
  };
  Kind kind = Kind::wheel_slip;
  double at = 0;              // start [s]
  double duration = 0;        // [s]; 0 = until the end
  // wheel_slip: 0-based wheel; CAN faults: the node, 0..3 = axis 1..4 slave, kMaster = the
  // master (frames to / from the transport), kAllNodes = every receiver (frame_loss only).
  int wheel = 0;
  double friction_scale = 0;  // wheel_slip: multiplies the wheel's floor friction
  double rate = 0;            // frame_loss: probability a frame is lost [0, 1]
  int burst = 1;              // frame_loss: frames lost in a row once a loss starts
  double extra_ms = 0;        // delay [ms]
  double jitter_ms = 0;       // delay: uniform extra in [0, jitter_ms) [ms]
  double drift = 0;           // drift [-]
  int line = 0;
  static constexpr int kMaster = 4;
  static constexpr int kAllNodes = 5;
};
const char* to_string(FaultSpec::Kind k);

// A bound on one metric of metrics.json, addressed by its dotted path
// (e.g. "platform.final_error_cm", "axes.0.iae_velocity_pulse").
struct Expectation {
  std::string metric;
  std::optional<double> min, max;
  int line = 0;
};

// What a run produces besides its records (DESIGN §8): the video rendered after the run,
// the HTML report, live DDS publishing. The command line (--video/--no-video, --no-report,
// --dds) overrides these.
// The scenario sets width, height, fps and overview_inset of the renderer's own options.
struct VideoSpec : media::VideoOptions {
  bool enabled = true;
};

// The scenario sets domain, interface, config_file ("config:") and rate_hz (at most the
// control rate) of the publisher's own settings.
struct DdsSpec : DdsSettings {
  bool enabled = false;
};

struct OutputsSpec {
  VideoSpec video;
  DdsSpec dds;
  bool report = true;
};

// A master program the user brings (`master:`, or `omnitwin run --master-cmd`): it replaces
// omni-master. In lockstep it runs under the virtual-time library (twin/master_vtime.hpp,
// docs/protocols/vtime.md); in realtime it runs plainly on the wall clock.
struct MasterSpec {
  std::string command;   // "PROGRAM ARGS…" with {iface} and {out} substituted; "" = omni-master
  // A statically linked program cannot load the library: fail the run (exit 3), or, when
  // asked, run it on the wall clock (realtime) instead.
  enum class OnStatic { fail, realtime } on_static = OnStatic::fail;
  double watchdog = 10;   // wall seconds the master may take between two waits (lockstep) [s]
  double stop_grace = 3;  // wall seconds between SIGTERM and SIGKILL at the end [s]
};

struct Scenario {
  std::string name;            // default: the file's stem
  std::string description;
  std::string file;            // the scenario file as given
  physics::PlatformParams platform;
  BusSpec bus;
  ClockMode clock = ClockMode::lockstep;
  ControllerSpec controller;
  PathSpec path;
  double settle = 2.0;         // time after the path ends before the run stops [s]
  double duration = 0;         // total simulated time [s] (path length + settle if absent,
                               // + bus.ethercat.startup on an EtherCAT bus)
  std::vector<FaultSpec> faults;
  std::vector<Expectation> expectations;
  OutputsSpec outputs;
  MasterSpec master;
  std::vector<std::string> overrides;  // "key=value" applied over the file, in order (run.json)
  // What the overrides changed beyond their own keys, for the user to read (e.g. settings of
  // the file's bus that a --bus to another kind left out). One sentence each, no prefix.
  std::vector<std::string> notes;
  // Lockstep with a master we did not write: it lives on the virtual clock.
  bool virtual_time_master() const { return !master.command.empty() && clock == ClockMode::lockstep; }
};

// "key=value" overrides from the command line, applied to the YAML tree before
// validation. Keys are dotted scenario paths (e.g. controller.period=0.005,
// platform.geometry.L=0.3, bus=direct).
struct Override {
  std::string key;
  std::string value;
};

// `omnitwin run --loopback`: confines everything a run puts on the network to this machine.
// CAN-family buses over UDP get iface=lo (their multicast joins and leaves on loopback only);
// EtherCAT and M-III keep auto/veth/mem (local by construction) and UDP to a loopback host;
// DDS publishes on lo. The sim clock is an abstract Unix socket and never leaves the machine.
// Throws ScenarioError (key: the setting) for what cannot be confined: a UDP transport bound
// to another interface or host, a raw Ethernet interface, a DDS configuration file (it names
// its own interfaces).
void confine_to_loopback(Scenario& s);

// Loads, merges (parameter file ← scenario platform section ← overrides) and validates.
// Throws ScenarioError on any problem. Not real-time safe (file I/O).
Scenario load_scenario(const std::string& path, const std::vector<Override>& overrides = {});

// The one YAML document of a file (a scenario, a sweep spec). Throws ScenarioError naming the
// file and line for a syntax error (a tab in the indentation named as such), a file that cannot
// be opened, a stray ',' or a second document. Not real-time safe.
YAML::Node load_yaml_file(const std::string& file);

// Parses "key=value" (as given to --set). Throws ScenarioError naming "--set".
Override parse_override(const std::string& text);

const char* to_string(BusKind b);
const char* to_string(ClockMode c);

}  // namespace omnitwin::twin
