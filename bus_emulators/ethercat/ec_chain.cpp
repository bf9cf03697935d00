// bus_emulators/ethercat — a line of ESCs (see ec_chain.hpp).
#include "bus_emulators/ethercat/ec_chain.hpp"

#include <algorithm>

namespace omnitwin::ethercat {

void EscChain::add(Esc* esc) {
  escs_.push_back(esc);
  powered_.push_back(true);
  arrive_.push_back(0);
  update_links();
}

bool EscChain::cable_ok(int c) const {
  const int n = size();
  if (c < 0 || c >= n) return false;
  if (c == break_at_) return false;
  if (!powered_[static_cast<std::size_t>(c)]) return false;
  if (c > 0 && !powered_[static_cast<std::size_t>(c - 1)]) return false;
  return true;
}

int EscChain::reachable() const {
  int k = 0;
  while (k < size() && cable_ok(k)) ++k;
  return k;
}

void EscChain::update_links() {
  for (int i = 0; i < size(); ++i) {
    Esc& e = *escs_[static_cast<std::size_t>(i)];
    e.set_port_link(0, cable_ok(i));
    e.set_port_link(1, cable_ok(i + 1));
  }
}

void EscChain::set_link_break(int after) {
  break_at_ = after;
  update_links();
}

void EscChain::set_powered(int i, bool on, SimTime t) {
  if (i < 0 || i >= size()) return;
  const bool was = powered_[static_cast<std::size_t>(i)];
  powered_[static_cast<std::size_t>(i)] = on;
  if (on && !was) escs_[static_cast<std::size_t>(i)]->power_cycle(t);
  update_links();
}

bool EscChain::process(std::span<std::uint8_t> pdu, SimTime t) noexcept {
  ++stats_.frames;
  PduView v;
  if (parse_pdu(pdu, v) != PduError::ok) {
    ++stats_.malformed;
    return false;
  }
  stats_.datagrams += v.count;
  const int n = reachable();
  if (n == 0) return false;
  SimTime a = t;
  for (int i = 0; i < n; ++i) {
    Esc& e = *escs_[static_cast<std::size_t>(i)];
    arrive_[static_cast<std::size_t>(i)] = a;
    for (std::size_t k = 0; k < v.count; ++k) e.process(v.datagrams[k], a);
    a += e.config().forward_delay_ns;
  }
  // Way back: a is now x_{n-1} (the last slave sent it back out of port 0).
  escs_[static_cast<std::size_t>(n - 1)]->end_of_frame();
  for (int i = n - 2; i >= 0; --i) {
    Esc& e = *escs_[static_cast<std::size_t>(i)];
    e.latch_port(1, a);
    e.end_of_frame();
    a += e.config().forward_delay_ns;
  }
  last_return_ = a;
  ++stats_.returned;
  note_process_wkc(v);
  return true;
}

void EscChain::note_process_wkc(const PduView& v) noexcept {
  std::int32_t wkc = -1;
  for (std::size_t k = 0; k < v.count; ++k) {
    const Cmd c = v.datagrams[k].cmd();
    if (c == Cmd::lrd || c == Cmd::lwr || c == Cmd::lrw) wkc = std::max(wkc, 0) + v.datagrams[k].wkc();
  }
  if (wkc >= 0) last_process_wkc_ = wkc;
}

SimTime EscChain::next_event_time() const noexcept {
  SimTime next = kNoEscEvent;
  for (int i = 0; i < size(); ++i) {
    if (powered_[static_cast<std::size_t>(i)]) next = std::min(next, escs_[static_cast<std::size_t>(i)]->next_event_time());
  }
  return next;
}

void EscChain::advance(SimTime t) noexcept {
  for (int i = 0; i < size(); ++i) {
    if (powered_[static_cast<std::size_t>(i)]) escs_[static_cast<std::size_t>(i)]->advance(t);
  }
}

}  // namespace omnitwin::ethercat
