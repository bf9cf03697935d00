// controller/ethercat — master-side CiA 402 drive layer (see ec_drive.hpp).
#include "controller/ethercat/ec_drive.hpp"

#include <fmt/format.h>

#include <algorithm>
#include <limits>

namespace omnitwin::controller::ethercat {

using botnana::PdsGoal;

namespace {
constexpr std::uint16_t kControlword = 0x6040, kStatusword = 0x6041;
constexpr std::uint16_t kCwMaster = 0x008F;  // bits the goal logic owns: 0–3, 7
constexpr int kResetCycles = 50;             // re-pulse fault reset after this many cycles

// Sizes and signedness of the CiA 402 objects, for slaves whose ESI does not list them.
struct Known {
  std::uint16_t index;
  std::uint8_t bytes;
  bool is_signed;
};
constexpr Known kKnown[] = {
    {0x603F, 2, false}, {0x6040, 2, false}, {0x6041, 2, false}, {0x605A, 2, true}, {0x605D, 2, true},
    {0x605E, 2, true},  {0x6060, 1, true},  {0x6061, 1, true},  {0x6062, 4, true}, {0x6064, 4, true},
    {0x6065, 4, false}, {0x606B, 4, true},  {0x606C, 4, true},  {0x6071, 2, true}, {0x6072, 2, false},
    {0x6074, 2, true},  {0x6077, 2, true},  {0x607A, 4, true},  {0x607C, 4, true}, {0x607D, 4, true},
    {0x607E, 1, false}, {0x607F, 4, false}, {0x6080, 4, false}, {0x6081, 4, false}, {0x6083, 4, false},
    {0x6084, 4, false}, {0x6085, 4, false}, {0x6087, 4, false}, {0x6098, 1, true}, {0x6099, 4, false},
    {0x609A, 4, false}, {0x60B1, 4, true},  {0x60B2, 2, true},  {0x60F4, 4, true}, {0x60FD, 4, false},
    {0x60FE, 4, false}, {0x60FF, 4, true},  {0x6502, 4, false},
};
const Known* known(std::uint16_t index) {
  const std::uint16_t base = index >= 0x6000 && index < 0x6800 ? static_cast<std::uint16_t>(0x6000 + (index - 0x6000) % 0x800) : index;
  for (const auto& k : kKnown)
    if (k.index == base) return &k;
  return nullptr;
}
bool signed_type(const std::string& t) {
  return t == "SINT" || t == "INT" || t == "DINT" || t == "LINT" || t.rfind("INTEGER", 0) == 0;
}
const omnitwin::ethercat::EsiObjectEntry* esi_entry(const SlaveStatus& s, std::uint16_t index, std::uint8_t sub) {
  if (!s.esi) return nullptr;
  const auto* o = s.esi->object(index);
  if (!o) return nullptr;
  for (const auto& e : o->entries)
    if (e.subindex == sub) return &e;
  return nullptr;
}
// "" when `value` fits an object of `bits` bits (signed or not); else why not, naming the
// value, the object and its type's range.
std::string range_error(std::int64_t value, unsigned bits, bool is_signed, std::uint16_t index, std::uint8_t sub) {
  if (bits == 0 || bits > 64 || (is_signed && bits == 64)) return "";
  const std::int64_t lo = is_signed ? -(std::int64_t{1} << (bits - 1)) : 0;
  const std::int64_t hi = is_signed    ? (std::int64_t{1} << (bits - 1)) - 1
                          : bits == 64 ? std::numeric_limits<std::int64_t>::max()
                                       : static_cast<std::int64_t>((std::uint64_t{1} << bits) - 1);
  if (value >= lo && value <= hi) return "";
  return fmt::format("{} does not fit 0x{:04X}:{:02X} ({}{}: {}..{})", value, index, sub, is_signed ? "INTEGER" : "UNSIGNED",
                     bits, lo, hi);
}
}  // namespace

const char* to_string(PdsState s) {
  switch (s) {
    case PdsState::not_ready_to_switch_on: return "not_ready_to_switch_on";
    case PdsState::switch_on_disabled: return "switch_on_disabled";
    case PdsState::ready_to_switch_on: return "ready_to_switch_on";
    case PdsState::switched_on: return "switched_on";
    case PdsState::operation_enabled: return "operation_enabled";
    case PdsState::quick_stop_active: return "quick_stop_active";
    case PdsState::fault_reaction_active: return "fault_reaction_active";
    case PdsState::fault: return "fault";
  }
  return "?";
}

PdsState decode_statusword(std::uint16_t sw) {
  if ((sw & 0x4F) == 0x0F) return PdsState::fault_reaction_active;
  if ((sw & 0x4F) == 0x08) return PdsState::fault;
  if ((sw & 0x4F) == 0x40) return PdsState::switch_on_disabled;
  if ((sw & 0x6F) == 0x21) return PdsState::ready_to_switch_on;
  if ((sw & 0x6F) == 0x23) return PdsState::switched_on;
  if ((sw & 0x6F) == 0x27) return PdsState::operation_enabled;
  if ((sw & 0x6F) == 0x07) return PdsState::quick_stop_active;
  return PdsState::not_ready_to_switch_on;
}

std::uint16_t controlword_towards(PdsState s, PdsGoal goal) {
  constexpr std::uint16_t disable_voltage = 0x0000, shutdown = 0x0006, switch_on = 0x0007, enable = 0x000F,
                          quick_stop = 0x0002;
  switch (goal) {
    case PdsGoal::switch_on_disabled:
      return disable_voltage;
    case PdsGoal::ready_to_switch_on:
      return s == PdsState::quick_stop_active ? disable_voltage : shutdown;
    case PdsGoal::switched_on:
      if (s == PdsState::switch_on_disabled) return shutdown;
      if (s == PdsState::quick_stop_active) return disable_voltage;
      return switch_on;
    case PdsGoal::operation_enabled:
      switch (s) {
        case PdsState::switch_on_disabled: return shutdown;
        case PdsState::ready_to_switch_on: return switch_on;
        case PdsState::switched_on: case PdsState::operation_enabled: case PdsState::quick_stop_active: return enable;
        default: return disable_voltage;
      }
    case PdsGoal::quick_stop_active:
      if (s == PdsState::operation_enabled || s == PdsState::quick_stop_active) return quick_stop;
      return s == PdsState::switched_on || s == PdsState::ready_to_switch_on ? quick_stop : disable_voltage;
  }
  return disable_voltage;
}

EcDrives::EcDrives(EcMaster& master) : m_(master) {}

std::uint16_t EcDrives::object(int ch, std::uint16_t index) {
  if (ch > 1 && index >= 0x6000 && index < 0x6800) return static_cast<std::uint16_t>(index + 0x800 * (ch - 1));
  return index;
}

EcDrives::Axis* EcDrives::find(int slave, int ch) {
  for (auto& a : axes_)
    if (a.slave == slave && a.ch == ch) return &a;
  return nullptr;
}
const EcDrives::Axis* EcDrives::find(int slave, int ch) const {
  for (const auto& a : axes_)
    if (a.slave == slave && a.ch == ch) return &a;
  return nullptr;
}

bool EcDrives::object_signed(int slave, std::uint16_t index, std::uint8_t sub) const {
  if (const auto* e = esi_entry(m_.slave(slave - 1), index, sub); e && !e->data_type.empty()) return signed_type(e->data_type);
  const Known* k = known(index);
  return k && k->is_signed;
}

unsigned EcDrives::object_bytes(int slave, std::uint16_t index, std::uint8_t sub) const {
  if (const auto* e = esi_entry(m_.slave(slave - 1), index, sub); e && e->bit_size) return (e->bit_size + 7u) / 8u;
  const Known* k = known(index);
  return k ? k->bytes : 0;
}

void EcDrives::update() {
  if (!built_) {
    if (m_.phase() != MasterPhase::running) return;
    for (int p = 0; p < m_.slave_count(); ++p) {
      const SlaveStatus& s = m_.slave(p);
      const int n = s.esi ? std::max(1, s.esi->axes) : 1;
      for (int ch = 1; ch <= n; ++ch) {
        const bool drive = (s.esi && s.esi->profile == 402) || m_.find_entry(p, object(ch, kStatusword), 0);
        if (!drive) continue;
        Axis a;
        a.slave = p + 1;
        a.ch = ch;
        a.cw_at = m_.find_entry(p, object(ch, kControlword), 0);
        a.sw_at = m_.find_entry(p, object(ch, kStatusword), 0);
        a.mode_display_at = m_.find_entry(p, object(ch, 0x6061), 0);
        axes_.push_back(a);
      }
    }
    built_ = true;
  }
  if (m_.stats().segment_losses != losses_seen_) {
    losses_seen_ = m_.stats().segment_losses;
    stop_axes();
  }
  for (auto& a : axes_) {
    if (a.sw_at) a.sw = static_cast<std::uint16_t>(m_.read_entry(*a.sw_at, false));
    a.state = decode_statusword(a.sw);
    if (a.mode_display_at && m_.read_entry(*a.mode_display_at, true) == 6 && (a.sw & 0x3400) == 0x1400) a.homed = true;
    // go: clear bit 4 once the drive acknowledged a set-point that has been out a cycle
    if (a.cw_user & 0x0010) {
      if (a.go_cycles > 0 && (a.sw & 0x1000)) {
        a.cw_user &= static_cast<std::uint16_t>(~0x0010);
        a.go_cycles = 0;
      } else {
        ++a.go_cycles;
      }
    } else {
      a.go_cycles = 0;
    }
    std::uint16_t cw = a.cw_user;
    if (a.goal) {
      std::uint16_t bits = 0;
      if (a.state == PdsState::fault || a.state == PdsState::fault_reaction_active) {
        if (a.reset_pending && a.state == PdsState::fault) {
          bits = (a.reset_phase % kResetCycles) == 0 ? 0x0000 : 0x0080;  // rising edge, held
          ++a.reset_phase;
        }
      } else {
        if (a.reset_pending && a.reset_phase > 0) a.reset_pending = false;  // left the fault
        if (a.reset_pending && a.state != PdsState::fault) a.reset_pending = false;
        bits = controlword_towards(a.state, *a.goal);
      }
      cw = static_cast<std::uint16_t>((a.cw_user & ~kCwMaster) | bits);
    }
    if (a.cw_at) m_.write_entry(*a.cw_at, cw);
  }
}

// The segment was lost: every axis's goal becomes quick stop (disable voltage where quick
// stop is not reachable), velocity and torque set-points zero, the position set-point held at
// the last actual position. What goes out once the segment is back.
void EcDrives::stop_axes() {
  for (auto& a : axes_) {
    a.goal = PdsGoal::quick_stop_active;
    a.reset_pending = false;
    a.cw_user &= static_cast<std::uint16_t>(~0x0010);
    const int p = a.slave - 1;
    for (const std::uint16_t index : {std::uint16_t{0x60FF}, std::uint16_t{0x6071}})
      if (const auto at = m_.find_entry(p, object(a.ch, index), 0)) m_.write_entry(*at, 0);
    const auto target = m_.find_entry(p, object(a.ch, 0x607A), 0), actual = m_.find_entry(p, object(a.ch, 0x6064), 0);
    if (target && actual) m_.write_entry(*target, m_.read_entry(*actual, true));
  }
  stopped_ = !axes_.empty();
}

std::optional<PdsState> EcDrives::state(int slave, int ch) const {
  const Axis* a = find(slave, ch);
  if (!a) return std::nullopt;
  return a->state;
}

std::uint16_t EcDrives::statusword(int slave, int ch) const {
  const Axis* a = find(slave, ch);
  return a ? a->sw : 0;
}

bool EcDrives::any_enabled() const {
  return std::any_of(axes_.begin(), axes_.end(), [](const Axis& a) { return a.state == PdsState::operation_enabled; });
}

bool EcDrives::all_enabled() const {
  if (axes_.empty()) return false;
  for (const auto& a : axes_)
    if (a.state != PdsState::operation_enabled) return false;
  return true;
}

std::optional<bool> EcDrives::homed(int slave, int ch) const {
  const Axis* a = find(slave, ch);
  if (!a) return std::nullopt;
  return a->homed;
}

bool EcDrives::set_homed(int slave, int ch, bool homed) {
  Axis* a = find(slave, ch);
  if (a) a->homed = homed;
  return a != nullptr;
}

bool EcDrives::has_drive(int slave, int ch) const { return find(slave, ch) != nullptr; }

std::optional<std::int64_t> EcDrives::read(int slave, int ch, std::uint16_t index, std::uint8_t sub) {
  const Axis* a = find(slave, ch);
  if (!a) {
    error_ = fmt::format("no drive at slave {} channel {}", slave, ch);
    return std::nullopt;
  }
  const std::uint16_t idx = object(ch, index);
  if (index == kControlword && sub == 0) return a->cw_user;
  if (index == kStatusword && sub == 0 && a->sw_at) return a->sw;
  if (const auto at = m_.find_entry(slave - 1, idx, sub)) return m_.read_entry(*at, object_signed(slave, idx, sub));
  const auto key = std::make_tuple(slave, idx, sub);
  if (const ReadBack* rb = read_back(slave, idx, sub)) return read_back_value(*rb, key);
  if (!sdo_reading_[key]) {
    const bool is_signed = object_signed(slave, idx, sub);
    const std::uint64_t id = m_.sdo_upload(slave - 1, idx, sub, [this, key, is_signed](const SdoResult& r) {
      sdo_reading_[key] = false;
      if (r.status == SdoStatus::done) {
        sdo_values_[key] = bytes_value(r.data, is_signed);
      } else {
        error_ = fmt::format("SDO upload 0x{:04X}:{} of slave {}: {} 0x{:08X}", r.request.index, r.request.sub,
                             r.position + 1, to_string(r.status), r.abort_code);
      }
    });
    sdo_reading_[key] = id != 0;
  }
  const auto it = sdo_values_.find(key);
  if (it == sdo_values_.end()) return std::nullopt;
  return it->second;
}

const ReadBack* EcDrives::read_back(int slave, std::uint16_t index, std::uint8_t sub) const {
  for (const auto& rb : m_.slave(slave - 1).read_back)
    if (rb.index == index && rb.sub == sub) return &rb;
  return nullptr;
}

// The master's copy of an object read back at start-up: the value written since (drive-nsl!),
// else the start-up answer; no upload. A drive that aborted it lacks the object.
std::optional<std::int64_t> EcDrives::read_back_value(const ReadBack& rb, const std::tuple<int, std::uint16_t, std::uint8_t>& key) {
  if (const auto it = sdo_values_.find(key); it != sdo_values_.end()) return it->second;
  const int slave = std::get<0>(key);
  if (rb.status == SdoStatus::done) return bytes_value(rb.data, object_signed(slave, rb.index, rb.sub));
  error_ = fmt::format("slave {} has no object 0x{:04X}:{:02X}: its start-up upload {}{}", slave, rb.index, rb.sub,
                       rb.status == SdoStatus::aborted ? "was aborted" : std::string("ended ") + to_string(rb.status),
                       rb.status == SdoStatus::aborted
                           ? fmt::format(" with 0x{:08X} ({})", rb.abort_code, sdo_abort_text(rb.abort_code))
                           : "");
  return std::nullopt;
}

bool EcDrives::write(int slave, int ch, std::uint16_t index, std::uint8_t sub, std::int64_t value) {
  Axis* a = find(slave, ch);
  if (!a) {
    error_ = fmt::format("no drive at slave {} channel {}", slave, ch);
    return false;
  }
  const std::uint16_t idx = object(ch, index);
  if (index == kControlword && sub == 0) {
    if (!fits(value, 16, false, idx, sub)) return false;
    a->cw_user = static_cast<std::uint16_t>(value);
    if (!(a->cw_user & 0x0010)) a->go_cycles = 0;
    if (!a->cw_at) m_.sdo_download(slave - 1, idx, 0, value_bytes(value, 2));
    return true;
  }
  if (const auto at = m_.find_entry(slave - 1, idx, sub)) {
    if (!at->output) {
      error_ = fmt::format("0x{:04X}:{} of slave {} is an input (TxPDO) object", idx, sub, slave);
      return false;
    }
    if (!fits(value, at->bits, object_signed(slave, idx, sub), idx, sub)) return false;
    m_.write_entry(*at, value);
    return true;
  }
  const unsigned bytes = object_bytes(slave, idx, sub);
  if (bytes == 0) {
    error_ = fmt::format("0x{:04X}:{} of slave {}: unknown object size", idx, sub, slave);
    return false;
  }
  if (!fits(value, bytes * 8, object_signed(slave, idx, sub), idx, sub)) return false;
  const auto key = std::make_tuple(slave, idx, sub);
  const std::uint64_t id = m_.sdo_download(slave - 1, idx, sub, value_bytes(value, bytes), [this, key, value, slave](const SdoResult& r) {
    if (r.status == SdoStatus::done) {
      sdo_values_[key] = value;
      return;
    }
    error_ = fmt::format("SDO download 0x{:04X}:{:02X} = {} to slave {} {}{}", r.request.index, r.request.sub, value,
                         slave, to_string(r.status),
                         r.status == SdoStatus::aborted
                             ? fmt::format(" by the drive: 0x{:08X} ({})", r.abort_code, sdo_abort_text(r.abort_code))
                             : "");
    std::string& failures = request_failures_[slave];
    if (failures.size() < 1024) failures += failures.empty() ? error_ : "; " + error_;  // bounded until taken
  });
  if (id == 0) {
    error_ = fmt::format("slave {} has no SDO mailbox", slave);
    return false;
  }
  return true;
}

bool EcDrives::fits(std::int64_t value, unsigned bits, bool is_signed, std::uint16_t index, std::uint8_t sub) {
  std::string why = range_error(value, bits, is_signed, index, sub);
  if (why.empty()) return true;
  error_ = std::move(why);
  return false;
}

void EcDrives::set_goal(int slave, int ch, PdsGoal goal) {
  Axis* a = find(slave, ch);
  if (!a) {
    error_ = fmt::format("no drive at slave {} channel {}", slave, ch);
    return;
  }
  a->goal = goal;
  a->reset_pending = true;
  a->reset_phase = 0;
  stopped_ = false;  // a new goal from the user lifts the segment-loss stop
}

void EcDrives::release_goal(int slave, int ch) {
  if (Axis* a = find(slave, ch)) {
    a->goal.reset();
    a->reset_pending = false;
  }
}

std::optional<botnana::ObjectRef> EcDrives::user_pdo(int slave, int ch, botnana::UserPdo which) const {
  if (!find(slave, ch)) return std::nullopt;
  return user_pdos_[static_cast<std::size_t>(which)];
}

void EcDrives::set_user_pdo(botnana::UserPdo which, botnana::ObjectRef object) {
  user_pdos_[static_cast<std::size_t>(which)] = object;
}

std::string EcDrives::take_request_failures(int slave) {
  const auto it = request_failures_.find(slave);
  if (it == request_failures_.end()) return "";
  std::string failures = std::move(it->second);
  request_failures_.erase(it);
  return failures;
}

bool EcDrives::requests_pending(int slave) const { return m_.sdo_pending(slave - 1) > 0; }

std::optional<std::uint16_t> EcDrives::last_emergency(int slave, int ch) const {
  if (slave < 1 || slave > m_.slave_count() || ch < 1) return std::nullopt;
  const auto& e = m_.slave(slave - 1).axis_emergency;
  if (static_cast<std::size_t>(ch) > e.size() || m_.slave(slave - 1).emergencies == 0) return std::nullopt;
  return e[static_cast<std::size_t>(ch) - 1];
}

}  // namespace omnitwin::controller::ethercat
