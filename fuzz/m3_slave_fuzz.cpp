// libFuzzer target for the M-III slave's command path: bus_emulators/mechatrolink3/m3_link
// (frame checks, phases, WDT, COMM_ALM) and m3_servo (every servo command on the shared drive
// core), fed frames a master might send.
//
// The input is a sequence of records: byte 0 the record's length L (frames are capped at the
// largest M-III frame), byte 1 a control byte (bit 0: step the drive 1 ms and advance the
// link's time first; bit 1: re-encode the record's bytes as a valid frame to this slave from
// the C1 master, so the FCS passes and the command parser is reached; bit 2: power cycle),
// then L bytes. Before the records the slave is powered on, told a 1 ms cycle and started,
// so the parser is reached in every phase. Properties checked: nothing crashes or throws
// (ASan/UBSan), every frame the slave sends decodes as a valid frame from its address to the
// C1 master with the same length as the command it answers, and the phase is always one of
// 1, 2, 3 (5 only after a power cycle). Abort on any violation.
//
//   see fuzz/CMakeLists.txt for the sources it compiles
#include <cstdlib>
#include <vector>

#include "bus_emulators/drive/axis_model.hpp"
#include "bus_emulators/mechatrolink3/m3_link.hpp"
#include "bus_emulators/mechatrolink3/m3_servo.hpp"

using namespace omnitwin;
using namespace omnitwin::m3;

namespace {

constexpr std::uint8_t kMe = 0x03;

// A valid frame to this slave carrying `raw` as its information field (the type and length
// forced to something the codec accepts), or empty.
std::vector<std::uint8_t> as_frame(std::span<const std::uint8_t> raw) {
  static constexpr std::size_t kLens[] = {8, 16, 32, 48, 64};
  const std::size_t n = kLens[raw.empty() ? 0 : raw[0] % 5];
  std::vector<std::uint8_t> data(n, 0);
  for (std::size_t i = 0; i < n && i + 1 < raw.size(); ++i) data[i] = raw[i + 1];
  const FrameType type = (!raw.empty() && (raw[0] & 0x80)) ? FrameType::event_command : FrameType::cyclic_command;
  if (type == FrameType::event_command) data.resize(64, 0);
  std::vector<std::uint8_t> out(kMaxFrame);
  out.resize(encode(FrameSpec{.dst = kMe, .src = kC1Master, .type = type, .sequence = 0, .retry = false,
                              .data = data},
                    out));
  // A copy of exactly its size: ASan sees a read past a frame's end only past its capacity (a
  // short command read at a long one's offsets stayed inside kMaxFrame and went unseen).
  return std::vector<std::uint8_t>(out.begin(), out.end());
}

}  // namespace

extern "C" int LLVMFuzzerTestOneInput(const std::uint8_t* data, std::size_t size) {
  ServoConfig cfg;
  cfg.drive.counts_per_rev = 10000;
  ServoProfile servo(cfg);
  drive::AxisModel axis;
  std::size_t last_command = 0;
  SlaveLink link(LinkConfig{.address = kMe}, servo, [&](std::span<const std::uint8_t> f, SimTime) {
    FrameView v;
    if (decode(f, v) != FrameStatus::ok || v.src != kMe || v.dst != kC1Master) std::abort();
    const bool answer = v.type == FrameType::cyclic_response || v.type == FrameType::event_response;
    if (answer && v.data.size() != last_command) std::abort();
  });
  SimTime t = 0;
  link.power_on(t);
  std::vector<std::uint8_t> notify(16, 0);
  put_i32(notify, 0, 1'000'000);
  std::vector<std::uint8_t> b(kMaxFrame);
  b.resize(encode(FrameSpec{.dst = kBroadcast, .type = FrameType::cycle_notify, .data = notify}, b));
  link.on_frame(b, t);
  std::vector<std::uint8_t> start(8, 0);
  b.assign(kMaxFrame, 0);
  b.resize(encode(FrameSpec{.dst = kBroadcast, .type = FrameType::comm_start, .data = start}, b));
  link.on_frame(b, t);
  bool cycled = false;
  for (std::size_t at = 0; at + 2 <= size;) {
    const std::size_t len = std::min<std::size_t>(data[at], kMaxFrame + 8);
    const std::uint8_t ctl = data[at + 1];
    const std::span<const std::uint8_t> raw(data + at + 2, std::min(len, size - at - 2));
    at += 2 + raw.size();
    if (ctl & 1) {
      axis.step(servo.step(t, axis.feedback()), 1e-3);
      t += 1'000'000;
      link.advance(t);
    }
    if (ctl & 4) {
      link.power_off(t);
      servo.power_cycle();
      link.power_on(t);
      cycled = true;
    }
    const std::vector<std::uint8_t> frame = (ctl & 2) ? as_frame(raw) : std::vector<std::uint8_t>(raw.begin(), raw.end());
    FrameView v;
    if (decode(frame, v) == FrameStatus::ok) last_command = v.data.size();
    link.on_frame(frame, t);
    const Phase p = link.phase();
    if (p != Phase::p1 && p != Phase::p2 && p != Phase::p3 && !(cycled && p == Phase::p5)) std::abort();
  }
  return 0;
}
