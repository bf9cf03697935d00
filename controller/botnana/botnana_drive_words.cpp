// controller layer — the drive words of seed 004 ("EtherCAT Drive 指令集") on DriveAccess.
//
// Every word takes the axis as ( … ch n ): n the EtherCAT slave number, ch the drive channel
// on it, both 1-based. Each word maps onto one DriveAccess call with the CiA 402 object seed
// 004 names (docs/botnana.md has the table); whether that object travels by PDO or SDO is
// the master's business (DriveAccess::write), except that every write is remembered per
// slave so that until-no-requests knows whose SDO queue to wait for. The seed's own Forth
// definitions (until-drive-on, until-no-fault, until-target-reached) are compiled from source
// in botnana_interpreter.cpp; until-no-requests, which the seed only uses, is a primitive
// that waits (retries at the next cycle) while any of those slaves has requests pending, then
// fails when one of those requests failed (DriveAccess::take_request_failures).
#include <algorithm>

#include <fmt/format.h>

#include "controller/botnana/botnana_interpreter.hpp"

namespace omnitwin::botnana {

namespace {

constexpr std::uint16_t kControlword = 0x6040;
constexpr std::uint16_t kStatusword = 0x6041;
constexpr std::uint16_t kDigitalInputs = 0x60FD;

constexpr std::int64_t obj(std::uint16_t index, std::uint8_t sub = 0) {
  return (static_cast<std::int64_t>(index) << 8) | sub;
}
constexpr std::uint16_t obj_index(std::int64_t aux) { return static_cast<std::uint16_t>(aux >> 8); }
constexpr std::uint8_t obj_sub(std::int64_t aux) { return static_cast<std::uint8_t>(aux & 0xFF); }
constexpr std::int64_t flag(bool b) { return b ? -1 : 0; }

}  // namespace

struct DriveWords {
  using In = Interpreter;
  using T = Interpreter::Task;
  using R = Interpreter::PrimResult;

  // Pops ( … ch n ) after checking that `args` cells (the axis included) are there and that
  // the axis exists.
  static bool axis(In& in, T& t, std::size_t args, int& slave, int& ch) {
    if (t.ds.size() < args) {
      t.error = "stack underflow";
      return false;
    }
    const std::int64_t n = t.ds.back();
    t.ds.pop_back();
    const std::int64_t c = t.ds.back();
    t.ds.pop_back();
    if (n < 1 || n > 65535 || c < 1 || c > 255) {
      t.error = fmt::format("no drive at slave {} channel {} (both count from 1)", n, c);
      return false;
    }
    slave = static_cast<int>(n);
    ch = static_cast<int>(c);
    if (!in.drives_.has_drive(slave, ch)) {
      t.error = fmt::format("no drive at slave {} channel {}", slave, ch);
      return false;
    }
    return true;
  }
  static std::int64_t pop(T& t) {
    const std::int64_t v = t.ds.back();
    t.ds.pop_back();
    return v;
  }
  static R push(T& t, std::int64_t v) {
    if (t.ds.size() >= In::kMaxDataStack) {
      t.error = "stack overflow";
      return R::error;
    }
    t.ds.push_back(v);
    return R::ok;
  }
  static void note_request(In& in, int slave) {
    if (std::find(in.request_slaves_.begin(), in.request_slaves_.end(), slave) == in.request_slaves_.end()) {
      in.request_slaves_.push_back(slave);
    }
  }
  static bool read(In& in, T& t, int slave, int ch, std::uint16_t index, std::uint8_t sub, std::int64_t& v) {
    const auto r = in.drives_.read(slave, ch, index, sub);
    if (!r) {
      const std::string why = in.drives_.last_error();
      t.error = fmt::format("object 0x{:04X}:{:02X} of slave {} channel {} not available{}{}", index, sub,
                            slave, ch, why.empty() ? "" : ": ", why);
      return false;
    }
    v = *r;
    return true;
  }
  static bool write(In& in, T& t, int slave, int ch, std::uint16_t index, std::uint8_t sub, std::int64_t v) {
    if (!in.drives_.write(slave, ch, index, sub, v)) {
      const std::string why = in.drives_.last_error();
      t.error = fmt::format("write of object 0x{:04X}:{:02X} of slave {} channel {} refused{}{}", index, sub,
                            slave, ch, why.empty() ? "" : ": ", why);
      return false;
    }
    note_request(in, slave);
    return true;
  }

  // ( v ch n -- ): writes object aux.
  static R obj_store(In& in, T& t, std::int64_t aux) {
    int slave = 0, ch = 0;
    if (!axis(in, t, 3, slave, ch)) return R::error;
    const std::int64_t v = pop(t);
    return write(in, t, slave, ch, obj_index(aux), obj_sub(aux), v) ? R::ok : R::error;
  }
  // ( ch n -- v ): reads object aux.
  static R obj_fetch(In& in, T& t, std::int64_t aux) {
    int slave = 0, ch = 0;
    std::int64_t v = 0;
    if (!axis(in, t, 2, slave, ch) || !read(in, t, slave, ch, obj_index(aux), obj_sub(aux), v)) return R::error;
    return push(t, v);
  }
  // ( ch n -- flag ): bit aux of the statusword.
  static R status_bit(In& in, T& t, std::int64_t aux) {
    int slave = 0, ch = 0;
    std::int64_t sw = 0;
    if (!axis(in, t, 2, slave, ch) || !read(in, t, slave, ch, kStatusword, 0, sw)) return R::error;
    return push(t, flag(((sw >> aux) & 1) != 0));
  }
  // ( ch n -- flag ): the statusword decodes as Operation enabled (bits 6,5,3,2,1,0 = 010111).
  static R drive_on_q(In& in, T& t, std::int64_t) {
    int slave = 0, ch = 0;
    std::int64_t sw = 0;
    if (!axis(in, t, 2, slave, ch) || !read(in, t, slave, ch, kStatusword, 0, sw)) return R::error;
    return push(t, flag((sw & 0x6F) == 0x27));
  }
  // ( ch n -- code ): the error code of the drive's last CoE emergency (0 after the reset's
  // "no error" emergency, -1 when none has come). Not in seed 004: the seed shows drive errors
  // only through drive-fault?; this adds the code the drive reported.
  static R emcy_fetch(In& in, T& t, std::int64_t) {
    int slave = 0, ch = 0;
    if (!axis(in, t, 2, slave, ch)) return R::error;
    const auto c = in.drives_.last_emergency(slave, ch);
    return push(t, c ? static_cast<std::int64_t>(*c) : -1);
  }
  // ( ch n -- flag ): bit aux of the digital inputs 0x60FD.
  static R dins_bit(In& in, T& t, std::int64_t aux) {
    int slave = 0, ch = 0;
    std::int64_t d = 0;
    if (!axis(in, t, 2, slave, ch) || !read(in, t, slave, ch, kDigitalInputs, 0, d)) return R::error;
    return push(t, flag(((d >> aux) & 1) != 0));
  }
  // ( ch n -- ): sets (aux bit 8 set) or clears bit (aux & 0xFF) of the controlword.
  static R cw_bit(In& in, T& t, std::int64_t aux) {
    int slave = 0, ch = 0;
    if (!axis(in, t, 2, slave, ch)) return R::error;
    const auto cw = in.drives_.read(slave, ch, kControlword, 0);
    std::int64_t v = cw.value_or(0);
    const std::int64_t bit = std::int64_t{1} << (aux & 0xFF);
    v = (aux & 0x100) != 0 ? (v | bit) : (v & ~bit);
    return write(in, t, slave, ch, kControlword, 0, v & 0xFFFF) ? R::ok : R::error;
  }
  // ( ch n -- ): set_goal(aux).
  static R goal(In& in, T& t, std::int64_t aux) {
    int slave = 0, ch = 0;
    if (!axis(in, t, 2, slave, ch)) return R::error;
    in.drives_.set_goal(slave, ch, static_cast<PdsGoal>(aux));
    return R::ok;
  }
  // ( cw ch n -- ): drive-cw! sets the whole controlword (seed 004: directly), so the
  // master's goal lets go of it: the state bits go out as written until the next goal word.
  static R cw_store(In& in, T& t, std::int64_t) {
    int slave = 0, ch = 0;
    if (!axis(in, t, 3, slave, ch)) return R::error;
    if (!write(in, t, slave, ch, kControlword, 0, pop(t))) return R::error;
    in.drives_.release_goal(slave, ch);
    return R::ok;
  }
  // ( goal ch n -- )
  static R pds_goal(In& in, T& t, std::int64_t) {
    int slave = 0, ch = 0;
    if (!axis(in, t, 3, slave, ch)) return R::error;
    const std::int64_t g = pop(t);
    if (g < 1 || g > 5) {
      t.error = fmt::format("PDS goal {} is not one of 1..5", g);
      return R::error;
    }
    in.drives_.set_goal(slave, ch, static_cast<PdsGoal>(g));
    return R::ok;
  }
  // ( ch n -- ): in Fault (or while the statusword is not known yet) the goal becomes
  // Switch on disabled, which the master reaches by a fault reset; otherwise nothing.
  static R reset_fault(In& in, T& t, std::int64_t) {
    int slave = 0, ch = 0;
    if (!axis(in, t, 2, slave, ch)) return R::error;
    const auto sw = in.drives_.read(slave, ch, kStatusword, 0);
    if (!sw || (*sw & 0x08) != 0) in.drives_.set_goal(slave, ch, PdsGoal::switch_on_disabled);
    return R::ok;
  }
  // ( ch n -- ) aux 1: +drive-homed, 0: -drive-homed; aux 2: drive-homed? ( ch n -- flag ).
  // The master's record (DriveAccess::homed), or the interpreter's own when it keeps none.
  static R homed(In& in, T& t, std::int64_t aux) {
    int slave = 0, ch = 0;
    if (!axis(in, t, 2, slave, ch)) return R::error;
    if (aux == 2) {
      if (const auto h = in.drives_.homed(slave, ch)) return push(t, flag(*h));
    } else if (in.drives_.set_homed(slave, ch, aux == 1)) {
      return R::ok;
    }
    const std::int64_t key = (static_cast<std::int64_t>(slave) << 16) | ch;
    auto it = std::find(in.homed_.begin(), in.homed_.end(), key);
    if (aux == 2) return push(t, flag(it != in.homed_.end()));
    if (aux == 1 && it == in.homed_.end()) in.homed_.push_back(key);
    if (aux == 0 && it != in.homed_.end()) in.homed_.erase(it);
    return R::ok;
  }
  // User-planned PDO entries: aux = UserPdo | (store ? 0x100 : 0).
  static R user_pdo(In& in, T& t, std::int64_t aux) {
    const bool store = (aux & 0x100) != 0;
    int slave = 0, ch = 0;
    if (!axis(in, t, store ? 3 : 2, slave, ch)) return R::error;
    const auto which = static_cast<UserPdo>(aux & 0xFF);
    const auto ref = in.drives_.user_pdo(slave, ch, which);
    if (!ref) {
      t.error = fmt::format("no user PDO entry configured for slave {} channel {}", slave, ch);
      return R::error;
    }
    if (store) {
      const std::int64_t v = pop(t);
      return write(in, t, slave, ch, ref->index, ref->sub, v) ? R::ok : R::error;
    }
    std::int64_t v = 0;
    if (!read(in, t, slave, ch, ref->index, ref->sub, v)) return R::error;
    return push(t, v);
  }
  // ( -- ): waits while a slave written to (or 1..slaves()) still has SDO requests queued;
  // then fails when the master reports that one of them failed (seed 004: it waits until the
  // command is actually set in the drive, and an aborted one never is).
  static R until_no_requests(In& in, T& t, std::int64_t) {
    for (int s : in.request_slaves_) {
      if (in.drives_.requests_pending(s)) return R::retry;
    }
    for (int s = 1; s <= in.drives_.slaves(); ++s) {
      if (in.drives_.requests_pending(s)) return R::retry;
    }
    std::string failures;
    const auto take = [&](int s) {
      const std::string f = in.drives_.take_request_failures(s);
      if (!f.empty()) failures += (failures.empty() ? "" : "; ") + f;
    };
    for (int s : in.request_slaves_) take(s);
    for (int s = 1; s <= in.drives_.slaves(); ++s) take(s);
    if (failures.empty()) return R::ok;
    t.error = "not set in the drive: " + failures;
    return R::error;
  }
  static R constant_value(In&, T& t, std::int64_t aux) { return push(t, aux); }

  static void install(In& in) {
    // Mode numbers (0x6060) and PDS goals, as the seed defines them.
    const std::pair<const char*, std::int64_t> constants[] = {
        {"pp", 1}, {"pv", 3}, {"tq", 4}, {"hm", 6}, {"csp", 8}, {"csv", 9}, {"cst", 10},
        {"switch-on-disabled", 1}, {"ready-to-switch-on", 2}, {"switched-on", 3},
        {"operation-enabled", 4}, {"quick-stop-active", 5}};
    for (const auto& [name, v] : constants) in.add_prim(name, constant_value, v);

    in.add_prim("pds-goal!", pds_goal);
    in.add_prim("drive-on", goal, static_cast<std::int64_t>(PdsGoal::operation_enabled));
    in.add_prim("drive-off", goal, static_cast<std::int64_t>(PdsGoal::switch_on_disabled));
    in.add_prim("drive-stop", goal, static_cast<std::int64_t>(PdsGoal::quick_stop_active));
    in.add_prim("reset-fault", reset_fault);
    in.add_prim("drive-on?", drive_on_q);
    in.add_prim("drive-fault?", status_bit, 3);
    in.add_prim("drive-emcy@", emcy_fetch);
    in.add_prim("target-reached?", status_bit, 10);
    in.add_prim("until-no-requests", until_no_requests, 0, false, /*background_only=*/true);

    const std::pair<const char*, std::int64_t> stores[] = {
        {"op-mode!", obj(0x6060)},          {"target-p!", obj(0x607A)},
        {"target-v!", obj(0x60FF)},
        {"v-ofs!", obj(0x60B1)},            {"drive-douts!", obj(0x60FE, 1)},
        {"drive-douts-mask!", obj(0x60FE, 2)}, {"drive-nsl!", obj(0x607D, 1)},
        {"drive-psl!", obj(0x607D, 2)},     {"drive-polarity!", obj(0x607E)},
        {"drive-vmax!", obj(0x6080)},       {"profile-a1!", obj(0x6083)},
        {"profile-a2!", obj(0x6084)},       {"profile-v!", obj(0x6081)},
        {"tq-slope!", obj(0x6087)},         {"homing-method!", obj(0x6098)},
        {"homing-v1!", obj(0x6099, 1)},     {"homing-v2!", obj(0x6099, 2)},
        {"homing-a!", obj(0x609A)}};
    for (const auto& [name, o] : stores) in.add_prim(name, obj_store, o);
    in.add_prim("drive-cw!", cw_store);

    const std::pair<const char*, std::int64_t> fetches[] = {
        {"target-p@", obj(0x607A)},  {"drive-sw@", obj(kStatusword)}, {"real-p@", obj(0x6064)},
        {"real-v@", obj(0x606C)},    {"real-tq@", obj(0x6077)},       {"demand-p@", obj(0x6062)},
        {"demand-v@", obj(0x606B)},  {"v-ofs@", obj(0x60B1)},         {"drive-dins@", obj(kDigitalInputs)},
        {"drive-nsl@", obj(0x607D, 1)}, {"drive-psl@", obj(0x607D, 2)}};
    for (const auto& [name, o] : fetches) in.add_prim(name, obj_fetch, o);

    in.add_prim("drive-nl?", dins_bit, 0);
    in.add_prim("drive-pl?", dins_bit, 1);
    in.add_prim("drive-org?", dins_bit, 2);

    // Controlword bits: go (4), PP change set immediately (5), relative (6), halt (8),
    // change on set-point (9).
    in.add_prim("go", cw_bit, 0x100 | 4);
    in.add_prim("+pp-imt", cw_bit, 0x100 | 5);
    in.add_prim("-pp-imt", cw_bit, 5);
    in.add_prim("+pp-rel", cw_bit, 0x100 | 6);
    in.add_prim("-pp-rel", cw_bit, 6);
    in.add_prim("+drive-halt", cw_bit, 0x100 | 8);
    in.add_prim("-drive-halt", cw_bit, 8);
    in.add_prim("+pp-cosp", cw_bit, 0x100 | 9);
    in.add_prim("-pp-cosp", cw_bit, 9);

    in.add_prim("+drive-homed", homed, 1);
    in.add_prim("-drive-homed", homed, 0);
    in.add_prim("drive-homed?", homed, 2);

    in.add_prim("drive-wpdo1!", user_pdo, 0x100 | static_cast<std::int64_t>(UserPdo::wpdo1));
    in.add_prim("drive-wpdo2!", user_pdo, 0x100 | static_cast<std::int64_t>(UserPdo::wpdo2));
    in.add_prim("drive-wpdo1@", user_pdo, static_cast<std::int64_t>(UserPdo::wpdo1));
    in.add_prim("drive-wpdo2@", user_pdo, static_cast<std::int64_t>(UserPdo::wpdo2));
    in.add_prim("drive-rpdo1@", user_pdo, static_cast<std::int64_t>(UserPdo::rpdo1));
    in.add_prim("drive-rpdo2@", user_pdo, static_cast<std::int64_t>(UserPdo::rpdo2));
  }
};

void Interpreter::install_drive_words() { DriveWords::install(*this); }

}  // namespace omnitwin::botnana
