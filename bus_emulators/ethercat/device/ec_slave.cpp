// bus_emulators/ethercat/device — DriveSlave, the servo slave firmware (see ec_slave.hpp).
#include "bus_emulators/ethercat/device/ec_slave.hpp"

#include "bus_emulators/ethercat/device/cia402_od.hpp"

#include <fmt/format.h>

#include <algorithm>
#include <cmath>
#include <cstring>
#include <utility>

#include "bus_emulators/ethercat/device/ec_sii.hpp"

namespace omnitwin::ethercat {

const char* to_string(SlaveApp a) {
  switch (a) {
    case SlaveApp::cia402: return "cia402";
    case SlaveApp::multiaxis: return "multiaxis";
  }
  return "?";
}

namespace {

constexpr std::uint16_t kRxAssign = 0x1C12, kTxAssign = 0x1C13;
constexpr std::size_t kCoeMailboxMax = 1024;

// Multi-axis module objects of slot k (seed 001): command 0x7000 + 0x10·k, status 0x6000 + 0x10·k,
// parameters 0x8000 + 0x10·k. Layout: docs/protocols/ethercat-multiaxis.md.
constexpr std::uint16_t kCmdModule = 0x7000, kStatusModule = 0x6000, kAxisParams = 0x8000;
constexpr std::uint16_t kHdrHandshake = 0x8000;
constexpr std::uint16_t kCtlEnable = 0x0001, kCtlReset = 0x0002, kCtlStop = 0x0004;
constexpr std::uint16_t kStEnabled = 0x0001, kStAlarm = 0x0002, kStReady = 0x0004, kStReached = 0x0008,
                        kStHomed = 0x0010, kStFollowing = 0x0020, kStAddress = 0x0040, kStMode = 0x0080,
                        kStQuickStop = 0x0100;
enum WorkMode : std::uint8_t { wm_idle = 0, wm_position = 1, wm_velocity = 2, wm_homing = 3, wm_encoder = 4 };

std::int8_t cia_mode(std::uint8_t work_mode) {
  switch (work_mode) {
    case wm_position: return static_cast<std::int8_t>(drive::Mode::csp);
    case wm_velocity: return static_cast<std::int8_t>(drive::Mode::csv);
    case wm_homing: return static_cast<std::int8_t>(drive::Mode::hm);
    default: return static_cast<std::int8_t>(drive::Mode::none);
  }
}

void copy_bits(std::uint8_t* dst, std::uint32_t dst_bit, const std::uint8_t* src, std::uint32_t src_bit,
               std::uint32_t bits) noexcept {
  if ((dst_bit | src_bit | bits) % 8 == 0) {
    std::memcpy(dst + dst_bit / 8, src + src_bit / 8, bits / 8);
    return;
  }
  for (std::uint32_t i = 0; i < bits; ++i) {
    const std::uint32_t s = src_bit + i, d = dst_bit + i;
    const bool v = (src[s >> 3] >> (s & 7)) & 1;
    const auto m = static_cast<std::uint8_t>(1u << (d & 7));
    dst[d >> 3] = static_cast<std::uint8_t>(v ? (dst[d >> 3] | m) : (dst[d >> 3] & ~m));
  }
}

}  // namespace

DriveSlave::DriveSlave(const DeviceDescription& desc, const DriveSlaveConfig& config) : desc_(desc), cfg_(config) {
  app_ = desc.profile == 5001 ? SlaveApp::multiaxis : SlaveApp::cia402;
  const int axes = cfg_.axes == 0 ? desc.axes : cfg_.axes;
  if (axes < 1 || axes > desc.axes)
    throw EsiError(fmt::format("{}: {} axes configured, '{}' has 1..{}", desc.source, axes, desc.name, desc.axes));
  sm_mbx_out_ = desc.sm_of_kind(SmKind::mbox_out);
  sm_mbx_in_ = desc.sm_of_kind(SmKind::mbox_in);
  sm_out_ = desc.sm_of_kind(SmKind::outputs);
  sm_in_ = desc.sm_of_kind(SmKind::inputs);
  if (sm_mbx_out_ < 0 || sm_mbx_in_ < 0 || !desc.coe.present)
    throw EsiError(fmt::format("{}: '{}' has no CoE mailbox SyncManagers", desc.source, desc.name));
  if (sm_out_ < 0 || sm_in_ < 0)
    throw EsiError(fmt::format("{}: '{}' has no Outputs/Inputs SyncManagers", desc.source, desc.name));
  axes_.reserve(static_cast<std::size_t>(axes));
  for (int a = 0; a < axes; ++a) axes_.push_back(std::make_unique<drive::Cia402Drive>(cfg_.drive));
  cards_.assign(static_cast<std::size_t>(axes), Card{});
  emcy_code_.assign(static_cast<std::size_t>(axes), 0);

  // The SII describes the fitted axes only: PDOs of absent cards are not assigned by default.
  if (app_ == SlaveApp::multiaxis) {
    for (auto& p : desc_.rx_pdos)
      if (p.index - 0x1600 >= axes) p.sm = -1;
    for (auto& p : desc_.tx_pdos)
      if (p.index - 0x1A00 >= axes) p.sm = -1;
  }
  build_od();
  install_pdo_checks();
  bind_sync_params(0x1C32, sync_out_);
  bind_sync_params(0x1C33, sync_in_);
  set_factor_objects();
  if (!build_layout(true, rx_) || !build_layout(false, tx_))
    throw EsiError(fmt::format("{}: '{}': default PDO assignment maps absent objects", desc.source, desc.name));
  in_image_.assign(kCoeMailboxMax, 0);

  CoeServerConfig cc;
  cc.sdo_info = desc.coe.sdo_info;
  cc.complete_access = desc.coe.complete_access;
  cc.mailbox_size = kCoeMailboxMax;
  coe_ = std::make_unique<CoeServer>(od_, cc);
  coe_->set_mailbox_size(desc.sms[static_cast<std::size_t>(sm_mbx_in_)].size);

  EscConfig ec = cfg_.esc;
  ec.sii = build_sii(desc_, cfg_.alias, cfg_.serial);
  esc_ = std::make_unique<Esc>(std::move(ec), this);
  esc_->set_sm_deactivated(sm_out_, true);  // outputs SM active in SAFE-OP (no error) and OP only
  close_mailbox(true);
}

// SSC keeps the mailbox SMs (SM0/SM1) deactivated in INIT (ETG.1000.6: the mailbox starts in
// PRE-OP); a master's mailbox accesses then get WKC 0. Reactivated at INIT → PRE-OP.
void DriveSlave::close_mailbox(bool closed) {
  esc_->set_sm_deactivated(sm_mbx_out_, closed);
  esc_->set_sm_deactivated(sm_mbx_in_, closed);
}

void DriveSlave::build_od() {
  od_.add_from_esi(desc_);
  if (auto* e = od_.entry(0x1018, 4)) e->set_int(static_cast<std::int64_t>(cfg_.serial));
  if (app_ == SlaveApp::cia402) {
    // Axes beyond the ESI's own objects get copies of axis 0's profile objects at +0x800·a.
    std::vector<OdObject> base;
    for (const auto& o : od_.objects())
      if (o.index >= 0x6000 && o.index < 0x6000 + kAxisOffset) base.push_back(o);
    for (int a = 1; a < axes(); ++a)
      for (const auto& o : base) {
        const auto idx = static_cast<std::uint16_t>(o.index + kAxisOffset * a);
        if (od_.find(idx)) continue;
        OdObject c = o;
        c.index = idx;
        od_.add(std::move(c));
      }
    for (int a = 0; a < axes(); ++a) bind_cia402_axis(a);
  } else {
    for (int a = 0; a < axes(); ++a) bind_multiaxis_axis(a);
    // The modules' entries, looked up once: the dictionary is complete here and never grows
    // afterwards, so the firmware cycle reads them without a search.
    modules_.assign(static_cast<std::size_t>(axes()), {});
    for (int k = 0; k < axes(); ++k)
      for (std::uint8_t sub = 1; sub <= 4; ++sub) {
        modules_[static_cast<std::size_t>(k)][sub - 1u] = od_.entry(static_cast<std::uint16_t>(kCmdModule + 0x10 * k), sub);
        modules_[static_cast<std::size_t>(k)][sub + 3u] = od_.entry(static_cast<std::uint16_t>(kStatusModule + 0x10 * k), sub);
      }
    if (auto* e = od_.entry(kRxAssign, 0)) e->set_int(axes());
    if (auto* e = od_.entry(kTxAssign, 0)) e->set_int(axes());
  }
}

void DriveSlave::bind_cia402_axis(int a) {
  bind_cia402_objects(od_, *axes_[static_cast<std::size_t>(a)], static_cast<std::uint16_t>(kAxisOffset * a));
}

void DriveSlave::bind_multiaxis_axis(int a) {
  auto& o = axes_[static_cast<std::size_t>(a)]->objects();
  const auto idx = static_cast<std::uint16_t>(kAxisParams + 0x10 * a);
  od_.bind(idx, 1, o.homing_method);
  od_.bind(idx, 2, o.homing_speed_switch);
  od_.bind(idx, 3, o.homing_speed_zero);
  od_.bind(idx, 4, o.homing_acceleration);
  od_.bind(idx, 5, o.following_error_window);
  od_.bind(idx, 6, o.position_window);
}

// 0x1C32/0x1C33 bound to the firmware's SmSyncParams (see ec_slave.hpp), with the sync mode's
// check and the "get cycle time" command.
void DriveSlave::bind_sync_params(std::uint16_t index, SmSyncParams& p) {
  OdObject* o = od_.find(index);
  if (!o) return;  // an ESI without the object: nothing to feed
  od_.bind(index, 1, p.sync_mode);
  od_.bind(index, 2, p.cycle_time);
  od_.bind(index, 3, p.shift_time);
  od_.bind(index, 4, p.supported);
  od_.bind(index, 5, p.min_cycle);
  od_.bind(index, 6, p.calc_copy);
  od_.bind(index, 8, p.get_cycle);
  od_.bind(index, 9, p.delay);
  od_.bind(index, 10, p.sync0_cycle);
  od_.bind(index, 11, p.sm_missed);
  od_.bind(index, 12, p.too_small);
  od_.bind(index, 13, p.shift_short);
  od_.bind(index, 32, p.sync_error);
  o->check = [](const OdObject&, std::uint8_t sub, std::span<const std::uint8_t> data) {
    if (sub != 1 || data.size() < 2) return SdoAbort::none;
    const auto v = static_cast<std::uint16_t>(data[0] | (data[1] << 8));
    return v == 0 || v == 2 ? SdoAbort::none : SdoAbort::value_range;
  };
  o->after_write = [this, &p](OdObject&, std::uint8_t sub) {
    if (sub == 1) {
      (&p == &sync_out_ ? sync_mode_written_out_ : sync_mode_written_in_) = true;
      return;
    }
    if (sub != 8 || (sync_out_.get_cycle != 2 && sync_in_.get_cycle != 2)) return;
    for (SmSyncParams* q : {&sync_out_, &sync_in_}) {  // one command clears both directions
      q->sm_missed = q->too_small = q->shift_short = 0;
      q->sync_error = 0;
      q->get_cycle = 0;
    }
  };
}

// Rational approximation p/q (q ≤ 1000) of a gear ratio, for 0x6091.
static void ratio_of(double r, std::uint32_t& p, std::uint32_t& q) {
  p = 1;
  q = 1;
  double best = 1e300;
  for (std::uint32_t d = 1; d <= 1000 && best > 1e-12; ++d) {
    const double n = std::round(r * d);
    if (n < 1) continue;
    const double err = std::abs(n / d - r);
    if (err < best) {
      best = err;
      p = static_cast<std::uint32_t>(n);
      q = d;
    }
  }
}

// 0x608F/0x6091/0x6092 of every axis from the drive configuration. Position units are motor
// encoder counts, so the CiA 402 position factor (0x608F · 0x6091 / 0x6092) is 1.
void DriveSlave::set_factor_objects() {
  std::uint32_t motor = 1, shaft = 1;
  ratio_of(cfg_.drive.gear_ratio, motor, shaft);
  const auto counts = static_cast<std::int64_t>(std::llround(cfg_.drive.counts_per_rev));
  for (int a = 0; a < axes(); ++a) {
    const auto off = static_cast<std::uint16_t>(kAxisOffset * a);
    auto set = [&](std::uint16_t idx, std::uint8_t sub, std::int64_t v) {
      if (OdEntry* e = od_.entry(static_cast<std::uint16_t>(idx + off), sub)) e->set_int(v);
    };
    set(0x608F, 1, counts);
    set(0x608F, 2, 1);
    set(0x6091, 1, motor);
    set(0x6091, 2, shaft);
    set(0x6092, 1, counts * motor);
    set(0x6092, 2, shaft);
    // 0x60C2: period value × 10^index s; the index must lie in -6..0 (µs … s).
    if (OdObject* ip = od_.find(static_cast<std::uint16_t>(0x60C2 + off))) {
      ip->check = [](const OdObject&, std::uint8_t sub, std::span<const std::uint8_t> data) {
        if (sub != 2 || data.empty()) return SdoAbort::none;
        const auto idx = static_cast<std::int8_t>(data[0]);
        return idx >= -6 && idx <= 0 ? SdoAbort::none : SdoAbort::value_range;
      };
    }
  }
}

void DriveSlave::install_pdo_checks() {
  std::vector<std::uint16_t> indices;
  for (const auto& o : od_.objects()) indices.push_back(o.index);
  for (const std::uint16_t i : indices) {
    OdObject* p = od_.find(i);
    if ((i >= 0x1600 && i <= 0x17FF) || (i >= 0x1A00 && i <= 0x1BFF)) {
      p->check = [this](const OdObject& obj, std::uint8_t sub, std::span<const std::uint8_t> data) {
        return check_mapping(obj, sub, data);
      };
    } else if (i == kRxAssign || i == kTxAssign) {
      p->check = [this](const OdObject& obj, std::uint8_t sub, std::span<const std::uint8_t> data) {
        return check_assign(obj, sub, data);
      };
    }
  }
}

SdoAbort DriveSlave::check_mapping(const OdObject& o, std::uint8_t sub, std::span<const std::uint8_t> data) const {
  const bool rx = o.index < 0x1A00;
  if (sub == 0) {
    const std::uint8_t n = data[0];
    if (n > o.max_subindex()) return SdoAbort::value_range;
    std::uint32_t bits = 0;
    for (int s = 1; s <= n; ++s) {  // int: n = 255 must end the loop
      const OdEntry* e = o.entry(static_cast<std::uint8_t>(s));
      if (!e) return SdoAbort::value_range;
      bits += static_cast<std::uint32_t>(e->as_int() & 0xFF);
    }
    if (bits > 8 * 256) return SdoAbort::pdo_length_exceeded;
    return SdoAbort::none;
  }
  if (o.entry(0) && o.entry(0)->as_int() != 0) return SdoAbort::subindex0_not_zero;
  std::uint32_t v = 0;
  std::memcpy(&v, data.data(), std::min<std::size_t>(data.size(), 4));
  const auto idx = static_cast<std::uint16_t>(v >> 16);
  const auto s = static_cast<std::uint8_t>(v >> 8);
  const auto bits = static_cast<std::uint8_t>(v);
  if (bits == 0) return SdoAbort::param_incompatible;
  if (idx == 0) return SdoAbort::none;  // padding
  const OdObject* target = od_.find(idx);
  if (!target) return SdoAbort::no_object;
  const OdEntry* e = target->entry(s);
  if (!e) return SdoAbort::no_subindex;
  if (!(e->access & (rx ? od_access::rxpdo : od_access::txpdo))) return SdoAbort::not_mappable;
  if (e->bits != bits) return SdoAbort::param_incompatible;
  return SdoAbort::none;
}

SdoAbort DriveSlave::check_assign(const OdObject& o, std::uint8_t sub, std::span<const std::uint8_t> data) const {
  if (sub == 0) return data[0] > o.max_subindex() ? SdoAbort::value_range : SdoAbort::none;
  if (o.entry(0) && o.entry(0)->as_int() != 0) return SdoAbort::subindex0_not_zero;
  std::uint16_t v = 0;
  std::memcpy(&v, data.data(), std::min<std::size_t>(data.size(), 2));
  const bool rx = o.index == kRxAssign;
  const bool in_range = rx ? (v >= 0x1600 && v <= 0x17FF) : (v >= 0x1A00 && v <= 0x1BFF);
  if (!in_range || !od_.find(v)) return SdoAbort::value_range;
  return SdoAbort::none;
}

std::size_t DriveSlave::assigned_bits(bool rx) const {
  std::size_t bits = 0;
  const OdObject* as = od_.find(rx ? kRxAssign : kTxAssign);
  if (!as || !as->entry(0)) return 0;
  const auto n = as->entry(0)->as_int();
  for (std::int64_t i = 1; i <= n; ++i) {
    const OdEntry* pe = as->entry(static_cast<std::uint8_t>(i));
    if (!pe) continue;
    const OdObject* map = od_.find(static_cast<std::uint16_t>(pe->as_int()));
    if (!map || !map->entry(0)) continue;
    for (std::int64_t k = 1; k <= map->entry(0)->as_int(); ++k)
      if (const OdEntry* me = map->entry(static_cast<std::uint8_t>(k))) bits += static_cast<std::size_t>(me->as_int() & 0xFF);
  }
  return bits;
}

std::size_t DriveSlave::output_bytes() const { return (assigned_bits(true) + 7) / 8; }
std::size_t DriveSlave::input_bytes() const { return (assigned_bits(false) + 7) / 8; }

bool DriveSlave::build_layout(bool rx, std::vector<PdoSlot>& out) const {
  out.clear();
  const OdObject* as = od_.find(rx ? kRxAssign : kTxAssign);
  if (!as || !as->entry(0)) return true;
  std::uint32_t at = 0;
  const auto n = as->entry(0)->as_int();
  for (std::int64_t i = 1; i <= n; ++i) {
    const OdEntry* pe = as->entry(static_cast<std::uint8_t>(i));
    if (!pe) return false;
    const OdObject* map = od_.find(static_cast<std::uint16_t>(pe->as_int()));
    if (!map || !map->entry(0)) return false;
    for (std::int64_t k = 1; k <= map->entry(0)->as_int(); ++k) {
      const OdEntry* me = map->entry(static_cast<std::uint8_t>(k));
      if (!me) return false;
      const auto v = static_cast<std::uint32_t>(me->as_int());
      PdoSlot slot;
      slot.offset = at;
      slot.bits = static_cast<std::uint16_t>(v & 0xFF);
      const auto idx = static_cast<std::uint16_t>(v >> 16);
      if (idx != 0) {
        slot.entry = const_cast<ObjectDictionary&>(od_).entry(idx, static_cast<std::uint8_t>(v >> 8));
        if (!slot.entry || slot.entry->bits != slot.bits) return false;
      }
      at += slot.bits;
      out.push_back(slot);
    }
  }
  return true;
}

OdState DriveSlave::od_state() const {
  switch (esc_->al_state()) {
    case AlState::safeop: return OdState::safeop;
    case AlState::op: return OdState::op;
    default: return OdState::preop;
  }
}

AlStatusCode DriveSlave::on_al_request(AlState from, AlState to, SimTime t) {
  auto refuse = [&](AlStatusCode c) {
    ++stats_.al_refused;
    if (from == AlState::safeop) esc_->set_sm_deactivated(sm_out_, true);  // SAFE-OP + error, as on a local error
    return c;
  };
  if (to == AlState::boot) return refuse(AlStatusCode::bootstrap_not_supported);
  if (to == AlState::init) {
    coe_->reset();
    outputs_stopped();
    esc_->set_sm_deactivated(sm_out_, true);
    close_mailbox(true);  // an unread reply in SM1 is dropped with it
    return AlStatusCode::none;
  }
  if (from == AlState::init && to == AlState::preop) {
    const SyncManager& out = esc_->sm(sm_mbx_out_);
    const SyncManager& in = esc_->sm(sm_mbx_in_);
    const bool ok = out.enabled && out.mailbox() && out.ecat_writes() && out.length >= 16 && in.enabled &&
                    in.mailbox() && !in.ecat_writes() && in.length >= 16 &&
                    !out.overlaps(in.start, in.length) && in.length <= kCoeMailboxMax;
    if (!ok) return refuse(AlStatusCode::invalid_mailbox_config);
    coe_->set_mailbox_size(in.length);
    close_mailbox(false);
    return AlStatusCode::none;
  }
  // SYNC0 requested with a cycle the ESC refuses (below DcClock::kMinSyncCycleNs): no process
  // data operation on it (AL status code 0x0030 invalid DC SYNC configuration). Only the steps
  // up (PRE-OP → SAFE-OP, SAFE-OP → OP) are refused; going down is always accepted.
  const bool up = (from == AlState::preop && to == AlState::safeop) || (from == AlState::safeop && to == AlState::op);
  if (up && esc_->dc().sync0_invalid()) return refuse(AlStatusCode::invalid_dc_sync_config);
  if (from == AlState::safeop && to == AlState::op) {
    esc_->set_sm_deactivated(sm_out_, false);  // the SAFE-OP + error case: the ack came with the OP request
    return AlStatusCode::none;
  }
  if (from == AlState::preop && to == AlState::safeop) {
    // A sync mode the master wrote must match the SYNC0 activation it made.
    const bool dc = sync0_driven();
    if ((sync_mode_written_out_ && (sync_out_.sync_mode == 2) != dc) ||
        (sync_mode_written_in_ && (sync_in_.sync_mode == 2) != dc))
      return refuse(AlStatusCode::invalid_dc_sync_config);
    follow_sync_mode(dc);
    const std::size_t ob = output_bytes(), ib = input_bytes();
    const SyncManager& o = esc_->sm(sm_out_);
    const SyncManager& i = esc_->sm(sm_in_);
    const bool out_ok = ob == 0 ? (!o.enabled || o.length == 0)
                                : (o.enabled && o.buffered() && o.ecat_writes() && o.length == ob);
    if (!out_ok) return refuse(AlStatusCode::invalid_output_config);
    const bool in_ok = ib == 0 ? (!i.enabled || i.length == 0)
                               : (i.enabled && i.buffered() && !i.ecat_writes() && i.length == ib);
    if (!in_ok) return refuse(AlStatusCode::invalid_input_config);
    // A buffered SyncManager takes three buffers of its length: the outputs' three must not run
    // into the inputs' or a mailbox, nor the inputs' into a mailbox (the slave stack checks
    // this; here a mapping larger than the gap the ESI leaves was taken into OP and the second
    // and third output buffers overwrote the inputs; found by a protocol review).
    const auto area = [&](int k) {  // [start, end) of SyncManager k's memory, 0 length when unused
      const SyncManager& s = esc_->sm(k);
      const std::uint32_t n = s.enabled ? (s.buffered() ? 3u : 1u) * s.length : 0u;
      return std::pair<std::uint32_t, std::uint32_t>{s.start, s.start + n};
    };
    const auto clash = [&](int a, int b) {
      const auto [a0, a1] = area(a);
      const auto [b0, b1] = area(b);
      return a1 > a0 && b1 > b0 && a0 < b1 && b0 < a1;
    };
    if (clash(sm_out_, sm_in_) || clash(sm_out_, sm_mbx_out_) || clash(sm_out_, sm_mbx_in_))
      return refuse(AlStatusCode::invalid_output_config);
    if (clash(sm_in_, sm_mbx_out_) || clash(sm_in_, sm_mbx_in_)) return refuse(AlStatusCode::invalid_input_config);
    if (!build_layout(true, rx_) || !build_layout(false, tx_) || ib > in_image_.size())
      return refuse(AlStatusCode::invalid_output_config);
    if (app_ == SlaveApp::multiaxis) multiaxis_status();
    pack_inputs();  // inputs valid from the first SAFE-OP read
    esc_->set_sm_deactivated(sm_out_, false);  // outputs are taken (not applied) from SAFE-OP on
    (void)t;
    return AlStatusCode::none;
  }
  if (to == AlState::preop || to == AlState::safeop) outputs_stopped();
  if (to == AlState::preop) esc_->set_sm_deactivated(sm_out_, true);
  return AlStatusCode::none;
}

void DriveSlave::on_mailbox(std::span<const std::uint8_t> mailbox, SimTime /*t*/) {
  coe_->on_mailbox(mailbox, od_state(), esc_->sm_unit(sm_mbx_in_).full());
  pump_mailbox();
}

void DriveSlave::on_outputs(std::span<const std::uint8_t> /*outputs*/, SimTime /*t*/) {
  outputs_fresh_ = true;
  // Outputs are taken from the last complete SM2 buffer at the firmware cycle (seed 001: the
  // slave reads the commands before t1 of its cycle), not at the moment the frame passes.
}

void DriveSlave::on_sync0(SimTime t) { firmware(t); }

// A local error (the watchdog) dropped the slave: outputs stop and SM2 is deactivated, so the
// master's WKC shows it; the acknowledge of the error activates SM2 again (on_al_error_cleared).
void DriveSlave::on_al_fallback(AlState /*from*/, AlState /*to*/, AlStatusCode /*code*/, SimTime /*t*/) {
  outputs_stopped();
  esc_->set_sm_deactivated(sm_out_, true);
}

void DriveSlave::on_al_error_cleared(AlState state, SimTime /*t*/) {
  if (state == AlState::safeop || state == AlState::op) esc_->set_sm_deactivated(sm_out_, false);
}

// SYNC0 activated and accepted by the ESC (an invalid cycle gives no pulses: free run instead).
bool DriveSlave::sync0_driven() const { return (esc_->read8(0x0981) & 0x03) == 0x03 && !esc_->dc().sync0_invalid(); }

void DriveSlave::cycle(SimTime t) noexcept {
  pump_mailbox();
  if (!sync0_driven()) firmware(t);
}

void DriveSlave::power_cycle(SimTime t) {
  esc_->power_cycle(t);
  esc_->set_sm_deactivated(sm_out_, true);
  close_mailbox(true);
  coe_->reset();
  for (auto& a : axes_) a->power_cycle();
  od_.restore_defaults();
  if (auto* e = od_.entry(0x1018, 4)) e->set_int(static_cast<std::int64_t>(cfg_.serial));
  sync_out_ = SmSyncParams{};
  sync_in_ = SmSyncParams{};
  sync_mode_written_out_ = sync_mode_written_in_ = false;
  outputs_fresh_ = false;
  last_cycle_ = -1;
  set_factor_objects();
  if (app_ == SlaveApp::multiaxis) {
    if (auto* e = od_.entry(kRxAssign, 0)) e->set_int(axes());
    if (auto* e = od_.entry(kTxAssign, 0)) e->set_int(axes());
  }
  build_layout(true, rx_);
  build_layout(false, tx_);
  cards_.assign(cards_.size(), Card{});
  emcy_code_.assign(emcy_code_.size(), 0);
  outputs_valid_ = false;
}

void DriveSlave::pump_mailbox() noexcept {
  while (coe_->has_reply()) {
    if (!esc_->post_mailbox(coe_->front())) break;
    coe_->pop();
    ++stats_.mailbox_posted;
  }
}

void DriveSlave::outputs_stopped() noexcept {
  if (!outputs_valid_) return;
  outputs_valid_ = false;
  for (auto& a : axes_) a->objects().controlword = 0;  // disable voltage: the drive stops
  for (auto& c : cards_) c.prev_control = 0;
}

// A sync mode the master did not write follows the SYNC0 activation.
void DriveSlave::follow_sync_mode(bool dc) noexcept {
  if (!sync_mode_written_out_) sync_out_.sync_mode = dc ? 2 : 0;
  if (!sync_mode_written_in_) sync_in_.sync_mode = dc ? 2 : 0;
}

// 0x1C32/0x1C33 live values at a firmware cycle at t (see SmSyncParams).
void DriveSlave::update_sync_params(SimTime t) noexcept {
  const bool dc = sync0_driven();
  const std::uint32_t sync0 = dc ? esc_->read32(0x09A0) : 0;
  const std::uint32_t local = last_cycle_ >= 0 && t > last_cycle_ ? static_cast<std::uint32_t>(std::min<SimTime>(t - last_cycle_, 0xFFFFFFFF)) : 0;
  last_cycle_ = t;
  // Counted once outputs are being applied (SSC counts after the first outputs in OP too).
  const bool missed = dc && esc_->al_state() == AlState::op && outputs_valid_ && !outputs_fresh_;
  outputs_fresh_ = false;
  follow_sync_mode(dc);
  for (SmSyncParams* p : {&sync_out_, &sync_in_}) {
    p->sync0_cycle = sync0;
    p->cycle_time = dc ? sync0 : local;
    if (dc && esc_->al_state() == AlState::op) {
      if (missed && p->sm_missed < 0xFFFF) ++p->sm_missed;
      p->sync_error = missed ? 1 : 0;
    }
  }
}

void DriveSlave::firmware(SimTime t) noexcept {
  ++stats_.cycles;
  update_sync_params(t);
  pump_mailbox();
  const AlState s = esc_->al_state();
  if (s == AlState::op) {
    const auto out = esc_->outputs(sm_out_);  // the Outputs SM of the ESI, as for the inputs
    const std::size_t need = (rx_.empty() ? 0 : (rx_.back().offset + rx_.back().bits + 7) / 8);
    if (!out.empty() && out.size() >= need) {
      for (const auto& slot : rx_)
        if (slot.entry) copy_bits(slot.entry->data(), 0, out.data(), slot.offset, slot.bits);
      outputs_valid_ = true;
      ++stats_.outputs_applied;
      if (app_ == SlaveApp::multiaxis) multiaxis_commands();
    }
  } else {
    outputs_stopped();
  }
  if (hook_) hook_(t);
  signal_emergencies();
  if (s == AlState::safeop || s == AlState::op) {
    if (app_ == SlaveApp::multiaxis) multiaxis_status();
    pack_inputs();
  }
}

void DriveSlave::signal_emergencies() noexcept {
  std::uint8_t reg = 0;
  for (int a = 0; a < axes(); ++a) {
    const std::uint16_t code = axes_[static_cast<std::size_t>(a)]->objects().error_code;
    if (code != 0) reg = static_cast<std::uint8_t>(reg | 0x01 | drive::error_class_bit(code));
  }
  if (OdEntry* e = od_.entry(0x1001, 0)) e->set_int(reg);
  for (int a = 0; a < axes(); ++a) {
    const std::uint16_t code = axes_[static_cast<std::size_t>(a)]->objects().error_code;
    std::uint16_t& last = emcy_code_[static_cast<std::size_t>(a)];
    if (code == last) continue;
    last = code;
    const std::uint8_t data[5] = {static_cast<std::uint8_t>(a + 1), 0, 0, 0, 0};
    if (esc_->al_state() != AlState::init && coe_->post_emergency(code, reg, data)) {
      ++stats_.emergencies;
    } else {
      ++stats_.emergencies_lost;
    }
  }
  pump_mailbox();
}

void DriveSlave::pack_inputs() noexcept {
  const std::size_t n = tx_.empty() ? 0 : (tx_.back().offset + tx_.back().bits + 7) / 8;
  std::fill_n(in_image_.begin(), n, 0);
  for (const auto& slot : tx_)
    if (slot.entry) copy_bits(in_image_.data(), slot.offset, slot.entry->data(), 0, slot.bits);
  // Into the Inputs SM of the ESI (sm_in_), never "the first buffered master-read SM": a master
  // may configure another SM (e.g. SM1) that way.
  if (n) esc_->write_inputs(sm_in_, std::span<const std::uint8_t>(in_image_.data(), n));
}

void DriveSlave::multiaxis_commands() noexcept {
  for (int k = 0; k < axes(); ++k) {
    const auto& m = modules_[static_cast<std::size_t>(k)];
    const OdEntry* h = m[0];
    const OdEntry* c = m[1];
    const OdEntry* v1 = m[2];
    const OdEntry* v2 = m[3];
    if (!h || !c || !v1 || !v2) continue;
    const auto hdr = static_cast<std::uint16_t>(h->as_int());
    const auto ctl = static_cast<std::uint16_t>(c->as_int());
    const int addr = hdr & 0xFF;
    Card& slot = cards_[static_cast<std::size_t>(k)];
    slot.address_error = addr > axes();
    if (slot.address_error) ++stats_.address_errors;
    slot.card = (addr >= 1 && addr <= axes()) ? addr - 1 : -1;
    if (slot.card < 0) continue;
    Card& card = cards_[static_cast<std::size_t>(slot.card)];
    drive::Cia402Drive& d = *axes_[static_cast<std::size_t>(slot.card)];
    auto& o = d.objects();
    // Work mode change with handshake: take the header's mode when its handshake bit differs
    // from the acknowledged one; acknowledge once the drive displays the mode.
    const auto mode = static_cast<std::uint8_t>((hdr >> 8) & 0x7F);
    const std::uint8_t hs = (hdr & kHdrHandshake) ? 1 : 0;
    card.mode_pending = false;
    if (hs != card.handshake) {
      if (mode > wm_encoder) {
        card.mode_pending = true;  // rejected: reported, never acknowledged
      } else {
        o.mode = cia_mode(mode);
        if (o.mode_display == o.mode) {
          card.work_mode = mode;
          card.handshake = hs;
        }
      }
    }
    switch (card.work_mode) {
      case wm_position:
        o.target_position = static_cast<std::int32_t>(v1->as_int());
        o.velocity_offset = static_cast<std::int32_t>(v2->as_int());
        break;
      case wm_velocity:
        o.target_velocity = static_cast<std::int32_t>(v1->as_int());
        break;
      default: break;
    }
    // Servo enable/reset/stop → CiA 402 controlword, one FSA step per cycle.
    const drive::State st = d.state();
    const bool reset_edge = (ctl & kCtlReset) && !(card.prev_control & kCtlReset);
    std::uint16_t cw = 0x0006;
    if (st == drive::State::fault || st == drive::State::fault_reaction_active) {
      cw = reset_edge ? 0x0080 : 0x0000;
    } else if (ctl & kCtlStop) {
      cw = (st == drive::State::operation_enabled || st == drive::State::quick_stop_active) ? 0x0002 : 0x0000;
    } else if (ctl & kCtlEnable) {
      switch (st) {
        case drive::State::ready_to_switch_on: cw = 0x0007; break;
        case drive::State::switched_on:
        case drive::State::operation_enabled: cw = 0x000F; break;
        case drive::State::quick_stop_active: cw = 0x0000; break;
        default: cw = 0x0006; break;
      }
      if (card.work_mode == wm_homing && cw == 0x000F && st == drive::State::operation_enabled) cw |= 0x0010;
    }
    o.controlword = cw;
    card.prev_control = ctl;
  }
}

void DriveSlave::multiaxis_status() noexcept {
  for (int k = 0; k < axes(); ++k) {
    const auto& m = modules_[static_cast<std::size_t>(k)];
    OdEntry* h = m[4];
    OdEntry* sw = m[5];
    OdEntry* v1 = m[6];
    OdEntry* v2 = m[7];
    if (!h || !sw || !v1 || !v2) continue;
    const Card& slot = cards_[static_cast<std::size_t>(k)];
    const int ci = slot.card >= 0 ? slot.card : k;
    const Card& card = cards_[static_cast<std::size_t>(ci)];
    const drive::Cia402Drive& d = *axes_[static_cast<std::size_t>(ci)];
    const auto& o = d.objects();
    const drive::State st = d.state();
    h->set_int((ci + 1) | (card.work_mode << 8) | (card.handshake ? kHdrHandshake : 0));
    std::uint16_t w = 0;
    if (st == drive::State::operation_enabled) w |= kStEnabled;
    if (st == drive::State::fault || st == drive::State::fault_reaction_active) w |= kStAlarm;
    if (st == drive::State::ready_to_switch_on || st == drive::State::switched_on || st == drive::State::operation_enabled) w |= kStReady;
    if (o.statusword & 0x0400) w |= kStReached;
    if (d.homed()) w |= kStHomed;
    if (o.error_code == drive::kErrorFollowing || (card.work_mode == wm_position && (o.statusword & 0x2000))) w |= kStFollowing;
    if (slot.address_error) w |= kStAddress;
    if (card.mode_pending) w |= kStMode;
    if (st == drive::State::quick_stop_active) w |= kStQuickStop;
    sw->set_int(w);
    if (card.work_mode == wm_velocity) {
      v1->set_int(o.velocity_actual);
      v2->set_int(o.position_actual);
    } else {
      v1->set_int(o.position_actual);
      v2->set_int(o.following_error_actual);
    }
  }
}

}  // namespace omnitwin::ethercat
