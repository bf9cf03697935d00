// Test support for the ecmaster tests (not a test file): our master core wired in-process to
// A's EscChain of B's DriveSlaves built from models/ethercat/omnitwin_drive.xml, each axis on
// C's AxisModel. One step() = drive/firmware cycle, one master tick, its frames (one, or more
// for an image larger than a frame) through the chain and back (unless dropped), the drive
// layer's update.
#pragma once

#include <functional>
#include <memory>
#include <span>
#include <vector>

#include "bus_emulators/drive/axis_model.hpp"
#include "bus_emulators/ethercat/device/ec_esi.hpp"
#include "bus_emulators/ethercat/device/ec_slave.hpp"
#include "bus_emulators/ethercat/ec_chain.hpp"
#include "controller/ethercat/ec_drive.hpp"
#include "controller/ethercat/ec_master.hpp"

namespace ecbench {

namespace ec = omnitwin::ethercat;
namespace me = omnitwin::controller::ethercat;

inline std::vector<ec::DeviceDescription> drive_esi() {
  return ec::load_esi(OMNITWIN_SOURCE_DIR "/models/ethercat/omnitwin_drive.xml");
}

// What the master's send callback handed out during one tick: its first frame, then any
// further ones (an image in frames of its own), their buffers kept from tick to tick.
struct TickFrames {
  std::vector<std::uint8_t> frame;               // the tick's first frame
  std::vector<std::vector<std::uint8_t>> more;    // its further frames
  std::size_t n_more = 0;                         // how many of `more` this tick sent
  bool sent = false;                              // the tick sent anything

  void new_tick() {
    sent = false;
    n_more = 0;
  }
  void catch_frame(std::span<const std::uint8_t> pdu) {
    if (!sent) {
      frame.assign(pdu.begin(), pdu.end());
      sent = true;
      return;
    }
    if (n_more == more.size()) more.emplace_back();
    more[n_more++].assign(pdu.begin(), pdu.end());
  }
};

struct Bench : TickFrames {
  std::vector<ec::DeviceDescription> devices = drive_esi();
  std::vector<std::unique_ptr<ec::DriveSlave>> slaves;
  std::vector<omnitwin::drive::AxisModel> models;
  ec::EscChain chain;
  std::unique_ptr<me::EcMaster> master;
  std::unique_ptr<me::EcDrives> drives;
  int drop_next = 0;  // frames to lose
  int late_every = 0; // > 0: every n-th frame passes the slaves but comes back too late
  int paused = 0;     // > 0: the master is not ticked for that many steps (a stalled master)
  // Called on every frame that comes back to the master, before on_frame(): a wire that changes it.
  std::function<void(std::vector<std::uint8_t>&)> tamper;
  std::uint64_t frames = 0;
  me::SimTime t = 0;
  me::SimTime cycle = 1'000'000;

  explicit Bench(int n = 4, me::EcMasterConfig cfg = {}, std::vector<ec::DeviceDescription> master_devices = {}) {
    for (int i = 0; i < n; ++i) {
      ec::DriveSlaveConfig sc;
      sc.serial = static_cast<std::uint32_t>(100 + i);
      slaves.push_back(std::make_unique<ec::DriveSlave>(devices[0], sc));
      models.emplace_back();
    }
    for (auto& s : slaves) chain.add(&s->esc());
    cfg.devices = master_devices.empty() ? devices : master_devices;
    cycle = cfg.cycle_ns;
    master = std::make_unique<me::EcMaster>(std::move(cfg), [this](std::span<const std::uint8_t> pdu) {
      catch_frame(pdu);
      return true;
    });
    drives = std::make_unique<me::EcDrives>(*master);
  }

  void step() {
    for (std::size_t i = 0; i < slaves.size(); ++i) {
      if (!chain.powered(static_cast<int>(i))) continue;
      auto& ax = slaves[i]->axis(0);
      const auto cmd = ax.step(t, models[i].feedback());
      models[i].step(cmd, static_cast<double>(cycle) * 1e-9);
      slaves[i]->cycle(t);
    }
    chain.advance(t);
    new_tick();
    if (paused > 0) {
      --paused;
    } else {
      master->tick(t);
    }
    if (sent) {
      pass(frame);
      for (std::size_t i = 0; i < n_more; ++i) pass(more[i]);
    }
    drives->update();
    t += cycle;
  }
  // One frame through the chain and back to the master (or dropped, or too late).
  void pass(std::vector<std::uint8_t>& f) {
    ++frames;
    if (drop_next > 0) {
      --drop_next;
    } else if (late_every > 0 && frames % late_every == 0) {
      chain.process(f, t);  // the slaves act on it; the master never sees it in time
    } else if (chain.process(f, t)) {
      if (tamper) tamper(f);
      master->on_frame(f, t + 50'000);
    }
  }
  // Steps until pred() or max steps; returns whether pred() held.
  template <class P>
  bool run_until(P pred, int max_steps = 20000) {
    for (int i = 0; i < max_steps; ++i) {
      if (pred()) return true;
      step();
    }
    return pred();
  }
  bool to_op(int max_steps = 20000) {
    return run_until([&] { return master->operational() || master->phase() == me::MasterPhase::failed; }, max_steps) &&
           master->operational();
  }
};

// A segment of seed 001's multi-axis slaves (models/ethercat/omnitwin_multiaxis.xml): `axes`
// axis cards in all, 8 per slave and the rest on the last (100 axes: 12 × 8 + 4), our master
// core in-process at `cycle` with distributed clocks, each card's drive stepped at rest by its
// slave's firmware cycle (SYNC0). One step() = the line to t (SYNC0 pulses), one master tick,
// the frame through the chain and back. The 100-axis segment of issue 17, item 4.
struct MultiAxisSegment : TickFrames {
  std::vector<ec::DeviceDescription> devices =
      ec::load_esi(OMNITWIN_SOURCE_DIR "/models/ethercat/omnitwin_multiaxis.xml");
  std::vector<std::unique_ptr<ec::DriveSlave>> slaves;
  ec::EscChain chain;
  std::unique_ptr<me::EcMaster> master;
  int drop_last = 0;  // ticks whose last frame (of several) is lost
  int drop_all = 0;   // ticks whose frames are all lost (the segment gone)
  me::SimTime t = 0;
  me::SimTime cycle = 100'000;

  MultiAxisSegment(int axes, me::SimTime cycle_ns, me::EcMasterConfig cfg = {}) : cycle(cycle_ns) {
    for (int left = axes, i = 0; left > 0; left -= 8, ++i) {
      ec::DriveSlaveConfig sc;
      sc.axes = left < 8 ? left : 8;
      sc.serial = static_cast<std::uint32_t>(1 + i);
      sc.drive.period_s = static_cast<double>(cycle_ns) * 1e-9;
      slaves.push_back(std::make_unique<ec::DriveSlave>(devices.front(), sc));
      ec::DriveSlave* sl = slaves.back().get();
      sl->set_cycle_hook([sl](me::SimTime at) {
        for (int a = 0; a < sl->axes(); ++a) sl->axis(a).step(at, omnitwin::drive::Feedback{});
      });
      chain.add(&sl->esc());
    }
    cfg.devices = devices;
    cfg.cycle_ns = cycle_ns;
    cfg.dc = true;
    cfg.expected_slaves = static_cast<int>(slaves.size());
    master = std::make_unique<me::EcMaster>(std::move(cfg), [this](std::span<const std::uint8_t> pdu) {
      catch_frame(pdu);
      return true;
    });
  }

  void step() {
    for (auto& s : slaves) s->cycle(t);  // mailbox replies (process data runs on SYNC0 once DC is on)
    chain.advance(t);
    new_tick();
    master->tick(t);
    if (!sent) return void(t += cycle);
    if (drop_all > 0) {
      --drop_all;
      return void(t += cycle);
    }
    if (chain.process(frame, t)) master->on_frame(frame, t + cycle / 2);
    for (std::size_t i = 0; i < n_more; ++i) {
      if (i + 1 == n_more && drop_last > 0) {
        --drop_last;
        continue;
      }
      if (chain.process(more[i], t)) master->on_frame(more[i], t + cycle / 2);
    }
    t += cycle;
  }
  bool to_op(int max_steps) {
    for (int k = 0; k < max_steps && !master->operational() && master->phase() != me::MasterPhase::failed; ++k) step();
    return master->operational();
  }
};

}  // namespace ecbench
