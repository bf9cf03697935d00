// bus_emulators/omni — the Omni application protocol codec; see omni_codec.hpp and
// docs/protocols/omni-can.md.
#include "bus_emulators/omni/omni_codec.hpp"

#include <cmath>

namespace omnitwin::omni {
namespace {

constexpr std::array<FunctionCode, 4> kFeedbackFunction = {
    FunctionCode::process_data_1, FunctionCode::process_data_2, FunctionCode::process_data_3,
    FunctionCode::process_data_4};

constexpr std::uint8_t kSpeedCommandDlc = 5;
constexpr std::uint8_t kSpeedFeedbackDlc = 6;
constexpr std::uint8_t kNmtDlc = 2;

bool is_slave(std::uint8_t n) { return axis_of_slave(n) != 0; }
bool answers_detection(std::uint8_t n) { return n == node::master || is_slave(n); }
bool is_nmt_target(std::uint8_t n) { return n == node::all || n == node::master || is_slave(n); }
bool is_param_receiver(std::uint8_t n) { return n == node::master || is_slave(n); }
bool is_param_sender(std::uint8_t n) { return n == node::pc || n == node::master; }

std::uint32_t be(const can::Frame& f, int from, int n) {
  std::uint32_t v = 0;
  for (int i = 0; i < n; ++i) v = (v << 8) | f.data[static_cast<std::size_t>(from + i)];
  return v;
}
void put_be(can::Frame& f, int from, int n, std::uint32_t v) {
  for (int i = n - 1; i >= 0; --i) {
    f.data[static_cast<std::size_t>(from + i)] = static_cast<std::uint8_t>(v & 0xFFu);
    v >>= 8;
  }
}

DecodeResult decode_nmt(const can::Frame& f, std::uint8_t id_node) {
  if (id_node == 0) {
    if (f.kind == can::FrameKind::remote) {
      if (f.dlc != 0) return DecodeError::wrong_dlc;
      return Message{DetectionRequest{}};
    }
    if (f.dlc != kNmtDlc) return DecodeError::wrong_dlc;
    if (!is_nmt_target(f.data[0])) return DecodeError::bad_node;
    const std::uint8_t s = f.data[1];
    if (s != static_cast<std::uint8_t>(NmtState::start) && s != static_cast<std::uint8_t>(NmtState::stop))
      return DecodeError::bad_value;
    return Message{NmtCommand{f.data[0], static_cast<NmtState>(s)}};
  }
  // IDs 0x001–0x0FF: NMT for slaves; the platform only answers detection there (table 4-2).
  if (f.kind != can::FrameKind::remote) return DecodeError::wrong_kind;
  if (f.dlc != 0) return DecodeError::wrong_dlc;
  if (!answers_detection(id_node)) return DecodeError::bad_node;
  return Message{DetectionAnswer{id_node}};
}

DecodeResult decode_speed_command(const can::Frame& f, std::uint8_t id_node) {
  if (f.kind != can::FrameKind::data) return DecodeError::wrong_kind;
  if (f.dlc != kSpeedCommandDlc) return DecodeError::wrong_dlc;
  if (id_node != node::master || f.data[0] != id_node) return DecodeError::bad_node;
  SpeedCommand c;
  c.sender = f.data[0];
  for (int k = 0; k < 4; ++k)  // byte 1 = axis 4 … byte 4 = axis 1
    c.axis[static_cast<std::size_t>(3 - k)] = static_cast<std::int8_t>(f.data[static_cast<std::size_t>(1 + k)]);
  return Message{c};
}

DecodeResult decode_feedback(const can::Frame& f, FunctionCode fc, std::uint8_t id_node) {
  if (f.kind != can::FrameKind::data) return DecodeError::wrong_kind;
  if (f.dlc != kSpeedFeedbackDlc) return DecodeError::wrong_dlc;
  if (id_node != node::master) return DecodeError::bad_node;  // receiver
  const std::uint8_t sender = f.data[0];
  const int axis = axis_of_slave(sender);
  if (axis == 0 || kFeedbackFunction[static_cast<std::size_t>(axis - 1)] != fc) return DecodeError::bad_node;
  return Message{SpeedFeedback{sender, f.data[1], static_cast<std::int32_t>(be(f, 2, 4))}};
}

DecodeResult decode_parameter(const can::Frame& f, std::uint8_t id_node) {
  if (f.kind != can::FrameKind::data) return DecodeError::wrong_kind;
  if (f.dlc != 4 && f.dlc != 6) return DecodeError::wrong_dlc;
  const std::uint8_t sender = f.data[0];
  if (!is_param_receiver(id_node) || !is_param_sender(sender) || sender == id_node)
    return DecodeError::bad_node;
  ParameterSetup p;
  p.receiver = id_node;
  p.sender = sender;
  p.data_type = f.data[1];
  p.width = f.dlc == 6 ? ParamWidth::four_bytes : ParamWidth::two_bytes;
  p.value = be(f, 2, f.dlc - 2);
  return Message{p};
}

can::Frame frame_for(const Message& m) {
  can::Frame f;
  if (const auto* n = std::get_if<NmtCommand>(&m)) {
    f.id = omni_id(FunctionCode::nmt, 0);
    f.dlc = kNmtDlc;
    f.data[0] = n->target;
    f.data[1] = static_cast<std::uint8_t>(n->state);
  } else if (std::holds_alternative<DetectionRequest>(m)) {
    f.id = omni_id(FunctionCode::nmt, 0);
    f.kind = can::FrameKind::remote;
  } else if (const auto* a = std::get_if<DetectionAnswer>(&m)) {
    f.id = omni_id(FunctionCode::nmt, a->node);
    f.kind = can::FrameKind::remote;
  } else if (const auto* c = std::get_if<SpeedCommand>(&m)) {
    f.id = omni_id(FunctionCode::broadcast_8x1byte, c->sender);
    f.dlc = kSpeedCommandDlc;
    f.data[0] = c->sender;
    for (int k = 0; k < 4; ++k)
      f.data[static_cast<std::size_t>(1 + k)] = static_cast<std::uint8_t>(c->axis[static_cast<std::size_t>(3 - k)]);
  } else if (const auto* s = std::get_if<SpeedFeedback>(&m)) {
    const auto fc = feedback_function(axis_of_slave(s->sender));
    // A non-slave sender gets function code 010; decode() then rejects the sender byte.
    f.id = omni_id(fc.value_or(FunctionCode::process_data_1), node::master);
    f.dlc = kSpeedFeedbackDlc;
    f.data[0] = s->sender;
    f.data[1] = s->data_type;
    put_be(f, 2, 4, static_cast<std::uint32_t>(s->value));
  } else if (const auto* p = std::get_if<ParameterSetup>(&m)) {
    const int n = p->width == ParamWidth::two_bytes ? 2 : 4;  // a bogus width fails the compare
    f.id = omni_id(FunctionCode::parameter_setup, p->receiver);
    f.dlc = static_cast<std::uint8_t>(2 + n);
    f.data[0] = p->sender;
    f.data[1] = p->data_type;
    put_be(f, 2, n, p->value);
  }
  return f;
}

}  // namespace

int axis_of_slave(std::uint8_t n) {
  for (std::size_t i = 0; i < node::slaves.size(); ++i)
    if (node::slaves[i] == n) return static_cast<int>(i) + 1;
  return 0;
}

std::uint8_t slave_of_axis(int axis) {
  return axis >= 1 && axis <= 4 ? node::slaves[static_cast<std::size_t>(axis - 1)] : 0;
}

std::optional<FunctionCode> feedback_function(int axis) {
  if (axis < 1 || axis > 4) return std::nullopt;
  return kFeedbackFunction[static_cast<std::size_t>(axis - 1)];
}

const char* to_string(OmniError e) {
  switch (e) {
    case OmniError::not_omni: return "not_omni";
    case OmniError::unknown_function: return "unknown_function";
    case OmniError::wrong_kind: return "wrong_kind";
    case OmniError::wrong_dlc: return "wrong_dlc";
    case OmniError::bad_node: return "bad_node";
    case OmniError::bad_value: return "bad_value";
  }
  return "unknown_error";
}

DecodeResult decode(const can::Frame& f) noexcept {
  if (f.extended || f.id > 0x7FFu) return DecodeError::not_omni;
  if (f.kind != can::FrameKind::data && f.kind != can::FrameKind::remote) return DecodeError::not_omni;
  if (f.dlc > 8) return DecodeError::wrong_dlc;
  const auto id = static_cast<std::uint16_t>(f.id);
  const FunctionCode fc = function_code(id);
  const std::uint8_t n = node_id(id);
  switch (fc) {
    case FunctionCode::nmt: return decode_nmt(f, n);
    case FunctionCode::broadcast_8x1byte: return decode_speed_command(f, n);
    case FunctionCode::process_data_1:
    case FunctionCode::process_data_2:
    case FunctionCode::process_data_3:
    case FunctionCode::process_data_4: return decode_feedback(f, fc, n);
    case FunctionCode::parameter_setup: return decode_parameter(f, n);
    case FunctionCode::broadcast_4x2byte: break;
  }
  return DecodeError::unknown_function;
}

EncodeResult encode(const Message& m) noexcept {
  if (const auto* p = std::get_if<ParameterSetup>(&m)) {
    if (p->width != ParamWidth::two_bytes && p->width != ParamWidth::four_bytes) return EncodeError::bad_value;
    if (p->width == ParamWidth::two_bytes && p->value > 0xFFFFu) return EncodeError::bad_value;
  }
  if (const auto* a = std::get_if<DetectionAnswer>(&m); a && a->node == 0) return EncodeError::bad_node;
  const can::Frame f = frame_for(m);
  // One source of truth for validity: the frame must decode back to exactly `m`.
  const DecodeResult back = decode(f);
  if (const auto* e = std::get_if<DecodeError>(&back)) return *e;
  if (!(std::get<Message>(back) == m)) return EncodeError::bad_value;
  return f;
}

std::int8_t saturate_axis_command(std::int64_t counts_per_sample) noexcept {
  if (counts_per_sample > 127) return 127;
  if (counts_per_sample < -128) return -128;
  return static_cast<std::int8_t>(counts_per_sample);
}

std::int8_t axis_command_from(double counts_per_sample) noexcept {
  if (std::isnan(counts_per_sample)) return 0;
  if (counts_per_sample >= 127.0) return 127;
  if (counts_per_sample <= -128.0) return -128;
  return static_cast<std::int8_t>(std::lround(counts_per_sample));
}

std::optional<std::array<ParameterSetup, 4>> fan_out_to_slaves(const ParameterSetup& from_pc) noexcept {
  if (from_pc.receiver != node::master || from_pc.sender != node::pc ||
      from_pc.data_type != data_type::slave_controller_setting || from_pc.value > 0xFFFFu)
    return std::nullopt;
  std::array<ParameterSetup, 4> out{};
  for (std::size_t i = 0; i < out.size(); ++i)
    out[i] = ParameterSetup{node::slaves[i], node::master, data_type::axis_controller_setting,
                            ParamWidth::two_bytes, from_pc.value};
  return out;
}

}  // namespace omnitwin::omni
