// controller/canopen — our CANopen master (see co_master.hpp).
#include "controller/canopen/co_master.hpp"

#include <fmt/format.h>

#include <algorithm>
#include <cmath>
#include <stdexcept>

#include "bus_emulators/canopen/co_eds.hpp"

namespace omnitwin::controller::canopen {

namespace co = omnitwin::canopen;

namespace {

constexpr SimTime kMs = 1'000'000;
constexpr std::uint32_t kInvalid = co::cob::invalid;

// The EDS's bit size of index:sub, checked for the PDO direction (rx: the master writes it).
std::uint32_t map_entry(const co::EdsDevice& eds, std::uint16_t idx, std::uint8_t sub, bool rx) {
  const co::EdsObject* o = eds.object(idx);
  const co::EdsEntry* e = o ? o->entry(sub) : nullptr;
  if (!e) throw std::runtime_error(fmt::format("{}: object 0x{:04X}:{} is missing", eds.source, idx, sub));
  const std::uint16_t access = co::eds_od_access(e->access, e->pdo_mapping);
  if (!(access & (rx ? co::od_access::rxpdo : co::od_access::txpdo)))
    throw std::runtime_error(fmt::format("{}: 0x{:04X}:{} may not be mapped into a {}", eds.source, idx, sub, rx ? "RPDO" : "TPDO"));
  return static_cast<std::uint32_t>(idx) << 16 | static_cast<std::uint32_t>(sub) << 8 | e->bits;
}

SdoStep dl(std::uint16_t idx, std::uint8_t sub, std::uint8_t bytes, std::uint32_t v, std::string what) {
  return SdoStep{false, idx, sub, bytes, v, std::move(what)};
}
SdoStep ul(std::uint16_t idx, std::uint8_t sub, std::string what) { return SdoStep{true, idx, sub, 0, 0, std::move(what)}; }

// CiA 301's procedure for one PDO: destroy it, set its parameters, clear the mapping, map,
// enable the mapping, create it.
void configure_pdo(std::vector<SdoStep>& s, bool tx, int n, std::uint32_t cob, std::uint8_t type,
                   const std::vector<std::uint32_t>& map, std::uint16_t inhibit_100us = 0, std::uint16_t event_ms = 0) {
  const auto comm = static_cast<std::uint16_t>((tx ? 0x1800 : 0x1400) + n);
  const auto mp = static_cast<std::uint16_t>((tx ? 0x1A00 : 0x1600) + n);
  const std::string name = fmt::format("{}PDO{}", tx ? "T" : "R", n + 1);
  s.push_back(dl(comm, 1, 4, cob | kInvalid, name + " off"));
  if (map.empty()) return;
  s.push_back(dl(comm, 2, 1, type, name + " transmission type"));
  if (tx) s.push_back(dl(comm, 3, 2, inhibit_100us, name + " inhibit time"));
  s.push_back(dl(comm, 5, 2, event_ms, name + " event timer"));
  s.push_back(dl(mp, 0, 1, 0, name + " mapping cleared"));
  for (std::size_t i = 0; i < map.size(); ++i) s.push_back(dl(mp, static_cast<std::uint8_t>(i + 1), 4, map[i], name + " mapping"));
  s.push_back(dl(mp, 0, 1, static_cast<std::uint32_t>(map.size()), name + " mapping enabled"));
  s.push_back(dl(comm, 1, 4, cob, name + " on"));
}

}  // namespace

const char* to_string(CoPhase p) {
  switch (p) {
    case CoPhase::resetting: return "resetting";
    case CoPhase::configuring: return "configuring";
    case CoPhase::starting: return "starting";
    case CoPhase::enabling: return "enabling";
    case CoPhase::running: return "running";
    case CoPhase::stopped: return "stopped";
    case CoPhase::finished: return "finished";
    case CoPhase::failed: return "failed";
  }
  return "?";
}

std::vector<SdoStep> startup_script(const CoProgramConfig& c, const co::EdsDevice& eds, std::uint8_t id) {
  std::vector<SdoStep> s;
  s.push_back(ul(0x1000, 0, "device type"));
  s.push_back(ul(0x1018, 1, "vendor ID"));
  s.push_back(ul(0x1018, 2, "product code"));
  s.push_back(ul(0x1008, 0, "device name"));
  s.push_back(dl(0x1017, 0, 2, c.node_heartbeat_ms, "producer heartbeat time"));
  if (c.master_node_id != 0 && c.master_heartbeat_ms != 0)
    s.push_back(dl(0x1016, 1, 4, static_cast<std::uint32_t>(c.master_node_id) << 16 | c.heartbeat_timeout_ms,
                   "consumer heartbeat time (the master)"));
  s.push_back(dl(0x1019, 0, 1, c.sync_counter, "SYNC counter overflow"));
  configure_pdo(s, false, 0, 0x200u + id, 1, {map_entry(eds, 0x6040, 0, true), map_entry(eds, 0x60FF, 0, true)});
  for (int n = 1; n < 4; ++n) configure_pdo(s, false, n, static_cast<std::uint32_t>(0x200 + 0x100 * n + id), 0, {});
  configure_pdo(s, true, 0, 0x180u + id, 1, {map_entry(eds, 0x6041, 0, false), map_entry(eds, 0x6064, 0, false)});
  // TPDO2 on change, at most every 10 SYNC periods, at least every 100: its share of the wire
  // scales with the SYNC as the synchronous PDOs' does.
  const double cycle_ms = c.cycle * 1e3;
  const auto inhibit = static_cast<std::uint16_t>(std::min(65535.0, std::round(cycle_ms * 10 * 10)));   // [100 µs]
  const auto event_ms = static_cast<std::uint16_t>(std::min(65535.0, std::round(cycle_ms * 100)));
  configure_pdo(s, true, 1, 0x280u + id, 254, {map_entry(eds, 0x6041, 0, false), map_entry(eds, 0x606C, 0, false)},
                inhibit, event_ms);
  for (int n = 2; n < 4; ++n) configure_pdo(s, true, n, static_cast<std::uint32_t>(0x180 + 0x100 * n + id), 0, {});
  s.push_back(dl(0x6060, 0, 1, c.mode == WheelMode::csv ? 9 : 3, "modes of operation"));
  if (c.sync_producer == id) {  // this drive produces SYNC: period, then the gen bit
    s.push_back(dl(0x1006, 0, 4, static_cast<std::uint32_t>(std::llround(c.cycle * 1e6)), "communication cycle period"));
    s.push_back(dl(0x1005, 0, 4, co::cob::gen | co::cob::sync, "COB-ID SYNC: this node produces SYNC"));
  }
  return s;
}

CoMaster::CoMaster(const CoProgramConfig& config, const co::EdsDevice& eds, SendFn send)
    : cfg_(config),
      send_(std::move(send)),
      sdo_([this](const can::Frame& f, SimTime t) { return this->send(f, t); },
           SdoClientConfig{.timeout_ns = std::llround(config.sdo_timeout_ms * 1e6), .channels = 4}),
      consumer_([this](const co::HeartbeatEvent& e) { on_heartbeat_event(e); }),
      sync_({co::cob::sync, std::llround(config.cycle * 1e9), config.sync_counter}),
      vendor_(eds.device_info.vendor_number),
      product_(eds.device_info.product_number) {
  for (std::size_t i = 0; i < 4; ++i) {
    Node& n = nodes_[i];
    n.view.id = cfg_.nodes[i];
    n.script = startup_script(cfg_, eds, n.view.id);
    consumer_.set(n.view.id, cfg_.heartbeat_timeout_ms);
  }
}

bool CoMaster::send(const can::Frame& f, SimTime t) {
  const bool ok = send_(f, t);
  ++(ok ? stats_.frames_tx : stats_.tx_refused);
  return ok;
}

void CoMaster::event(SimTime t, const std::string& text, bool warning) {
  if (event_) event_(t, text, warning);
}

CoMaster::Node* CoMaster::by_id(std::uint8_t id) {
  for (Node& n : nodes_)
    if (n.view.id == id) return &n;
  return nullptr;
}

void CoMaster::nmt(co::NmtCommand c, std::uint8_t node, SimTime t) {
  can::Frame f = co::frame11(co::cob::nmt, 2);
  f.data[0] = static_cast<std::uint8_t>(c);
  f.data[1] = node;
  send(f, t);
  ++stats_.nmt_sent;
}

simclock::MasterState CoMaster::report_state() const {
  if (end_from_ >= 0 && !end_done_) return state_at_end_;
  switch (phase_) {
    case CoPhase::running: return simclock::MasterState::running;
    case CoPhase::stopped:
    case CoPhase::failed: return simclock::MasterState::stopped;
    case CoPhase::finished: return simclock::MasterState::finished;
    default: return simclock::MasterState::detecting;
  }
}

void CoMaster::enter(CoPhase p, SimTime t) {
  if (p == phase_) return;
  event(t, fmt::format("phase {} -> {}", to_string(phase_), to_string(p)));
  phase_ = p;
}

void CoMaster::stop(simclock::StopReason r, std::uint8_t node, SimTime t, const std::string& why) {
  if (phase_ == CoPhase::stopped || phase_ == CoPhase::failed) return;
  const bool starting = phase_ != CoPhase::running && phase_ != CoPhase::enabling;
  reason_ = r;
  reason_node_ = node;
  event(t, why, true);
  const bool startup_reason = r == simclock::StopReason::startup_timeout || r == simclock::StopReason::config_failed;
  enter(starting && startup_reason ? CoPhase::failed : CoPhase::stopped, t);
}

// ---------------------------------------------------------------------------------------
// Receiving

void CoMaster::on_frame(const can::Frame& f, SimTime t) {
  ++stats_.frames_rx;
  if (f.extended || f.kind != can::FrameKind::data) return;
  const std::uint32_t fn = f.id & 0x780, id = f.id & 0x7F;
  if (fn == co::cob::heartbeat) {
    consumer_.on_frame(f, t);
    if (Node* n = by_id(static_cast<std::uint8_t>(id))) n->view.nmt = consumer_.state(n->view.id);
    return;
  }
  Node* n = by_id(static_cast<std::uint8_t>(id));
  if (!n) return;
  if (fn == co::cob::sdo_tx) return sdo_.on_frame(f, t);
  if (fn == co::cob::emcy && id != 0) return on_emcy(*n, f, t);
  if (fn == co::cob::tpdo1 || fn == co::cob::tpdo2) return on_tpdo(*n, f);
}

void CoMaster::on_tpdo(Node& n, const can::Frame& f) {
  if (f.dlc < 6) return;  // our mapping: statusword + a 32-bit value
  ++stats_.tpdo_rx;
  ++n.view.tpdos;
  n.view.statusword = co::get_u16(f.data.data());
  const auto v = static_cast<std::int32_t>(co::get_u32(f.data.data() + 2));
  if ((f.id & 0x780) == co::cob::tpdo1) n.view.position = v;
  else n.view.velocity = v;
}

void CoMaster::on_emcy(Node& n, const can::Frame& f, SimTime t) {
  if (f.dlc != 8) return;
  const std::uint16_t code = co::get_u16(f.data.data());
  ++stats_.emcy;
  ++n.view.emcy;
  n.view.last_emcy = code;
  event(t, fmt::format("EMCY from node {}: code 0x{:04X}, error register 0x{:02X}", n.view.id, code, f.data[2]), code != 0);
  // An error of a wheel drive while the platform moves stops it (a reset EMCY does not).
  if (code != 0 && (phase_ == CoPhase::running || phase_ == CoPhase::enabling) && (f.data[2] & 0x01))
    stop(simclock::StopReason::drive_fault, n.view.id, t,
         fmt::format("node {} reported error 0x{:04X}: platform stopped", n.view.id, code));
}

void CoMaster::on_heartbeat_event(const co::HeartbeatEvent& e) {
  Node* n = by_id(e.node);
  if (!n) return;
  n->view.nmt = e.state;
  // Before starting the drives produce no heartbeat yet (0x1017 is configured on the way), and
  // a failed start-up supervises nothing.
  const bool supervised = phase_ != CoPhase::resetting && phase_ != CoPhase::configuring && phase_ != CoPhase::failed;
  switch (e.kind) {
    case co::HeartbeatEvent::timeout:
      if (!supervised) return;
      ++stats_.heartbeat_timeouts;
      n->view.lost = true;
      n->start_sent = false;
      event(e.t, fmt::format("node {}: heartbeat lost", e.node), true);
      if (phase_ == CoPhase::running || phase_ == CoPhase::enabling || phase_ == CoPhase::starting)
        stop(simclock::StopReason::node_missing, e.node, e.t, fmt::format("node {} missing: platform stopped", e.node));
      return;
    case co::HeartbeatEvent::boot_up:
      ++stats_.boot_ups;
      event(e.t, fmt::format("node {}: boot-up", e.node));
      n->view.configured = false;
      n->step = 0;
      n->step_sent = false;
      n->start_sent = false;
      if (phase_ == CoPhase::running || phase_ == CoPhase::enabling || phase_ == CoPhase::stopped) n->view.lost = true;
      if (phase_ == CoPhase::running || phase_ == CoPhase::enabling)
        stop(simclock::StopReason::node_missing, e.node, e.t, fmt::format("node {} was reset: platform stopped", e.node));
      return;
    case co::HeartbeatEvent::resumed:
    case co::HeartbeatEvent::state_changed:
      // Recovered: operational again after we started it (not a stale heartbeat it had queued
      // while bus-off).
      if (n->view.lost && e.state == NmtState::operational && n->start_sent) {
        n->view.lost = false;
        ++stats_.recoveries;
        event(e.t, fmt::format("node {} back in OPERATIONAL", e.node));
      }
      if (phase_ == CoPhase::running && e.state != NmtState::operational) {
        n->view.lost = true;
        stop(simclock::StopReason::node_missing, e.node, e.t,
             fmt::format("node {} left OPERATIONAL ({}): platform stopped", e.node, co::to_string(e.state)));
      }
      return;
  }
}

// ---------------------------------------------------------------------------------------
// The cycle

void CoMaster::on_tick(SimTime t) {
  if (end_done_) return;  // NMT stop sent: the master is silent
  ++stats_.ticks;
  if (start_ < 0) start_ = t;
  if (end_from_ >= 0) return end_tick(t);
  consumer_.on_time(t);
  sdo_.on_time(t);
  const bool cyclic = phase_ != CoPhase::resetting && phase_ != CoPhase::configuring && phase_ != CoPhase::failed;
  if (cyclic) {
    // SYNC from the master unless a drive produces it (then the RPDOs wait for the drive's).
    if (cfg_.sync_producer == 0 && sync_.send_one(t, [this](const can::Frame& f, SimTime at) { return send(f, at); }))
      ++stats_.syncs;
    send_rpdos(t);
    send_heartbeat(t);
  }
  const bool late = t - start_ > std::llround(cfg_.startup_timeout * 1e9);
  switch (phase_) {
    case CoPhase::resetting: {
      if (!reset_sent_) {
        nmt(co::NmtCommand::reset_communication, 0, t);
        reset_sent_ = true;
        return;
      }
      bool all = true;
      for (const Node& n : nodes_) all = all && consumer_.heard(n.view.id);
      if (all) enter(CoPhase::configuring, t);
      else if (late) stop(simclock::StopReason::startup_timeout, 0, t, "not every drive booted in time");
      return;
    }
    case CoPhase::configuring: {
      run_scripts(t);
      bool all = true;
      for (const Node& n : nodes_) all = all && n.view.configured;
      if (phase_ != CoPhase::configuring) return;
      if (all) {
        nmt(co::NmtCommand::start, 0, t);
        enter(CoPhase::starting, t);
        next_heartbeat_ = t;
      } else if (late) {
        stop(simclock::StopReason::startup_timeout, 0, t, "the drives' configuration did not finish in time");
      }
      return;
    }
    case CoPhase::starting: {
      bool all = true;
      for (const Node& n : nodes_) all = all && consumer_.state(n.view.id) == NmtState::operational;
      if (all) enter(CoPhase::enabling, t);
      else if (late) stop(simclock::StopReason::startup_timeout, 0, t, "not every drive reached OPERATIONAL in time");
      return;
    }
    case CoPhase::enabling: {
      bool all = true;
      for (const Node& n : nodes_) all = all && (n.view.statusword & 0x6F) == 0x27;
      if (all) {
        running_since_ = t;
        enter(CoPhase::running, t);
      } else if (late) {
        stop(simclock::StopReason::startup_timeout, 0, t, "not every drive reached operation enabled in time");
      }
      return;
    }
    case CoPhase::stopped:
      run_scripts(t);  // a drive that came back is configured and started again
      return;
    default:
      return;
  }
}

// Each drive's script, one SDO at a time per drive; a drive whose script ended is started
// (after a recovery: on its own, NMT start to that node).
void CoMaster::run_scripts(SimTime t) {
  for (Node& n : nodes_) {
    if (!consumer_.heard(n.view.id)) continue;
    if (!n.view.configured && !run_script(n, t)) return;  // an SDO failed: the phase changed
    // Stopped: a lost drive heard again (configured anew after a boot-up, or back from
    // bus-off in PRE-OPERATIONAL with its configuration) is started again.
    const bool back = n.view.lost && consumer_.alive(n.view.id) && consumer_.state(n.view.id) != NmtState::operational;
    if (n.view.configured && phase_ == CoPhase::stopped && back && !n.start_sent) {
      nmt(co::NmtCommand::start, n.view.id, t);
      n.start_sent = true;
    }
  }
}

bool CoMaster::run_script(Node& n, SimTime t) {
  if (n.step_sent) {
    const SdoResult* r = sdo_.result(n.view.id);
    if (r && r->status == SdoStatus::busy) return true;
    n.step_sent = false;
    const SdoStep& s = n.script[n.step];
    if (!r || r->status == SdoStatus::aborted) {
      const auto code = static_cast<std::uint32_t>(r ? r->code : SdoAbort::general);
      ++stats_.sdo_aborts;
      stats_.last_abort = code;
      stop(simclock::StopReason::config_failed, n.view.id, t,
           fmt::format("node {}: SDO {} 0x{:04X}:{} ({}) aborted with 0x{:08X} ({})", n.view.id,
                       s.upload ? "upload" : "download", s.index, s.sub, s.what, code,
                       ethercat::to_string(static_cast<SdoAbort>(code))));
      return false;
    }
    ++stats_.sdo_done;
    if (s.upload) {
      const std::uint32_t v = r->data.size() >= 4 ? co::get_u32(r->data.data()) : 0;
      if (s.index == 0x1008) event(t, fmt::format("node {}: {}", n.view.id, std::string(r->data.begin(), r->data.end())));
      else if (s.index == 0x1000 && (v & 0xFFFF) != 402) {
        stop(simclock::StopReason::config_failed, n.view.id, t,
             fmt::format("node {}: device type 0x{:08X} is not a CiA 402 drive", n.view.id, v));
        return false;
      } else if (s.index == 0x1018 && !identity_ok(n, s.sub, v, t)) {
        return false;
      }
    }
    if (++n.step >= n.script.size()) {
      n.view.configured = true;
      event(t, fmt::format("node {}: configured ({} SDO transfers)", n.view.id, n.script.size()));
      return true;
    }
  }
  const SdoStep& s = n.script[n.step];
  if (s.upload) {
    sdo_.upload(n.view.id, s.index, s.sub, t);
  } else {
    std::uint8_t b[4];
    co::put_u32(b, s.value);
    sdo_.download(n.view.id, s.index, s.sub, std::span<const std::uint8_t>(b, s.bytes), t);
  }
  n.step_sent = true;
  return true;
}

// Identity 0x1018 sub 1 (vendor) or 2 (product) read from node n against the EDS's number
// (not checked when the EDS gives none); a mismatch stops the start-up (config_failed).
bool CoMaster::identity_ok(Node& n, std::uint8_t sub, std::uint32_t v, SimTime t) {
  const std::uint32_t expected = sub == 1 ? vendor_ : sub == 2 ? product_ : 0;
  if (expected == 0 || v == expected) return true;
  stop(simclock::StopReason::config_failed, n.view.id, t,
       fmt::format("node {}: {} 0x{:08X}, expected 0x{:08X} (the EDS's)", n.view.id, sub == 1 ? "vendor ID" : "product code",
                   v, expected));
  return false;
}

// CiA 402's power-up from the statusword: fault → reset edge, switch on disabled → shutdown,
// ready → switch on, switched on → enable operation; running holds enable operation; stopped
// and finished hold quick stop / shutdown.
std::uint16_t CoMaster::controlword_for(Node& n) {
  const std::uint16_t sw = n.view.statusword;
  if (phase_ == CoPhase::finished) return 0x06;
  if (phase_ == CoPhase::stopped || phase_ == CoPhase::failed) return 0x02;
  if (sw & 0x08) {  // fault: a rising edge of bit 7
    n.fault_reset = !n.fault_reset;
    return n.fault_reset ? 0x80 : 0x00;
  }
  if ((sw & 0x4F) == 0x40) return 0x06;  // switch on disabled
  if ((sw & 0x6F) == 0x21) return 0x07;  // ready to switch on
  if ((sw & 0x6F) == 0x23) return 0x0F;  // switched on
  return 0x0F;
}

void CoMaster::send_rpdos(SimTime t) {
  for (std::size_t i = 0; i < 4; ++i) {
    Node& n = nodes_[i];
    if (!n.view.configured) continue;
    can::Frame f = co::frame11(0x200u + n.view.id, 6);
    co::put_u16(f.data.data(), end_from_ >= 0 ? ending_controlword(n, t) : controlword_for(n));
    const std::int32_t v = phase_ == CoPhase::running ? velocity_[i] : 0;
    co::put_u32(f.data.data() + 2, static_cast<std::uint32_t>(v));
    send(f, t);
  }
}

void CoMaster::finish(SimTime t) {
  if (phase_ != CoPhase::running) return;
  velocity_ = {};
  enter(CoPhase::finished, t);
}

// The master's own heartbeat, when one is due (the drives watch it: 0x1016).
void CoMaster::send_heartbeat(SimTime t) {
  if (cfg_.master_node_id == 0 || cfg_.master_heartbeat_ms == 0 || t < next_heartbeat_) return;
  can::Frame hb = co::frame11(co::cob::heartbeat + cfg_.master_node_id, 1);
  hb.data[0] = static_cast<std::uint8_t>(NmtState::operational);
  send(hb, t);
  next_heartbeat_ = t + cfg_.master_heartbeat_ms * kMs;
}

// Operation enabled → quick stop (0x02: the drive brakes on its quick-stop ramp); quick stop
// active → quick stop until half of kEndNs is over, then disable voltage (0x00: a drive whose
// quick-stop option holds it there is let go); any other state → disable voltage.
std::uint16_t CoMaster::ending_controlword(const Node& n, SimTime t) const {
  const std::uint16_t sw = n.view.statusword & 0x6F;
  if (sw == 0x27) return 0x02;
  if (sw == 0x07 && t - end_from_ < kEndNs / 2) return 0x02;
  return 0x00;
}

// A drive whose TPDOs run: it has sent one, or its heartbeat says OPERATIONAL (the heartbeat
// may lag the NMT start by a period, the TPDOs do not).
bool CoMaster::reporting(const Node& n) const {
  return n.view.configured && !n.view.lost && (n.view.tpdos > 0 || consumer_.state(n.view.id) == NmtState::operational);
}

// A reporting drive that has sent no statusword since the end began: the last one before it
// may predate a controlword the drive has since taken (switched on → operation enabled).
bool CoMaster::awaiting_statusword(const Node& n) const { return reporting(n) && n.view.tpdos <= n.tpdos_at_end; }

bool CoMaster::statuswords_fresh() const {
  return std::none_of(nodes_.begin(), nodes_.end(), [this](const Node& n) { return awaiting_statusword(n); });
}

// A drive still powering its motor, as its last statusword says: operation enabled or quick
// stop active.
bool CoMaster::enabled(const Node& n) {
  const std::uint16_t sw = n.view.statusword & 0x6F;
  return n.view.configured && !n.view.lost && (sw == 0x27 || sw == 0x07);
}

bool CoMaster::any_enabled() const {
  return std::any_of(nodes_.begin(), nodes_.end(), [](const Node& n) { return enabled(n); });
}

// The end's bound passed: which drive is still enabled, or has not reported since it began.
void CoMaster::warn_unfinished_end(SimTime t) {
  for (const Node& n : nodes_) {
    if (enabled(n))
      event(t, fmt::format("end: node {} still enabled after {} ms (statusword 0x{:04X}): NMT stop regardless", n.view.id,
                           kEndNs / kMs, n.view.statusword), true);
    else if (awaiting_statusword(n))
      event(t, fmt::format("end: node {} sent no statusword in {} ms: NMT stop regardless", n.view.id, kEndNs / kMs), true);
  }
}

// One tick of the end sequence: NMT stop once no drive is enabled (or kEndNs is over), else
// SYNC and the ending controlwords.
void CoMaster::end_tick(SimTime t) {
  sdo_.on_time(t);
  const bool over = statuswords_fresh() && !any_enabled();
  if (over || t - end_from_ >= kEndNs) {
    if (!over) warn_unfinished_end(t);
    nmt(co::NmtCommand::stop, 0, t);
    end_done_ = true;
    return;
  }
  if (cfg_.sync_producer == 0 && sync_.send_one(t, [this](const can::Frame& f, SimTime at) { return send(f, at); }))
    ++stats_.syncs;
  send_rpdos(t);
  // The drives still watch the master's heartbeat: a gap longer than their timeout would
  // fault one still enabled.
  if (phase_ != CoPhase::resetting && phase_ != CoPhase::configuring && phase_ != CoPhase::failed) send_heartbeat(t);
}

void CoMaster::shutdown(SimTime t) {
  if (end_from_ >= 0) return;  // already ending
  velocity_ = {};
  state_at_end_ = report_state();
  if (phase_ == CoPhase::running || phase_ == CoPhase::enabling) enter(CoPhase::finished, t);
  for (Node& n : nodes_) n.tpdos_at_end = n.view.tpdos;
  end_from_ = t;
  end_tick(t);
}

}  // namespace omnitwin::controller::canopen
