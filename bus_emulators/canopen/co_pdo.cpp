// bus_emulators/canopen — the process data objects of one node (see co_pdo.hpp).
#include "bus_emulators/canopen/co_pdo.hpp"

#include <algorithm>
#include <cstring>

namespace omnitwin::canopen {

namespace {

constexpr std::uint16_t kRxComm = 0x1400, kRxMap = 0x1600, kTxComm = 0x1800, kTxMap = 0x1A00;
constexpr SimTime kMs = 1'000'000;

std::uint16_t comm_index(int n, bool tx) { return static_cast<std::uint16_t>((tx ? kTxComm : kRxComm) + n); }
std::uint16_t map_index(int n, bool tx) { return static_cast<std::uint16_t>((tx ? kTxMap : kRxMap) + n); }

std::int64_t value_of(const ObjectDictionary& od, std::uint16_t idx, std::uint8_t sub, std::int64_t dflt) {
  const OdEntry* e = od.entry(idx, sub);
  return e ? e->as_int() : dflt;
}

std::uint32_t le32(std::span<const std::uint8_t> d) {
  std::uint32_t v = 0;
  std::memcpy(&v, d.data(), std::min<std::size_t>(d.size(), 4));
  return v;
}

bool sync_type(std::uint8_t t) { return t <= 240; }
bool event_type(std::uint8_t t) { return t >= 254; }

}  // namespace

PdoEngine::PdoEngine(ObjectDictionary& od, std::uint8_t node_id) : od_(od), node_id_(node_id) {}

void PdoEngine::attach() {
  for (int n = 0; n < kMaxPdos; ++n) {
    install_hooks(n, false);
    install_hooks(n, true);
  }
  resolve_all();
}

void PdoEngine::install_hooks(int n, bool tx) {
  OdObject* comm = od_.find(comm_index(n, tx));
  OdObject* map = od_.find(map_index(n, tx));
  if (!comm || !map) return;
  comm->check = [this, n, tx](const OdObject&, std::uint8_t sub, std::span<const std::uint8_t> d) {
    return check_comm(n, tx, sub, d);
  };
  map->check = [this, n, tx](const OdObject&, std::uint8_t sub, std::span<const std::uint8_t> d) {
    return check_mapping(n, tx, sub, d);
  };
  comm->after_write = [this, n, tx](OdObject&, std::uint8_t) { resolve(n, tx); };
  map->after_write = [this, n, tx](OdObject&, std::uint8_t) { resolve(n, tx); };
}

void PdoEngine::resolve_all() {
  for (int n = 0; n < kMaxPdos; ++n) {
    resolve(n, false);
    resolve(n, true);
  }
}

// Reads one PDO's parameters and mapping into its resolved form. An inconsistent mapping (an
// entry gone, too long) leaves the PDO invalid.
void PdoEngine::resolve(int n, bool tx) {
  Pdo& p = (tx ? tx_ : rx_)[static_cast<std::size_t>(n)];
  const std::uint16_t ci = comm_index(n, tx), mi = map_index(n, tx);
  p.present = od_.find(ci) && od_.find(mi);
  p.valid = false;
  if (!p.present) return;
  const auto cob_id = static_cast<std::uint32_t>(value_of(od_, ci, 1, cob::invalid));
  p.cob_id = cob_id & cob::id_mask_11;
  p.rtr_allowed = !(cob_id & cob::no_rtr);
  p.type = static_cast<std::uint8_t>(value_of(od_, ci, 2, 255));
  p.inhibit_ns = tx ? value_of(od_, ci, 3, 0) * 100'000 : 0;
  p.event_ns = value_of(od_, ci, 5, 0) * kMs;
  p.sync_start = static_cast<std::uint8_t>(tx ? value_of(od_, ci, 6, 0) : 0);
  p.n = static_cast<int>(value_of(od_, mi, 0, 0));
  p.bytes = 0;
  for (int i = 0; i < p.n && i < kMaxMapped; ++i) {
    const auto v = static_cast<std::uint32_t>(value_of(od_, mi, static_cast<std::uint8_t>(i + 1), 0));
    const auto idx = static_cast<std::uint16_t>(v >> 16);
    OdEntry* e = idx >= 0x1000 ? od_.entry(idx, static_cast<std::uint8_t>(v >> 8)) : nullptr;
    if (idx >= 0x1000 && !e) return;  // the mapped object vanished: stays invalid
    p.map[static_cast<std::size_t>(i)] = {e ? e->data() : nullptr, static_cast<std::uint8_t>((v & 0xFF) / 8)};
    p.bytes += (v & 0xFF) / 8;
  }
  if (p.n > kMaxMapped || p.bytes > 8) return;
  p.valid = !(cob_id & cob::invalid) && !(cob_id & cob::frame_29) && p.cob_id != 0;
  p.buffered = false;
  p.sync_count = 0;
  p.started = p.sync_start == 0;
}

// ---------------------------------------------------------------------------------------
// Checks of SDO writes

SdoAbort PdoEngine::check_comm(int n, bool tx, std::uint8_t sub, std::span<const std::uint8_t> d) const {
  const Pdo& p = (tx ? tx_ : rx_)[static_cast<std::size_t>(n)];
  const bool valid_now = !(static_cast<std::uint32_t>(value_of(od_, comm_index(n, tx), 1, cob::invalid)) & cob::invalid);
  switch (sub) {
    case 1: {
      const std::uint32_t v = le32(d);
      if (v & cob::frame_29) return SdoAbort::value_range;  // 29-bit PDOs: not supported
      if ((v & cob::id_mask_11) == 0 && !(v & cob::invalid)) return SdoAbort::value_range;
      // The identifier may change only while the PDO does not exist (bit 31 set).
      if (valid_now && !(v & cob::invalid) && (v & cob::id_mask_11) != p.cob_id) return SdoAbort::value_range;
      return SdoAbort::none;
    }
    case 2: {
      const std::uint8_t t = d[0];
      const bool ok = tx ? (t <= 240 || t >= 252) : (t <= 240 || t >= 254);
      return ok ? SdoAbort::none : SdoAbort::value_range;
    }
    case 3:  // inhibit time: not while the PDO exists
      return tx && valid_now ? SdoAbort::state : SdoAbort::none;
    case 6:
      return d[0] > 240 ? SdoAbort::value_range : SdoAbort::none;
    default:
      return SdoAbort::none;
  }
}

SdoAbort PdoEngine::check_mapping(int n, bool tx, std::uint8_t sub, std::span<const std::uint8_t> d) const {
  const auto cob_id = static_cast<std::uint32_t>(value_of(od_, comm_index(n, tx), 1, cob::invalid));
  if (!(cob_id & cob::invalid)) return SdoAbort::state;  // the PDO must not exist
  const std::uint16_t mi = map_index(n, tx);
  if (sub != 0) {
    if (value_of(od_, mi, 0, 0) != 0) return SdoAbort::subindex0_not_zero;
    return check_entry(tx, le32(d));
  }
  // Enabling the mapping: every entry 1..count valid, 64 bits at most.
  const std::uint8_t count = d[0];
  if (count > kMaxMapped) return SdoAbort::value_range;
  std::uint32_t bits = 0;
  for (std::uint8_t s = 1; s <= count; ++s) {
    const auto v = static_cast<std::uint32_t>(value_of(od_, mi, s, 0));
    if (const SdoAbort a = check_entry(tx, v); a != SdoAbort::none) return a;
    bits += v & 0xFF;
  }
  return bits > 64 ? SdoAbort::pdo_length_exceeded : SdoAbort::none;
}

SdoAbort PdoEngine::check_entry(bool tx, std::uint32_t v) const {
  const auto idx = static_cast<std::uint16_t>(v >> 16);
  const auto sub = static_cast<std::uint8_t>(v >> 8);
  const auto bits = static_cast<std::uint8_t>(v);
  if (bits == 0 || bits % 8 != 0) return SdoAbort::param_incompatible;  // byte-granular mapping
  if (idx >= 0x0002 && idx <= 0x0007 && sub == 0) {  // dummy entry: RPDO only, its type's size
    static constexpr std::uint8_t kDummyBits[8] = {0, 0, 8, 16, 32, 8, 16, 32};
    return !tx && kDummyBits[idx] == bits ? SdoAbort::none : SdoAbort::not_mappable;
  }
  const OdObject* o = od_.find(idx);
  if (!o) return SdoAbort::no_object;
  const OdEntry* e = o->entry(sub);
  if (!e) return SdoAbort::no_subindex;
  if (!(e->access & (tx ? od_access::txpdo : od_access::rxpdo))) return SdoAbort::not_mappable;
  if (e->bits != bits) return SdoAbort::param_incompatible;
  return SdoAbort::none;
}

// ---------------------------------------------------------------------------------------
// The cyclic path

void PdoEngine::gather(const Pdo& p, std::uint8_t* out) const {
  int at = 0;
  for (int i = 0; i < p.n; ++i) {
    const Mapped& m = p.map[static_cast<std::size_t>(i)];
    if (m.ptr) std::memcpy(out + at, m.ptr, m.bytes);
    else std::memset(out + at, 0, m.bytes);
    at += m.bytes;
  }
}

void PdoEngine::scatter(const Pdo& p, const std::uint8_t* in) const {
  int at = 0;
  for (int i = 0; i < p.n; ++i) {
    const Mapped& m = p.map[static_cast<std::size_t>(i)];
    if (m.ptr) std::memcpy(m.ptr, in + at, m.bytes);
    at += m.bytes;
  }
}

bool PdoEngine::changed(const Pdo& p) const {
  std::uint8_t now[8] = {};
  gather(p, now);
  return !p.sent_once || std::memcmp(now, p.buffer.data(), static_cast<std::size_t>(p.bytes)) != 0;
}

bool PdoEngine::transmit(Pdo& p, const std::uint8_t* data, SimTime now, const SendFn& send) {
  can::Frame f = frame11(p.cob_id, static_cast<std::uint8_t>(p.bytes));
  std::memcpy(f.data.data(), data, static_cast<std::size_t>(p.bytes));
  if (data != p.buffer.data()) std::memcpy(p.buffer.data(), data, static_cast<std::size_t>(p.bytes));
  p.last_tx = now;
  p.sent_once = true;
  if (!send(f, now)) {
    ++stats_.tx_refused;
    return false;
  }
  ++stats_.tpdo_tx;
  return true;
}

RpdoStatus PdoEngine::on_frame(const can::Frame& f, SimTime now, NmtState s, const SendFn& send) {
  if (s != NmtState::operational || f.extended) return RpdoStatus::not_rpdo;
  if (f.kind == can::FrameKind::remote) {
    for (Pdo& p : tx_) {
      if (!p.valid || p.cob_id != f.id || !p.rtr_allowed || (p.type != 252 && p.type != 253)) continue;
      std::uint8_t d[8] = {};
      if (p.type == 253) gather(p, d);
      else std::memcpy(d, p.buffer.data(), 8);  // sampled at the last SYNC
      if (transmit(p, d, now, send)) ++stats_.rtr_answers;
    }
    return RpdoStatus::not_rpdo;
  }
  for (Pdo& p : rx_) {
    if (!p.valid || p.cob_id != f.id || f.kind != can::FrameKind::data) continue;
    ++stats_.rpdo_rx;
    p.last_rx = now;
    p.deadline_missed = false;
    if (f.dlc < p.bytes) {
      ++stats_.length_errors;
      error(0x8210, now);
      return RpdoStatus::too_short;
    }
    if (sync_type(p.type)) {
      std::memcpy(p.buffer.data(), f.data.data(), 8);
      p.buffered = true;
    } else {
      scatter(p, f.data.data());
    }
    if (f.dlc > p.bytes) {
      ++stats_.length_errors;
      error(0x8220, now);
      return RpdoStatus::too_long;
    }
    return RpdoStatus::applied;
  }
  return RpdoStatus::not_rpdo;
}

void PdoEngine::on_sync(std::uint8_t counter, SimTime now, NmtState s, const SendFn& send) {
  if (s != NmtState::operational) return;
  for (Pdo& p : rx_)
    if (p.valid && p.buffered) scatter(p, p.buffer.data()), p.buffered = false;
  for (Pdo& p : tx_) {
    if (!p.valid) continue;
    if (p.type == 252) {  // sampled now, sent on request
      gather(p, p.buffer.data());
      continue;
    }
    if (!sync_type(p.type)) continue;
    if (p.type == 0) {
      if (changed(p)) {
        std::uint8_t d[8] = {};
        gather(p, d);
        transmit(p, d, now, send);
      }
      continue;
    }
    // Every type-th SYNC, starting at the SYNC whose counter equals the start value.
    if (!p.started) {
      if (counter == 0 || counter != p.sync_start) continue;
      p.started = true;
      p.sync_count = 0;  // this SYNC is the first one counted
    }
    if (++p.sync_count < p.type) continue;
    p.sync_count = 0;
    std::uint8_t d[8] = {};
    gather(p, d);
    transmit(p, d, now, send);
  }
}

void PdoEngine::on_time(SimTime now, NmtState s, const SendFn& send) {
  if (s != NmtState::operational) return;
  for (Pdo& p : tx_) {
    if (!p.valid || !event_type(p.type)) continue;
    if (p.last_tx >= 0 && now - p.last_tx < p.inhibit_ns) continue;
    const bool timer = p.event_ns > 0 && p.last_tx >= 0 && now - p.last_tx >= p.event_ns;
    if (!timer && !changed(p)) continue;
    std::uint8_t d[8] = {};
    gather(p, d);
    transmit(p, d, now, send);
  }
  for (Pdo& p : rx_) {
    if (!p.valid || p.event_ns == 0 || p.last_rx < 0 || p.deadline_missed) continue;
    if (now - p.last_rx <= p.event_ns) continue;
    p.deadline_missed = true;
    ++stats_.rpdo_timeouts;
    error(0x8250, now);
  }
}

void PdoEngine::on_operational(SimTime /*now*/) {
  for (Pdo& p : tx_) {
    p.sent_once = false;  // event-driven ones send their data once
    p.last_tx = -1;
    p.sync_count = 0;
    p.started = p.sync_start == 0;
  }
  for (Pdo& p : rx_) {
    p.buffered = false;
    p.last_rx = -1;  // deadline monitoring starts with the first RPDO received (CiA 301)
    p.deadline_missed = false;
  }
}

}  // namespace omnitwin::canopen
