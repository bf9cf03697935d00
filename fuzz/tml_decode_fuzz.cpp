// libFuzzer target for bus_emulators/tml: the serial receiver and packet codec, and the TMLCAN and
// TechCAN decoders.
//
// Byte 0 picks the path. Serial (even): the rest is fed byte by byte to a drive-role and a
// host-role SerialReceiver; every decoded message must re-encode to a packet that decodes to the
// same message, and the counters must add up to the events seen. CAN (odd): the rest is read as
// a raw frame — bytes 1–4 identifier (little-endian, any value), byte 5 flags (bit 0 extended,
// bits 1–2 kind: 0 data, 1 remote, 2 error, 3 an out-of-range value), byte 6 DLC (any value),
// then up to 8 data bytes — and given to both CAN decoders. Whatever TMLCAN decodes must
// re-encode to the same frame; whatever TechCAN decodes (other than PONG) must re-encode to a
// frame that decodes to the same message (less the destination where that layout drops it). describe() must work on every decoded message.
// Abort on any mismatch.
//
//   clang++ -std=c++20 -g -O1 -fsanitize=fuzzer,address,undefined -I. fuzz/tml_decode_fuzz.cpp \
//     bus_emulators/tml/tml_message.cpp bus_emulators/tml/tml_serial.cpp bus_emulators/tml/tml_can.cpp \
//     bus_emulators/can/can_frame.cpp -lfmt
//   ./a.out -max_total_time=30
#include <cstdlib>

#include "bus_emulators/tml/tml_can.hpp"
#include "bus_emulators/tml/tml_serial.hpp"

using namespace omnitwin;
using namespace omnitwin::tml;

namespace {

void check_serial(const std::uint8_t* data, std::size_t size) {
  std::uint64_t events = 0;
  auto on_event = [&](const RxEvent& e) {
    ++events;
    if (e.kind != RxEventKind::message) return;
    Message back;
    if (decode_packet(encode_packet(e.message).view(), back) != PacketStatus::ok || !(back == e.message)) std::abort();
    if (describe(e.message).empty()) std::abort();
  };
  SerialReceiver drive(Role::drive, on_event), host(Role::host, on_event);
  for (std::size_t i = 0; i < size; ++i) {
    drive.on_byte(data[i], static_cast<std::int64_t>(i));
    host.on_byte(data[i], static_cast<std::int64_t>(i));
  }
  std::uint64_t counted = 0;
  for (const RxStats* s : {&drive.stats(), &host.stats()})
    counted += s->messages + s->acks + s->syncs + s->bad_checksums + s->bad_lengths + s->junk;
  if (counted != events) std::abort();
}

void check_can(const std::uint8_t* data, std::size_t size) {
  auto byte = [&](std::size_t i) -> std::uint8_t { return i < size ? data[i] : 0; };
  can::Frame f;
  f.id = static_cast<std::uint32_t>(byte(0)) | static_cast<std::uint32_t>(byte(1)) << 8 |
         static_cast<std::uint32_t>(byte(2)) << 16 | static_cast<std::uint32_t>(byte(3)) << 24;
  f.extended = (byte(4) & 1u) != 0;
  const unsigned kind = (byte(4) >> 1) & 3u;
  f.kind = kind == 3 ? static_cast<can::FrameKind>(0x7F) : static_cast<can::FrameKind>(kind);
  f.dlc = byte(5);
  for (std::size_t i = 0; i < 8; ++i) f.data[i] = byte(6 + i);

  Message m;
  if (decode_tmlcan(f, m) == CanStatus::ok) {
    can::Frame g;
    if (encode_tmlcan(m, g) != CanStatus::ok || !(g == f) || describe(m).empty()) std::abort();
  }
  TechCanMessage t;
  if (decode_techcan(f, t) == CanStatus::ok && t.kind != TechCanKind::pong) {
    if (describe(t.message, t.destination_known).empty()) std::abort();
    // Re-encode with a destination TechCAN can carry where it was not carried.
    Message again = t.message;
    if (!t.destination_known) again.id_code = axis_id_code(1);
    can::Frame g;
    if (encode_techcan(again, g) != CanStatus::ok) return;  // e.g. a sync opcode outside 0x020
    TechCanMessage u;
    if (decode_techcan(g, u) != CanStatus::ok) std::abort();
    Message want = again;  // a layout may drop the destination (e.g. a TakeData opcode in a normal frame)
    if (!u.destination_known) want.id_code = 0;
    if (!(u.message == want)) std::abort();
  }
}

}  // namespace

extern "C" int LLVMFuzzerTestOneInput(const std::uint8_t* data, std::size_t size) {
  if (size == 0) return 0;
  if (data[0] % 2 == 0) check_serial(data + 1, size - 1);
  else check_can(data + 1, size - 1);
  return 0;
}
