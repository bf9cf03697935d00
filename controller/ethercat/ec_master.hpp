// controller/ethercat — our EtherCAT master as a frames-and-ticks protocol core
// (facts/ethercat.md; DESIGN §4, §7).
//
// Shaped like controller/omni_master: no sockets, no clock, no globals. tick(t) is the cycle
// timer: it hands out ONE EtherCAT PDU through the send callback (in OP, plus one per frame
// of a cyclic image too large to ride in it); on_frame(pdu, t) takes each PDU when it comes
// back. One exchange per tick. When a PDU of the previous tick has not come back by the next
// tick it is counted as lost and the tick builds its datagrams
// again (configuration steps are simply repeated; the cyclic exchange just counts).
//
// Two levels of state machine, as open masters do it:
//  * the master phase (MasterPhase): count → reset → address → sii → configure → [dc] →
//    running, or failed (with error()). Legal transitions:
//      count → reset       BRD 0x0000 answered by ≥ 1 slave (and by config.expected_slaves
//                           when set; a different count → failed)
//      reset → address     the BWR resets (FMMUs, SMs, DC activation, AL control INIT+ack) came back
//      address → sii       every APWR 0x0010 (station 0x1001 + position) had WKC 1
//      sii → configure     every slave's SII is read and matched to an ESI DeviceDescription
//                           (vendor + product); an unknown identity → failed, naming it
//      configure → dc|running  every slave read its PDO mapping (PRE-OP done); the logical
//                           image is laid out (outputs of all slaves, then all inputs)
//      dc → running         propagation delays, offsets and SYNC0 written
//      any → failed         a slave step failed before the first OP (error() says which)
//  * one step machine per slave (SlaveStep), each step adding its datagrams to the tick's PDU:
//      sii_cmd ⇄ sii_data → hold_sii → mbx_sm  (sii_data also commands the next EEPROM read
//                           behind its data read, so one exchange per read once running) → to_preop → wait_preop → startup_sdo → pdo_read
//      → wait_layout → pd_config → to_safeop → wait_safeop → to_op → wait_op → op
//      op → offline         (WKC supervision active) AL status read unanswered
//      op → to_init         AL status read shows the slave left OP (or the error bit)
//      offline → to_init    the slave answers APWR 0x0010 at its position again (re-addressed)
//      to_init → wait_init → mbx_sm → … → pd_config → [dc_read → dc_write] → to_safeop → … → op
//                           (reconfiguration with the existing layout; a DC slave gets its
//                           offset from the reference clock's system time again, its measured
//                           delay and SYNC0)
//      wait_preop|wait_safeop|wait_op → ack_error → error (before the first OP) | offline
//                           (after it): the AL status error bit; 0x0134 is read and reported
//      wait_init → to_init   a pending error bit is acknowledged (0x0120 | 0x10)
//      any → error|offline  step timeout (error before the first OP, offline after)
// Every step that does not get its WKC is repeated on the next tick until its timeout.
// The mailbox (CoE SDO) is served per slave alongside its steps: one mailbox datagram per
// slave per frame (write SM0, then poll SM1; a lost read asks the slave to repeat its reply
// through the SM1 repeat bit), internal requests (start-up SDOs, PDO mapping)
// before the user's SDO queue. Cyclic process data: one LRW over the whole image (laid out
// separate or overlapped, EcMasterConfig::image_layout) (+ FRMW
// 0x0910 to the reference clock when DC is on), expected WKC = 2 × slaves with outputs +
// slaves with inputs. An image too large to ride in the tick's frame beside the rest goes in
// frames of its own sent right after it, cut at slave boundaries into groups of consecutive
// slaves, one LRW frame each (as SOEM splits its IOmap into several LRW frames); the tick's
// frame keeps the configuration, mailbox and DC traffic. The cycle's WKC is the sum over its
// LRWs, judged once every frame is back (or at the next tick: a frame missing is lost, its
// part 0).
// After the first OP, every al_check_every_ns a BRD 0x0130 rides along:
// a slave that is not in OP (or shows the error bit) while the WKC is still right — e.g. one
// that fell to SAFE-OP by its watchdog — is found by the same AL status reads.
// Once supervising, a cyclic frame that does not come back by the next tick is a cycle with
// WKC 0: counted as a lost frame AND a WKC error. segment_loss_cycles consecutive cycles
// (and segment_loss_ns) without any WKC (lost, or WKC 0: no slave touched the frame) mean the segment is gone: the
// master leaves OP in its own view (every slave → offline, operational() false,
// segment_lost() true, stop_reason() says why, one event line), and the offline probes bring
// the slaves back through INIT → OP if the segment returns (segment_lost() false again once
// every slave is back in OP; stats count both).
// Emergencies: with the mailbox SMs the master also writes the ECAT event mask (0x0200) = SM1
// event, so a slave with something in SM1 sets that bit in the IRQ field of every datagram it
// passes (the cyclic one included). A frame whose IRQ shows it makes every mailbox slave without
// a transfer read its SM1 until it is empty; a CoE emergency found there, or in the middle of an
// SDO transfer, is counted per slave (last code, error register), logged as an event line and
// never mistaken for an SDO answer.
// Allocation: configuration and SDO requests allocate; a steady cyclic tick does not.
#pragma once

#include <array>
#include <cstdint>
#include <deque>
#include <functional>
#include <map>
#include <optional>
#include <span>
#include <string>
#include <vector>

#include "bus_emulators/ethercat/device/ec_esi.hpp"
#include "bus_emulators/ethercat/ec_al.hpp"
#include "bus_emulators/ethercat/ec_frame.hpp"
#include "controller/ethercat/ec_sdo.hpp"
#include "controller/ethercat/ec_sii_reader.hpp"

namespace omnitwin::controller::ethercat {

using SimTime = omnitwin::ethercat::SimTime;
using omnitwin::ethercat::DeviceDescription;

// AL states as written to 0x0120 / read from 0x0130 (bits 3:0): the ESC's own type.
using omnitwin::ethercat::AlState;
// The text of an AL status code (0x0134) as read from the wire, "unknown AL status code" for a
// code the ETG list does not have. Real-time safe.
const char* al_status_text(std::uint16_t code);

enum class MasterPhase : std::uint8_t { count, reset, address, sii, configure, dc, running, failed };
const char* to_string(MasterPhase p);

enum class SlaveStep : std::uint8_t {
  sii_cmd, sii_data, hold_sii, to_init, wait_init, mbx_sm, to_preop, wait_preop, startup_sdo,
  pdo_read, wait_layout, pd_config, dc_read, dc_write, to_safeop, wait_safeop, to_op, wait_op, op, offline,
  ack_error, error
};
const char* to_string(SlaveStep s);

// One start-up SDO download (PRE-OP, before the PDO mapping is read; PDO remapping is written
// this way too: 0x1C12:0 = 0, 0x1600:n …, 0x1C12:1 …, 0x1C12:0 = n). When the object is also
// mapped into the slave's outputs, the process image starts with the same value.
struct StartupSdo {
  int position = -1;                // 0-based slave position; -1 = every slave
  std::uint16_t index = 0;
  std::uint8_t sub = 0;
  std::vector<std::uint8_t> data;   // little endian, its size is the object's size
  std::string origin{};             // where it was configured ("FILE:LINE"), for errors
};

// An object of a slave's dictionary.
struct ObjectAddress {
  std::uint16_t index = 0;
  std::uint8_t sub = 0;
};

// One object read back from a slave during start-up (EcMasterConfig::read_back).
struct ReadBack {
  std::uint16_t index = 0;
  std::uint8_t sub = 0;
  SdoStatus status = SdoStatus::pending;
  std::uint32_t abort_code = 0;        // aborted: why (e.g. 0x06020000, no such object)
  std::vector<std::uint8_t> data;      // done: the value, little endian
};

enum class ImageLayout : std::uint8_t { automatic, separate, overlapped };

struct EcMasterConfig {
  std::vector<DeviceDescription> devices;  // ESI descriptions the slaves are matched against
  SimTime cycle_ns = 1'000'000;            // tick period [ns] (DC SYNC0 cycle)
  bool dc = false;                         // distributed clocks (delays, offsets, SYNC0)
  SimTime sync0_shift_ns = 0;              // SYNC0 shift added to the start time [ns]
  std::vector<StartupSdo> startup;
  // Objects uploaded from every CiA 402 slave (ESI profile 402) in PRE-OP, after its
  // start-up SDOs, for each of its axes (axis n's at index + 0x800 × (n − 1) for 0x6000–
  // 0x67FF), into SlaveStatus::read_back. An upload the slave aborts (it lacks the object)
  // is recorded there and does not hold the slave back.
  std::vector<ObjectAddress> read_back;
  int expected_slaves = -1;                // > 0: the bus must have exactly this many
  // The count phase fails ("no slave answered within … s") when no slave has answered its BRD
  // this long after the first tick [ns] (0 = wait for ever).
  SimTime startup_timeout_ns = 10'000'000'000;
  SimTime state_timeout_ns = 2'000'000'000;   // an AL state change [ns]
  SimTime sdo_timeout_ns = 1'000'000'000;     // one SDO transfer [ns]
  SimTime step_timeout_ns = 500'000'000;      // any other step without its WKC [ns]
  SimTime probe_every_ns = 50'000'000;        // an offline slave is probed this often [ns]
  int wkc_loss_cycles = 3;                 // consecutive WKC mismatches → find the missing slave
  int segment_loss_cycles = 10;            // consecutive cycles without any WKC → segment lost (0 = off)
  // …and at least this long [ns]: at short cycles a host stall of a few ms is not a lost
  // segment (the slaves' SM watchdogs, 100 ms, keep them in OP through it). At cycles of 1 ms
  // and longer the cycle count decides, as before.
  SimTime segment_loss_ns = 10'000'000;
  SimTime al_check_every_ns = 100'000'000; // BRD 0x0130 with the cyclic frame this often [ns]
  std::uint32_t logical_base = 0x00010000; // logical address of the image
  // How the LRW lays the image out on the wire. separate: every slave's outputs, then every
  // slave's inputs (out + in bytes). overlapped: each slave's outputs and inputs share one
  // logical range of max(out, in) bytes — its ESC writes the outputs first and puts its inputs
  // in their place (facts/ethercat.md, LRW) — so twice the axes fit one frame. automatic:
  // separate while that fits one frame, else overlapped. Either layout spreads over several
  // frames when one does not hold it (each slave's data whole in one of them).
  ImageLayout image_layout = ImageLayout::automatic;
  int max_cyclic_frames = 16;              // an image needing more frames than this is refused
};

// Where a PDO entry sits in the logical image.
struct EntryLocation {
  std::uint32_t bit_offset = 0;  // from the start of the image
  std::uint8_t bits = 0;
  bool output = false;           // RxPDO (master → slave)
};

struct SlaveStatus {
  int position = 0;
  // The slave's number in messages and in the configuration (`slave:`): position + 1.
  int number() const { return position + 1; }
  std::uint16_t station = 0;
  SiiInfo sii;
  const DeviceDescription* esi = nullptr;
  std::vector<PdoInfo> rx_pdos, tx_pdos;   // the assigned PDOs in use (SM2 / SM3)
  bool pdo_from_coe = false;               // mapping read over CoE (else SII/ESI)
  std::uint32_t out_offset = 0, out_bytes = 0;  // byte offsets within the image
  std::uint32_t in_offset = 0, in_bytes = 0;
  std::uint32_t out_logical = 0, in_logical = 0;  // offsets from logical_base on the wire
  AlState al_state = AlState::init;        // last AL status read (INIT until read)
  std::uint16_t al_code = 0;               // last AL status code read (0x0134)
  SlaveStep step = SlaveStep::sii_cmd;
  std::int64_t dc_delay_ns = 0;            // propagation delay from the reference clock
  bool dc = false;                         // takes part in DC
  std::uint64_t recoveries = 0;            // times brought back to OP
  std::uint64_t emergencies = 0;           // CoE emergencies read from its mailbox
  std::uint16_t last_emergency = 0;        // the last one's error code (0x0000: reset / none)
  std::uint8_t last_error_register = 0;    // … and its error register
  // Per axis (the emergency's first data byte, 1-based, as our drives send it; 1 otherwise):
  // the last code, index 0 = axis 1. Grows on the first emergency of a higher axis.
  std::vector<std::uint16_t> axis_emergency;
  // EcMasterConfig::read_back's answers from the last start-up, every axis's in turn.
  std::vector<ReadBack> read_back;
};

struct EcMasterStats {
  std::uint64_t ticks = 0;
  std::uint64_t frames_sent = 0;       // accepted by the send callback
  std::uint64_t send_failures = 0;     // refused by the send callback
  std::uint64_t frames_received = 0;   // replies matched to the outstanding frame
  std::uint64_t stray_frames = 0;      // unparsable, unexpected or not ours
  std::uint64_t lost_frames = 0;       // sent, not back by the next tick
  std::uint64_t cycles = 0;            // cyclic LRW exchanges that came back
  std::uint64_t wkc_errors = 0;        // cycles with WKC != expected (supervised)
  std::uint64_t timeouts = 0;          // step / SDO timeouts
  std::uint64_t sdo_done = 0, sdo_failed = 0;
  std::uint64_t slaves_lost = 0, recoveries = 0;
  std::uint64_t segment_losses = 0;    // times the whole segment went silent (left OP)
  std::uint64_t segment_returns = 0;   // times every slave was back in OP after such a loss
  std::uint64_t emergencies = 0;       // CoE emergencies read (every slave)
  std::uint16_t last_wkc = 0, expected_wkc = 0;
};

struct SdoResult {
  std::uint64_t id = 0;
  int position = 0;
  SdoRequest request;
  SdoStatus status = SdoStatus::pending;
  std::uint32_t abort_code = 0;        // aborted: SDO abort code; mailbox_error: its code
  std::vector<std::uint8_t> data;      // upload result
};

class EcMaster {
 public:
  // Sends one PDU (EtherCAT header + datagrams); false = refused.
  using SendFn = std::function<bool(std::span<const std::uint8_t>)>;
  using SdoCallback = std::function<void(const SdoResult&)>;
  using EventFn = std::function<void(const std::string&)>;

  EcMaster(EcMasterConfig config, SendFn send);
  EcMaster(const EcMaster&) = delete;  // internal SDO callbacks refer to this object
  EcMaster& operator=(const EcMaster&) = delete;

  // The cycle timer at t [ns]: notes lost frames, runs timeouts, sends 1 PDU (+ the cyclic
  // image's further frames in OP). Real-time safe once running (no allocation).
  void tick(SimTime t);
  // A PDU that came back at t [ns]. Unparsable or unexpected PDUs are counted, never thrown.
  void on_frame(std::span<std::uint8_t> pdu, SimTime t);

  // SDO queue (served between cycles; callbacks run inside on_frame/tick). position 0-based.
  // Returns the request id (0 when the slave does not exist or has no mailbox).
  std::uint64_t sdo_upload(int position, std::uint16_t index, std::uint8_t sub, SdoCallback cb = {});
  std::uint64_t sdo_download(int position, std::uint16_t index, std::uint8_t sub,
                             std::vector<std::uint8_t> data, SdoCallback cb = {});
  std::size_t sdo_pending(int position) const;      // user requests queued or in progress
  const std::optional<SdoResult>& last_sdo() const { return last_sdo_; }

  // Process image: outputs (all slaves) then inputs. Real-time safe.
  std::span<std::uint8_t> image() { return image_; }
  std::span<const std::uint8_t> image() const { return image_; }
  std::uint32_t output_bytes() const { return out_total_; }
  // The layout the image took (separate until the layout is done) and the LRW's data length.
  bool image_overlapped() const { return overlapped_; }
  std::uint32_t lrw_bytes() const { return static_cast<std::uint32_t>(wire_.empty() ? image_.size() : wire_.size()); }
  // LRWs the cyclic image takes per cycle (1 until laid out), and whether they go in frames of
  // their own (beside the tick's frame) rather than in the tick's frame.
  int cyclic_frames() const { return groups_.empty() ? 1 : static_cast<int>(groups_.size()); }
  bool image_in_own_frames() const { return lrw_own_frames_; }
  std::optional<EntryLocation> find_entry(int position, std::uint16_t index, std::uint8_t sub) const;
  // An entry's value as an integer: its low 64 bits where it is wider (a mapping can say up to
  // 255 bits), sign-extended when is_signed. write_entry() writes value into the low 64 bits
  // and zeros above them (a value wider than the entry is cut to its bits: the caller checks
  // the range, as EcDrives::write does). Bits past the image's end are read as 0 and not
  // written. Real-time safe.
  std::int64_t read_entry(const EntryLocation& at, bool is_signed) const;
  void write_entry(const EntryLocation& at, std::int64_t value);

  // The end of the run (ticks go on): from the next tick on, instead of the phase's frame,
  // AL control SAFE-OP to every slave until none reports OP, then INIT (with the error
  // acknowledge) until every slave that answers reports INIT, read back by a BRD of the AL
  // status. No supervision, no mailbox, no cyclic image meanwhile. Drives should be stopped
  // through the image before. shutdown_done(): every slave answered INIT (at once without slaves).
  void shutdown();
  bool shutting_down() const { return stopping_; }
  bool shutdown_done() const { return stop_done_; }

  MasterPhase phase() const { return phase_; }
  // A PDU sent at the last tick (its frame or one of the image's own frames) is not back yet.
  bool awaiting_reply() const { return awaiting_ || groups_out_ > 0; }
  bool operational() const;            // running and every slave in OP
  bool supervising() const { return operational_once_; }
  bool segment_lost() const { return segment_lost_; }  // left OP: the segment went silent
  // Why the master last left OP on its own ("" = never): the segment-lost line.
  const std::string& stop_reason() const { return stop_reason_; }
  const std::string& error() const { return error_; }
  int slave_count() const { return static_cast<int>(slaves_.size()); }
  const SlaveStatus& slave(int position) const { return slaves_.at(position); }
  const EcMasterStats& stats() const { return stats_; }
  const EcMasterConfig& config() const { return config_; }
  const std::deque<std::string>& events() const { return events_; }  // last 64, oldest first
  void set_event_callback(EventFn fn) { on_event_ = std::move(fn); }

 private:
  enum class SlotKind : std::uint8_t { count, reset, address, step, mbx, repeat, check, al_brd, lrw, frmw, dc, event_mask,
                                      stop_control, stop_status };
  struct Slot {
    SlotKind kind = SlotKind::count;
    int slave = -1;
    int sub = 0;
    omnitwin::ethercat::Cmd cmd = omnitwin::ethercat::Cmd::nop;  // as sent: a reply must come back with the same command
    std::uint16_t length = 0;    // and the same data length, or it is not this frame's
  };
  // The cyclic image's frames: group g is slaves [first, first + count) on the wire bytes
  // [logical, logical + bytes) from logical_base.
  struct CyclicGroup {
    std::uint32_t logical = 0, bytes = 0;
    int first = 0, count = 0;
  };
  struct MbxJob {
    std::uint64_t id = 0;
    SdoRequest req;
    SdoCallback cb;
    bool internal = false;
  };
  struct Slave : SlaveStatus {
    std::vector<std::uint16_t> sii_words;
    SimTime step_since = 0;
    bool step_ok = true;
    int step_subs = 0;
    int sii_retries = 0;
    int sii_read_words = 0;         // words per EEPROM read (0 = not known yet)
    std::size_t sii_ahead = 0;      // word address the sii_data frame also commanded (0 = none)
    enum class SiiNext : std::uint8_t { read_again, next, command, done } sii_next = SiiNext::command;
    AlState target = AlState::init;
    bool ack = false;               // next AL control write acknowledges an error
    bool check = false;             // AL status read requested by WKC supervision
    SimTime next_probe = 0;
    // mailbox
    std::deque<MbxJob> internal_jobs, user_jobs;
    std::optional<MbxJob> job;
    SdoTransfer xfer;
    bool mbx_writing = true;
    SimTime mbx_since = 0;
    std::uint8_t counter = 0;
    std::vector<std::uint8_t> mbx_buf;
    std::uint64_t dc_ref_sys = 0, dc_own_sys = 0, dc_own_offset = 0;
    bool mbx_read_sent = false;     // the outstanding frame carries a mailbox read
    bool repeat_pending = false;    // that frame was lost: ask for the reply again
    bool repeat_toggle = false;     // SM1 repeat request bit as last written
    bool mbx_poll = false;          // read SM1 without a request: an SM1 event was seen (emergencies)
    int internal_failed = 0;
    std::string internal_error;
    // PDO mapping read over CoE
    std::map<std::uint16_t, std::vector<std::uint16_t>> assign;   // 0x1C12/0x1C13 → PDOs
    std::map<std::uint16_t, std::vector<std::uint32_t>> mapping;  // PDO → entries
  };

  void emit(std::string msg);
  void fail(std::string msg);
  bool send_frame(omnitwin::ethercat::PduBuilder& b);
  void shutdown_tick();
  void stop_status(const omnitwin::ethercat::Datagram& d);
  bool startup_positions_ok();
  void enter(Slave& s, SlaveStep step, SimTime t);
  void slave_fill(Slave& s, omnitwin::ethercat::PduBuilder& b, SimTime t);
  void slave_reply(Slave& s, const omnitwin::ethercat::Datagram& d, int sub, SimTime t);
  void slave_timeouts(Slave& s, SimTime t);
  void step_failed(Slave& s, const std::string& why, SimTime t);
  void mbx_fill(Slave& s, omnitwin::ethercat::PduBuilder& b, SimTime t);
  void mbx_reply(Slave& s, const omnitwin::ethercat::Datagram& d, SimTime t);
  bool take_emergency(Slave& s, std::span<const std::uint8_t> mailbox);
  void mbx_poll_fill(Slave& s, omnitwin::ethercat::PduBuilder& b);
  void add_repeat_request(Slave& s, omnitwin::ethercat::PduBuilder& b);
  void fill_slaves(omnitwin::ethercat::PduBuilder& b, SimTime t);
  void finish_job(Slave& s, SdoStatus status);
  void queue_internal(Slave& s, SdoRequest req, SdoCallback cb);
  void queue_read_back(Slave& s);
  void start_pdo_read(Slave& s);
  void finish_pdo_read(Slave& s);
  bool mbx_ready(const Slave& s) const;
  bool mbx_busy(const Slave& s) const;
  void after_frame(SimTime t, bool from_frame);
  void cyclic_wkc(std::uint16_t wkc, bool returned, SimTime t);
  void copy_outputs(const CyclicGroup& g);
  void take_group(const CyclicGroup& g, const omnitwin::ethercat::Datagram& d, SimTime t);
  void send_groups();
  bool on_group_frame(const omnitwin::ethercat::PduView& v, SimTime t);
  bool matches_slots(const omnitwin::ethercat::PduView& v) const;
  void close_cycle(bool returned, SimTime t);
  void lose_segment(SimTime t);
  int segment_loss_threshold() const;
  void layout();
  void dc_fill(omnitwin::ethercat::PduBuilder& b, SimTime t);
  void dc_fill_slave(omnitwin::ethercat::PduBuilder& b, const Slave& s);
  void dc_reply(const omnitwin::ethercat::Datagram& d, int slave, int sub, SimTime t);
  bool add(omnitwin::ethercat::PduBuilder& b, Slot slot, omnitwin::ethercat::Cmd cmd, std::uint16_t adp,
           std::uint16_t ado, std::uint16_t len, const void* data = nullptr);
  std::uint64_t queue_user(int position, SdoRequest req, SdoCallback cb);
  int sm_index(const Slave& s, std::uint8_t type, int fallback) const;

  EcMasterConfig config_;
  SendFn send_;
  EventFn on_event_;
  MasterPhase phase_ = MasterPhase::count;
  std::vector<Slave> slaves_;
  std::string error_;
  std::deque<std::string> events_;
  EcMasterStats stats_;
  std::optional<SdoResult> last_sdo_;
  std::uint64_t next_id_ = 1;

  std::array<std::uint8_t, omnitwin::ethercat::kMaxPdu> tx_{};
  std::array<Slot, omnitwin::ethercat::kMaxDatagrams> slots_{};
  std::size_t slot_count_ = 0;
  bool awaiting_ = false;
  std::uint8_t index_ = 0;        // datagram index of the outstanding frame's first datagram
  bool reset_ok_ = false;
  std::size_t addr_from_ = 0, addr_next_ = 0;  // address phase: this frame's first slave / the one after its last

  std::vector<std::uint8_t> image_;   // outputs of every slave, then inputs (entry offsets)
  std::uint32_t out_total_ = 0, in_total_ = 0;
  bool overlapped_ = false;           // each slave's outputs and inputs share one range
  // Overlapped or in several frames: the LRWs' data (group after group); empty: image_ itself.
  std::vector<std::uint8_t> wire_;
  std::vector<CyclicGroup> groups_;      // empty until laid out; one group = one LRW
  bool lrw_own_frames_ = false;          // each group in a frame of its own (else: in the tick's)
  std::vector<std::uint8_t> group_out_;  // own frames: group g's is out, not back yet
  int groups_out_ = 0;                   // how many of those
  std::uint8_t index_stride_ = 1;        // datagram indices the last tick used (1 + own frames)
  std::array<std::uint8_t, omnitwin::ethercat::kMaxPdu> group_tx_{};
  int cycle_parts_ = 0, cycle_back_ = 0; // LRWs of the open cycle sent / come back (0 = none open)
  std::uint32_t cycle_wkc_ = 0;          // their WKCs so far
  bool layout_done_ = false;
  bool operational_once_ = false;
  SimTime first_tick_ = -1;       // the start-up timeout counts from here
  bool stopping_ = false, stop_done_ = false;  // shutdown(): under way / every slave in INIT
  AlState stop_target_ = AlState::safeop;      // what its AL control writes ask for
  int wkc_bad_run_ = 0;
  int silent_run_ = 0;            // consecutive supervised cycles without any WKC
  bool segment_lost_ = false;
  std::string stop_reason_;
  SimTime next_al_check_ = 0;
  std::uint16_t expected_wkc_ = 0;
  std::size_t fill_from_ = 0;  // the slave the next frame's per-slave datagrams start with
  bool add_failed_ = false;    // an add() since the last fill_slaves() check did not fit

  // DC
  int dc_step_ = 0;               // 0 latch, 1 read, 2 write offsets/delays, 3 SYNC0, 4 done
  int dc_ref_ = -1;               // position of the reference clock
  std::vector<std::array<std::uint32_t, 4>> dc_ports_;
  std::vector<std::uint64_t> dc_local_;
  std::uint64_t dc_ref_time_ = 0;
  SimTime dc_read_t_ = 0;
  bool dc_ok_ = true;
  std::size_t dc_from_ = 0;       // steps 1–3: the slave this frame's part of the step starts at
  int dc_last_ = -1;              // … and the last slave it carries (-1: none)
  std::uint64_t dc_start_ = 0;    // SYNC0 start time written to every slave [ns, system time]
};

}  // namespace omnitwin::controller::ethercat
