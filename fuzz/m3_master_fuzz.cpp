// libFuzzer target for controller/mechatrolink3/m3_master: our C1 master fed whatever comes
// back on the line while it runs its driver sequence and cyclic exchange with two slaves.
//
// The input is a sequence of records: byte 0 a delay in µs before the record (the master's
// timers run meanwhile: deadlines pass, cycles begin), byte 1 a control byte (bit 0: re-encode
// the record's bytes as a valid frame to the C1 master from slave 03h or 04h, bit 1 choosing
// which, bit 2 making it a cyclic response, else a frame type from the next byte, so the FCS
// passes and the master's matching is reached; bit 3: from another C1 master, address 01h),
// byte 2 the record's length L, then L bytes. Properties checked: nothing crashes or throws
// (ASan/UBSan); the driver state is always a defined one; per slave, retries never exceed
// exchanges × retry slots and recovered retries never exceed retries; every frame the master
// sends decodes as a valid frame from address 01h. Abort on any violation.
#include <cstdlib>
#include <vector>

#include "controller/mechatrolink3/m3_master.hpp"

using namespace omnitwin::m3;

namespace {

std::vector<std::uint8_t> as_frame(std::uint8_t ctl, std::span<const std::uint8_t> raw) {
  static constexpr FrameType kTypes[] = {FrameType::detect_reply, FrameType::delay_reply, FrameType::cyclic_response,
                                         FrameType::event_response, FrameType::sync};
  FrameType type = (ctl & 4) ? FrameType::cyclic_response : kTypes[raw.empty() ? 0 : raw[0] % 5];
  std::size_t n = 32;
  if (type == FrameType::detect_reply || type == FrameType::sync) n = 8;
  if (type == FrameType::delay_reply) n = 0;
  if (type == FrameType::event_response) n = 64;
  std::vector<std::uint8_t> data(n, 0);
  for (std::size_t i = 0; i < n && i + 1 < raw.size(); ++i) data[i] = raw[i + 1];
  const std::uint8_t src = (ctl & 8) ? kC1Master : ((ctl & 2) ? 0x04 : 0x03);
  const std::uint8_t seq = raw.size() > 40 ? raw[40] : 0;
  std::vector<std::uint8_t> out(kMaxFrame);
  out.resize(encode(FrameSpec{.dst = kC1Master, .src = src, .type = type, .sequence = seq, .retry = false, .data = data},
                    out));
  return out;
}

}  // namespace

extern "C" int LLVMFuzzerTestOneInput(const std::uint8_t* data, std::size_t size) {
  MasterConfig cfg;
  cfg.slaves = {MasterSlave{.address = 0x03}, MasterSlave{.address = 0x04}};
  cfg.cycle_ns = 1'000'000;
  cfg.detect_timeout_ns = 20'000;
  C1Master master(
      cfg,
      [](std::span<const std::uint8_t> f, SimTime) {
        FrameView v;
        if (decode(f, v) != FrameStatus::ok || v.src != kC1Master) std::abort();
      },
      [](std::uint64_t, SimTime) {});
  SimTime t = 0;
  master.start(t);
  for (std::size_t at = 0; at + 3 <= size;) {
    const SimTime delay = static_cast<SimTime>(data[at]) * 1'000;
    const std::uint8_t ctl = data[at + 1];
    const std::size_t len = std::min<std::size_t>(data[at + 2], size - at - 3);
    const std::span<const std::uint8_t> raw(data + at + 3, len);
    at += 3 + len;
    t += delay;
    master.advance(t);
    const std::vector<std::uint8_t> frame = (ctl & 1) ? as_frame(ctl, raw) : std::vector<std::uint8_t>(raw.begin(), raw.end());
    master.on_frame(frame, t);
    if (std::string(to_string(master.state())) == "?") std::abort();
    for (int k = 0; k < master.slaves(); ++k) {
      const SlaveCounters& c = master.counters(k);
      if (c.retries > c.exchanges * static_cast<std::uint64_t>(cfg.retry_slots) || c.retry_recovered > c.retries)
        std::abort();
    }
  }
  master.advance(t + 5'000'000);
  return 0;
}
