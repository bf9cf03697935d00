// bus_emulators/canopen — the EMCY producer (see co_emcy.hpp).
#include "bus_emulators/canopen/co_emcy.hpp"

#include "bus_emulators/drive/cia402_drive.hpp"

#include <algorithm>

namespace omnitwin::canopen {

std::uint8_t register_bit_of(std::uint16_t code) { return drive::error_class_bit(code); }

EmcyProducer::EmcyProducer(ObjectDictionary& od, std::uint8_t node_id) : od_(od), node_id_(node_id) {
  if (OdObject* h = od_.find(0x1003)) {
    // CiA 301: only 0 may be written to sub 0, and it deletes the history.
    h->check = [](const OdObject&, std::uint8_t sub, std::span<const std::uint8_t> d) {
      return sub == 0 && d[0] != 0 ? SdoAbort::value_range : SdoAbort::none;
    };
    h->after_write = [](OdObject& o, std::uint8_t sub) {
      if (sub != 0) return;
      for (OdEntry& e : o.entries)
        if (e.subindex != 0) e.set_int(0);
    };
  }
  if (OdObject* c = od_.find(0x1014)) {
    c->check = [](const OdObject& o, std::uint8_t, std::span<const std::uint8_t> d) {
      const auto before = static_cast<std::uint32_t>(o.entries.front().as_int());
      const std::uint32_t v = get_u32(d.data());
      if (v & cob::frame_29) return SdoAbort::value_range;  // 29-bit identifiers: not supported
      if (v & cob::invalid) return SdoAbort::none;
      if ((v & cob::id_mask_11) == 0) return SdoAbort::value_range;
      // As for PDOs: the identifier changes only while the EMCY is invalid (bit 31 set).
      const bool valid_now = !(before & cob::invalid);
      return valid_now && (v & cob::id_mask_11) != (before & cob::id_mask_11) ? SdoAbort::value_range : SdoAbort::none;
    };
  }
}

std::uint8_t EmcyProducer::error_register() const {
  std::uint8_t r = 0;
  for (int i = 0; i < active_n_; ++i) r |= static_cast<std::uint8_t>(error_register::generic | register_bit_of(active_[static_cast<std::size_t>(i)].code));
  return r;
}

void EmcyProducer::update_register() {
  if (OdEntry* e = od_.entry(0x1001, 0)) e->set_int(error_register());
}

// The newest error at 0x1003:1, the others one down; sub 0 counts them (up to the entries the
// object has).
void EmcyProducer::push_history(std::uint16_t code, std::array<std::uint8_t, 5> mfr) {
  OdObject* h = od_.find(0x1003);
  if (!h || !h->entry(0)) return;
  const int cap = h->max_subindex();
  for (int s = cap; s > 1; --s) {
    OdEntry* dst = h->entry(static_cast<std::uint8_t>(s));
    const OdEntry* src = h->entry(static_cast<std::uint8_t>(s - 1));
    if (dst && src) dst->set_int(src->as_int());
  }
  // Low 16 bits the error code, high 16 bits manufacturer-specific additional information.
  if (OdEntry* first = h->entry(1)) first->set_int(static_cast<std::int64_t>(code | (std::uint32_t{mfr[0]} << 16) | (std::uint32_t{mfr[1]} << 24)));
  OdEntry* n = h->entry(0);
  n->set_int(std::min<std::int64_t>(n->as_int() + 1, cap));
}

EmcyProducer::Pending* EmcyProducer::find_active(std::uint16_t code) {
  Pending* end = active_.begin() + active_n_;
  Pending* it = std::find_if(active_.begin(), end, [code](const Pending& p) { return p.code == code; });
  return it == end ? nullptr : it;
}

bool EmcyProducer::active(std::uint16_t code) const {
  return const_cast<EmcyProducer*>(this)->find_active(code) != nullptr;  // a lookup; nothing changes
}

bool EmcyProducer::raise(std::uint16_t code, SimTime now, const SendFn& send, std::array<std::uint8_t, 5> mfr) {
  if (find_active(code)) return true;
  if (active_n_ < kActive) active_[static_cast<std::size_t>(active_n_++)] = {code, 0, mfr};
  update_register();
  push_history(code, mfr);
  const std::size_t before = dropped_;
  enqueue({code, error_register(), mfr}, now, send);
  return dropped_ == before;
}

bool EmcyProducer::clear(std::uint16_t code, SimTime now, const SendFn& send) {
  Pending* it = find_active(code);
  if (!it) return false;
  std::copy(it + 1, active_.begin() + active_n_, it);
  --active_n_;
  update_register();
  if (active_n_ == 0) enqueue({emcy_code::reset, 0, {}}, now, send);
  return true;
}

void EmcyProducer::forget_all() {
  active_n_ = 0;
  queue_n_ = 0;
  missed_ = false;
  update_register();
}

void EmcyProducer::reset_communication() {
  queue_n_ = 0;
  last_sent_ = -1;
}

void EmcyProducer::set_nmt_state(NmtState s, SimTime now, const SendFn& send) {
  const bool may_send = s == NmtState::pre_operational || s == NmtState::operational;
  if (may_send == may_send_) return;
  may_send_ = may_send;
  if (!may_send) {
    missed_ = missed_ || queue_n_ > 0;  // what was waiting for the inhibit time is not sent
    queue_n_ = 0;
    return;
  }
  if (!missed_) return;
  missed_ = false;
  // Back: the master hears the present state — every active error, or that none is left.
  if (active_n_ == 0) enqueue({emcy_code::reset, 0, {}}, now, send);
  for (int i = 0; i < active_n_; ++i) {
    Pending p = active_[static_cast<std::size_t>(i)];
    p.reg = error_register();
    enqueue(p, now, send);
  }
}

void EmcyProducer::enqueue(const Pending& p, SimTime now, const SendFn& send) {
  if (!may_send_) {  // not in this NMT state: recorded only, signalled on the way back
    missed_ = true;
    return;
  }
  if (queue_n_ >= kQueue) {
    ++dropped_;
    return;
  }
  queue_[static_cast<std::size_t>(queue_n_++)] = p;
  on_time(now, send);
}

void EmcyProducer::on_time(SimTime now, const SendFn& send) {
  const OdEntry* inh = od_.entry(0x1015, 0);
  const SimTime inhibit = inh ? inh->as_int() * 100'000 : 0;  // [100 µs] → ns
  while (queue_n_ > 0 && (last_sent_ < 0 || now - last_sent_ >= inhibit)) {
    emit(queue_[0], now, send);
    std::copy(queue_.begin() + 1, queue_.begin() + queue_n_, queue_.begin());
    --queue_n_;
  }
}

void EmcyProducer::emit(const Pending& p, SimTime now, const SendFn& send) {
  const OdEntry* cob_e = od_.entry(0x1014, 0);
  const auto cob_id = cob_e ? static_cast<std::uint32_t>(cob_e->as_int()) : cob::emcy + node_id_;
  last_sent_ = now;
  if (cob_id & cob::invalid) return;  // EMCY disabled: recorded, not sent
  can::Frame f = frame11(cob_id, 8);
  put_u16(f.data.data(), p.code);
  f.data[2] = p.reg;
  std::copy(p.mfr.begin(), p.mfr.end(), f.data.begin() + 3);
  if (send(f, now)) ++sent_;
}

}  // namespace omnitwin::canopen
