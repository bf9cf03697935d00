// controller/ethercat — the master core (see ec_master.hpp for the state machines).
#include "controller/ethercat/ec_master.hpp"

#include <fmt/format.h>

#include <algorithm>
#include <cstring>

namespace omnitwin::controller::ethercat {

namespace ec = omnitwin::ethercat;
using ec::Cmd;
using ec::get_u16;
using ec::get_u32;
using ec::get_u64;
using ec::put_u16;
using ec::put_u32;
using ec::put_u64;

namespace {
constexpr std::uint16_t kStationBase = 0x1001;
// Slaves one master addresses: the configured addresses 0x1001 + k stay below 0xF000, and a
// count beyond this is a corrupted WKC, not a segment (SOEM's default limit is 200).
constexpr int kMaxSlaves = 4096;
constexpr std::uint16_t kRegStation = 0x0010, kRegAlControl = 0x0120, kRegAlStatus = 0x0130,
                        kRegEeprom = 0x0500, kRegFmmu = 0x0600, kRegSm = 0x0800, kRegDcRecv = 0x0900,
                        kRegDcSysTime = 0x0910, kRegDcRecvLocal = 0x0918, kRegDcOffset = 0x0920,
                        kRegDcDelay = 0x0928, kRegDcActivation = 0x0981, kRegDcAssign = 0x0980,
                        kRegDcStart = 0x0990, kRegDcCycle0 = 0x09A0, kRegEventMask = 0x0200;
constexpr std::uint8_t kEventSm1 = 0x20;  // ECAT event request/mask bit of SM1 (bit 4 + 1)
constexpr std::size_t kMaxEvents = 64;
constexpr int kSiiRetries = 20;

std::uint16_t position_adp(int position) { return static_cast<std::uint16_t>(0 - position); }
}  // namespace

const char* al_status_text(std::uint16_t code) {
  const char* text = omnitwin::ethercat::to_string(static_cast<omnitwin::ethercat::AlStatusCode>(code));
  return std::strcmp(text, "?") == 0 ? "unknown AL status code" : text;
}

const char* to_string(MasterPhase p) {
  switch (p) {
    case MasterPhase::count: return "count";
    case MasterPhase::reset: return "reset";
    case MasterPhase::address: return "address";
    case MasterPhase::sii: return "sii";
    case MasterPhase::configure: return "configure";
    case MasterPhase::dc: return "dc";
    case MasterPhase::running: return "running";
    case MasterPhase::failed: return "failed";
  }
  return "?";
}

const char* to_string(SlaveStep s) {
  switch (s) {
    case SlaveStep::sii_cmd: return "sii_cmd";
    case SlaveStep::sii_data: return "sii_data";
    case SlaveStep::hold_sii: return "hold_sii";
    case SlaveStep::to_init: return "to_init";
    case SlaveStep::wait_init: return "wait_init";
    case SlaveStep::mbx_sm: return "mbx_sm";
    case SlaveStep::to_preop: return "to_preop";
    case SlaveStep::wait_preop: return "wait_preop";
    case SlaveStep::startup_sdo: return "startup_sdo";
    case SlaveStep::pdo_read: return "pdo_read";
    case SlaveStep::wait_layout: return "wait_layout";
    case SlaveStep::pd_config: return "pd_config";
    case SlaveStep::dc_read: return "dc_read";
    case SlaveStep::dc_write: return "dc_write";
    case SlaveStep::to_safeop: return "to_safeop";
    case SlaveStep::wait_safeop: return "wait_safeop";
    case SlaveStep::to_op: return "to_op";
    case SlaveStep::wait_op: return "wait_op";
    case SlaveStep::op: return "op";
    case SlaveStep::offline: return "offline";
    case SlaveStep::ack_error: return "ack_error";
    case SlaveStep::error: return "error";
  }
  return "?";
}

EcMaster::EcMaster(EcMasterConfig config, SendFn send) : config_(std::move(config)), send_(std::move(send)) {}

void EcMaster::emit(std::string msg) {
  if (on_event_) on_event_(msg);
  events_.push_back(std::move(msg));
  while (events_.size() > kMaxEvents) events_.pop_front();
}

void EcMaster::fail(std::string msg) {
  if (phase_ == MasterPhase::failed) return;
  phase_ = MasterPhase::failed;
  error_ = msg;
  emit("failed: " + msg);
}

bool EcMaster::operational() const {
  if (phase_ != MasterPhase::running || slaves_.empty()) return false;
  return std::all_of(slaves_.begin(), slaves_.end(), [](const Slave& s) { return s.step == SlaveStep::op; });
}

void EcMaster::enter(Slave& s, SlaveStep step, SimTime t) {
  s.step = step;
  s.step_since = t;
  if (step == SlaveStep::startup_sdo) {
    s.internal_failed = 0;
    s.internal_error.clear();
    for (const auto& st : config_.startup) {
      if (st.position >= 0 && st.position != s.position) continue;
      if (!s.sii.has_coe()) {
        step_failed(s, fmt::format("start-up SDO 0x{:04X}:{} but the slave has no CoE mailbox", st.index, st.sub), t);
        return;
      }
      queue_internal(s, SdoRequest{false, st.index, st.sub, st.data}, {});
    }
    queue_read_back(s);
  } else if (step == SlaveStep::pdo_read) {
    start_pdo_read(s);
  }
}

// Every slave's step datagrams, each step whole or not at all: a large segment's per-slave
// datagrams do not all fit one frame, and a step sent in part would go wrong (an SII read
// whose next command was cut off reads the wrong address). The first slave whose step does not
// fit is rolled back and starts the next frame, so every slave gets its turn. A slave's
// mailbox datagram goes whole or waits for a later frame on its own: beside a cyclic image
// that fills the frame (35 drives of 42 bytes) there is no room for mailbox traffic at all.
// What a fill set on the slave before its datagrams (step_subs, the SII look-ahead, a mailbox
// job begun) is set again by its next fill.
void EcMaster::fill_slaves(ec::PduBuilder& b, SimTime t) {
  const std::size_t n = slaves_.size();
  std::size_t filled = 0;
  // Runs fill; when one of its datagrams did not fit, takes all of them back. Returns whether
  // they went in.
  const auto whole = [&](auto&& fill) {
    const ec::PduBuilder::Mark mark = b.mark();
    const std::size_t slots = slot_count_;
    add_failed_ = false;
    fill();
    if (!add_failed_) return true;
    b.rewind(mark);
    slot_count_ = slots;
    return false;
  };
  for (; filled < n; ++filled) {
    Slave& s = slaves_[(fill_from_ + filled) % n];
    if (!whole([&] { slave_fill(s, b, t); })) break;  // its step starts the next frame
    // A transfer's mailbox datagram may wait a frame (a cyclic image may leave no room for
    // it): on its own.
    if (mbx_ready(s) && mbx_busy(s) && !whole([&] { mbx_fill(s, b, t); })) s.mbx_read_sent = false;
  }
  // Then the polls of idle mailboxes (an SM1 event: emergencies), in the room transfers left.
  // A poll before a transfer took the room for good: the event bit the transfer's own reply
  // keeps raising made every idle slave poll again each frame.
  for (std::size_t k = 0; k < filled; ++k) {
    Slave& s = slaves_[(fill_from_ + k) % n];
    if (mbx_ready(s) && !mbx_busy(s) && !whole([&] { mbx_fill(s, b, t); })) s.mbx_read_sent = false;
  }
  // The next frame starts after the last slave served, or, when every slave was, one further
  // on: no slave is always last in line for the room.
  fill_from_ = n == 0 ? 0 : (fill_from_ + (filled == n ? 1 : filled)) % n;
}

// A mailbox transfer is under way or queued for the slave (not just a poll).
bool EcMaster::mbx_busy(const Slave& s) const {
  return s.job || !s.internal_jobs.empty() || (s.step == SlaveStep::op && !s.user_jobs.empty());
}

bool EcMaster::add(ec::PduBuilder& b, Slot slot, Cmd cmd, std::uint16_t adp, std::uint16_t ado, std::uint16_t len,
                   const void* data) {
  if (slot_count_ >= slots_.size() || b.add(cmd, index_, adp, ado, len, data) < 0) {
    add_failed_ = true;
    return false;
  }
  slot.cmd = cmd;
  slot.length = len;
  slots_[slot_count_++] = slot;
  return true;
}

// ---------------------------------------------------------------------------------------
// tick

void EcMaster::tick(SimTime t) {
  ++stats_.ticks;
  if (awaiting_) {
    ++stats_.lost_frames;
    awaiting_ = false;
    // A lost mailbox read may have emptied SM1: ask the slave to repeat its reply.
    for (auto& s : slaves_)
      if (s.mbx_read_sent && (s.job || s.mbx_poll)) s.repeat_pending = true;
  }
  // Further cyclic frames that are not back: lost too.
  if (groups_out_ > 0) {
    stats_.lost_frames += static_cast<std::uint64_t>(groups_out_);
    std::fill(group_out_.begin(), group_out_.end(), std::uint8_t{0});
    groups_out_ = 0;
  }
  // A cycle with a frame that never came back: the WKC of the frames that did (0 if none).
  if (cycle_parts_ > 0) close_cycle(false, t);
  for (auto& s : slaves_) s.mbx_read_sent = false;
  if (stopping_) return shutdown_tick();
  if (phase_ == MasterPhase::failed) return;
  if (first_tick_ < 0) first_tick_ = t;
  if (phase_ == MasterPhase::count && config_.startup_timeout_ns > 0 && t - first_tick_ >= config_.startup_timeout_ns) {
    fail(fmt::format("no slave answered within {} s", static_cast<double>(config_.startup_timeout_ns) * 1e-9));
    return;
  }
  for (auto& s : slaves_) slave_timeouts(s, t);
  if (phase_ == MasterPhase::failed) return;
  after_frame(t, false);  // progress that needs no reply (every slave waiting at a barrier)
  if (phase_ == MasterPhase::failed) return;

  index_ = static_cast<std::uint8_t>(index_ + index_stride_);
  index_stride_ = 1;
  slot_count_ = 0;
  bool lrw_added = false;
  ec::PduBuilder b(tx_);
  switch (phase_) {
    case MasterPhase::count:
      add(b, {SlotKind::count}, Cmd::brd, 0, 0x0000, 2);
      break;
    case MasterPhase::reset: {
      static constexpr std::array<std::uint8_t, 256> zeros{};
      const std::uint16_t init_ack = 0x0011;
      add(b, {SlotKind::reset, -1, 0}, Cmd::bwr, 0, kRegFmmu, 256, zeros.data());
      add(b, {SlotKind::reset, -1, 1}, Cmd::bwr, 0, kRegSm, 128, zeros.data());
      add(b, {SlotKind::reset, -1, 2}, Cmd::bwr, 0, kRegDcActivation, 1, zeros.data());
      add(b, {SlotKind::reset, -1, 3}, Cmd::bwr, 0, kRegEeprom, 1, zeros.data());
      std::uint8_t al[2];
      put_u16(al, init_ack);
      add(b, {SlotKind::reset, -1, 4}, Cmd::bwr, 0, kRegAlControl, 2, al);
      break;
    }
    case MasterPhase::address:
      // As many APWRs as one frame chains (64), from addr_from_ on: a longer segment is
      // addressed over several frames.
      for (addr_next_ = addr_from_; addr_next_ < slaves_.size(); ++addr_next_) {
        const Slave& s = slaves_[addr_next_];
        std::uint8_t a[2];
        put_u16(a, s.station);
        if (!add(b, {SlotKind::address, s.position}, Cmd::apwr, position_adp(s.position), kRegStation, 2, a)) break;
      }
      break;
    case MasterPhase::dc:
      dc_fill(b, t);
      break;
    case MasterPhase::running: {
      // The image's LRW, when it fits beside everything else (else it goes in frames of its own).
      if (!lrw_own_frames_ && !groups_.empty() && groups_[0].bytes > 0) {
        const CyclicGroup& g = groups_[0];
        copy_outputs(g);
        const std::uint8_t* data = wire_.empty() ? image_.data() : wire_.data() + g.logical;
        const auto len = static_cast<std::uint16_t>(g.bytes);
        if (b.add_logical(Cmd::lrw, index_, config_.logical_base + g.logical, len, data) >= 0) {
          slots_[slot_count_++] = Slot{SlotKind::lrw, -1, 0, Cmd::lrw, len};
          lrw_added = true;
        }
      }
      if (config_.dc && dc_ref_ >= 0) {
        add(b, {SlotKind::frmw}, Cmd::frmw, slaves_[dc_ref_].station, kRegDcSysTime, 8);
      }
      if (operational_once_ && t >= next_al_check_) {
        add(b, {SlotKind::al_brd}, Cmd::brd, 0, kRegAlStatus, 2);
        next_al_check_ = t + config_.al_check_every_ns;
      }
      [[fallthrough]];
    }
    case MasterPhase::sii:
    case MasterPhase::configure:
      fill_slaves(b, t);
      break;
    case MasterPhase::failed:
      break;
  }
  const bool sent = send_frame(b);
  cycle_back_ = 0;
  cycle_wkc_ = 0;
  if (phase_ == MasterPhase::running && lrw_own_frames_) {
    send_groups();
  } else if (lrw_added && sent) {
    cycle_parts_ = 1;
  }
}

// The tick's frame out, when it has datagrams; true when the callback took it.
bool EcMaster::send_frame(ec::PduBuilder& b) {
  if (b.datagrams() == 0) return false;
  const std::size_t n = b.finish();
  const bool sent = send_ && send_(std::span<const std::uint8_t>(tx_.data(), n));
  ++(sent ? stats_.frames_sent : stats_.send_failures);
  awaiting_ = sent;
  return sent;
}

void EcMaster::shutdown() {
  if (stopping_) return;
  stopping_ = true;
  stop_target_ = AlState::safeop;
  stop_done_ = slaves_.empty();
  emit(stop_done_ ? std::string("shutdown: no slaves") : "shutdown: slaves to SAFE-OP, then INIT");
}

// One frame of the shutdown: BWR AL control (SAFE-OP, or INIT + error acknowledge), BRD AL status.
void EcMaster::shutdown_tick() {
  if (stop_done_) return;
  index_ = static_cast<std::uint8_t>(index_ + index_stride_);
  index_stride_ = 1;
  slot_count_ = 0;
  ec::PduBuilder b(tx_);
  std::uint8_t al[2];
  put_u16(al, stop_target_ == AlState::init ? std::uint16_t{0x0011} : static_cast<std::uint16_t>(AlState::safeop));
  add(b, {SlotKind::stop_control}, Cmd::bwr, 0, kRegAlControl, 2, al);
  add(b, {SlotKind::stop_status}, Cmd::brd, 0, kRegAlStatus, 2);
  send_frame(b);
}

// The shutdown's BRD of the AL status (the states of every slave reached, ORed): no slave in OP
// any more → ask for INIT; only INIT → done.
void EcMaster::stop_status(const ec::Datagram& d) {
  if (d.wkc() == 0) return;  // nobody answered: the caller's bounded wait ends it
  const std::uint16_t st = get_u16(d.data()) & 0x0F;
  if (stop_target_ == AlState::safeop) {
    if (!(st & static_cast<std::uint16_t>(AlState::op))) stop_target_ = AlState::init;
    return;
  }
  if (st != static_cast<std::uint16_t>(AlState::init)) return;
  stop_done_ = true;
  if (d.wkc() == slaves_.size())
    for (auto& s : slaves_) s.al_state = AlState::init;
  emit(fmt::format("shutdown: {} of {} slaves answered in INIT", d.wkc(), slaves_.size()));
}

// Overlapped or in several frames: each slave's outputs of group g at its place in wire_ (for
// overlapped ranges, the start; the rest is its inputs' room). Real-time safe.
void EcMaster::copy_outputs(const CyclicGroup& g) {
  if (wire_.empty()) return;
  for (int i = g.first; i < g.first + g.count; ++i) {
    const Slave& s = slaves_[static_cast<std::size_t>(i)];
    std::memcpy(wire_.data() + s.out_logical, image_.data() + s.out_offset, s.out_bytes);
  }
}

// The image in frames of its own, one LRW per group, right behind the tick's frame (datagram
// index index_ + 1 + g).
void EcMaster::send_groups() {
  for (std::size_t g = 0; g < groups_.size(); ++g) {
    const CyclicGroup& grp = groups_[g];
    copy_outputs(grp);
    ec::PduBuilder b(group_tx_);
    const auto index = static_cast<std::uint8_t>(index_ + 1 + g);
    if (b.add_logical(Cmd::lrw, index, config_.logical_base + grp.logical, static_cast<std::uint16_t>(grp.bytes),
                      wire_.data() + grp.logical) < 0)
      continue;  // cannot happen: layout() sized every group to a frame
    const std::size_t n = b.finish();
    if (send_(std::span<const std::uint8_t>(group_tx_.data(), n))) {
      ++stats_.frames_sent;
      group_out_[g] = 1;
      ++groups_out_;
      ++cycle_parts_;
    } else {
      ++stats_.send_failures;
    }
  }
  index_stride_ = static_cast<std::uint8_t>(1 + groups_.size());
}

// One group's LRW came back: its slaves' inputs into the image, its WKC into the cycle's.
void EcMaster::take_group(const CyclicGroup& g, const ec::Datagram& d, SimTime t) {
  if (wire_.empty()) {
    std::memcpy(image_.data() + out_total_, d.data() + out_total_, in_total_);
  } else {
    for (int i = g.first; i < g.first + g.count; ++i) {
      const Slave& s = slaves_[static_cast<std::size_t>(i)];
      std::memcpy(image_.data() + s.in_offset, d.data() + (s.in_logical - g.logical), s.in_bytes);
    }
  }
  cycle_wkc_ += d.wkc();
  if (++cycle_back_ == cycle_parts_) close_cycle(true, t);
}

// One of the image's own frames (one LRW at index_ + 1 + g, still out)? Takes it and says so.
bool EcMaster::on_group_frame(const ec::PduView& v, SimTime t) {
  if (v.count != 1 || v.datagrams[0].cmd() != Cmd::lrw) return false;
  const ec::Datagram& d = v.datagrams[0];
  const std::size_t g = static_cast<std::uint8_t>(d.index() - index_ - 1);
  if (g >= groups_.size() || !group_out_[g] || d.length() != groups_[g].bytes) return false;
  group_out_[g] = 0;
  --groups_out_;
  ++stats_.frames_received;
  if (d.irq() & kEventSm1)  // someone has mail: read every idle mailbox until it is empty
    for (auto& s : slaves_)
      if (!s.job && mbx_ready(s)) s.mbx_poll = true;
  take_group(groups_[g], d, t);
  return true;
}

// The cycle is over: every LRW back (returned) or the next tick came first. Judges its WKC.
void EcMaster::close_cycle(bool returned, SimTime t) {
  const auto wkc = static_cast<std::uint16_t>(cycle_wkc_);
  cycle_parts_ = cycle_back_ = 0;
  cycle_wkc_ = 0;
  if (returned) {
    ++stats_.cycles;
    stats_.last_wkc = wkc;
    stats_.expected_wkc = expected_wkc_;
  }
  cyclic_wkc(wkc, returned, t);
}

// ---------------------------------------------------------------------------------------
// on_frame

// Every datagram came back with the command and data length it went out with: the handlers
// read each reply at the offsets and sizes they asked for.
bool EcMaster::matches_slots(const ec::PduView& v) const {
  for (std::size_t i = 0; i < v.count; ++i)
    if (v.datagrams[i].cmd() != slots_[i].cmd || v.datagrams[i].length() != slots_[i].length) return false;
  return true;
}

void EcMaster::on_frame(std::span<std::uint8_t> pdu, SimTime t) {
  ec::PduView v;
  if (ec::parse_pdu(pdu, v) != ec::PduError::ok) {
    ++stats_.stray_frames;
    return;
  }
  if (groups_out_ > 0 && on_group_frame(v, t)) return;
  if (!awaiting_ || v.count != slot_count_ || v.datagrams[0].index() != index_ || !matches_slots(v)) {
    ++stats_.stray_frames;
    return;
  }
  awaiting_ = false;
  ++stats_.frames_received;
  bool sm1_event = false;
  for (std::size_t i = 0; i < v.count; ++i) {
    const ec::Datagram& d = v.datagrams[i];
    const Slot& sl = slots_[i];
    if (d.irq() & kEventSm1) sm1_event = true;
    switch (sl.kind) {
      case SlotKind::count: {
        const int n = d.wkc();
        if (n == 0) break;
        if (config_.expected_slaves > 0 && n != config_.expected_slaves) {
          fail(fmt::format("found {} slaves, the configuration expects {}", n, config_.expected_slaves));
          return;
        }
        if (n > kMaxSlaves) {
          fail(fmt::format("the broadcast read counted {} slaves, more than the {} this master addresses", n, kMaxSlaves));
          return;
        }
        slaves_.clear();
        slaves_.resize(static_cast<std::size_t>(n));
        for (int k = 0; k < n; ++k) {
          slaves_[k].position = k;
          slaves_[k].station = static_cast<std::uint16_t>(kStationBase + k);
        }
        emit(fmt::format("{} slaves found", n));
        if (!startup_positions_ok()) return;
        phase_ = MasterPhase::reset;
        reset_ok_ = true;
        break;
      }
      case SlotKind::reset:
        if (d.wkc() == 0) reset_ok_ = false;
        break;
      case SlotKind::address:
        if (d.wkc() != 1) reset_ok_ = false;
        break;
      case SlotKind::step:
        slave_reply(slaves_[sl.slave], d, sl.sub, t);
        break;
      case SlotKind::mbx:
        mbx_reply(slaves_[sl.slave], d, t);
        break;
      case SlotKind::event_mask:
        break;  // best effort: a slave without it is only read on requests
      case SlotKind::repeat:
        if (d.wkc() == 1) {
          slaves_[sl.slave].repeat_pending = false;
          slaves_[sl.slave].repeat_toggle = !slaves_[sl.slave].repeat_toggle;
        }
        break;
      case SlotKind::check: {
        Slave& s = slaves_[sl.slave];
        s.check = false;
        if (s.step != SlaveStep::op) break;
        if (d.wkc() != 1) {
          ++stats_.slaves_lost;
          emit(fmt::format("slave {} (station 0x{:04X}) lost: no answer to the AL status read", s.number(), s.station));
          enter(s, SlaveStep::offline, t);
          s.next_probe = t + config_.probe_every_ns;
          break;
        }
        const std::uint16_t st = get_u16(d.data());
        s.al_state = static_cast<AlState>(st & 0x0F);
        s.al_code = get_u16(d.data() + 4);
        if ((st & 0x0F) != static_cast<std::uint16_t>(AlState::op) || (st & 0x10)) {
          emit(fmt::format("slave {} (station 0x{:04X}) left OP: state {}{}, AL status code 0x{:04X} ({})", s.number(),
                           s.station, to_string(s.al_state), (st & 0x10) ? " + error" : "", s.al_code,
                           al_status_text(s.al_code)));
          s.ack = (st & 0x10) != 0;
          enter(s, SlaveStep::to_init, t);
        }
        break;
      }
      case SlotKind::lrw:
        if (cycle_parts_ > 0) take_group(groups_[0], d, t);
        break;
      case SlotKind::frmw:
        break;
      case SlotKind::al_brd: {
        // ORed AL status of every slave reached: anything but plain OP, or a slave missing
        const std::uint16_t st = get_u16(d.data());
        if ((st & 0x1F) != static_cast<std::uint16_t>(AlState::op) || d.wkc() != slaves_.size()) {
          for (auto& s : slaves_) s.check = s.step == SlaveStep::op;
        }
        break;
      }
      case SlotKind::dc:
        dc_reply(d, sl.slave, sl.sub, t);
        break;
      case SlotKind::stop_control:
        break;
      case SlotKind::stop_status:
        stop_status(d);
        break;
    }
    if (phase_ == MasterPhase::failed) return;
  }
  if (stopping_) return;
  if (sm1_event)  // someone has mail: read every idle mailbox until it is empty
    for (auto& s : slaves_)
      if (!s.job && mbx_ready(s)) s.mbx_poll = true;
  after_frame(t, true);
}

// Every start-up SDO names a slave the count found (else failed, naming the entry).
bool EcMaster::startup_positions_ok() {
  for (const auto& st : config_.startup) {
    if (st.position < static_cast<int>(slaves_.size())) continue;
    fail(fmt::format("{}start-up SDO 0x{:04X}:{} names slave {}, but the bus has {} slave(s)",
                     st.origin.empty() ? "" : st.origin + ": ", st.index, st.sub, st.position + 1, slaves_.size()));
    return false;
  }
  return true;
}

void EcMaster::after_frame(SimTime t, bool from_frame) {
  switch (phase_) {
    case MasterPhase::reset:
      if (!from_frame) break;
      if (reset_ok_) phase_ = MasterPhase::address;
      reset_ok_ = true;
      break;
    case MasterPhase::address:
      if (!from_frame) break;
      if (reset_ok_ && addr_next_ < slaves_.size()) {
        addr_from_ = addr_next_;  // the next frame addresses the rest
      } else if (reset_ok_) {
        phase_ = MasterPhase::sii;
        for (auto& s : slaves_) enter(s, SlaveStep::sii_cmd, t);
      }
      reset_ok_ = true;
      break;
    case MasterPhase::sii: {
      if (!std::all_of(slaves_.begin(), slaves_.end(), [](const Slave& s) { return s.step == SlaveStep::hold_sii; })) break;
      for (auto& s : slaves_) {
        const DeviceDescription* best = nullptr;
        for (const auto& d : config_.devices) {
          if (d.vendor_id != s.sii.vendor || d.product_code != s.sii.product) continue;
          if (!best || d.revision == s.sii.revision) best = &d;
        }
        if (!best) {
          fail(fmt::format("slave {} (vendor 0x{:08X}, product 0x{:08X}, revision 0x{:08X}, \"{}\") matches no ESI "
                           "device description",
                           s.number(), s.sii.vendor, s.sii.product, s.sii.revision, s.sii.name));
          return;
        }
        s.esi = best;
        s.dc = config_.dc && !best->dc.empty();
        emit(fmt::format("slave {} station 0x{:04X}: {} (vendor 0x{:08X}, product 0x{:08X}, rev 0x{:08X})", s.number(),
                         s.station, best->name, s.sii.vendor, s.sii.product, s.sii.revision));
      }
      phase_ = MasterPhase::configure;
      for (auto& s : slaves_) enter(s, SlaveStep::mbx_sm, t);
      break;
    }
    case MasterPhase::configure:
      if (!std::all_of(slaves_.begin(), slaves_.end(), [](const Slave& s) { return s.step == SlaveStep::wait_layout; })) break;
      layout();
      if (phase_ == MasterPhase::failed) return;
      if (config_.dc) {
        phase_ = MasterPhase::dc;
        dc_step_ = 0;
        dc_from_ = 0;
        dc_ok_ = true;
      } else {
        phase_ = MasterPhase::running;
        for (auto& s : slaves_) enter(s, SlaveStep::pd_config, t);
      }
      break;
    case MasterPhase::dc:
      if (dc_step_ >= 4) {
        phase_ = MasterPhase::running;
        for (auto& s : slaves_) enter(s, SlaveStep::pd_config, t);
      }
      break;
    case MasterPhase::running:
      if (!operational_once_ && operational()) {
        operational_once_ = true;
        wkc_bad_run_ = 0;
        emit(fmt::format("all {} slaves in OP, expected WKC {}", slaves_.size(), expected_wkc_));
      }
      if (segment_lost_ && operational()) {
        segment_lost_ = false;
        ++stats_.segment_returns;
        emit(fmt::format("segment back: all {} slaves in OP again", slaves_.size()));
      }
      break;
    default:
      break;
  }
}

// Supervision of one cyclic exchange (once OP was reached): WKC errors, the search for a
// missing slave after wkc_loss_cycles, the segment watch. `returned` false: the frame was lost.
void EcMaster::cyclic_wkc(std::uint16_t wkc, bool returned, SimTime t) {
  if (!operational_once_ || stopping_) return;
  if (returned && wkc == expected_wkc_) {
    wkc_bad_run_ = 0;
    silent_run_ = 0;
    return;
  }
  ++stats_.wkc_errors;
  silent_run_ = wkc == 0 ? silent_run_ + 1 : 0;
  if (++wkc_bad_run_ == config_.wkc_loss_cycles) {
    emit(fmt::format("WKC {} instead of {} for {} cycles{}: checking the slaves", wkc, expected_wkc_, wkc_bad_run_,
                     returned ? "" : " (frame lost)"));
  }
  if (wkc_bad_run_ >= config_.wkc_loss_cycles) {
    for (auto& s : slaves_) s.check = s.step == SlaveStep::op;
  }
  if (config_.segment_loss_cycles > 0 && silent_run_ >= segment_loss_threshold() && !segment_lost_) lose_segment(t);
}

// Silent cycles that make a lost segment: segment_loss_cycles, and enough of them to span
// segment_loss_ns.
int EcMaster::segment_loss_threshold() const {
  const SimTime cycle = std::max<SimTime>(1, config_.cycle_ns);
  const auto span = static_cast<int>((config_.segment_loss_ns + cycle - 1) / cycle);
  return std::max(config_.segment_loss_cycles, span);
}

// The whole segment went silent: leave OP in our own view; the offline probes look for it.
void EcMaster::lose_segment(SimTime t) {
  segment_lost_ = true;
  ++stats_.segment_losses;
  stop_reason_ = fmt::format("segment lost: {} consecutive cycles without a valid WKC; leaving OP, drives stopped",
                             silent_run_);
  emit(stop_reason_);
  for (auto& s : slaves_) {
    s.check = false;
    if (s.step == SlaveStep::offline) continue;
    ++stats_.slaves_lost;
    enter(s, SlaveStep::offline, t);
    s.next_probe = t + config_.probe_every_ns;
  }
}

// ---------------------------------------------------------------------------------------
// layout: outputs of every slave, then inputs in the image; on the wire separate or overlapped,
// in as many frames as it takes; expected WKC

void EcMaster::layout() {
  std::uint32_t out = 0, in = 0;
  for (auto& s : slaves_) {
    std::uint32_t ob = 0, ib = 0;
    for (const auto& p : s.rx_pdos) ob += p.bits();
    for (const auto& p : s.tx_pdos) ib += p.bits();
    s.out_bytes = (ob + 7) / 8;
    s.in_bytes = (ib + 7) / 8;
    s.out_offset = out;
    out += s.out_bytes;
  }
  for (auto& s : slaves_) {
    s.in_offset = out + in;
    in += s.in_bytes;
  }
  out_total_ = out;
  in_total_ = in;
  // Room a frame leaves for an LRW's data: the EtherCAT header, the datagram's header and WKC.
  // In the tick's own frame 64 bytes more stay free for what rides along (FRMW 0x0910, BRD
  // 0x0130, a mailbox datagram); an image that does not fit there goes in frames of its own,
  // leaving the tick's frame to the slaves' configuration, mailbox and DC traffic.
  const std::uint32_t room = ec::kMaxPdu - 2 - ec::kDatagramHeaderSize - ec::kWkcSize;
  const std::uint32_t room_shared = room - 64;
  overlapped_ = config_.image_layout == ImageLayout::overlapped ||
                (config_.image_layout == ImageLayout::automatic && out + in > room_shared);
  // Consecutive slaves share a frame while their bytes fit it; a slave's data is never split.
  groups_.clear();
  std::uint32_t at = 0;
  for (std::size_t i = 0; i < slaves_.size(); ++i) {
    const Slave& s = slaves_[i];
    const std::uint32_t need = overlapped_ ? std::max(s.out_bytes, s.in_bytes) : s.out_bytes + s.in_bytes;
    if (groups_.empty() || groups_.back().bytes + need > room) {
      if (need > room) {
        fail(fmt::format("slave {}'s process data of {} bytes does not fit one frame", s.number(), need));
        return;
      }
      groups_.push_back({at, 0, static_cast<int>(i), 0});
    }
    groups_.back().bytes += need;
    ++groups_.back().count;
    at += need;
  }
  if (static_cast<int>(groups_.size()) > std::max(1, config_.max_cyclic_frames)) {
    fail(fmt::format("process image of {} bytes{} needs {} frames, more than max_cyclic_frames {}", at,
                     overlapped_ ? " (overlapped)" : "", groups_.size(), config_.max_cyclic_frames));
    return;
  }
  // Each group on the wire: overlapped, one range per slave; separate, its slaves' outputs then
  // their inputs. One separate group is the image itself (outputs of all, then inputs).
  for (const CyclicGroup& g : groups_) {
    std::uint32_t outs = 0;
    for (int i = g.first; i < g.first + g.count; ++i) outs += slaves_[static_cast<std::size_t>(i)].out_bytes;
    std::uint32_t o = g.logical, in_at = g.logical + outs;
    for (int i = g.first; i < g.first + g.count; ++i) {
      Slave& s = slaves_[static_cast<std::size_t>(i)];
      s.out_logical = o;
      s.in_logical = overlapped_ ? o : in_at;
      o += overlapped_ ? std::max(s.out_bytes, s.in_bytes) : s.out_bytes;
      in_at += overlapped_ ? 0 : s.in_bytes;
    }
  }
  lrw_own_frames_ = groups_.size() > 1 || (groups_.size() == 1 && groups_[0].bytes > room_shared);
  group_out_.assign(groups_.size(), 0);
  groups_out_ = 0;
  if (overlapped_ || lrw_own_frames_) {
    wire_.assign(at, 0);
  } else {
    wire_.clear();
  }
  image_.assign(out + in, 0);
  int wkc = 0;
  for (const auto& s : slaves_) wkc += (s.out_bytes ? 2 : 0) + (s.in_bytes ? 1 : 0);
  expected_wkc_ = static_cast<std::uint16_t>(wkc);
  layout_done_ = true;
  // A start-up value of an object that is also mapped into the outputs would be overwritten
  // by the first cyclic frame: the image starts with it instead.
  for (const auto& st : config_.startup) {
    for (const auto& s : slaves_) {
      if (st.position >= 0 && st.position != s.position) continue;
      const auto at = find_entry(s.position, st.index, st.sub);
      if (at && at->output) write_entry(*at, bytes_value(st.data, false));
    }
  }
  emit(fmt::format("process image: {} output bytes, {} input bytes{}{}, expected WKC {}", out, in,
                   overlapped_ ? fmt::format(", overlapped in {} bytes", at) : std::string(),
                   lrw_own_frames_ ? fmt::format(", in {} frames of its own", groups_.size()) : std::string(), wkc));
}

std::optional<EntryLocation> EcMaster::find_entry(int position, std::uint16_t index, std::uint8_t sub) const {
  if (!layout_done_ || position < 0 || position >= slave_count()) return std::nullopt;
  const Slave& s = slaves_[position];
  for (int dir = 0; dir < 2; ++dir) {
    const auto& pdos = dir == 0 ? s.rx_pdos : s.tx_pdos;
    std::uint32_t bit = (dir == 0 ? s.out_offset : s.in_offset) * 8;
    for (const auto& p : pdos) {
      for (const auto& e : p.entries) {
        if (e.index == index && e.sub == sub && index != 0) return EntryLocation{bit, e.bits, dir == 0};
        bit += e.bits;
      }
    }
  }
  return std::nullopt;
}

std::int64_t EcMaster::read_entry(const EntryLocation& at, bool is_signed) const {
  std::uint64_t v = 0;
  const unsigned n = std::min<unsigned>(at.bits, 64);  // a shift by 64 or more is undefined
  for (unsigned i = 0; i < n; ++i) {
    const std::uint32_t bit = at.bit_offset + i;
    if (bit / 8 >= image_.size()) break;
    if (image_[bit / 8] & (1u << (bit % 8))) v |= 1ULL << i;
  }
  if (is_signed && at.bits > 0 && at.bits < 64 && (v >> (at.bits - 1)) & 1) v |= ~0ULL << at.bits;
  return static_cast<std::int64_t>(v);
}

void EcMaster::write_entry(const EntryLocation& at, std::int64_t value) {
  const auto v = static_cast<std::uint64_t>(value);
  for (unsigned i = 0; i < at.bits; ++i) {
    const std::uint32_t bit = at.bit_offset + i;
    if (bit / 8 >= image_.size()) break;
    const auto mask = static_cast<std::uint8_t>(1u << (bit % 8));
    if (i < 64 && (v >> i) & 1) image_[bit / 8] |= mask;  // zeros above bit 63
    else image_[bit / 8] &= static_cast<std::uint8_t>(~mask);
  }
}

int EcMaster::sm_index(const Slave& s, std::uint8_t type, int fallback) const {
  for (std::size_t i = 0; i < s.sii.sms.size(); ++i)
    if (s.sii.sms[i].type == type) return static_cast<int>(i);
  if (s.esi) {
    const int k = s.esi->sm_of_kind(static_cast<ec::SmKind>(type));
    if (k >= 0) return k;
  }
  return fallback;
}

// ---------------------------------------------------------------------------------------
// per-slave steps

bool EcMaster::mbx_ready(const Slave& s) const {
  if (!s.sii.has_coe()) return false;
  switch (s.step) {
    case SlaveStep::startup_sdo: case SlaveStep::pdo_read: case SlaveStep::wait_layout: case SlaveStep::pd_config:
    case SlaveStep::to_safeop: case SlaveStep::wait_safeop: case SlaveStep::to_op: case SlaveStep::wait_op:
    case SlaveStep::op:
      return true;
    default:
      return false;
  }
}

void EcMaster::step_failed(Slave& s, const std::string& why, SimTime t) {
  const std::string msg = fmt::format("slave {} (station 0x{:04X}) {}: {}", s.number(), s.station, to_string(s.step), why);
  if (!operational_once_) {
    s.step = SlaveStep::error;
    fail(msg);
    return;
  }
  emit(msg);
  enter(s, SlaveStep::offline, t);
  s.next_probe = t + config_.probe_every_ns;
}

void EcMaster::slave_timeouts(Slave& s, SimTime t) {
  // mailbox
  if (s.job && t - s.mbx_since > config_.sdo_timeout_ns) {
    ++stats_.timeouts;
    s.xfer.fail(SdoStatus::timeout);
    finish_job(s, SdoStatus::timeout);
  }
  SimTime limit = config_.step_timeout_ns;
  switch (s.step) {
    case SlaveStep::wait_init: case SlaveStep::wait_preop: case SlaveStep::wait_safeop: case SlaveStep::wait_op:
      limit = config_.state_timeout_ns;
      break;
    case SlaveStep::startup_sdo: case SlaveStep::pdo_read:
      limit = config_.sdo_timeout_ns * 64;  // many transfers; each has its own timeout
      break;
    case SlaveStep::hold_sii: case SlaveStep::wait_layout: case SlaveStep::op: case SlaveStep::offline:
    case SlaveStep::error:
      return;
    default:
      break;
  }
  if (t - s.step_since > limit) {
    ++stats_.timeouts;
    step_failed(s, "timed out", t);
  }
}

void EcMaster::slave_fill(Slave& s, ec::PduBuilder& b, SimTime t) {
  s.step_ok = true;
  auto step = [&](int sub, Cmd cmd, std::uint16_t ado, std::uint16_t len, const void* data = nullptr) {
    add(b, {SlotKind::step, s.position, sub}, cmd, s.station, ado, len, data);
  };
  auto al_write = [&](AlState st) {
    std::uint8_t a[2];
    put_u16(a, static_cast<std::uint16_t>(static_cast<std::uint16_t>(st) | (s.ack ? 0x10 : 0)));
    s.target = st;
    step(0, Cmd::fpwr, kRegAlControl, 2, a);
  };
  switch (s.step) {
    case SlaveStep::sii_cmd: {
      std::uint8_t a[4];
      put_u32(a, static_cast<std::uint32_t>(s.sii_words.size()));
      std::uint8_t c[2];
      put_u16(c, 0x0100);
      step(0, Cmd::fpwr, 0x0504, 4, a);
      step(1, Cmd::fpwr, 0x0502, 2, c);
      break;
    }
    case SlaveStep::sii_data: {
      step(0, Cmd::fprd, 0x0502, 14);
      s.sii_ahead = 0;
      s.step_subs = 1;
      if (s.sii_read_words > 0) {  // the next read's command right behind this read
        std::uint8_t a[4], c[2];
        s.sii_ahead = s.sii_words.size() + static_cast<std::size_t>(s.sii_read_words);
        put_u32(a, static_cast<std::uint32_t>(s.sii_ahead));
        put_u16(c, 0x0100);
        step(1, Cmd::fpwr, 0x0504, 4, a);
        step(2, Cmd::fpwr, 0x0502, 2, c);
        s.step_subs = 3;
      }
      break;
    }
    case SlaveStep::to_init: al_write(AlState::init); break;
    case SlaveStep::to_preop: al_write(AlState::preop); break;
    case SlaveStep::to_safeop: al_write(AlState::safeop); break;
    case SlaveStep::to_op: al_write(AlState::op); break;
    case SlaveStep::wait_init: case SlaveStep::wait_preop: case SlaveStep::wait_safeop: case SlaveStep::wait_op:
      step(0, Cmd::fprd, kRegAlStatus, 6);
      break;
    case SlaveStep::ack_error: {
      std::uint8_t a[2];
      put_u16(a, static_cast<std::uint16_t>(static_cast<std::uint16_t>(s.al_state) | 0x10));
      step(0, Cmd::fpwr, kRegAlControl, 2, a);
      break;
    }
    case SlaveStep::mbx_sm: {
      s.repeat_toggle = false;
      s.repeat_pending = false;
      if (s.sii.mbx_out_size == 0) {  // no mailbox: straight on
        enter(s, SlaveStep::to_preop, t);
        al_write(AlState::preop);
        break;
      }
      std::uint8_t sm[16]{};
      const int i0 = 0, i1 = 1;
      put_u16(sm, s.sii.mbx_out_start);
      put_u16(sm + 2, s.sii.mbx_out_size);
      sm[4] = s.sii.sms.size() > 0 && s.sii.sms[i0].control ? s.sii.sms[i0].control : 0x26;
      sm[6] = 0x01;
      put_u16(sm + 8, s.sii.mbx_in_start);
      put_u16(sm + 10, s.sii.mbx_in_size);
      sm[12] = s.sii.sms.size() > 1 && s.sii.sms[i1].control ? s.sii.sms[i1].control : 0x22;
      sm[14] = 0x01;
      step(0, Cmd::fpwr, kRegSm, 16, sm);
      const std::uint8_t mask[2] = {kEventSm1, 0};  // ECAT event mask: SM1 (emergencies)
      add(b, {SlotKind::event_mask, s.position}, Cmd::fpwr, s.station, kRegEventMask, 2, mask);
      break;
    }
    case SlaveStep::pd_config: {
      int sub = 0;
      auto sm_bytes = [&](int idx, std::uint32_t len, std::uint8_t def_control) {
        std::uint8_t sm[8]{};
        std::uint16_t start = 0;
        std::uint8_t control = def_control;
        if (idx < static_cast<int>(s.sii.sms.size())) {
          start = s.sii.sms[idx].start;
          if (s.sii.sms[idx].control) control = s.sii.sms[idx].control;
        } else if (s.esi && idx < static_cast<int>(s.esi->sms.size())) {
          start = s.esi->sms[idx].start;
          control = s.esi->sms[idx].control;
        }
        put_u16(sm, start);
        put_u16(sm + 2, static_cast<std::uint16_t>(len));
        sm[4] = control;
        sm[6] = len ? 0x01 : 0x00;
        step(sub++, Cmd::fpwr, static_cast<std::uint16_t>(kRegSm + 8 * idx), 8, sm);
        return start;
      };
      auto fmmu_bytes = [&](int idx, std::uint32_t logical, std::uint32_t len, std::uint16_t phys, std::uint8_t type) {
        std::uint8_t f[16]{};
        put_u32(f, logical);
        put_u16(f + 4, static_cast<std::uint16_t>(len));
        f[6] = 0;
        f[7] = 7;
        put_u16(f + 8, phys);
        f[10] = 0;
        f[11] = type;
        f[12] = 0x01;
        step(sub++, Cmd::fpwr, static_cast<std::uint16_t>(kRegFmmu + 16 * idx), 16, f);
      };
      int fmmu = 0;
      if (s.out_bytes) {
        const std::uint16_t start = sm_bytes(sm_index(s, 3, 2), s.out_bytes, 0x64);
        fmmu_bytes(fmmu++, config_.logical_base + s.out_logical, s.out_bytes, start, 0x02);
      }
      if (s.in_bytes) {
        const std::uint16_t start = sm_bytes(sm_index(s, 4, 3), s.in_bytes, 0x20);
        fmmu_bytes(fmmu++, config_.logical_base + s.in_logical, s.in_bytes, start, 0x01);
      }
      s.step_subs = sub;
      if (sub == 0) {
        enter(s, SlaveStep::to_safeop, t);
        al_write(AlState::safeop);
      }
      break;
    }
    case SlaveStep::dc_read:
      // the reference's system time and ours in one frame (ours a delay later), our offset
      add(b, {SlotKind::step, s.position, 0}, Cmd::fprd, slaves_[dc_ref_].station, kRegDcSysTime, 8);
      step(1, Cmd::fprd, kRegDcSysTime, 8);
      step(2, Cmd::fprd, kRegDcOffset, 8);
      break;
    case SlaveStep::dc_write: {
      std::uint8_t o[8], dl[4], off[1] = {0}, c[4], st[8], act[2];
      const std::int64_t correction =
          static_cast<std::int64_t>(s.dc_ref_sys) + s.dc_delay_ns - static_cast<std::int64_t>(s.dc_own_sys);
      put_u64(o, s.dc_own_offset + static_cast<std::uint64_t>(correction));
      put_u32(dl, static_cast<std::uint32_t>(s.dc_delay_ns));
      const auto cycle = static_cast<std::uint64_t>(config_.cycle_ns);
      put_u32(c, static_cast<std::uint32_t>(cycle));
      std::uint64_t start = s.dc_ref_sys + 20'000'000;
      if (cycle) start = (start / cycle + 1) * cycle;
      put_u64(st, static_cast<std::uint64_t>(static_cast<std::int64_t>(start) + config_.sync0_shift_ns));
      put_u16(act, s.esi && !s.esi->dc.empty() && s.esi->dc[0].assign_activate ? s.esi->dc[0].assign_activate : 0x0300);
      step(0, Cmd::fpwr, kRegDcOffset, 8, o);
      step(1, Cmd::fpwr, kRegDcDelay, 4, dl);
      step(2, Cmd::fpwr, kRegDcActivation, 1, off);
      step(3, Cmd::fpwr, kRegDcCycle0, 4, c);
      step(4, Cmd::fpwr, kRegDcStart, 8, st);
      step(5, Cmd::fpwr, kRegDcAssign, 2, act);
      break;
    }
    case SlaveStep::startup_sdo:
      if (s.internal_jobs.empty() && !(s.job && s.job->internal)) {
        if (s.internal_failed) {
          step_failed(s, s.internal_error, t);
          break;
        }
        enter(s, SlaveStep::pdo_read, t);
      }
      break;
    case SlaveStep::pdo_read:
      if (s.internal_jobs.empty() && !(s.job && s.job->internal)) {
        finish_pdo_read(s);
        if (s.step == SlaveStep::error || phase_ == MasterPhase::failed) break;
        if (layout_done_) {
          std::uint32_t ob = 0, ib = 0;
          for (const auto& p : s.rx_pdos) ob += p.bits();
          for (const auto& p : s.tx_pdos) ib += p.bits();
          if ((ob + 7) / 8 != s.out_bytes || (ib + 7) / 8 != s.in_bytes) {
            step_failed(s, "its PDO mapping changed size since the layout", t);
            break;
          }
          enter(s, SlaveStep::pd_config, t);
        } else {
          enter(s, SlaveStep::wait_layout, t);
        }
      }
      break;
    case SlaveStep::op:
      if (s.check) add(b, {SlotKind::check, s.position}, Cmd::fprd, s.station, kRegAlStatus, 6);
      break;
    case SlaveStep::offline:
      if (t >= s.next_probe) {
        std::uint8_t a[2];
        put_u16(a, s.station);
        add(b, {SlotKind::step, s.position, 0}, Cmd::apwr, position_adp(s.position), kRegStation, 2, a);
        s.next_probe = t + config_.probe_every_ns;
      }
      break;
    default:
      break;
  }
}

void EcMaster::slave_reply(Slave& s, const ec::Datagram& d, int sub, SimTime t) {
  const std::uint16_t wkc = d.wkc();
  switch (s.step) {
    case SlaveStep::sii_cmd:
      if (wkc != 1) s.step_ok = false;
      if (sub == 1 && s.step_ok) enter(s, SlaveStep::sii_data, t);
      break;
    case SlaveStep::sii_data: {
      using Next = Slave::SiiNext;
      if (sub == 0) {
        s.sii_next = Next::read_again;
        if (wkc != 1) break;
        const std::uint8_t* p = d.data();
        const std::uint16_t status = get_u16(p);
        if (status & 0x8000) break;  // busy: read again
        if (status & 0x7800 || get_u32(p + 2) != s.sii_words.size()) {
          if (++s.sii_retries > kSiiRetries) {
            step_failed(s, fmt::format("EEPROM read error, status 0x{:04X}", status), t);
            s.sii_next = Next::done;
            break;
          }
          s.sii_next = Next::command;
          break;
        }
        const int words = (status & 0x0040) ? 4 : 2;
        s.sii_read_words = words;
        s.sii_retries = 0;  // counts consecutive failures
        for (int i = 0; i < words; ++i) s.sii_words.push_back(get_u16(p + 6 + 2 * i));
        std::size_t need = 0;
        const SiiScan scan = sii_scan(s.sii_words, &need);
        s.sii_next = Next::done;
        if (scan == SiiScan::complete) {
          s.sii = parse_sii(s.sii_words);
          enter(s, SlaveStep::hold_sii, t);
        } else if (scan == SiiScan::malformed) {
          step_failed(s, "SII category chain runs past the EEPROM", t);
        } else {
          s.sii_next = Next::next;
        }
      } else if (wkc != 1) {
        s.step_ok = false;
      }
      if (sub != s.step_subs - 1) break;
      switch (s.sii_next) {
        case Next::read_again:  // the data was not there: command this address again if we
                                // overwrote the command with the next one
          if (s.sii_ahead) enter(s, SlaveStep::sii_cmd, t);
          break;
        case Next::next:
          if (s.step_ok && s.sii_ahead == s.sii_words.size()) enter(s, SlaveStep::sii_data, t);
          else enter(s, SlaveStep::sii_cmd, t);
          break;
        case Next::command:
          enter(s, SlaveStep::sii_cmd, t);
          break;
        case Next::done:
          break;
      }
      break;
    }
    case SlaveStep::to_init: case SlaveStep::to_preop: case SlaveStep::to_safeop: case SlaveStep::to_op:
      if (wkc == 1) {
        s.ack = false;
        enter(s, static_cast<SlaveStep>(static_cast<int>(s.step) + 1), t);
      }
      break;
    case SlaveStep::wait_init: case SlaveStep::wait_preop: case SlaveStep::wait_safeop: case SlaveStep::wait_op: {
      if (wkc != 1) break;
      const std::uint16_t st = get_u16(d.data());
      s.al_state = static_cast<AlState>(st & 0x0F);
      s.al_code = get_u16(d.data() + 4);
      if (st & 0x10) {
        if (s.step == SlaveStep::wait_init) {  // a pending error: acknowledge and go on
          s.ack = true;
          enter(s, SlaveStep::to_init, t);
          break;
        }
        const std::string msg =
            fmt::format("slave {} (station 0x{:04X}) refused {}: state {} + error, AL status code 0x{:04X} ({})",
                        s.number(), s.station, to_string(s.target), to_string(s.al_state), s.al_code,
                        al_status_text(s.al_code));
        enter(s, SlaveStep::ack_error, t);
        if (!operational_once_) {
          error_ = msg;
        }
        emit(msg);
        break;
      }
      if (s.al_state == s.target) {
        switch (s.step) {
          case SlaveStep::wait_init: enter(s, SlaveStep::mbx_sm, t); break;
          case SlaveStep::wait_preop: enter(s, SlaveStep::startup_sdo, t); break;
          case SlaveStep::wait_safeop: enter(s, SlaveStep::to_op, t); break;
          default:
            enter(s, SlaveStep::op, t);
            if (operational_once_) {
              ++s.recoveries;
              ++stats_.recoveries;
              emit(fmt::format("slave {} (station 0x{:04X}) back in OP", s.number(), s.station));
            }
            break;
        }
      }
      break;
    }
    case SlaveStep::ack_error:
      if (wkc == 1) {
        if (!operational_once_) {
          s.step = SlaveStep::error;
          fail(error_.empty() ? fmt::format("slave {} AL error", s.number()) : error_);
        } else {
          enter(s, SlaveStep::offline, t);
          s.next_probe = t + config_.probe_every_ns;
        }
      }
      break;
    case SlaveStep::mbx_sm:
      if (wkc == 1) enter(s, SlaveStep::to_preop, t);
      break;
    case SlaveStep::pd_config:
      if (wkc != 1) s.step_ok = false;
      if (sub == s.step_subs - 1 && s.step_ok)
        enter(s, operational_once_ && s.dc && dc_ref_ >= 0 ? SlaveStep::dc_read : SlaveStep::to_safeop, t);
      break;
    case SlaveStep::dc_read:
      if (wkc != 1) s.step_ok = false;
      if (sub == 0) s.dc_ref_sys = get_u64(d.data());
      if (sub == 1) s.dc_own_sys = get_u64(d.data());
      if (sub == 2) {
        s.dc_own_offset = get_u64(d.data());
        if (s.step_ok) enter(s, SlaveStep::dc_write, t);
      }
      break;
    case SlaveStep::dc_write:
      if (wkc != 1) s.step_ok = false;
      if (sub == 5 && s.step_ok) {
        emit(fmt::format("slave {} (station 0x{:04X}) rejoins distributed clocks", s.number(), s.station));
        enter(s, SlaveStep::to_safeop, t);
      }
      break;
    case SlaveStep::offline:
      if (wkc == 1) {
        emit(fmt::format("slave {} answers again: station 0x{:04X} set, reconfiguring", s.number(), s.station));
        s.ack = true;
        s.job.reset();
        s.internal_jobs.clear();
        enter(s, SlaveStep::to_init, t);
      }
      break;
    default:
      break;
  }
}

// ---------------------------------------------------------------------------------------
// mailbox

// EcMasterConfig::read_back for every axis of a CiA 402 slave; each answer (or abort) lands
// in s.read_back, and none fails the step (the callback keeps it out of internal_failed).
void EcMaster::queue_read_back(Slave& s) {
  s.read_back.clear();
  if (!s.esi || s.esi->profile != 402 || !s.sii.has_coe()) return;
  for (int axis = 0; axis < std::max(1, s.esi->axes); ++axis) {
    for (const auto& o : config_.read_back) {
      const bool per_axis = o.index >= 0x6000 && o.index < 0x6800;
      const auto index = static_cast<std::uint16_t>(o.index + (per_axis ? 0x800 * axis : 0));
      s.read_back.push_back(ReadBack{index, o.sub, SdoStatus::pending, 0, {}});
      const std::size_t k = s.read_back.size() - 1;
      queue_internal(s, SdoRequest{true, index, o.sub, {}}, [&s, k](const SdoResult& r) {
        if (k >= s.read_back.size()) return;
        s.read_back[k].status = r.status;
        s.read_back[k].abort_code = r.abort_code;
        s.read_back[k].data = r.data;
      });
    }
  }
}

void EcMaster::queue_internal(Slave& s, SdoRequest req, SdoCallback cb) {
  s.internal_jobs.push_back(MbxJob{0, std::move(req), std::move(cb), true});
}

std::uint64_t EcMaster::queue_user(int position, SdoRequest req, SdoCallback cb) {
  if (position < 0 || position >= slave_count()) return 0;
  Slave& s = slaves_[position];
  if (phase_ >= MasterPhase::configure && !s.sii.has_coe()) return 0;
  const std::uint64_t id = next_id_++;
  s.user_jobs.push_back(MbxJob{id, std::move(req), std::move(cb), false});
  return id;
}

std::uint64_t EcMaster::sdo_upload(int position, std::uint16_t index, std::uint8_t sub, SdoCallback cb) {
  return queue_user(position, SdoRequest{true, index, sub, {}}, std::move(cb));
}

std::uint64_t EcMaster::sdo_download(int position, std::uint16_t index, std::uint8_t sub, std::vector<std::uint8_t> data,
                                     SdoCallback cb) {
  return queue_user(position, SdoRequest{false, index, sub, std::move(data)}, std::move(cb));
}

std::size_t EcMaster::sdo_pending(int position) const {
  if (position < 0 || position >= slave_count()) return 0;
  const Slave& s = slaves_[position];
  return s.user_jobs.size() + (s.job && !s.job->internal ? 1 : 0);
}

void EcMaster::mbx_fill(Slave& s, ec::PduBuilder& b, SimTime t) {
  if (!s.job) {
    std::deque<MbxJob>* q = !s.internal_jobs.empty() ? &s.internal_jobs : nullptr;
    if (!q && s.step == SlaveStep::op && !s.user_jobs.empty()) q = &s.user_jobs;
    if (!q) {
      mbx_poll_fill(s, b);
      return;
    }
    s.job = std::move(q->front());
    q->pop_front();
    s.xfer.begin(s.job->req, s.sii.mbx_out_size);
    s.mbx_writing = true;
    s.mbx_since = t;
    s.counter = static_cast<std::uint8_t>(s.counter % 7 + 1);
    if (s.xfer.step() == SdoTransfer::Step::done) {
      finish_job(s, s.xfer.status());
      return;
    }
  }
  if (s.repeat_pending && !s.mbx_writing) {
    add_repeat_request(s, b);
    return;
  }
  s.repeat_pending = false;
  if (s.mbx_writing) {
    s.mbx_buf.assign(s.sii.mbx_out_size, 0);
    if (s.xfer.next_request(s.mbx_buf, s.counter) == 0) return;
    add(b, {SlotKind::mbx, s.position}, Cmd::fpwr, s.station, s.sii.mbx_out_start, s.sii.mbx_out_size, s.mbx_buf.data());
  } else if (add(b, {SlotKind::mbx, s.position}, Cmd::fprd, s.station, s.sii.mbx_in_start, s.sii.mbx_in_size)) {
    s.mbx_read_sent = true;
  }
}

// The SM1 repeat request: SM1 activate (0x080E) with bit 1 toggled, enable kept.
void EcMaster::add_repeat_request(Slave& s, ec::PduBuilder& b) {
  const std::uint8_t act = static_cast<std::uint8_t>(0x01 | (s.repeat_toggle ? 0x00 : 0x02));
  add(b, {SlotKind::repeat, s.position}, Cmd::fpwr, s.station, kRegSm + 8 + 6, 1, &act);
}

// No transfer: read SM1 (or ask for its repeat after a lost read) while mbx_poll is set.
void EcMaster::mbx_poll_fill(Slave& s, ec::PduBuilder& b) {
  if (!s.mbx_poll) return;
  if (s.repeat_pending) {
    add_repeat_request(s, b);
    return;
  }
  if (add(b, {SlotKind::mbx, s.position}, Cmd::fprd, s.station, s.sii.mbx_in_start, s.sii.mbx_in_size))
    s.mbx_read_sent = true;
}

bool EcMaster::take_emergency(Slave& s, std::span<const std::uint8_t> mailbox) {
  const auto e = parse_emergency(mailbox);
  if (!e) return false;
  ++s.emergencies;
  ++stats_.emergencies;
  s.last_emergency = e->code;
  s.last_error_register = e->error_register;
  const std::size_t axis = e->data[0] >= 1 && e->data[0] <= 64 ? e->data[0] : 1;
  if (s.axis_emergency.size() < axis) s.axis_emergency.resize(axis, 0);
  s.axis_emergency[axis - 1] = e->code;
  emit(fmt::format("slave {} (station 0x{:04X}) emergency 0x{:04X} ({}), error register 0x{:02X}, data {:02X}", s.number(),
                   s.station, e->code, emergency_text(e->code), e->error_register, fmt::join(e->data, " ")));
  return true;
}

void EcMaster::mbx_reply(Slave& s, const ec::Datagram& d, SimTime) {
  const std::span<const std::uint8_t> mbx(d.data(), d.length());
  if (!s.job) {  // a poll: an emergency, or the mailbox is empty (WKC 0) and polling ends
    if (d.wkc() != 1) {
      s.mbx_poll = false;
      return;
    }
    take_emergency(s, mbx);  // anything else there (a stale repeated answer) is dropped
    return;
  }
  if (d.wkc() != 1) return;  // mailbox full (write) or empty (read): again next tick
  if (s.mbx_writing) {
    s.mbx_writing = false;
    return;
  }
  if (take_emergency(s, mbx)) return;  // not the answer: keep reading
  switch (s.xfer.on_reply(mbx)) {
    case SdoTransfer::ReplyOutcome::ignored:
      break;
    case SdoTransfer::ReplyOutcome::progress:
      s.mbx_writing = true;
      s.counter = static_cast<std::uint8_t>(s.counter % 7 + 1);
      break;
    case SdoTransfer::ReplyOutcome::finished:
      finish_job(s, s.xfer.status());
      break;
  }
}

void EcMaster::finish_job(Slave& s, SdoStatus status) {
  if (!s.job) return;
  MbxJob job = std::move(*s.job);
  s.job.reset();
  SdoResult r;
  r.id = job.id;
  r.position = s.position;
  r.request = job.req;
  r.status = status;
  r.abort_code = s.xfer.abort_code();
  r.data = s.xfer.data();
  if (status == SdoStatus::done) {
    ++stats_.sdo_done;
  } else {
    ++stats_.sdo_failed;
    const std::string msg = fmt::format("slave {} SDO {} 0x{:04X}:{:02X} {}{}", s.number(),
                                        job.req.upload ? "upload" : "download", job.req.index, job.req.sub,
                                        to_string(status),
                                        status == SdoStatus::aborted
                                            ? fmt::format(" 0x{:08X} ({})", r.abort_code, sdo_abort_text(r.abort_code))
                                            : "");
    if (job.internal && !job.cb) {
      ++s.internal_failed;
      s.internal_error = msg;
    }
    if (!job.internal) emit(msg);
  }
  if (!job.internal) last_sdo_ = r;
  if (job.cb) job.cb(r);
}

// PDO assignment and mapping over CoE: 0x1C12/0x1C13 sub 0 (count), each assigned PDO, then
// each PDO's sub 0 and entries. Results land in s.assign / s.mapping; finish_pdo_read() turns
// them into PdoInfo (or falls back to the SII categories, then to the ESI).
void EcMaster::start_pdo_read(Slave& s) {
  s.assign.clear();
  s.mapping.clear();
  s.pdo_from_coe = false;
  if (!s.sii.has_coe()) return;
  s.pdo_from_coe = true;
  for (const std::uint16_t assign : {std::uint16_t{0x1C12}, std::uint16_t{0x1C13}}) {
    queue_internal(s, SdoRequest{true, assign, 0, {}}, [this, &s, assign](const SdoResult& r) {
      if (r.status != SdoStatus::done || r.data.empty()) {
        s.pdo_from_coe = false;
        return;
      }
      s.assign[assign].assign(r.data[0], 0);
      // An int index: a count of 255 must end the loop (an 8-bit index would wrap and queue forever).
      for (int i = 1; i <= r.data[0]; ++i) {
        const auto sub = static_cast<std::uint8_t>(i);
        queue_internal(s, SdoRequest{true, assign, sub, {}}, [this, &s, assign, i](const SdoResult& r2) {
          if (r2.status != SdoStatus::done || r2.data.size() < 2) {
            s.pdo_from_coe = false;
            return;
          }
          const std::uint16_t pdo = get_u16(r2.data.data());
          s.assign[assign][i - 1] = pdo;
          queue_internal(s, SdoRequest{true, pdo, 0, {}}, [this, &s, pdo](const SdoResult& r3) {
            if (r3.status != SdoStatus::done || r3.data.empty()) {
              s.pdo_from_coe = false;
              return;
            }
            s.mapping[pdo].assign(r3.data[0], 0);
            for (int k = 1; k <= r3.data[0]; ++k) {
              queue_internal(s, SdoRequest{true, pdo, static_cast<std::uint8_t>(k), {}}, [&s, pdo, k](const SdoResult& r4) {
                if (r4.status != SdoStatus::done || r4.data.size() < 4) {
                  s.pdo_from_coe = false;
                  return;
                }
                s.mapping[pdo][k - 1] = get_u32(r4.data.data());
              });
            }
          });
        });
      }
    });
  }
}

void EcMaster::finish_pdo_read(Slave& s) {
  s.rx_pdos.clear();
  s.tx_pdos.clear();
  if (s.pdo_from_coe) {
    for (const std::uint16_t assign : {std::uint16_t{0x1C12}, std::uint16_t{0x1C13}}) {
      auto& out = assign == 0x1C12 ? s.rx_pdos : s.tx_pdos;
      for (const std::uint16_t pdo : s.assign[assign]) {
        PdoInfo p;
        p.index = pdo;
        p.sm = assign == 0x1C12 ? 2 : 3;
        for (const std::uint32_t m : s.mapping[pdo]) {
          p.entries.push_back({static_cast<std::uint16_t>(m >> 16), static_cast<std::uint8_t>(m >> 8),
                               static_cast<std::uint8_t>(m)});
        }
        out.push_back(std::move(p));
      }
    }
    return;
  }
  // No CoE (or the CoE read failed): the SII PDO categories, then the ESI.
  const int sm_out = sm_index(s, 3, 2), sm_in = sm_index(s, 4, 3);
  for (const auto& p : s.sii.rx_pdos)
    if (p.sm == sm_out) s.rx_pdos.push_back(p);
  for (const auto& p : s.sii.tx_pdos)
    if (p.sm == sm_in) s.tx_pdos.push_back(p);
  if (s.rx_pdos.empty() && s.tx_pdos.empty() && s.esi) {
    auto conv = [](const ec::EsiPdo& e) {
      PdoInfo p;
      p.index = e.index;
      p.sm = e.sm;
      for (const auto& en : e.entries) p.entries.push_back({en.index, en.subindex, en.bit_length});
      return p;
    };
    for (const auto& p : s.esi->rx_pdos)
      if (p.sm == sm_out) s.rx_pdos.push_back(conv(p));
    for (const auto& p : s.esi->tx_pdos)
      if (p.sm == sm_in) s.tx_pdos.push_back(conv(p));
  }
}

// ---------------------------------------------------------------------------------------
// distributed clocks (line topology): latch the port receive times, propagation delay of
// slave i = (round trip at the reference − round trip at i) / 2, offset so that every slave's
// system time equals the reference's local time, then SYNC0 (cycle, start time, activation).

// The DC set-up's datagrams for this tick: step 0 one BWR; steps 1–3 a few per DC slave, as
// many slaves (each whole) as fit the frame from dc_from_ on — a long segment takes a step in
// several frames (3 datagrams per slave: 21 slaves fill the 64 a frame may chain).
void EcMaster::dc_fill(ec::PduBuilder& b, SimTime t) {
  dc_last_ = -1;
  if (dc_step_ == 0) {
    std::uint8_t z[4]{};
    add(b, {SlotKind::dc, -1, 0}, Cmd::bwr, 0, kRegDcRecv, 4, z);
    return;
  }
  if (dc_step_ == 3 && dc_from_ == 0) {
    // One SYNC0 start for every slave: 20 ms after the reference's system time now (as read in
    // step 1, advanced by the time since), on a cycle boundary, plus the shift.
    const auto cycle = static_cast<std::uint64_t>(config_.cycle_ns);
    std::uint64_t start = dc_ref_time_ + static_cast<std::uint64_t>(std::max<SimTime>(0, t - dc_read_t_)) + 20'000'000;
    if (cycle) start = (start / cycle + 1) * cycle;
    dc_start_ = static_cast<std::uint64_t>(static_cast<std::int64_t>(start) + config_.sync0_shift_ns);
  }
  for (std::size_t i = dc_from_; i < slaves_.size(); ++i) {
    const Slave& s = slaves_[i];
    if (!s.dc) continue;
    const ec::PduBuilder::Mark mark = b.mark();
    const std::size_t slots = slot_count_;
    add_failed_ = false;
    dc_fill_slave(b, s);
    if (add_failed_) {  // this slave starts the next frame
      b.rewind(mark);
      slot_count_ = slots;
      break;
    }
    dc_last_ = s.position;
  }
  if (dc_last_ < 0) {  // no DC slave left from dc_from_ on: the step is done
    if (dc_step_ == 1 && dc_ref_ < 0) dc_step_ = 3;  // no DC slave at all
    ++dc_step_;
    dc_from_ = 0;
  }
}

// One slave's datagrams of DC step 1 (read the latched port times, its local receive time and
// system time), 2 (write its offset and delay) or 3 (SYNC0 cycle, start, activation).
void EcMaster::dc_fill_slave(ec::PduBuilder& b, const Slave& s) {
  switch (dc_step_) {
    case 1:
      add(b, {SlotKind::dc, s.position, 0}, Cmd::fprd, s.station, kRegDcRecv, 16);
      add(b, {SlotKind::dc, s.position, 1}, Cmd::fprd, s.station, kRegDcRecvLocal, 8);
      add(b, {SlotKind::dc, s.position, 2}, Cmd::fprd, s.station, kRegDcSysTime, 8);
      break;
    case 2: {
      std::uint8_t o[8], dl[4];
      const std::int64_t off = static_cast<std::int64_t>(dc_local_[dc_ref_]) + s.dc_delay_ns -
                               static_cast<std::int64_t>(dc_local_[s.position]);
      put_u64(o, static_cast<std::uint64_t>(off));
      put_u32(dl, static_cast<std::uint32_t>(s.dc_delay_ns));
      add(b, {SlotKind::dc, s.position, 0}, Cmd::fpwr, s.station, kRegDcOffset, 8, o);
      add(b, {SlotKind::dc, s.position, 1}, Cmd::fpwr, s.station, kRegDcDelay, 4, dl);
      break;
    }
    case 3: {
      std::uint8_t c[4], st[8], act[2];
      put_u32(c, static_cast<std::uint32_t>(config_.cycle_ns));
      put_u64(st, dc_start_);
      const std::uint16_t aa = s.esi && !s.esi->dc.empty() && s.esi->dc[0].assign_activate ? s.esi->dc[0].assign_activate : 0x0300;
      put_u16(act, aa);
      add(b, {SlotKind::dc, s.position, 0}, Cmd::fpwr, s.station, kRegDcCycle0, 4, c);
      add(b, {SlotKind::dc, s.position, 1}, Cmd::fpwr, s.station, kRegDcStart, 8, st);
      add(b, {SlotKind::dc, s.position, 2}, Cmd::fpwr, s.station, kRegDcAssign, 2, act);
      break;
    }
    default:
      break;
  }
}

void EcMaster::dc_reply(const ec::Datagram& d, int slave, int sub, SimTime t) {
  if (d.wkc() == 0) dc_ok_ = false;
  const bool last = slave < 0 || slave == dc_last_;  // the frame's last slave of this step
  const int last_sub = dc_step_ == 1 || dc_step_ == 3 ? 2 : dc_step_ == 2 ? 1 : 0;
  if (dc_step_ == 1 && slave >= 0) {
    if (dc_ports_.size() != slaves_.size()) {
      dc_ports_.assign(slaves_.size(), {});
      dc_local_.assign(slaves_.size(), 0);
    }
    if (sub == 0) for (int p = 0; p < 4; ++p) dc_ports_[slave][p] = get_u32(d.data() + 4 * p);
    if (sub == 1) dc_local_[slave] = get_u64(d.data());
    if (sub == 2 && (dc_ref_ < 0 || slave == dc_ref_)) {
      dc_ref_time_ = get_u64(d.data());
      dc_read_t_ = t;
    }
    if (dc_ref_ < 0 || slave < dc_ref_) dc_ref_ = slave;
  }
  if (!last || sub != last_sub) return;
  if (!dc_ok_) {  // repeat this frame's part of the step
    dc_ok_ = true;
    return;
  }
  // More DC slaves behind this frame's: the step goes on with them in the next frame.
  if (slave >= 0 && std::any_of(slaves_.begin() + slave + 1, slaves_.end(), [](const Slave& s) { return s.dc; })) {
    dc_from_ = static_cast<std::size_t>(slave) + 1;
    return;
  }
  dc_from_ = 0;
  if (dc_step_ == 1) {
    if (dc_ref_ < 0) {  // no DC slave
      dc_step_ = 4;
      return;
    }
    auto round_trip = [&](int i) -> std::int64_t {
      const auto& p = dc_ports_[i];
      return p[1] ? static_cast<std::int64_t>(static_cast<std::uint32_t>(p[1] - p[0])) : 0;
    };
    const std::int64_t ref_rt = round_trip(dc_ref_);
    for (auto& s : slaves_) {
      if (!s.dc) continue;
      s.dc_delay_ns = s.position == dc_ref_ ? 0 : std::max<std::int64_t>(0, (ref_rt - round_trip(s.position)) / 2);
    }
    emit(fmt::format("DC: reference clock slave {}, delays measured", dc_ref_));
  }
  ++dc_step_;
}

}  // namespace omnitwin::controller::ethercat
