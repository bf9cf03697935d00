// libFuzzer target for the EtherCAT frame path: bus_emulators/ethercat/ec_frame (parse_pdu,
// PduBuilder), the transports' check_pdu (ethercat/transport), and every datagram through a
// line of real emulated slaves (ec_chain → ec_esc: addressing, registers, SyncManagers, FMMUs,
// SII EEPROM interface, distributed clocks, AL state machine → device/ec_slave firmware).
//
// The slaves are built once: two single-axis drives (models/ethercat/omnitwin_drive.xml) and
// the multi-axis controller (models/ethercat/omnitwin_multiaxis.xml, 2 cards). Their state
// carries across inputs (as on a real bus); every kEpoch inputs they are rebuilt in their
// power-on state at t = 0 and brought up by the set-up master (ec_fuzz_master.hpp), in turn to
// PRE-OP, SAFE-OP, OP and INIT, so fuzzed frames meet configured mailboxes, process-data SMs
// and FMMUs as well (they are also rebuilt before an input when a slave's SYNC0 runs faster
// than every kMinSync0CycleNs: the emulator then spends ~0.3 s per frame). Since a failure may
// depend on the inputs before it, a failed check writes the inputs since the restart (the
// failing one last) to ./ec_datagram_history-<pid>; replay with
// `EC_FUZZ_REPLAY=that-file ./ec_datagram_fuzz any-input-file`. Reproducers of bugs found are
// kept in fuzz/corpus/ec_datagram/crash-* (single inputs from the start-up state).
//
// Every input is used twice:
//  1. raw: the bytes are an EtherCAT PDU as a transport would hand it over;
//  2. built: the bytes are read as datagram records — cmd u8, ADP u16, ADO u16, length u16
//     (11 bits, clamped to what still fits), data (missing bytes 0) — appended with PduBuilder,
//     so the fuzzer reaches the ESC without having to get the chain lengths right.
// Properties checked (trap on failure; ASan/UBSan check memory and UB):
//  - parse_pdu: ok ⇔ a chain of 1..64 datagrams covers exactly the header length (M bits set
//    on all but the last), count 0 on error, error names exist; check_pdu agrees (ok with the
//    same size whenever parse_pdu is ok; foreign exactly when the type is not 1);
//  - PduBuilder: what it built parses back to the same datagrams;
//  - EscChain::process returns true exactly when the PDU parses; the frame keeps its length,
//    the EtherCAT header, padding, each datagram's cmd, index, length/flags word and ADO; IRQ
//    bits are only added (slaves OR their masked ECAT event requests in);
//    ADP moves by the number of slaves for position and broadcast commands and not otherwise;
//    the WKC rises by at most (1 read + 2 write) per slave and command kind; NOP, undefined
//    commands and write-only commands (APWR, FPWR, BWR, LWR) leave the data as it was;
//  - every slave's AL status register mirrors its AL state, error flag and status code, and
//    the state is one the firmware allows (never BOOT).
//
//   ./ec_datagram_fuzz -dict=fuzz/ec_datagram.dict -max_total_time=60
#include <algorithm>
#include <array>
#include <cstdint>
#include <cstdio>
#include <cstdlib>
#include <cstring>
#include <memory>
#include <span>
#include <vector>

#include "bus_emulators/ethercat/device/ec_slave.hpp"
#include "bus_emulators/ethercat/ec_chain.hpp"
#include "bus_emulators/ethercat/ec_frame.hpp"
#include "bus_emulators/ethercat/transport/ec_transport.hpp"
#include "fuzz/ec_fuzz_master.hpp"

using namespace omnitwin::ethercat;

namespace {

constexpr std::uint64_t kEpoch = 512;  // inputs between restarts
// SYNC0 cycles below this make every datagram run up to 100000 firmware cycles (Esc::advance
// delivers every missed pulse): the harness restarts rather than fuzz at ~3 inputs/s.
constexpr std::uint32_t kMinSync0CycleNs = 50'000;

fuzz::History& history() {
  static fuzz::History h("./ec_datagram_");
  return h;
}

#define CHECK(cond) EC_FUZZ_CHECK(history(), cond)

struct Bus {
  DeviceDescription drive = fuzz::shipped_device("omnitwin_drive.xml");
  DeviceDescription multi = fuzz::shipped_device("omnitwin_multiaxis.xml");
  std::vector<std::unique_ptr<DriveSlave>> slaves;
  std::unique_ptr<EscChain> chain;
  SimTime t = 0;
  std::uint64_t inputs = 0;
  std::uint8_t epoch = 0;

  Bus() { restart(0); }

  // New slaves (power-on state, fresh firmware and drives) at t = 0, brought to the state of
  // this restart (tag % 4: PRE-OP, SAFE-OP, OP, INIT), so what follows depends on the inputs since.
  void restart(std::uint8_t tag) {
    static constexpr AlState kTargets[] = {AlState::preop, AlState::safeop, AlState::op, AlState::init};
    epoch = tag;
    history().restart(tag);
    t = 0;
    chain = std::make_unique<EscChain>();
    slaves.clear();
    DriveSlaveConfig cfg;
    cfg.axes = 1;
    for (int i = 0; i < 2; ++i) {
      cfg.serial = 100 + static_cast<std::uint32_t>(i);
      slaves.push_back(std::make_unique<DriveSlave>(drive, cfg));
    }
    cfg.axes = 2;
    cfg.serial = 200;
    slaves.push_back(std::make_unique<DriveSlave>(multi, cfg));
    for (auto& s : slaves) chain->add(&s->esc());
    fuzz::Master m(*chain, t);
    for (int i = 0; i < chain->size(); ++i) m.bring_up(i, *slaves[static_cast<std::size_t>(i)], kTargets[tag % 4]);
  }

  // A slave with DC SYNC0 running at a cycle below kMinSync0CycleNs (see there).
  bool sync0_storm() const {
    for (const auto& s : slaves) {
      const DcClock& dc = s->esc().dc();
      if (dc.sync0_active() && dc.sync0_cycle() > 0 && dc.sync0_cycle() < kMinSync0CycleNs) return true;
    }
    return false;
  }

  // The firmware and drives after each frame.
  void after_frame() {
    t += 250'000;  // 250 µs per frame
    chain->advance(t);
    for (auto& s : slaves) {
      s->cycle(t);
      for (int a = 0; a < s->axes(); ++a) s->axis(a).step(t, omnitwin::drive::Feedback{});
    }
    for (auto& s : slaves) check_al(s->esc());
  }

  static void check_al(const Esc& e) {
    const AlState s = e.al_state();
    CHECK(s == AlState::init || s == AlState::preop || s == AlState::safeop || s == AlState::op);
    const std::uint16_t st = e.read16(0x0130);
    CHECK((st & 0x0F) == static_cast<std::uint16_t>(s));
    CHECK(((st & 0x10) != 0) == e.al_error());
    CHECK(e.read16(0x0134) == static_cast<std::uint16_t>(e.al_status_code()));
    CHECK(to_string(s) != nullptr && to_string(e.al_status_code()) != nullptr);
  }
};

// What one slave may add to the WKC for this command at most.
int max_wkc_per_slave(std::uint8_t raw) {
  if (raw > static_cast<std::uint8_t>(Cmd::frmw)) return 0;
  const Cmd c = static_cast<Cmd>(raw);
  if (c == Cmd::nop) return 0;
  if (c == Cmd::armw || c == Cmd::frmw) return 1;  // the addressed one reads, the others write
  if (cmd_reads(c) && cmd_writes(c)) return 3;      // read +1, write +2
  return 1;
}

// parse_pdu's structural properties and its agreement with check_pdu.
PduError parse_and_check(std::span<std::uint8_t> pdu, PduView& v) {
  const PduError e = parse_pdu(pdu, v);
  CHECK(to_string(e) != nullptr);
  std::size_t size = 0;
  const PduCheck pc = check_pdu(pdu.data(), pdu.size(), size);
  if (pdu.size() >= kEcatHeaderSize && (get_u16(pdu.data()) >> 12) != kPduTypeSlaves) {
    CHECK(e == PduError::wrong_type && pc == PduCheck::foreign);
  }
  if (e != PduError::ok) {
    CHECK(v.count == 0);
    return e;
  }
  CHECK(pc == PduCheck::ok && size == v.length);
  CHECK(v.count >= 1 && v.count <= kMaxDatagrams);
  CHECK(v.length == kEcatHeaderSize + (get_u16(pdu.data()) & 0x07FF) && v.length <= pdu.size());
  std::size_t pos = kEcatHeaderSize;
  for (std::size_t i = 0; i < v.count; ++i) {
    const Datagram& d = v.datagrams[i];
    CHECK(d.header() == pdu.data() + pos);
    CHECK(d.more() == (i + 1 < v.count));
    CHECK(d.payload().data() == d.data() && d.payload().size() == d.length());
    pos += d.size();
  }
  CHECK(pos == v.length);
  return e;
}

// One frame through the chain with the properties of the file comment.
void run_frame(Bus& bus, std::span<std::uint8_t> pdu) {
  PduView v;
  const PduError e = parse_and_check(pdu, v);
  std::vector<std::uint8_t> before(pdu.begin(), pdu.end());
  const bool back = bus.chain->process(pdu, bus.t);
  CHECK(back == (e == PduError::ok));
  if (!back) {
    CHECK(std::equal(before.begin(), before.end(), pdu.begin()));  // a dropped frame is not touched
    bus.after_frame();
    return;
  }
  const int n = bus.chain->reachable();
  // Header and padding as they were.
  CHECK(std::memcmp(before.data(), pdu.data(), kEcatHeaderSize) == 0);
  CHECK(std::memcmp(before.data() + v.length, pdu.data() + v.length, pdu.size() - v.length) == 0);
  PduView again;
  CHECK(parse_pdu(pdu, again) == PduError::ok && again.count == v.count && again.length == v.length);
  for (std::size_t i = 0; i < v.count; ++i) {
    const Datagram& d = v.datagrams[i];
    const std::size_t off = static_cast<std::size_t>(d.header() - pdu.data());
    const std::uint8_t* b = before.data() + off;
    const std::uint8_t* a = pdu.data() + off;
    CHECK(a[0] == b[0] && a[1] == b[1]);                  // cmd, index
    CHECK(std::memcmp(a + 4, b + 4, 4) == 0);             // ADO, length/flags
    CHECK((get_u16(a + 8) & get_u16(b + 8)) == get_u16(b + 8));  // IRQ: slaves only OR events in
    const std::uint8_t raw = b[0];
    const bool defined = raw <= static_cast<std::uint8_t>(Cmd::frmw);
    const CmdAddressing how = defined ? addressing(static_cast<Cmd>(raw)) : CmdAddressing::none;
    const std::uint16_t adp_before = get_u16(b + 2), adp_after = get_u16(a + 2);
    if (how == CmdAddressing::position || how == CmdAddressing::broadcast) {
      CHECK(adp_after == static_cast<std::uint16_t>(adp_before + n));
    } else {
      CHECK(adp_after == adp_before);
    }
    const std::size_t len = d.length();
    const auto wkc_rise = static_cast<std::uint16_t>(get_u16(a + kDatagramHeaderSize + len) -
                                                     get_u16(b + kDatagramHeaderSize + len));
    CHECK(wkc_rise <= max_wkc_per_slave(raw) * n);
    const bool data_kept = !defined || how == CmdAddressing::none ||
                           (cmd_writes(static_cast<Cmd>(raw)) && !cmd_reads(static_cast<Cmd>(raw)));
    if (data_kept) CHECK(std::memcmp(a + kDatagramHeaderSize, b + kDatagramHeaderSize, len) == 0);
    if (!defined || how == CmdAddressing::none) CHECK(wkc_rise == 0);
  }
  bus.after_frame();
}

// The input read as datagram records, built with PduBuilder (file comment, 2.).
std::size_t build(const std::uint8_t* data, std::size_t size, std::span<std::uint8_t> buf) {
  PduBuilder b(buf);
  struct Added { std::uint8_t cmd; std::uint16_t adp, ado, len; std::size_t off; };
  std::array<Added, kMaxDatagrams> added{};
  std::size_t count = 0, pos = 0;
  auto byte = [&](std::size_t i) -> std::uint8_t { return i < size ? data[i] : 0; };
  while (pos < size && count < kMaxDatagrams) {
    const std::uint8_t cmd = byte(pos);
    const auto adp = static_cast<std::uint16_t>(byte(pos + 1) | byte(pos + 2) << 8);
    const auto ado = static_cast<std::uint16_t>(byte(pos + 3) | byte(pos + 4) << 8);
    std::size_t len = static_cast<std::size_t>(byte(pos + 5) | (byte(pos + 6) & 0x07) << 8);
    pos += 7;
    if (b.room() == 0) break;
    len = std::min(len, b.room());
    std::array<std::uint8_t, kMaxDatagramData> d{};
    const std::size_t have = pos < size ? std::min(len, size - pos) : 0;
    if (have > 0) std::memcpy(d.data(), data + pos, have);
    pos += have;
    const int off = b.add(static_cast<Cmd>(cmd), static_cast<std::uint8_t>(count), adp, ado,
                          static_cast<std::uint16_t>(len), d.data());
    CHECK(off >= 0);  // room() promised it fits
    CHECK(std::memcmp(buf.data() + off, d.data(), len) == 0);
    added[count++] = Added{cmd, adp, ado, static_cast<std::uint16_t>(len), static_cast<std::size_t>(off)};
  }
  if (count == 0) return 0;
  CHECK(b.datagrams() == count);
  const std::size_t n = b.finish();
  CHECK(n == b.size() && n <= kMaxPdu);
  PduView v;
  CHECK(parse_and_check(buf.first(n), v) == PduError::ok);
  CHECK(v.count == count && v.length == n);
  for (std::size_t i = 0; i < count; ++i) {
    const Datagram& d = v.datagrams[i];
    CHECK(d.raw_cmd() == added[i].cmd && d.index() == i && d.adp() == added[i].adp && d.ado() == added[i].ado);
    CHECK(d.length() == added[i].len && d.wkc() == 0 && d.irq() == 0 && !d.circulating());
    CHECK(static_cast<std::size_t>(d.data() - buf.data()) == added[i].off);
    CHECK(d.logical() == (static_cast<std::uint32_t>(added[i].adp) | static_cast<std::uint32_t>(added[i].ado) << 16));
  }
  return n;
}

// One input: the raw PDU, then the PDU built from its records.
void one_input(Bus& bus, const std::uint8_t* data, std::size_t size) {
  history().record(data, size);
  std::vector<std::uint8_t> pdu(data, data + size);  // own copy: the chain writes in place
  run_frame(bus, pdu);
  std::array<std::uint8_t, kMaxPdu> buf{};
  const std::size_t n = build(data, size, buf);
  if (n > 0) run_frame(bus, std::span<std::uint8_t>(buf.data(), n));
}

}  // namespace

extern "C" int LLVMFuzzerTestOneInput(const std::uint8_t* data, std::size_t size) {
  static Bus bus;
  fuzz::replay_recorded(history(), bus, one_input);  // EC_FUZZ_REPLAY: a recorded failure first
  if (++bus.inputs % kEpoch == 0 || bus.sync0_storm()) {
    bus.inputs = 0;
    bus.restart(static_cast<std::uint8_t>(bus.epoch + 1));
  }
  one_input(bus, data, size);
  return 0;
}
