// bus_emulators/tml — an IDM drive on a CAN bus (see tml_can_node.hpp).
#include "bus_emulators/tml/tml_can_node.hpp"

#include <stdexcept>

namespace omnitwin::tml {

namespace {
const DriveSetup& checked(const DriveSetup& s) {
  if (s.protocol != Protocol::tmlcan && s.protocol != Protocol::techcan)
    throw std::invalid_argument("tml::TmlCanNode: the protocol must be TMLCAN or TechCAN");
  return s;
}
}  // namespace

TmlCanNode::TmlCanNode(const DriveSetup& setup, FrameSink out)
    : out_(std::move(out)), drive_(checked(setup), [this](const Message& m, SimTime t) { send(m, t); }) {}

void TmlCanNode::on_frame(const can::Frame& f, SimTime t) {
  if (!drive_.powered()) return;
  ++stats_.frames_in;
  if (drive_.setup().protocol == Protocol::techcan) return on_techcan(f, t);
  on_tmlcan(f, t);
}

void TmlCanNode::on_techcan(const can::Frame& f, SimTime t) {
  TechCanMessage tm;
  const CanStatus st = decode_techcan(f, tm);
  // CANopen COB-IDs and 29-bit frames share the bus: not ours.
  if (st == CanStatus::unknown_cob_id || st == CanStatus::wrong_format || st == CanStatus::not_data_frame) {
    ++stats_.foreign;
    return;
  }
  if (st != CanStatus::ok) {
    ++stats_.malformed;
    return;
  }
  if (tm.kind == TechCanKind::take_data || tm.kind == TechCanKind::take_data2 || tm.kind == TechCanKind::pong) {
    ++stats_.others_answers;  // their destination is not carried: a host's business
    return;
  }
  ++stats_.delivered;
  drive_.on_message(tm.message, t);
}

void TmlCanNode::on_tmlcan(const can::Frame& f, SimTime t) {
  Message m;
  const CanStatus st = decode_tmlcan(f, m);
  if (st == CanStatus::wrong_format || st == CanStatus::not_data_frame) {
    ++stats_.foreign;
    return;
  }
  if (st != CanStatus::ok) {
    ++stats_.malformed;
    return;
  }
  ++stats_.delivered;
  drive_.on_message(m, t);
}

void TmlCanNode::send(const Message& m, SimTime t) {
  can::Frame f;
  const CanStatus st = drive_.setup().protocol == Protocol::techcan ? encode_techcan(m, f) : encode_tmlcan(m, f);
  if (st != CanStatus::ok) {
    ++stats_.encode_errors;
    return;
  }
  ++stats_.frames_out;
  if (!out_ || !out_(f, t)) ++stats_.send_refused;
}

}  // namespace omnitwin::tml
