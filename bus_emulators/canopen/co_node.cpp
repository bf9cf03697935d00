// bus_emulators/canopen — one CANopen slave node (see co_node.hpp).
#include "bus_emulators/canopen/co_node.hpp"

#include <cstring>
#include <stdexcept>

namespace omnitwin::canopen {

void restore_defaults(ObjectDictionary& od, std::uint16_t lo, std::uint16_t hi) {
  for (const OdObject& co : od.objects()) {
    if (co.index < lo || co.index > hi) continue;
    OdObject* o = od.find(co.index);
    for (OdEntry& e : o->entries) {
      if (e.default_value.empty()) continue;
      if (e.bound() && !(e.access & od_access::write_all)) continue;  // the application's value
      std::memcpy(e.data(), e.default_value.data(), std::min(e.default_value.size(), e.bytes()));
    }
  }
}

Node::Node(ObjectDictionary& od, std::uint8_t node_id, SendFn send, NodeHooks hooks)
    : od_(od),
      send_(std::move(send)),
      send_counted_([this](const can::Frame& f, SimTime t) { return this->send(f, t); }),
      hooks_(std::move(hooks)),
      nmt_(node_id),
      ec_(node_id),
      consumer_([this](const HeartbeatEvent& e) {
        if (e.kind == HeartbeatEvent::timeout) communication_error(emcy_code::life_guard, e.t);
      }),
      sdo_(od, node_id, send_counted_),
      pdo_(od, node_id),
      emcy_(od, node_id) {
  if (!valid_node_id(node_id)) throw std::invalid_argument("CANopen node ID must be 1..127");
  heartbeat_ms_ = od_.entry(0x1017, 0);
  guard_ms_ = od_.entry(0x100C, 0);
  life_factor_ = od_.entry(0x100D, 0);
  sync_cob_ = od_.entry(0x1005, 0);
  sync_overflow_ = od_.entry(0x1019, 0);
  sync_period_ = od_.entry(0x1006, 0);
  time_cob_ = od_.entry(0x1012, 0);
  error_behaviour_ = od_.entry(0x1029, 1);
  pdo_.attach();
  pdo_.set_error_handler(&Node::pdo_error, this);
  if (OdObject* c = od_.find(0x1016)) c->after_write = [this](OdObject&, std::uint8_t) { configure_consumer(); };
  if (OdObject* c = od_.find(0x1019)) c->check = [this](const OdObject&, std::uint8_t, std::span<const std::uint8_t> d) {
    // CiA 301: not while a communication cycle period is set; 1 and 241..255 are reserved.
    if (sync_period_ && sync_period_->as_int() != 0) return SdoAbort::state;
    return d[0] == 1 || d[0] > 240 ? SdoAbort::value_range : SdoAbort::none;
  };
}

bool Node::send(const can::Frame& f, SimTime t) {
  const bool ok = send_(f, t);
  ++(ok ? stats_.frames_tx : stats_.tx_refused);
  return ok;
}

void Node::pdo_error(void* ctx, std::uint16_t code, SimTime now) {
  auto* n = static_cast<Node*>(ctx);
  // A length error is a condition: signalled once when it begins and cleared by the next RPDO
  // of the right length (as CANopenNode does). Raised and cleared per frame, a mis-sized RPDO
  // at 1 kHz put two EMCYs per frame on the bus and flushed 0x1003 (found by a protocol review).
  if (n->emcy_.active(code)) return;
  n->emcy_.raise(code, now, n->send_counted_);
  ++n->stats_.emcy;
}

ErrorControlParams Node::ec_params() const {
  ErrorControlParams p;
  if (heartbeat_ms_) p.heartbeat_ms = static_cast<std::uint16_t>(heartbeat_ms_->as_int());
  if (guard_ms_) p.guard_time_ms = static_cast<std::uint16_t>(guard_ms_->as_int());
  if (life_factor_) p.life_factor = static_cast<std::uint8_t>(life_factor_->as_int());
  return p;
}

void Node::configure_consumer() {
  consumer_.clear();
  const OdObject* c = od_.find(0x1016);
  if (!c) return;
  for (const OdEntry& e : c->entries)
    if (e.subindex != 0) consumer_.set_from_entry(static_cast<std::uint32_t>(e.as_int()));
}

void Node::power_on(SimTime now) {
  apply(NmtTransition::reset_node, now);
}

// One NMT transition and what it implies for the other layers.
void Node::apply(NmtTransition tr, SimTime now) {
  const NmtState before = nmt_.state();
  if (!nmt_.apply(tr, now, send_counted_)) return;
  emcy_.set_nmt_state(nmt_.state(), now, send_counted_);
  switch (tr) {
    case NmtTransition::reset_node:
      if (hooks_.on_nmt) hooks_.on_nmt(tr, now);  // the application resets first
      restore_defaults(od_, 0x2000, 0xFFFF);
      emcy_.forget_all();  // no "error reset" EMCY: the boot-up message comes first
      reset_communication(now);
      return;
    case NmtTransition::reset_communication:
      if (hooks_.on_nmt) hooks_.on_nmt(tr, now);
      reset_communication(now);
      return;
    case NmtTransition::start:
      if (before != NmtState::operational) pdo_.on_operational(now);
      break;
    default:
      break;
  }
  if (hooks_.on_nmt) hooks_.on_nmt(tr, now);
}

// Communication objects to their defaults, every layer restarted, then the boot-up message.
void Node::reset_communication(SimTime now) {
  restore_defaults(od_, 0x1000, 0x1FFF);
  sync_producer_.stop();
  if (OdEntry* r = od_.entry(0x1001, 0)) r->set_int(emcy_.error_register());
  pdo_.resolve_all();
  sdo_.reset();
  emcy_.reset_communication();
  ec_.reset(now);
  configure_consumer();
  nmt_.apply(NmtTransition::boot_up, now, send_counted_);
  emcy_.set_nmt_state(nmt_.state(), now, send_counted_);  // after the boot-up message
  ec_.restart(now);
  if (hooks_.on_nmt) hooks_.on_nmt(NmtTransition::boot_up, now);
}

void Node::communication_error(std::uint16_t code, SimTime now) {
  emcy_.raise(code, now, send_counted_);
  ++stats_.emcy;
  if (hooks_.on_comm_error) hooks_.on_comm_error(code, now);  // the application first: the cause is this code
  const std::int64_t behaviour = error_behaviour_ ? error_behaviour_->as_int() : 0;
  if (behaviour == 0 && nmt_.state() == NmtState::operational) apply(NmtTransition::enter_pre_operational, now);
  if (behaviour == 2) apply(NmtTransition::stop, now);
}

void Node::on_bus_off_recovered(SimTime now) { communication_error(emcy_code::bus_off_recovered, now); }

void Node::raise_error(std::uint16_t code, SimTime now, std::array<std::uint8_t, 5> mfr) {
  if (emcy_.raise(code, now, send_counted_, mfr)) ++stats_.emcy;
}

void Node::clear_error(std::uint16_t code, SimTime now) { emcy_.clear(code, now, send_counted_); }

void Node::on_frame(const can::Frame& f, SimTime now) {
  if (nmt_.state() == NmtState::initialising) return;  // powered off or resetting
  ++stats_.frames_rx;
  NmtTransition tr{};
  if (nmt_.decode(f, tr)) {
    ++stats_.nmt_commands;
    apply(tr, now);
    return;
  }
  const std::uint8_t id = nmt_.node_id();
  if (!f.extended && f.id == cob::heartbeat + id) {  // a guarding request for us
    if (f.kind == can::FrameKind::remote &&
        ec_.on_guard_request(now, ec_params(), nmt_.state(), send_counted_) == LifeGuardEvent::resumed)
      emcy_.clear(emcy_code::life_guard, now, send_counted_);
    return;
  }
  consumer_.on_frame(f, now);
  if (nmt_.state() == NmtState::stopped) return;  // only NMT and error control
  if (!f.extended && f.id == cob::sdo_rx + id) {
    sdo_.on_frame(f, now, nmt_.state() == NmtState::operational ? OdState::op : OdState::preop);
    return;
  }
  const std::uint32_t sync_id = cob_of(sync_cob_, cob::sync);
  std::uint8_t counter = 0;
  const auto overflow = static_cast<std::uint8_t>(sync_overflow_ ? sync_overflow_->as_int() : 0);
  switch (decode_sync(f, sync_id, overflow, counter)) {
    case SyncDecode::ok:
      emcy_.clear(0x8240, now, send_counted_);  // the condition ends with a SYNC of the right length
      on_sync(counter, now);
      return;
    case SyncDecode::bad_length:
      ++stats_.sync_length_errors;
      // Unexpected SYNC data length: signalled once while it lasts (see pdo_error).
      if (!emcy_.active(0x8240)) emcy_.raise(0x8240, now, send_counted_);
      return;
    case SyncDecode::not_sync:
      break;
  }
  const std::uint32_t time_id = cob_of(time_cob_, cob::time | cob::invalid);
  if (time_id & cob::invalid) {  // bit 31: this node consumes TIME
    if (auto t = decode_time(f, time_id & cob::id_mask_11)) {
      last_time_ = t;
      last_time_at_ = now;
      ++stats_.time_stamps;
      return;
    }
  }
  if (pdo_.on_frame(f, now, nmt_.state(), send_counted_) == RpdoStatus::applied) {
    emcy_.clear(0x8210, now, send_counted_);  // a length error ends with a frame of the right length
    emcy_.clear(0x8220, now, send_counted_);
  }
}

void Node::on_sync(std::uint8_t counter, SimTime now) {
  ++stats_.syncs;
  pdo_.on_sync(counter, now, nmt_.state(), send_counted_);
  if (hooks_.on_sync) hooks_.on_sync(counter, now);
}

// The node as SYNC producer (0x1005 bit 30): its SYNCs go out and are acted on here.
void Node::produce_sync(SimTime now) {
  const std::uint32_t cob_id = cob_of(sync_cob_, cob::sync);
  const SimTime period = sync_period_ ? sync_period_->as_int() * 1000 : 0;  // [µs] → ns
  if (!(cob_id & cob::gen) || period <= 0 || nmt_.state() == NmtState::stopped) {
    sync_producer_.stop();
    return;
  }
  const auto overflow = static_cast<std::uint8_t>(sync_overflow_ ? sync_overflow_->as_int() : 0);
  const SyncProducerConfig want{cob_id & cob::id_mask_11, period, overflow};
  if (!sync_producer_.running() || sync_producer_.config().period_ns != want.period_ns ||
      sync_producer_.config().cob_id != want.cob_id || sync_producer_.config().counter_overflow != want.counter_overflow) {
    sync_producer_.configure(want);
    sync_producer_.start(now + period);
    return;
  }
  sync_producer_.on_time(now, [this](const can::Frame& f, SimTime at) {
    const bool ok = send(f, at);
    on_sync(f.dlc == 1 ? f.data[0] : 0, at);
    return ok;
  });
}

void Node::on_time(SimTime now) {
  if (nmt_.state() == NmtState::initialising) return;
  produce_sync(now);
  if (ec_.on_time(now, ec_params(), nmt_.state(), send_counted_) == LifeGuardEvent::lost)
    communication_error(emcy_code::life_guard, now);
  consumer_.on_time(now);
  sdo_.on_time(now);
  emcy_.on_time(now, send_counted_);
  pdo_.on_time(now, nmt_.state(), send_counted_);
}

}  // namespace omnitwin::canopen
