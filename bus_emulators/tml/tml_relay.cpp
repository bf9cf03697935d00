// bus_emulators/tml — the relay axis (see tml_relay.hpp).
#include "bus_emulators/tml/tml_relay.hpp"

#include <stdexcept>

#include "bus_emulators/tml/tml_can.hpp"

namespace omnitwin::tml {

TmlRelay::TmlRelay(TmlDrive& drive, Protocol can_protocol, FrameSink to_can, HostSink to_host)
    : drive_(drive), protocol_(can_protocol), to_can_(std::move(to_can)), to_host_(std::move(to_host)) {
  if (protocol_ != Protocol::tmlcan && protocol_ != Protocol::techcan)
    throw std::invalid_argument("tml::TmlRelay: the CAN side is tmlcan or techcan");
}

// Answers and unsolicited messages for the host carry its ID code: our axis with HOST set.
bool TmlRelay::host_answer(const Message& m) const {
  return is_host(m.id_code) && id_of(m.id_code) == drive_.axis();
}

void TmlRelay::from_host(const Message& m, SimTime t) {
  // Ours (our axis, axis 0, a group we are in) to the drive; all but our own axis also to CAN.
  const bool ours = drive_.accepts(m.id_code);
  if (ours) {
    ++stats_.own;
    drive_.on_message(m, t);
  }
  const bool only_ours = ours && !is_group(m.id_code) && id_of(m.id_code) == drive_.axis();
  if (only_ours) return;
  can::Frame f;
  const CanStatus st = protocol_ == Protocol::tmlcan ? encode_tmlcan(m, f) : encode_techcan(m, f);
  if (st != CanStatus::ok) {
    ++stats_.not_encodable;
    return;
  }
  if (to_can_(f, t)) ++stats_.to_can;
}

void TmlRelay::from_can(const can::Frame& f, SimTime t) {
  Message m;
  if (protocol_ == Protocol::tmlcan) {
    if (decode_tmlcan(f, m) != CanStatus::ok) return void(++stats_.ignored);
  } else {
    TechCanMessage tm;
    if (decode_techcan(f, tm) != CanStatus::ok) return void(++stats_.ignored);
    // TechCAN does not carry the destination of TakeData/TakeData2: every answer on the bus
    // goes to the host (a relay is the only host-facing node), addressed to it as on RS-232.
    if (!tm.destination_known) {
      ++stats_.to_host;
      Message a = tm.message;
      a.id_code = host_id_code(drive_.axis());
      return to_host_(a, t);
    }
    m = tm.message;
  }
  if (host_answer(m)) {
    ++stats_.to_host;
    return to_host_(m, t);
  }
  if (drive_.accepts(m.id_code)) drive_.on_message(m, t);  // a CAN message for the relay drive
  else ++stats_.ignored;
}

}  // namespace omnitwin::tml
