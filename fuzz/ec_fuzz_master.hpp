// fuzz/ — a minimal EtherCAT master for the EtherCAT fuzz targets' set-up: it brings emulated
// DriveSlaves to a given AL state through datagrams only (built with PduBuilder and passed
// through the EscChain), as a real master does, so that the fuzzed frames and mailboxes meet
// slaves configured over the wire and not through back doors.
//
// Bring-up of the slave at position p (steps of IgH/SOEM-style masters, facts/ethercat.md):
//   APWR 0x0010 station address;
//   INIT → PRE-OP:  FPWR SM0/SM1 (0x0800/0x0808) from the ESI mailbox SMs (or a given mailbox
//                   size), AL control 2;
//   PRE-OP → SAFE-OP: FPWR SM2/SM3 with the PDO sizes the slave reports, FMMU0 (outputs,
//                   logical kOutputsLogical + 0x40·p) and FMMU1 (inputs, kInputsLogical + 0x40·p),
//                   AL control 4;
//   SAFE-OP → OP:   one LRW of the whole image, AL control 8.
// Every step checks its working counter and the AL status: the set-up is deterministic, so a
// failing step is a bug (trap), not an input to skip. Set-up code: allocates, not RT.
#pragma once

#include <array>
#include <cstdint>
#include <cstdio>
#include <cstdlib>
#include <cstring>
#include <span>
#include <string>
#include <vector>

#include <unistd.h>

#include "bus_emulators/ethercat/device/ec_esi.hpp"
#include "bus_emulators/ethercat/device/ec_slave.hpp"
#include "bus_emulators/ethercat/ec_chain.hpp"
#include "bus_emulators/ethercat/ec_frame.hpp"
#include "bus_emulators/ethercat/ec_registers.hpp"

namespace omnitwin::ethercat::fuzz {

inline constexpr std::uint32_t kOutputsLogical = 0x00010000;  // FMMU0 of slave p: + 0x40·p
inline constexpr std::uint32_t kInputsLogical = 0x00020000;   // FMMU1 of slave p: + 0x40·p
inline constexpr std::uint16_t kFirstStation = 0x1001;        // station address of position p: + p

[[noreturn]] inline void fail(const char* what) {
  std::fprintf(stderr, "ec fuzz set-up: %s\n", what);
  std::abort();
}

// The first device of a shipped ESI file (models/ethercat/<file>).
inline DeviceDescription shipped_device(const char* file) {
  try {
    auto all = load_esi(std::string(OMNITWIN_SOURCE_DIR) + "/models/ethercat/" + file);
    return all.at(0);
  } catch (const std::exception& e) {
    std::fprintf(stderr, "%s\n", e.what());
    fail("cannot load the shipped ESI");
  }
}

class Master {
 public:
  Master(EscChain& chain, SimTime& t) : chain_(chain), t_(t) {}

  // One frame with one datagram; returns its WKC and copies the returned data into `out`
  // (may be null). The simulated time moves on by 10 µs.
  int exchange(Cmd cmd, std::uint16_t adp, std::uint16_t ado, const void* data, std::uint16_t len,
               void* out = nullptr) {
    PduBuilder b(buf_);
    const int off = b.add(cmd, 0x5A, adp, ado, len, data);
    if (off < 0) fail("datagram does not fit");
    const std::size_t n = b.finish();
    if (!chain_.process(std::span<std::uint8_t>(buf_.data(), n), t_)) fail("frame lost");
    t_ += 10'000;
    if (out != nullptr) std::memcpy(out, buf_.data() + off, len);
    return get_u16(buf_.data() + off + len);
  }
  int apwr(int pos, std::uint16_t ado, const void* d, std::uint16_t n) {
    return exchange(Cmd::apwr, static_cast<std::uint16_t>(-pos), ado, d, n);
  }
  int fpwr(std::uint16_t station, std::uint16_t ado, const void* d, std::uint16_t n) {
    return exchange(Cmd::fpwr, station, ado, d, n);
  }
  int fprd(std::uint16_t station, std::uint16_t ado, void* out, std::uint16_t n) {
    return exchange(Cmd::fprd, station, ado, nullptr, n, out);
  }
  void expect_wkc(int got, int want, const char* what) {
    if (got != want) {
      std::fprintf(stderr, "ec fuzz set-up: %s: WKC %d, expected %d\n", what, got, want);
      std::abort();
    }
  }

  // AL control `state` and the check that the slave is there without error.
  void request_state(std::uint16_t station, AlState state) {
    const std::uint16_t ctl = static_cast<std::uint16_t>(state) | reg::kAlControlErrorAck;
    std::uint8_t v[2];
    put_u16(v, ctl);
    expect_wkc(fpwr(station, reg::kAlControl, v, 2), 1, "AL control");
    std::uint8_t st[2] = {};
    expect_wkc(fprd(station, reg::kAlStatus, st, 2), 1, "AL status");
    if (get_u16(st) != static_cast<std::uint16_t>(state)) {
      std::fprintf(stderr, "ec fuzz set-up: AL status %#x after request %#x\n", get_u16(st), ctl);
      std::abort();
    }
  }

  // Brings the (powered, INIT) slave at position `pos` to `target`; mailbox_bytes != 0 sets
  // both mailbox SMs to that length instead of the ESI's default sizes.
  void bring_up(int pos, DriveSlave& s, AlState target, std::uint16_t mailbox_bytes = 0) {
    const auto station = static_cast<std::uint16_t>(kFirstStation + pos);
    std::uint8_t v[16] = {};
    put_u16(v, station);
    expect_wkc(apwr(pos, reg::kStationAddress, v, 2), 1, "station address");
    if (target == AlState::init) return;
    const auto& sms = s.description().sms;
    for (int i = 0; i < 2; ++i) {
      const EsiSyncManager& m = sms.at(static_cast<std::size_t>(i));
      sm_regs(v, m.start, mailbox_bytes != 0 ? mailbox_bytes : m.size, m.control);
      expect_wkc(fpwr(station, static_cast<std::uint16_t>(reg::kSm0 + 8 * i), v, 8), 1, "mailbox SM");
    }
    request_state(station, AlState::preop);
    if (target == AlState::preop) return;
    const int so = s.output_sm(), si = s.input_sm();
    const auto ob = static_cast<std::uint16_t>(s.output_bytes());
    const auto ib = static_cast<std::uint16_t>(s.input_bytes());
    const EsiSyncManager& mo = sms.at(static_cast<std::size_t>(so));
    const EsiSyncManager& mi = sms.at(static_cast<std::size_t>(si));
    sm_regs(v, mo.start, ob, mo.control);
    expect_wkc(fpwr(station, static_cast<std::uint16_t>(reg::kSm0 + 8 * so), v, 8), 1, "outputs SM");
    sm_regs(v, mi.start, ib, mi.control);
    expect_wkc(fpwr(station, static_cast<std::uint16_t>(reg::kSm0 + 8 * si), v, 8), 1, "inputs SM");
    fmmu_regs(v, kOutputsLogical + 0x40u * static_cast<std::uint32_t>(pos), ob, mo.start, 2);
    expect_wkc(fpwr(station, reg::kFmmu0, v, 16), 1, "outputs FMMU");
    fmmu_regs(v, kInputsLogical + 0x40u * static_cast<std::uint32_t>(pos), ib, mi.start, 1);
    expect_wkc(fpwr(station, reg::kFmmu0 + reg::kFmmuSize, v, 16), 1, "inputs FMMU");
    request_state(station, AlState::safeop);
    if (target == AlState::safeop) return;
    // One process-data exchange (outputs all zero: controlword 0) before OP.
    std::vector<std::uint8_t> img(ob, 0);
    exchange(Cmd::lwr, static_cast<std::uint16_t>(kOutputsLogical + 0x40u * static_cast<std::uint32_t>(pos)),
             static_cast<std::uint16_t>(kOutputsLogical >> 16), img.data(), ob);
    request_state(station, AlState::op);
  }

 private:
  static void sm_regs(std::uint8_t* v, std::uint16_t start, std::uint16_t len, std::uint8_t control) {
    std::memset(v, 0, 8);
    put_u16(v, start);
    put_u16(v + 2, len);
    v[4] = control;
    v[6] = len > 0 ? 0x01 : 0x00;
  }
  static void fmmu_regs(std::uint8_t* v, std::uint32_t logical, std::uint16_t len, std::uint16_t phys,
                        std::uint8_t type) {
    std::memset(v, 0, 16);
    put_u32(v, logical);
    put_u16(v + 4, len);
    v[6] = 0;
    v[7] = 7;
    put_u16(v + 8, phys);
    v[10] = 0;
    v[11] = type;
    v[12] = len > 0 ? 0x01 : 0x00;
  }

  EscChain& chain_;
  SimTime& t_;
  std::array<std::uint8_t, kMaxPdu> buf_{};
};

// The inputs since the last restart of a stateful target, so that a failure found after many
// inputs can be replayed. On a failed check the target calls dump() (file
// "<prefix>history-<pid>": u8 restart tag, then per input u32 length + bytes) and traps; running
// the target with EC_FUZZ_REPLAY=<that file> and any one input replays the restart and every
// recorded input in order before that input (replay(), first call only).
class History {
 public:
  explicit History(const char* prefix) : prefix_(prefix) {}

  void restart(std::uint8_t tag) {
    tag_ = tag;
    bytes_.clear();
  }
  void record(const std::uint8_t* data, std::size_t size) {
    std::uint8_t n[4];
    put_u32(n, static_cast<std::uint32_t>(size));
    bytes_.insert(bytes_.end(), n, n + 4);
    bytes_.insert(bytes_.end(), data, data + size);
  }
  void dump() const {
    const std::string path = std::string(prefix_) + "history-" + std::to_string(::getpid());
    if (FILE* f = std::fopen(path.c_str(), "wb")) {
      std::fputc(tag_, f);
      if (!bytes_.empty()) std::fwrite(bytes_.data(), 1, bytes_.size(), f);
      std::fclose(f);
      std::fprintf(stderr, "ec fuzz: inputs since the restart written to %s (replay: EC_FUZZ_REPLAY=%s)\n",
                   path.c_str(), path.c_str());
    }
  }
  // The recorded restart tag and inputs of EC_FUZZ_REPLAY, once; false when not replaying.
  bool replay(std::uint8_t& tag, std::vector<std::vector<std::uint8_t>>& inputs) {
    if (replayed_) return false;
    replayed_ = true;
    const char* path = std::getenv("EC_FUZZ_REPLAY");
    if (path == nullptr) return false;
    FILE* f = std::fopen(path, "rb");
    if (f == nullptr) fail("EC_FUZZ_REPLAY cannot be read");
    std::vector<std::uint8_t> b;
    for (int c; (c = std::fgetc(f)) != EOF;) b.push_back(static_cast<std::uint8_t>(c));
    std::fclose(f);
    if (b.empty()) fail("EC_FUZZ_REPLAY is empty");
    tag = b[0];
    for (std::size_t pos = 1; pos + 4 <= b.size();) {
      const std::size_t n = get_u32(&b[pos]);
      pos += 4;
      if (pos + n > b.size()) fail("EC_FUZZ_REPLAY is truncated");
      inputs.emplace_back(b.begin() + static_cast<std::ptrdiff_t>(pos), b.begin() + static_cast<std::ptrdiff_t>(pos + n));
      pos += n;
    }
    return true;
  }

 private:
  const char* prefix_;
  std::uint8_t tag_ = 0;
  std::vector<std::uint8_t> bytes_;
  bool replayed_ = false;
};

// A failed invariant: says where, writes the history for replay, and traps (libFuzzer keeps
// the input). Targets wrap it as CHECK(cond) with their own history.
[[noreturn]] inline void check_failed(const History& h, const char* file, int line, const char* what) {
  std::fprintf(stderr, "%s:%d: check failed: %s\n", file, line, what);
  h.dump();
  __builtin_trap();
}

// EC_FUZZ_REPLAY: before a target's first input, re-run a recorded failure's history on a rig
// restarted with the recorded tag. `rig` has restart(tag) and a count `inputs`; `one_input(rig,
// data, size)` is the target's step.
template <class Rig, class OneInput>
void replay_recorded(History& h, Rig& rig, OneInput one_input) {
  std::uint8_t tag = 0;
  std::vector<std::vector<std::uint8_t>> earlier;
  if (!h.replay(tag, earlier)) return;
  rig.restart(tag);
  for (const auto& in : earlier) one_input(rig, in.data(), in.size());
  rig.inputs = earlier.size();
}

#define EC_FUZZ_CHECK(history, cond)                                                    \
  do {                                                                                  \
    if (!(cond)) ::omnitwin::ethercat::fuzz::check_failed(history, __FILE__, __LINE__, #cond); \
  } while (0)

}  // namespace omnitwin::ethercat::fuzz
