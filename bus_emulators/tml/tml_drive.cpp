// bus_emulators/tml — one emulated Technosoft IDM drive (see tml_drive.hpp).
#include "bus_emulators/tml/tml_drive.hpp"

#include <algorithm>
#include <cmath>
#include <stdexcept>

namespace omnitwin::tml {

namespace {

constexpr double kFixed = 65536.0;  // 16.16 fixed point
constexpr std::int64_t kNsPerMs = 1'000'000;

std::uint16_t lo(std::uint32_t v) { return static_cast<std::uint16_t>(v & 0xFFFF); }
std::uint16_t hi(std::uint32_t v) { return static_cast<std::uint16_t>(v >> 16); }
std::int32_t set_lo(std::int32_t v, std::uint16_t w) {
  return static_cast<std::int32_t>((static_cast<std::uint32_t>(v) & 0xFFFF0000u) | w);
}
std::int32_t set_hi(std::int32_t v, std::uint16_t w) {
  return static_cast<std::int32_t>((static_cast<std::uint32_t>(v) & 0xFFFFu) | static_cast<std::uint32_t>(w) << 16);
}
std::int32_t clamp32(double v) {
  return static_cast<std::int32_t>(std::clamp(std::llround(v), -2147483648LL, 2147483647LL));
}
std::uint16_t sat16(std::int32_t v) { return static_cast<std::uint16_t>(static_cast<std::int16_t>(std::clamp(v, -32768, 32767))); }

bool faulted(drive::State s) { return s == drive::State::fault || s == drive::State::fault_reaction_active; }
bool axis_on(drive::State s) { return s == drive::State::operation_enabled || s == drive::State::quick_stop_active; }
bool on_can(Protocol p) { return p == Protocol::tmlcan || p == Protocol::techcan; }

enum class InstrResult : std::uint8_t { done, unknown, refused };

}  // namespace

const char* to_string(Protocol p) {
  switch (p) {
    case Protocol::rs232: return "RS-232";
    case Protocol::rs485: return "RS-485";
    case Protocol::tmlcan: return "TMLCAN";
    case Protocol::techcan: return "TechCAN";
  }
  return "?";
}

Message instruction(std::uint16_t dest, std::uint16_t opcode) {
  Message m;
  m.id_code = dest, m.opcode = opcode;
  return m;
}

Message instruction(std::uint16_t dest, std::uint16_t opcode, std::uint16_t data) {
  Message m = instruction(dest, opcode);
  m.data[m.count++] = data;
  return m;
}

Message bitset_instruction(std::uint16_t dest, std::uint32_t mask) {
  Message m = instruction(dest, instr::bitset, static_cast<std::uint16_t>(mask));
  m.data[m.count++] = static_cast<std::uint16_t>(mask >> 16);
  return m;
}

// ---- Set-up and power --------------------------------------------------------------------------

TmlDrive::TmlDrive(const DriveSetup& setup, Send send) : setup_(setup), send_(std::move(send)), core_(setup.drive) {
  if (setup.axis == 0) throw std::invalid_argument("tml::TmlDrive: axis ID 0 is the broadcast axis (1-255)");
  if (setup.protocol == Protocol::techcan && setup.axis > 31)
    throw std::invalid_argument("tml::TmlDrive: TechCAN axis IDs are 1-31");
  if (!(setup.sample_period_s > 0)) throw std::invalid_argument("tml::TmlDrive: sample period must be > 0");
}

void TmlDrive::power_on(SimTime t) {
  powered_ = true;
  core_.power_cycle();
  core_.objects().halt_option = 1;  // STOP decelerates at the profile deceleration (= CACC)
  core_.objects().mode = static_cast<std::int8_t>(drive::Mode::pp);
  axis_ = setup_.axis, groups_ = setup_.groups;
  kpp_ = 0x0120;  // the value the seed's example drive answers (ch. 3 example 2)
  masterid_ = master_id(setup_.host_axis);
  srl_mask_ = srh_mask_ = mer_mask_ = 0;
  cpos_ = cspd_ = 0;
  cacc_ = static_cast<std::int32_t>(kFixed);  // 1 IU: 1 count/sample² (our power-on default)
  motion_ = Motion::position;
  relative_ = want_on_ = halt_ = fault_reset_ = update_pending_ = set_point_high_ = false;
  motion_complete_ = true;
  t0_ = now_ = t;
  time_offset_ms_ = 0, sync_latch_ms_ = 0, sync_period_ms_ = 0, next_sync_t_ = 0;
  update_status();
}

// ---- Units -------------------------------------------------------------------------------------

double TmlDrive::speed_iu_to_counts_s(std::int32_t iu) const { return iu / kFixed / setup_.sample_period_s; }

double TmlDrive::acc_iu_to_counts_s2(std::int32_t iu) const {
  return iu / kFixed / (setup_.sample_period_s * setup_.sample_period_s);
}

std::int32_t TmlDrive::counts_s_to_speed_iu(double counts_s) const {
  return clamp32(counts_s * setup_.sample_period_s * kFixed);
}

std::uint32_t TmlDrive::drive_time_ms(SimTime t) const {
  return static_cast<std::uint32_t>((t - t0_) / kNsPerMs + time_offset_ms_);
}

// ---- Registers ---------------------------------------------------------------------------------

bool TmlDrive::read_word(std::uint16_t a, std::uint16_t& w) const {
  const drive::Objects& o = core_.objects();
  const auto pos = static_cast<std::uint32_t>(o.position_actual);
  const auto spd = static_cast<std::uint32_t>(counts_s_to_speed_iu(o.velocity_actual));
  const auto dem = static_cast<std::uint32_t>(o.position_demand);
  const std::uint32_t now_ms = drive_time_ms(now_);
  const double sample_ms = setup_.sample_period_s * 1000.0;
  switch (a) {
    case reg::kpp: w = kpp_; return true;
    case reg::poserr: w = sat16(o.following_error_actual); return true;
    case reg::srl: w = srl_; return true;
    case reg::srh: w = srh_; return true;
    case reg::mer: w = mer_; return true;
    case reg::apos: w = lo(pos); return true;
    case reg::apos + 1: w = hi(pos); return true;
    case reg::aspd: w = lo(spd); return true;
    case reg::aspd + 1: w = hi(spd); return true;
    case reg::cpos: w = lo(static_cast<std::uint32_t>(cpos_)); return true;
    case reg::cpos + 1: w = hi(static_cast<std::uint32_t>(cpos_)); return true;
    case reg::cspd: w = lo(static_cast<std::uint32_t>(cspd_)); return true;
    case reg::cspd + 1: w = hi(static_cast<std::uint32_t>(cspd_)); return true;
    case reg::cacc: w = lo(static_cast<std::uint32_t>(cacc_)); return true;
    case reg::cacc + 1: w = hi(static_cast<std::uint32_t>(cacc_)); return true;
    case reg::tpos: w = lo(dem); return true;
    case reg::tpos + 1: w = hi(dem); return true;
    case reg::errmax: w = static_cast<std::uint16_t>(std::min<std::uint32_t>(o.following_error_window, 0xFFFF)); return true;
    case reg::terrmax: w = static_cast<std::uint16_t>(std::lround(o.following_error_timeout / sample_ms)); return true;
    case reg::masterid: w = masterid_; return true;
    case reg::srl_mask: w = srl_mask_; return true;
    case reg::srh_mask: w = srh_mask_; return true;
    case reg::mer_mask: w = mer_mask_; return true;
    case reg::aar: w = static_cast<std::uint16_t>(groups_ << 8 | axis_); return true;
    case reg::time: w = lo(now_ms); return true;
    case reg::time + 1: w = hi(now_ms); return true;
    case reg::sync_time: w = lo(sync_latch_ms_); return true;
    case reg::sync_time + 1: w = hi(sync_latch_ms_); return true;
    case reg::sync_period: w = sync_period_ms_; return true;
    default: return false;
  }
}

bool TmlDrive::write_word(std::uint16_t a, std::uint16_t w) {
  drive::Objects& o = core_.objects();
  const double sample_ms = setup_.sample_period_s * 1000.0;
  switch (a) {
    case reg::kpp: kpp_ = w; return true;
    case reg::cpos: cpos_ = set_lo(cpos_, w); return true;
    case reg::cpos + 1: cpos_ = set_hi(cpos_, w); return true;
    case reg::cspd: cspd_ = set_lo(cspd_, w); return true;
    case reg::cspd + 1: cspd_ = set_hi(cspd_, w); return true;
    case reg::cacc: cacc_ = set_lo(cacc_, w); return true;
    case reg::cacc + 1: cacc_ = set_hi(cacc_, w); return true;
    case reg::errmax: o.following_error_window = w; return true;
    case reg::terrmax:
      o.following_error_timeout = static_cast<std::uint16_t>(std::clamp(std::lround(w * sample_ms), 0L, 65535L));
      return true;
    case reg::masterid: masterid_ = w; return true;
    case reg::srl_mask: srl_mask_ = w; return true;
    case reg::srh_mask: srh_mask_ = w; return true;
    case reg::mer_mask: mer_mask_ = w; return true;
    default: return false;  // read-only or not modelled
  }
}

bool TmlDrive::read(std::uint16_t address, bool wide, std::uint32_t& value) const {
  std::uint16_t l = 0, h = 0;
  if (!read_word(address, l)) return false;
  if (!wide) {
    value = l;
    return true;
  }
  // 32-bit: the word at address (low) and the next (high), as SR32 = SRH:SRL.
  if (!read_word(static_cast<std::uint16_t>(address + 1), h)) return false;
  value = static_cast<std::uint32_t>(h) << 16 | l;
  return true;
}

bool TmlDrive::write(std::uint16_t address, bool wide, std::uint32_t value) {
  // Check both words first, so a 32-bit write is all or nothing.
  std::uint16_t probe = 0;
  if (!read_word(address, probe) || (wide && !read_word(static_cast<std::uint16_t>(address + 1), probe))) return false;
  if (!write_word(address, lo(value))) return false;
  return !wide || write_word(static_cast<std::uint16_t>(address + 1), hi(value));
}

// ---- Messages ----------------------------------------------------------------------------------

bool TmlDrive::accepts(std::uint16_t id_code) const {
  if (is_host(id_code)) return false;  // for the host: the relay forwards it, no drive executes it
  if (is_group(id_code)) return is_broadcast(id_code) || (id_of(id_code) & groups_) != 0;
  return id_of(id_code) == 0 || id_of(id_code) == axis_;
}

void TmlDrive::on_message(const Message& m, SimTime t) {
  if (!powered_) return;
  now_ = t;
  // ID code bits 15–13 and 3–1 are zero (seed ch. 2): a malformed ID code addresses nobody.
  if (!id_code_valid(m.id_code)) {
    ++stats_.invalid_id_codes;
    return;
  }
  const Kind k = classify(m).kind;
  // Answers of other drives are not for us (TechCAN does not even carry their destination).
  if (k == Kind::take_data || k == Kind::take_data2) {
    ++stats_.not_for_us;
    return;
  }
  if (is_host(m.id_code)) {
    ++stats_.for_host;
    return;
  }
  if (!accepts(m.id_code)) {
    ++stats_.not_for_us;
    return;
  }
  ++stats_.handled;
  execute(m, t);
}

void TmlDrive::execute(const Message& m, SimTime t) {
  const Classified c = classify(m);
  switch (c.kind) {
    case Kind::assign16:
    case Kind::assign32:
      if (!c.complete) ++stats_.refused;
      else if (!write(c.address, c.wide, c.value)) ++stats_.unknown_addresses;
      return;
    case Kind::give_me_data:
    case Kind::give_me_data2: return answer_request(m, c, t);
    case Kind::sync: return on_sync(t);
    case Kind::set_master_time:
      if (c.complete && !sync_master()) on_master_time(c.value);
      return;
    case Kind::take_data:
    case Kind::take_data2: return;  // filtered in on_message
    case Kind::pvt: ++stats_.unknown_opcodes; return;  // PVT motion is not modelled
    case Kind::generic: break;
  }
  const InstrResult r = static_cast<InstrResult>(run_instruction(m));
  if (r == InstrResult::unknown) ++stats_.unknown_opcodes;
  if (r == InstrResult::refused) ++stats_.refused;
}

void TmlDrive::answer_request(const Message& m, const Classified& c, SimTime t) {
  // GiveMeData goes to one axis only; on RS-485 no request to a group or to axis 0 (every drive
  // on the line takes those: the answers would collide).
  const bool group = is_group(m.id_code);
  if (!c.complete || (group && c.kind == Kind::give_me_data) || (to_many(m.id_code) && setup_.protocol == Protocol::rs485)) {
    ++stats_.refused;
    return;
  }
  std::uint32_t value = 0;
  if (!read(c.address, c.wide, value)) {
    ++stats_.unknown_addresses;
    return;
  }
  // The answer goes to the requester (its ID code is data 1) and names us.
  const Message a = c.kind == Kind::give_me_data ? take_data(c.sender, axis_id_code(axis_), c.address, value, c.wide)
                                                 : take_data2(c.sender, axis_, c.address, value, c.wide);
  ++stats_.answers_sent;
  emit(a, t);
}

std::uint8_t TmlDrive::run_instruction(const Message& m) {
  const bool has_data = m.count >= 1;
  const std::uint16_t d = m.data[0];
  drive::Objects& o = core_.objects();
  switch (m.opcode) {
    case instr::axison: want_on_ = true; break;
    case instr::axisoff: want_on_ = false, update_pending_ = set_point_high_ = false; break;
    case instr::upd: update_pending_ = true, halt_ = false; break;
    case instr::stop: halt_ = true; break;
    case instr::faultr: fault_reset_ = true; break;
    case instr::bitset: {
      // MODE / TUM / CPA / CPR: the masks a drive of ours understands; others refused.
      if (m.count != 2) return static_cast<std::uint8_t>(InstrResult::refused);
      const std::uint32_t mask = static_cast<std::uint32_t>(m.data[0]) | static_cast<std::uint32_t>(m.data[1]) << 16;
      if (mask == bitset_data::mode_sp) motion_ = Motion::speed, o.mode = static_cast<std::int8_t>(drive::Mode::pv);
      else if (mask == bitset_data::mode_pp) motion_ = Motion::position, o.mode = static_cast<std::int8_t>(drive::Mode::pp);
      else if (mask == bitset_data::cpa) relative_ = false;
      else if (mask == bitset_data::cpr) relative_ = true;
      else if (mask != bitset_data::tum1) return static_cast<std::uint8_t>(InstrResult::refused);
      break;
    }
    case instr::groupid:
      if (!has_data || d > 8) return static_cast<std::uint8_t>(InstrResult::refused);
      groups_ = group_mask(d);
      break;
    case instr::addgrid:
    case instr::remgrid:
      if (!has_data || d < 1 || d > 8) return static_cast<std::uint8_t>(InstrResult::refused);
      groups_ = m.opcode == instr::addgrid ? static_cast<std::uint8_t>(groups_ | group_mask(d))
                                           : static_cast<std::uint8_t>(groups_ & ~group_mask(d));
      break;
    case instr::setsync:
      // Synchronisation is a CAN service (seed ch. 5).
      if (!has_data || !on_can(setup_.protocol)) return static_cast<std::uint8_t>(InstrResult::refused);
      sync_period_ms_ = d;
      next_sync_t_ = now_ + static_cast<SimTime>(d) * kNsPerMs;
      break;
    default: return static_cast<std::uint8_t>(InstrResult::unknown);
  }
  return static_cast<std::uint8_t>(InstrResult::done);
}

void TmlDrive::on_sync(SimTime t) {
  ++stats_.syncs_received;
  sync_latch_ms_ = drive_time_ms(t);
}

void TmlDrive::on_master_time(std::uint32_t master_ms) {
  // The master's time at the last SYNC minus ours at the same SYNC: shift our clock by it.
  time_offset_ms_ += static_cast<std::int32_t>(master_ms - sync_latch_ms_);
  sync_latch_ms_ = master_ms;
}

void TmlDrive::emit(const Message& m, SimTime t) {
  if (send_) send_(m, t);
}

// ---- The drive period --------------------------------------------------------------------------

void TmlDrive::apply_update() {
  drive::Objects& o = core_.objects();
  motion_complete_ = false;  // a new motion starts (SRL.10 = 0, seed ch. 3 example 3)
  const double acc = std::max(1.0, std::fabs(acc_iu_to_counts_s2(cacc_)));
  o.profile_acceleration = o.profile_deceleration = static_cast<std::uint32_t>(std::min(acc, 4.0e9));
  if (motion_ == Motion::speed) {
    o.target_velocity = clamp32(speed_iu_to_counts_s(cspd_));
    return;
  }
  o.target_position = cpos_;
  o.profile_velocity = static_cast<std::uint32_t>(std::min(std::fabs(speed_iu_to_counts_s(cspd_)), 4.0e9));
  set_point_high_ = true;  // the new set-point bit, until the core acknowledges it
}

std::uint16_t TmlDrive::next_controlword() {
  namespace cw = drive::cw;
  const drive::State s = core_.state();
  if (fault_reset_ && s == drive::State::fault) return cw::kFaultReset;
  if (!want_on_) return cw::kShutdown;  // power stage off, ready for the next AXISON
  switch (s) {
    case drive::State::switch_on_disabled: return cw::kShutdown;
    case drive::State::ready_to_switch_on:
    case drive::State::switched_on: return cw::kEnableOperation;
    case drive::State::operation_enabled: break;
    default: return 0;  // powering up, stopping or faulted: wait (AXISON does not reset faults)
  }
  std::uint16_t c = cw::kEnableOperation;
  if (halt_) c |= cw::halt;
  if (motion_ == Motion::position) {
    c |= cw::change_immediately;  // UPD applies at once
    if (relative_) c |= cw::relative;
    if (set_point_high_) c |= cw::new_set_point;
  }
  return c;
}

drive::Command TmlDrive::step(SimTime t, const drive::Feedback& fb) {
  if (!powered_) return drive::Command{};
  now_ = t;
  // UPD: a position set-point waits until the previous one's bit has fallen.
  if (update_pending_ && !(motion_ == Motion::position && set_point_high_)) {
    apply_update();
    update_pending_ = false;
  }
  core_.objects().controlword = next_controlword();
  const drive::Command cmd = core_.step(t, fb);
  ++stats_.steps;
  const drive::State s = core_.state();
  if (set_point_high_ && motion_ == Motion::position && (core_.objects().statusword & drive::sw::set_point_ack))
    set_point_high_ = false;
  if (s != drive::State::fault) fault_reset_ = false;
  if (faulted(s)) want_on_ = update_pending_ = set_point_high_ = false;  // a fault switches the axis off
  const std::uint16_t old_srl = srl_, old_srh = srh_, old_mer = mer_;
  update_status();
  send_masked_changes(old_srl, old_srh, old_mer, t);
  run_sync_master(t);
  return cmd;
}

void TmlDrive::update_status() {
  const drive::Objects& o = core_.objects();
  const drive::State s = core_.state();
  const bool on = axis_on(s);
  srl_ = 0;
  if (on) srl_ |= bits::srl_axis_on;
  // Motion complete, latched: set while off (nothing moves) and the first time the core reports
  // the target of the last UPD reached (not again as the position wavers at the window's edge);
  // only the next UPD clears it.
  const bool set_point_taken = !update_pending_ && !set_point_high_;
  if (!on || (set_point_taken && (o.statusword & drive::sw::target_reached))) motion_complete_ = true;
  if (motion_complete_) srl_ |= bits::srl_motion_complete;
  srh_ = faulted(s) ? bits::srh_fault : 0;
  mer_ = o.error_code == drive::kErrorFollowing ? bits::mer_control_error : 0;
}

void TmlDrive::send_masked_changes(std::uint16_t old_srl, std::uint16_t old_srh, std::uint16_t old_mer, SimTime t) {
  if (setup_.protocol == Protocol::rs485) return;  // type C is forbidden on RS-485
  // SRL/SRH go together as SR32 at SRL's address (seed ch. 3 example 3).
  if (((old_srl ^ srl_) & srl_mask_) != 0 || ((old_srh ^ srh_) & srh_mask_) != 0) {
    emit(take_data2(masterid_, axis_, reg::srl, static_cast<std::uint32_t>(srh_) << 16 | srl_, true), t);
    ++stats_.take_data2_sent;
  }
  if (((old_mer ^ mer_) & mer_mask_) != 0) {
    emit(take_data2(masterid_, axis_, reg::mer, mer_, false), t);
    ++stats_.take_data2_sent;
  }
}

void TmlDrive::run_sync_master(SimTime t) {
  if (sync_period_ms_ == 0 || t < next_sync_t_) return;
  // SYNC latches every drive's time (ours too), then the master's time at that SYNC.
  sync_latch_ms_ = drive_time_ms(t);
  emit(sync_message(), t);
  emit(set_master_time(sync_latch_ms_), t);
  ++stats_.syncs_sent;
  next_sync_t_ += static_cast<SimTime>(sync_period_ms_) * kNsPerMs;
  if (next_sync_t_ <= t) next_sync_t_ = t + static_cast<SimTime>(sync_period_ms_) * kNsPerMs;
}

}  // namespace omnitwin::tml
