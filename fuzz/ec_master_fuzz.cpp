// libFuzzer target for controller/ethercat/ec_master: our EtherCAT master, which reads back every
// frame from slaves we did not write (an unmodified SOEM drives ours; ours must survive theirs).
// Two emulated drives (models/ethercat/omnitwin_drive.xml) on an in-process line, the tests'
// bench (tests/controller/ethercat/ec_bench.hpp), so the master reaches every phase: counting,
// addressing, SII, mailbox and PDO mapping over CoE, SAFE-OP, OP and its supervision. The input
// is what the wire does to the frames on their way back.
//
// Records of 8 bytes [steps][op][a][b][c][d][e][f] (missing bytes 0): `steps` bus cycles (0..255)
// run as they should, then one more cycle whose returning frame `op` (byte 1 % 8) changes:
//   0 nothing; 1 lost; 2 byte (a | b << 8) % size XORed with c (never 0); 3 cut to that many
//   bytes; 4 three bytes from there overwritten with c, d, e; 5 slave f % 2 powers off, 6 on;
//   7 a user SDO upload from slave f % 2, index b << 8 | a, subindex c (served by the mailbox).
// Properties checked: nothing crashes or throws (ASan/UBSan); every phase and slave step has a
// name; the master's counters never say more frames came back than it sent. Abort on any
// violation.
//
//   build/fuzz/ec_master_fuzz fuzz/corpus/ec_master
#include <cstdio>
#include <cstdlib>
#include <cstring>
#include <string>

#include "tests/controller/ethercat/ec_bench.hpp"

namespace {

namespace me = omnitwin::controller::ethercat;

// One cycle as ecbench::Bench::step(), with `change` applied to each returning frame.
template <class Change>
void cycle(ecbench::Bench& b, Change change) {
  for (std::size_t i = 0; i < b.slaves.size(); ++i) {
    if (!b.chain.powered(static_cast<int>(i))) continue;
    auto& ax = b.slaves[i]->axis(0);
    b.models[i].step(ax.step(b.t, b.models[i].feedback()), static_cast<double>(b.cycle) * 1e-9);
    b.slaves[i]->cycle(b.t);
  }
  b.chain.advance(b.t);
  b.new_tick();
  b.master->tick(b.t);
  auto pass = [&](std::vector<std::uint8_t>& f) {
    std::vector<std::uint8_t> back = f;
    if (!b.chain.process(back, b.t)) return;
    if (!change(back)) return;
    // A copy of exactly its size: a frame cut short keeps its capacity, and ASan sees a read
    // past its end only past the capacity (libstdc++'s vectors are not annotated).
    std::vector<std::uint8_t> exact(back.begin(), back.end());
    b.master->on_frame(exact, b.t + 50'000);
  };
  if (b.sent) {
    pass(b.frame);
    for (std::size_t i = 0; i < b.n_more; ++i) pass(b.more[i]);
  }
  b.drives->update();
  b.t += b.cycle;
}

void check(const ecbench::Bench& b) {
  if (std::string(me::to_string(b.master->phase())) == "?") std::abort();
  for (int i = 0; i < b.master->slave_count(); ++i)
    if (std::string(me::to_string(b.master->slave(i).step)) == "?") std::abort();
  const me::EcMasterStats& st = b.master->stats();
  if (st.frames_received > st.frames_sent) std::abort();
}

}  // namespace

extern "C" int LLVMFuzzerTestOneInput(const std::uint8_t* data, std::size_t size) {
  ecbench::Bench b(2);
  std::uint8_t r[8];
  for (std::size_t at = 0; at < size; at += sizeof r) {
    std::memset(r, 0, sizeof r);
    std::memcpy(r, data + at, std::min(sizeof r, size - at));
    for (int k = 0; k < r[0]; ++k) cycle(b, [](std::vector<std::uint8_t>&) { return true; });
    const int op = r[1] % 8;
    const std::size_t pos = static_cast<std::size_t>(r[2] | r[3] << 8);
    if (op == 5 || op == 6) b.chain.set_powered(r[7] % 2, op == 6, b.t);
    if (op == 7) b.master->sdo_upload(r[7] % 2, static_cast<std::uint16_t>(r[3] << 8 | r[2]), r[4]);
    cycle(b, [&](std::vector<std::uint8_t>& f) {
      if (f.empty()) return true;
      switch (op) {
        case 1: return false;
        case 2: f[pos % f.size()] ^= r[4] ? r[4] : 1; return true;
        case 3: f.resize(pos % f.size()); return true;
        case 4:
          for (std::size_t k = 0; k < 3; ++k) f[(pos + k) % f.size()] = r[4 + k];
          return true;
        default: return true;
      }
    });
    check(b);
  }
  for (int k = 0; k < 50; ++k) cycle(b, [](std::vector<std::uint8_t>&) { return true; });
  check(b);
  // EC_MASTER_FUZZ_SHOW=1: where the input left the master (to check what a seed reaches).
  if (std::getenv("EC_MASTER_FUZZ_SHOW"))
    std::fprintf(stderr, "phase %s, operational %d, cycles %llu, lost %llu, stray %llu\n", me::to_string(b.master->phase()),
                 b.master->operational() ? 1 : 0, static_cast<unsigned long long>(b.master->stats().cycles),
                 static_cast<unsigned long long>(b.master->stats().lost_frames),
                 static_cast<unsigned long long>(b.master->stats().stray_frames));
  return 0;
}
