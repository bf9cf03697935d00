// bus_emulators/ethercat — the ESC core (see ec_esc.hpp).
#include "bus_emulators/ethercat/ec_esc.hpp"

#include <algorithm>
#include <cstring>
#include <utility>

#include "bus_emulators/ethercat/ec_registers.hpp"

namespace omnitwin::ethercat {

namespace {
bool overlaps(std::uint32_t a, std::uint32_t n, std::uint32_t r, std::uint32_t rn) {
  return a < r + rn && r < a + n;
}
}  // namespace

Esc::Esc(EscConfig config, EscApplication* app)
    : cfg_(std::move(config)),
      app_(app),
      mem_(0x1000 + static_cast<std::size_t>(cfg_.ram_kib) * 1024, 0),
      sii_(cfg_.sii, cfg_.eeprom_busy_ns),
      dc_(cfg_.oscillator_drift, cfg_.power_on_time_ns, 0) {
  cfg_.fmmus = std::min<std::uint8_t>(cfg_.fmmus, kMaxFmmus);
  cfg_.sync_managers = std::min<std::uint8_t>(cfg_.sync_managers, kMaxSyncManagers);
  last_read_.assign(mem_.size(), 0);
  parked_.assign(mem_.size(), 0);
  init_registers();
}

void Esc::init_registers() {
  std::fill(mem_.begin(), mem_.end(), 0);
  mem_[reg::kType] = cfg_.type;
  mem_[reg::kRevision] = cfg_.revision;
  put_u16(&mem_[reg::kBuild], cfg_.build);
  mem_[reg::kFmmuCount] = cfg_.fmmus;
  mem_[reg::kSmCount] = cfg_.sync_managers;
  mem_[reg::kRamSize] = cfg_.ram_kib;
  mem_[reg::kPortDescriptor] = cfg_.port_descriptor;
  put_u16(&mem_[reg::kFeatures], cfg_.features);
  put_u16(&mem_[reg::kWatchdogDivider], reg::kDefaultWatchdogDivider);
  put_u16(&mem_[reg::kWatchdogTimePdi], reg::kDefaultWatchdogTime);
  put_u16(&mem_[reg::kWatchdogTimePd], reg::kDefaultWatchdogTime);
  put_u16(&mem_[reg::kWatchdogStatusPd], 0x0001);
  put_u16(&mem_[reg::kEepromControl], reg::kEepromRead8 | 0x0080);
  if (dc_supported()) {
    put_u16(&mem_[reg::kDcSpeedCounterStart], 0x1000);
    mem_[reg::kDcTimeDiffFilter] = 4;
    mem_[reg::kDcSpeedFilter] = 12;
  }
  for (auto& s : sms_) {
    s = SmUnit{};
  }
  for (auto& f : fmmus_) f = Fmmu{};
  state_ = AlState::init;
  error_ = false;
  code_ = AlStatusCode::none;
  wd_expired_ = false;
  latch_pending_ = false;
  last_read_len_ = 0;
  parked_sm_ = -1;
  reload_from_sii();
  update_al_registers();
  update_dl_status();
  put_u16(&mem_[reg::kEcatEventRequest], 0);
}

void Esc::reload_from_sii() {
  const std::uint16_t w0 = sii_.word(0);
  mem_[reg::kPdiControl] = static_cast<std::uint8_t>(w0 & 0xFF);
  mem_[reg::kEscConfig] = static_cast<std::uint8_t>(w0 >> 8);
  put_u16(&mem_[reg::kDcPulseLength], sii_.word(2) == 0xFFFF ? 0 : sii_.word(2));
  put_u16(&mem_[reg::kStationAlias], sii_.word(4) == 0xFFFF ? 0 : sii_.word(4));
}

void Esc::set_oscillator_drift(double drift, SimTime t) {
  cfg_.oscillator_drift = drift;
  dc_.set_drift(drift, t);
}

void Esc::power_cycle(SimTime t) {
  dc_.reset(t);
  init_registers();
  now_ = t;
  wd_last_ = t;
}

std::uint8_t Esc::read8(std::uint16_t r) const { return mem_at(r); }
std::uint16_t Esc::read16(std::uint16_t r) const {
  return static_cast<std::uint16_t>(mem_at(r) | (mem_at(r + 1u) << 8));
}
std::uint32_t Esc::read32(std::uint16_t r) const {
  return static_cast<std::uint32_t>(read16(r)) | (static_cast<std::uint32_t>(read16(static_cast<std::uint16_t>(r + 2))) << 16);
}
std::uint64_t Esc::read64(std::uint16_t r) const {
  return static_cast<std::uint64_t>(read32(r)) | (static_cast<std::uint64_t>(read32(static_cast<std::uint16_t>(r + 4))) << 32);
}

// ---- registers --------------------------------------------------------------------------------

bool Esc::writable(std::uint32_t a) const {
  if (a >= mem_.size()) return false;
  if (a < 0x0010) return false;                                   // ESC information
  if (a == 0x0012 || a == 0x0013) return false;                   // alias: from the SII
  if (a == 0x0110 || a == 0x0111) return false;                   // DL status
  if (a >= 0x0130 && a <= 0x0135) return false;                   // AL status, code
  if (a >= 0x0140 && a <= 0x0141) return false;                   // PDI control, ESC config
  if (a >= 0x0150 && a <= 0x0153) return false;                   // PDI configuration
  if (a >= 0x0210 && a <= 0x0211) return false;                   // ECAT event request
  if (a >= 0x0220 && a <= 0x0223) return false;                   // AL event request
  if (a >= 0x0440 && a <= 0x0443) return false;                   // watchdog status, counters
  if (a == 0x0501) return false;                                  // PDI EEPROM access state
  if (a >= reg::kSm0 && a < reg::kSmEnd) {
    const std::uint32_t off = (a - reg::kSm0) % reg::kSmSize;
    return off != reg::kSmStatus && off != reg::kSmPdiControl;
  }
  if (dc_supported()) {
    if (a >= 0x0900 && a <= 0x091F) return false;                 // receive times, system time (side effects)
    if (a >= 0x092C && a <= 0x092F) return false;                 // system time difference
    if (a >= 0x0932 && a <= 0x0933) return false;                 // speed counter diff
    if (a >= 0x0982 && a <= 0x098F) return false;                 // pulse length, status
    if (a >= 0x0998 && a <= 0x099F) return false;                 // next SYNC1
  }
  return true;
}

// SyncManagers act on the process memory only: the ESC datasheets describe them as guarding
// areas of the process data RAM (from 0x1000), never the registers below it (the exact datasheet
// wording was not at hand when this was written; the behaviour is a model choice). An SM whose
// area — for a 3-buffer SM all three buffers, start .. start + 3·length — is not entirely inside
// process RAM (0x1000 .. end of RAM) is not activated: its registers keep what was written, but
// it stays disabled (status and handshake inactive), ECAT accesses to its area go to the plain
// memory without redirection and the PDI cannot post into it.
bool Esc::sm_in_process_ram(const SyncManager& r) const {
  const std::size_t buffers = r.buffered() ? 3 : 1;
  return r.start >= kProcessRam && static_cast<std::size_t>(r.start) + buffers * r.length <= mem_.size();
}

void Esc::raise_event(std::uint16_t bits, bool on) {
  const std::uint16_t ev = read16(reg::kEcatEventRequest);
  put_u16(&mem_[reg::kEcatEventRequest], static_cast<std::uint16_t>(on ? (ev | bits) : (ev & ~bits)));
}

void Esc::update_al_registers() {
  const auto v = static_cast<std::uint16_t>(static_cast<std::uint16_t>(state_) | (error_ ? reg::kAlStatusError : 0));
  if (v != read16(reg::kAlStatus)) raise_event(reg::kEventAlStatus, true);
  put_u16(&mem_[reg::kAlStatus], v);
  put_u16(&mem_[reg::kAlStatusCode], static_cast<std::uint16_t>(code_));
}

void Esc::update_dl_status() {
  std::uint16_t v = 0x0001;  // PDI operational (EEPROM loaded)
  for (int p = 0; p < 4; ++p) {
    const bool implemented = ((cfg_.port_descriptor >> (2 * p)) & 3) != 0;
    if (!implemented) continue;
    if (links_[static_cast<std::size_t>(p)]) {
      v |= static_cast<std::uint16_t>(1u << (reg::kDlStatusLinkBit0 + p));
      v |= static_cast<std::uint16_t>(1u << (reg::kDlStatusLoopBit0 + 2 * p + 1));  // communication
    } else {
      v |= static_cast<std::uint16_t>(1u << (reg::kDlStatusLoopBit0 + 2 * p));      // loop closed
    }
  }
  if (v != read16(reg::kDlStatus)) raise_event(reg::kEventDlStatus, true);
  put_u16(&mem_[reg::kDlStatus], v);
}

void Esc::set_port_link(int port, bool up) {
  if (port < 0 || port > 3) return;
  if (links_[static_cast<std::size_t>(port)] && !up) {  // lost link counter 0x0310 + port
    std::uint8_t& c = mem_[reg::kLostLinkCounter + static_cast<std::size_t>(port)];
    if (c < 0xFF) ++c;
  }
  links_[static_cast<std::size_t>(port)] = up;
  update_dl_status();
}

void Esc::update_sm_registers(int i) {
  const std::size_t base = reg::kSm0 + static_cast<std::size_t>(i) * reg::kSmSize;
  mem_[base + reg::kSmStatus] = sms_[static_cast<std::size_t>(i)].status_byte();
  mem_[base + reg::kSmPdiControl] = sms_[static_cast<std::size_t>(i)].reg.pdi_control;
  const auto& u = sms_[static_cast<std::size_t>(i)];
  sms_[static_cast<std::size_t>(i)].reg.status = mem_[base + reg::kSmStatus];
  if (i < 8 && u.reg.mailbox() && !u.reg.ecat_writes()) {
    raise_event(static_cast<std::uint16_t>(reg::kEventSm0 << i), u.reg.enabled && u.full());
  }
}

// ESC datasheet Section II (SyncManager registers): start address, length and control are
// writable only while the SM is disabled (+0x6 bit 0 = 0). A write reaching an enabled SM keeps
// them; only its activate byte takes effect, so one write that disables and moves the SM
// disables it in place.
void Esc::restore_sm_area(int i) {
  const std::size_t base = reg::kSm0 + static_cast<std::size_t>(i) * reg::kSmSize;
  const SyncManager& r = sms_[static_cast<std::size_t>(i)].reg;
  put_u16(&mem_[base], r.start);
  put_u16(&mem_[base + 2], r.length);
  mem_[base + 4] = r.control;
}

void Esc::refresh_for_read(std::uint32_t a, std::uint32_t n, SimTime t) {
  if (overlaps(a, n, reg::kEepromControl, 2)) {
    put_u16(&mem_[reg::kEepromControl], sii_.control(&mem_[reg::kEepromConfig], t));
  }
  if (dc_supported() && overlaps(a, n, reg::kDcSystemTime, 8)) {
    put_u64(&mem_[reg::kDcSystemTime], static_cast<std::uint64_t>(dc_.system(t)));
  }
}

void Esc::after_write(std::uint32_t a, std::uint32_t n, const std::uint8_t* st_in, SimTime t) {
  if (overlaps(a, n, reg::kAlControl, 2)) al_control_written(t);
  if (overlaps(a, n, reg::kEepromControl, 2)) {
    const auto r = sii_.on_control_write(&mem_[reg::kEepromConfig], t);
    if (r == SiiEeprom::Result::reloaded) reload_from_sii();
  }
  if (overlaps(a, n, reg::kFmmu0, reg::kFmmuEnd - reg::kFmmu0)) {
    for (int i = 0; i < cfg_.fmmus; ++i) {
      const std::uint32_t base = reg::kFmmu0 + static_cast<std::uint32_t>(i) * reg::kFmmuSize;
      if (overlaps(a, n, base, reg::kFmmuSize)) fmmus_[static_cast<std::size_t>(i)] = decode_fmmu(&mem_[base]);
    }
  }
  if (overlaps(a, n, reg::kSm0, reg::kSmEnd - reg::kSm0)) {
    for (int i = 0; i < cfg_.sync_managers; ++i) {
      const std::uint32_t base = reg::kSm0 + static_cast<std::uint32_t>(i) * reg::kSmSize;
      if (!overlaps(a, n, base, reg::kSmSize)) continue;
      auto& u = sms_[static_cast<std::size_t>(i)];
      const bool repeat_before = (u.reg.activate & 0x02) != 0;
      if (u.reg.enabled) restore_sm_area(i);  // start, length, control: writable while disabled only
      u.configure(&mem_[base]);
      if (u.reg.enabled && !sm_in_process_ram(u.reg)) u.reg.enabled = false;  // not activated
      const bool repeat_now = (u.reg.activate & 0x02) != 0;
      if (i == parked_sm_ && !u.full()) parked_sm_ = -1;  // reconfigured: its content is gone
      if (repeat_before != repeat_now && u.reg.enabled && u.reg.mailbox() && !u.reg.ecat_writes()) {
        repeat_mailbox(i);  // then acknowledge
        u.reg.pdi_control = static_cast<std::uint8_t>((u.reg.pdi_control & ~0x02) | (repeat_now ? 0x02 : 0));
      }
      update_sm_registers(i);
    }
  }
  if (!dc_supported()) return;
  if (overlaps(a, n, reg::kDcReceiveTimePort0, 4)) {
    const auto lt = static_cast<std::uint64_t>(dc_.local(t));
    put_u32(&mem_[reg::kDcReceiveTimePort0], static_cast<std::uint32_t>(lt));
    put_u64(&mem_[reg::kDcReceiveTimeEpu], lt);
    latch_pending_ = true;
  }
  if (overlaps(a, n, reg::kDcSystemTime, 8) && st_in != nullptr) {
    const bool wide = a <= reg::kDcSystemTime && a + n >= reg::kDcSystemTime + 8u;
    dc_.sample(wide ? get_u64(st_in) : get_u32(st_in), wide, t);
    put_u32(&mem_[reg::kDcSystemTimeDiff], dc_.difference_register());
  }
  if (overlaps(a, n, reg::kDcSystemTimeOffset, 8)) dc_.set_offset(get_u64(&mem_[reg::kDcSystemTimeOffset]));
  if (overlaps(a, n, reg::kDcSystemTimeDelay, 4)) dc_.set_delay(get_u32(&mem_[reg::kDcSystemTimeDelay]));
  if (overlaps(a, n, reg::kDcSpeedCounterStart, 2)) {
    dc_.reset_loop(t);
    put_u32(&mem_[reg::kDcSystemTimeDiff], 0);
  }
  if (overlaps(a, n, reg::kDcActivation, 1) || overlaps(a, n, reg::kDcSync0Cycle, 4) ||
      overlaps(a, n, reg::kDcSync1Cycle, 4)) {
    // Start time 0x0990 is taken when the activation (or a cycle) is written.
    dc_.configure_sync(mem_[reg::kDcActivation], get_u64(&mem_[reg::kDcStartTime]),
                       get_u32(&mem_[reg::kDcSync0Cycle]), t);
    dc_.configure_sync1((mem_[reg::kDcActivation] & 0x04) != 0, get_u32(&mem_[reg::kDcSync1Cycle]));
    mem_[reg::kDcActivationStatus] =
        static_cast<std::uint8_t>((dc_.sync0_active() ? 0x01 : 0x00) | (dc_.sync1_active() ? 0x02 : 0x00));
    if (dc_.sync0_active()) put_u64(&mem_[reg::kDcStartTime], dc_.next_sync0());
  }
}

// ---- AL state machine -------------------------------------------------------------------------

void Esc::al_control_written(SimTime t) {
  const AlDecision d = al_decide(state_, error_, read16(reg::kAlControl));
  if (d.clear_error) {
    const bool was = error_;
    error_ = false;
    code_ = AlStatusCode::none;
    if (was && app_ != nullptr) app_->on_al_error_cleared(state_, t);
  }
  switch (d.transition) {
    case AlTransition::ignored:
    case AlTransition::stay:
      break;
    case AlTransition::legal: {
      const AlStatusCode c = app_ != nullptr ? app_->on_al_request(state_, d.target, t) : AlStatusCode::none;
      if (c == AlStatusCode::none) {
        enter_state(d.target, t);
      } else {
        error_ = true;
        code_ = c;
      }
      break;
    }
    case AlTransition::invalid:
      error_ = true;
      code_ = AlStatusCode::invalid_state_change;
      break;
    case AlTransition::unknown_state:
      error_ = true;
      code_ = AlStatusCode::unknown_state;
      break;
  }
  update_al_registers();
}

void Esc::enter_state(AlState s, SimTime t) {
  state_ = s;
  if (s == AlState::op) {
    wd_last_ = t;
    wd_expired_ = false;
    put_u16(&mem_[reg::kWatchdogStatusPd], 0x0001);
  }
  update_al_registers();
}

void Esc::set_al_error(AlState fall_to, AlStatusCode code, SimTime t) {
  const AlState from = state_;
  if (al_rank(fall_to) < al_rank(state_)) state_ = fall_to;
  error_ = true;
  code_ = code;
  update_al_registers();
  if (state_ != from && app_ != nullptr) app_->on_al_fallback(from, state_, code, t);
}

void Esc::set_sm_deactivated(int i, bool off) {
  if (i < 0 || i >= cfg_.sync_managers) return;
  auto& u = sms_[static_cast<std::size_t>(i)];
  if (u.reg.pdi_deactivated() == off) return;
  u.reg.pdi_control = static_cast<std::uint8_t>(off ? (u.reg.pdi_control | 0x01) : (u.reg.pdi_control & ~0x01));
  u.reset();  // buffers start afresh either way
  if (i == parked_sm_) parked_sm_ = -1;
  if (u.reg.mailbox() && !u.reg.ecat_writes()) last_read_len_ = 0;  // nothing left to repeat
  update_sm_registers(i);
}

// ---- time -------------------------------------------------------------------------------------

void Esc::watchdog_check(SimTime t) {
  if (state_ != AlState::op || wd_expired_) return;
  const std::uint16_t wd_time = read16(reg::kWatchdogTimePd);
  if (wd_time == 0) return;
  int trigger_sm = -1;
  for (int i = 0; i < cfg_.sync_managers; ++i) {
    const auto& r = sms_[static_cast<std::size_t>(i)].reg;
    if (r.active() && r.buffered() && r.ecat_writes() && r.watchdog_trigger()) {
      trigger_sm = i;
      break;
    }
  }
  if (trigger_sm < 0) return;
  const std::int64_t limit = static_cast<std::int64_t>(wd_time) * (read16(reg::kWatchdogDivider) + 2) * 40;
  if (t - wd_last_ <= limit) return;
  wd_expired_ = true;
  put_u16(&mem_[reg::kWatchdogStatusPd], 0x0000);
  mem_[reg::kWatchdogCounterPd] = static_cast<std::uint8_t>(mem_[reg::kWatchdogCounterPd] + 1);
  // Outputs to their safe state (zero): every buffer of the SM.
  const auto& r = sms_[static_cast<std::size_t>(trigger_sm)].reg;
  const std::size_t end = std::min<std::size_t>(mem_.size(), static_cast<std::size_t>(r.start) + 3u * r.length);
  if (r.start < end) std::fill(mem_.begin() + r.start, mem_.begin() + static_cast<std::ptrdiff_t>(end), 0);
  set_al_error(AlState::safeop, AlStatusCode::watchdog, t);
}

void Esc::advance(SimTime t) noexcept {
  if (t < now_) t = now_;
  watchdog_check(t);
  if (dc_supported()) {
    // At most kMaxSync0PerAdvance pulses reach the firmware per call; pulses missed beyond
    // that (a long jump of t) are dropped, as a firmware busy that long would miss interrupts.
    SimTime when = 0;
    int delivered = 0;
    while (dc_.pop_sync0(t, when)) {
      mem_[reg::kDcSync0Status] = 0x01;
      put_u64(&mem_[reg::kDcStartTime], dc_.next_sync0());
      if (app_ != nullptr) app_->on_sync0(when);
      put_u64(&mem_[reg::kDcNextSync1], dc_.next_sync1());
      deliver_sync1(t);
      if (++delivered == kMaxSync0PerAdvance) {
        const std::uint64_t before = dc_.next_sync0();
        dc_.skip_sync0_to(t);
        if (dc_.sync0_cycle() != 0 && dc_.next_sync0() != before) {
          stats_.sync0_dropped += (dc_.next_sync0() - before) / dc_.sync0_cycle();
        }
        put_u64(&mem_[reg::kDcStartTime], dc_.next_sync0());
        break;
      }
    }
    deliver_sync1(t);  // a SYNC1 pulse shifted after the last SYNC0 pulse
  }
  now_ = t;
}

// The SYNC1 pulse armed by the last SYNC0 pulse, if it is due by t.
void Esc::deliver_sync1(SimTime t) noexcept {
  SimTime when = 0;
  if (!dc_.pop_sync1(t, when)) return;
  mem_[reg::kDcSync1Status] = 0x01;
  if (app_ != nullptr) app_->on_sync1(when);
}

SimTime Esc::next_event_time() const noexcept {
  SimTime next = kNoEscEvent;
  if (dc_supported() && dc_.sync0_active()) {
    next = std::max(now_, dc_.sim_time_of_system(static_cast<std::int64_t>(dc_.next_sync0())));
  }
  if (dc_supported() && dc_.next_sync1() != 0) {
    next = std::min(next, std::max(now_, dc_.sim_time_of_system(static_cast<std::int64_t>(dc_.next_sync1()))));
  }
  if (state_ == AlState::op && !wd_expired_) {
    const std::uint16_t wd_time = read16(reg::kWatchdogTimePd);
    bool armed = false;
    for (int i = 0; i < cfg_.sync_managers; ++i) {
      const auto& r = sms_[static_cast<std::size_t>(i)].reg;
      if (r.active() && r.buffered() && r.ecat_writes() && r.watchdog_trigger()) armed = true;
    }
    if (armed && wd_time != 0) {
      const std::int64_t limit = static_cast<std::int64_t>(wd_time) * (read16(reg::kWatchdogDivider) + 2) * 40;
      next = std::min(next, wd_last_ + limit + 1);
    }
  }
  return next;
}

void Esc::latch_port(int port, SimTime t) noexcept {
  if (!latch_pending_ || port < 0 || port > 3) return;
  put_u32(&mem_[reg::kDcReceiveTimePort0 + 4u * static_cast<std::uint32_t>(port)],
          static_cast<std::uint32_t>(dc_.local(t)));
}

// ---- datagrams --------------------------------------------------------------------------------

void Esc::sm_event(int i, SmEvent e, SimTime t) {
  auto& u = sms_[static_cast<std::size_t>(i)];
  switch (e) {
    case SmEvent::none:
    case SmEvent::buffer_read:
      break;
    case SmEvent::mailbox_read:
      mailbox_read(i);
      break;
    case SmEvent::mailbox_written:
      if (app_ != nullptr && static_cast<std::size_t>(u.reg.start) + u.reg.length <= mem_.size()) {
        app_->on_mailbox(std::span<const std::uint8_t>(&mem_[u.reg.start], u.reg.length), t);
      }
      u.set_full(false);  // the firmware has read it
      break;
    case SmEvent::buffer_written:
      if (u.reg.watchdog_trigger()) {
        wd_last_ = t;
        if (!wd_expired_) put_u16(&mem_[reg::kWatchdogStatusPd], 0x0001);
      }
      if (app_ != nullptr) {
        const auto o = outputs(i);
        if (!o.empty()) app_->on_outputs(o, t);
      }
      break;
  }
  update_sm_registers(i);
}

Esc::Access Esc::physical(std::uint16_t ado, std::uint8_t* data, std::uint16_t n, bool rd, bool wr,
                          bool or_read, SimTime t) {
  Access acc{rd, wr};
  const std::uint32_t a = ado;
  const bool pd_active = al_rank(state_) >= al_rank(AlState::safeop);
  std::array<int, kMaxSyncManagers> hit{};
  int hits = 0;
  for (int i = 0; i < cfg_.sync_managers; ++i) {
    const auto& u = sms_[static_cast<std::size_t>(i)];
    if (!u.reg.enabled || !u.reg.overlaps(a, n)) continue;
    hit[static_cast<std::size_t>(hits++)] = i;
    if (acc.read && !u.ecat_allowed(false, pd_active)) acc.read = false;
    if (acc.write && !u.ecat_allowed(true, pd_active)) acc.write = false;
  }
  if ((rd && !acc.read) || (wr && !acc.write)) ++stats_.refused;
  if (!acc.read && !acc.write) return acc;

  // System-time writes carry the reference time: keep the incoming bytes.
  std::array<std::uint8_t, 8> st{};
  bool st_valid = false;
  if (acc.write && overlaps(a, n, reg::kDcSystemTime, 8)) {
    for (std::uint32_t k = 0; k < 8; ++k) {
      const std::uint32_t x = reg::kDcSystemTime + k;
      if (x >= a && x < a + n) st[k] = data[x - a];
    }
    st_valid = true;
  }
  if (acc.read) refresh_for_read(a, n, t);
  for (int h = 0; h < hits; ++h) {
    auto& u = sms_[static_cast<std::size_t>(hit[static_cast<std::size_t>(h)])];
    const bool dir_write = u.reg.ecat_writes();
    if (dir_write ? acc.write : acc.read) u.ecat_begin(a, n, dir_write);
  }
  for (std::uint32_t k = 0; k < n; ++k) {
    const std::uint32_t x = a + k;
    if (x > 0xFFFF) break;
    std::uint32_t p = x;
    for (int h = 0; h < hits; ++h) {
      const auto& u = sms_[static_cast<std::size_t>(hit[static_cast<std::size_t>(h)])];
      if (u.reg.overlaps(x, 1)) p = u.redirect(x, u.reg.ecat_writes());
    }
    const std::uint8_t in = data[k];
    if (acc.read) data[k] = or_read ? static_cast<std::uint8_t>(in | mem_at(p)) : mem_at(p);
    // Both the datagram's address and the (redirected) buffer address must be writable.
    if (acc.write && writable(x) && writable(p)) mem_[p] = in;
  }
  for (int h = 0; h < hits; ++h) {
    const int i = hit[static_cast<std::size_t>(h)];
    auto& u = sms_[static_cast<std::size_t>(i)];
    const bool dir_write = u.reg.ecat_writes();
    if (dir_write ? acc.write : acc.read) sm_event(i, u.ecat_end(a, n, dir_write), t);
  }
  if (acc.read) {  // reading a status register acknowledges its event
    if (overlaps(a, n, reg::kDlStatus, 2)) raise_event(reg::kEventDlStatus, false);
    if (overlaps(a, n, reg::kAlStatus, 2)) raise_event(reg::kEventAlStatus, false);
  }
  if (acc.write) after_write(a, n, st_valid ? st.data() : nullptr, t);
  return acc;
}

void Esc::logical(Datagram& d, SimTime t, bool& did_read, bool& did_write) {
  const Cmd c = d.cmd();
  const bool rd = c != Cmd::lwr;
  const bool wr = c != Cmd::lrd;
  const bool pd_active = al_rank(state_) >= al_rank(AlState::safeop);
  std::uint8_t* data = d.data();
  // Outputs first (from the incoming frame), then inputs into the frame.
  for (int pass = 0; pass < 2; ++pass) {
    const bool writing = pass == 0;
    if (writing ? !wr : !rd) continue;
    for (int f = 0; f < cfg_.fmmus; ++f) {
      const Fmmu& fm = fmmus_[static_cast<std::size_t>(f)];
      if (writing ? !fm.writes() : !fm.reads()) continue;
      const FmmuSpan s = fmmu_overlap(fm, d.logical(), d.length());
      if (s.bits == 0) continue;
      const std::uint32_t pa = s.first_byte();
      const std::uint32_t pn = s.last_byte() - pa + 1;
      bool ok = true;
      std::array<int, kMaxSyncManagers> hit{};
      int hits = 0;
      for (int i = 0; i < cfg_.sync_managers; ++i) {
        const auto& u = sms_[static_cast<std::size_t>(i)];
        if (!u.reg.enabled || !u.reg.overlaps(pa, pn)) continue;
        hit[static_cast<std::size_t>(hits++)] = i;
        if (!u.ecat_allowed(writing, pd_active)) ok = false;
      }
      if (!ok) {
        ++stats_.refused;
        continue;
      }
      for (int h = 0; h < hits; ++h) sms_[static_cast<std::size_t>(hit[static_cast<std::size_t>(h)])].ecat_begin(pa, pn, writing);
      // The physical byte behind address x: a 3-buffer SM redirects to its current buffer.
      const auto target = [&](std::uint32_t x) {
        std::uint32_t p = x;
        for (int h = 0; h < hits; ++h) {
          const auto& u = sms_[static_cast<std::size_t>(hit[static_cast<std::size_t>(h)])];
          if (u.reg.overlaps(x, 1)) p = u.redirect(x, writing);
        }
        return p;
      };
      // Byte-aligned spans (every FMMU a master lays out for byte-sized PDOs) move byte by
      // byte with the same checks; bit-granular ones bit by bit.
      const bool bytes = (s.physical_bit & 7) == 0 && (s.frame_bit & 7) == 0 && (s.bits & 7) == 0;
      // The common case in one block: a byte span in process RAM (every byte writable) inside
      // at most one SyncManager, whose buffer moves the whole span by the same amount.
      const auto& h0 = sms_[static_cast<std::size_t>(hit[0])].reg;
      const bool block = bytes && pa >= kProcessRam &&
                         (hits == 0 || (hits == 1 && pa >= h0.start && pa + pn <= static_cast<std::uint32_t>(h0.start) + h0.length));
      const std::uint32_t p0 = block ? target(pa) : 0;
      const bool fast = block && p0 + pn <= mem_.size();
      if (fast) {
        std::uint8_t* fb = data + (s.frame_bit >> 3);
        if (writing) {
          std::memcpy(mem_.data() + p0, fb, pn);
        } else {
          std::memcpy(fb, mem_.data() + p0, pn);
        }
      }
      for (std::uint32_t k = 0; bytes && !fast && k < s.bits / 8; ++k) {
        const std::uint32_t x = (s.physical_bit >> 3) + k;
        const std::uint32_t p = target(x);
        if (p >= mem_.size()) continue;
        std::uint8_t* fb = data + (s.frame_bit >> 3) + k;
        if (writing) {
          if (writable(x) && writable(p)) mem_[p] = *fb;
        } else {
          *fb = mem_[p];
        }
      }
      for (std::uint32_t b = 0; !bytes && b < s.bits; ++b) {
        const std::uint32_t pbit = s.physical_bit + b;
        const std::uint32_t x = pbit >> 3;
        const std::uint32_t p = target(x);
        if (p >= mem_.size()) continue;
        const std::uint32_t pb = (p << 3) | (pbit & 7);
        if (writing) {
          if (writable(x) && writable(p)) set_bit(mem_.data(), pb, get_bit(data, s.frame_bit + b));
        } else {
          set_bit(data, s.frame_bit + b, get_bit(mem_.data(), pb));
        }
      }
      for (int h = 0; h < hits; ++h) {
        const int i = hit[static_cast<std::size_t>(h)];
        sm_event(i, sms_[static_cast<std::size_t>(i)].ecat_end(pa, pn, writing), t);
      }
      if (writing) {
        did_write = true;
      } else {
        did_read = true;
      }
    }
  }
}

void Esc::process(Datagram& d, SimTime t) noexcept {
  advance(t);
  ++stats_.datagrams;
  handle(d, t);
  const auto irq = static_cast<std::uint16_t>(read16(reg::kEcatEventRequest) & read16(reg::kEcatEventMask));
  if (irq != 0) d.set_irq(static_cast<std::uint16_t>(d.irq() | irq));
}

void Esc::handle(Datagram& d, SimTime t) {
  if (d.raw_cmd() > static_cast<std::uint8_t>(Cmd::frmw)) {
    ++stats_.malformed;
    return;
  }
  const Cmd c = d.cmd();
  std::uint16_t inc = 0;
  switch (addressing(c)) {
    case CmdAddressing::none:
      return;
    case CmdAddressing::position:
    case CmdAddressing::node: {
      bool me = false;
      if (addressing(c) == CmdAddressing::position) {
        me = d.adp() == 0;
        d.set_adp(static_cast<std::uint16_t>(d.adp() + 1));
      } else {
        const bool alias_on = (mem_[reg::kDlControlAlias] & 0x01) != 0;
        me = d.adp() == station_address() || (alias_on && d.adp() == alias());
      }
      const bool rmw = c == Cmd::armw || c == Cmd::frmw;
      if (!me && !rmw) return;
      ++stats_.addressed;
      bool rd = cmd_reads(c), wr = cmd_writes(c);
      if (rmw) {
        rd = me;
        wr = !me;
      }
      const Access a = physical(d.ado(), d.data(), d.length(), rd, wr, false, t);
      if (a.read) inc = static_cast<std::uint16_t>(inc + 1);
      if (a.write) inc = static_cast<std::uint16_t>(inc + (rd && wr ? 2 : 1));
      break;
    }
    case CmdAddressing::broadcast: {
      d.set_adp(static_cast<std::uint16_t>(d.adp() + 1));
      ++stats_.addressed;
      const bool rd = cmd_reads(c), wr = cmd_writes(c);
      const Access a = physical(d.ado(), d.data(), d.length(), rd, wr, true, t);
      if (a.read) inc = static_cast<std::uint16_t>(inc + 1);
      if (a.write) inc = static_cast<std::uint16_t>(inc + (rd && wr ? 2 : 1));
      break;
    }
    case CmdAddressing::logical: {
      bool did_read = false, did_write = false;
      logical(d, t, did_read, did_write);
      if (did_read || did_write) ++stats_.addressed;
      if (did_read) inc = static_cast<std::uint16_t>(inc + 1);
      if (did_write) inc = static_cast<std::uint16_t>(inc + (c == Cmd::lrw ? 2 : 1));
      break;
    }
  }
  if (inc != 0) d.set_wkc(static_cast<std::uint16_t>(d.wkc() + inc));
}

// ---- PDI side ---------------------------------------------------------------------------------

int Esc::find_sm(bool mailbox, bool ecat_writes) const {
  for (int i = 0; i < cfg_.sync_managers; ++i) {
    const auto& r = sms_[static_cast<std::size_t>(i)].reg;
    if (r.enabled && r.length > 0 && r.mailbox() == mailbox && (mailbox || r.buffered()) && r.ecat_writes() == ecat_writes) return i;
  }
  return -1;
}

bool Esc::post_mailbox(std::span<const std::uint8_t> reply) {
  const int i = find_sm(true, false);
  if (i < 0) return false;
  auto& u = sms_[static_cast<std::size_t>(i)];
  if (u.full() || reply.size() > u.reg.length || !sm_in_process_ram(u.reg)) {
    return false;
  }
  fill_mailbox(i, reply);
  update_sm_registers(i);
  return true;
}

void Esc::fill_mailbox(int i, std::span<const std::uint8_t> data) {
  auto& u = sms_[static_cast<std::size_t>(i)];
  std::memset(&mem_[u.reg.start], 0, u.reg.length);
  std::memcpy(&mem_[u.reg.start], data.data(), std::min<std::size_t>(data.size(), u.reg.length));
  u.set_full(true);
}

// The master read the whole reply in read mailbox SM i: it is what a repeat request brings back.
// A reply a repeat set aside follows now (ESC Technology Section I §8.6).
void Esc::mailbox_read(int i) {
  const auto& r = sms_[static_cast<std::size_t>(i)].reg;
  if (!sm_in_process_ram(r)) return;
  std::memcpy(last_read_.data(), &mem_[r.start], r.length);
  last_read_len_ = r.length;
  if (parked_sm_ != i) return;
  parked_sm_ = -1;
  fill_mailbox(i, std::span<const std::uint8_t>(parked_.data(), parked_len_));
}

// Repeat request on read mailbox SM i: the reply the master last read goes back in. A newer one
// already waiting there is set aside until the repeated one has been read, so none is lost.
void Esc::repeat_mailbox(int i) {
  const auto& u = sms_[static_cast<std::size_t>(i)];
  if (last_read_len_ == 0 || !sm_in_process_ram(u.reg)) return;
  if (u.full() && parked_sm_ < 0) {
    std::memcpy(parked_.data(), &mem_[u.reg.start], u.reg.length);
    parked_len_ = u.reg.length;
    parked_sm_ = i;
  }
  fill_mailbox(i, std::span<const std::uint8_t>(last_read_.data(), last_read_len_));
}

std::span<const std::uint8_t> Esc::outputs(int i) const {
  if (i < 0 || i >= cfg_.sync_managers) return {};
  const auto& u = sms_[static_cast<std::size_t>(i)];
  if (!u.reg.buffered() || !u.reg.ecat_writes() || u.latest() < 0) return {};
  const std::size_t off = u.reg.start + static_cast<std::size_t>(u.latest()) * u.reg.length;
  if (off + u.reg.length > mem_.size()) return {};
  return {&mem_[off], u.reg.length};
}

std::span<const std::uint8_t> Esc::outputs() const {
  const int i = find_sm(false, true);
  return i < 0 ? std::span<const std::uint8_t>{} : outputs(i);
}

bool Esc::write_inputs(int i, std::span<const std::uint8_t> in) {
  if (i < 0 || i >= cfg_.sync_managers) return false;
  auto& u = sms_[static_cast<std::size_t>(i)];
  if (!u.reg.enabled || !u.reg.buffered() || u.reg.ecat_writes() || !sm_in_process_ram(u.reg)) return false;
  const int b = u.pdi_write_buffer();
  const std::size_t off = u.reg.start + static_cast<std::size_t>(b) * u.reg.length;
  if (off + u.reg.length > mem_.size()) return false;
  const std::size_t n = std::min<std::size_t>(in.size(), u.reg.length);
  std::memset(&mem_[off], 0, u.reg.length);
  std::memcpy(&mem_[off], in.data(), n);
  u.pdi_commit(b);
  update_sm_registers(i);
  return true;
}

void Esc::write_inputs(std::span<const std::uint8_t> in) {
  const int i = find_sm(false, false);
  if (i >= 0) write_inputs(i, in);
}

}  // namespace omnitwin::ethercat
