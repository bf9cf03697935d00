// bus_emulators/canopen — the vocabulary every CANopen layer shares (CiA 301): the
// pre-defined connection set's COB-IDs, NMT states and commands, the object dictionary types
// and the send callback through which every protocol core hands frames out.
//
// The object dictionary is CoE's (ethercat/device/ec_od): CoE is CiA 301's dictionary carried
// in EtherCAT mailboxes, with the same data type codes and SDO abort codes, so both buses
// share one implementation. CANopen has no SAFE-OP: the OD is accessed with OdState::preop in
// PRE-OPERATIONAL and OdState::op in OPERATIONAL (STOPPED allows no SDO at all).
//
// Time is integer nanoseconds on the caller's timeline (the twin's simulated clock, or a
// master's monotonic clock); nothing in canopen/ reads a clock or touches a socket.
#pragma once

#include <cstdint>
#include <functional>

#include "bus_emulators/can/can_frame.hpp"
#include "bus_emulators/ethercat/device/ec_od.hpp"

namespace omnitwin::canopen {

using SimTime = std::int64_t;  // [ns]

using ethercat::ObjectDictionary;
using ethercat::OdEntry;
using ethercat::OdObject;
using ethercat::OdState;
using ethercat::SdoAbort;
namespace od_access = ethercat::od_access;
namespace data_type = ethercat::coe_type;  // CiA 301 table 44 = ETG.1000.6 table 63

// Hands one frame to the bus at `at` [ns]. Returns false when the frame could not be queued
// (the caller counts it). Must be real-time safe in the owner's implementation.
using SendFn = std::function<bool(const can::Frame& f, SimTime at)>;

// Function codes of the pre-defined connection set (COB-ID = function code + node ID).
namespace cob {
inline constexpr std::uint32_t nmt = 0x000, sync = 0x080, emcy = 0x080, time = 0x100,
                               tpdo1 = 0x180, rpdo1 = 0x200, tpdo2 = 0x280, rpdo2 = 0x300,
                               tpdo3 = 0x380, rpdo3 = 0x400, tpdo4 = 0x480, rpdo4 = 0x500,
                               sdo_tx = 0x580, sdo_rx = 0x600, heartbeat = 0x700;
// Bits of a COB-ID entry (0x1005, 0x1014, 0x1400.., 0x1800..).
inline constexpr std::uint32_t invalid = 0x8000'0000u, no_rtr = 0x4000'0000u, frame_29 = 0x2000'0000u,
                               gen = 0x4000'0000u;  // 0x1005 bit 30: this node generates SYNC
inline constexpr std::uint32_t id_mask_11 = 0x7FF, id_mask_29 = 0x1FFF'FFFF;
}  // namespace cob

// NMT states (the byte a heartbeat or guarding answer carries, without the toggle bit).
enum class NmtState : std::uint8_t {
  initialising = 0x00,  // boot-up message content; never stays here
  stopped = 0x04,
  operational = 0x05,
  pre_operational = 0x7F,
};
const char* to_string(NmtState s);

// NMT command specifiers (0x000 [cs, node]; node 0 = all nodes).
enum class NmtCommand : std::uint8_t {
  start = 0x01,
  stop = 0x02,
  enter_pre_operational = 0x80,
  reset_node = 0x81,
  reset_communication = 0x82,
};
const char* to_string(NmtCommand c);

// Valid CANopen node IDs.
inline constexpr bool valid_node_id(int id) { return id >= 1 && id <= 127; }

// Little-endian helpers for frame payloads. Real-time safe.
inline std::uint16_t get_u16(const std::uint8_t* p) { return static_cast<std::uint16_t>(p[0] | (p[1] << 8)); }
inline std::uint32_t get_u32(const std::uint8_t* p) {
  return static_cast<std::uint32_t>(p[0]) | (static_cast<std::uint32_t>(p[1]) << 8) |
         (static_cast<std::uint32_t>(p[2]) << 16) | (static_cast<std::uint32_t>(p[3]) << 24);
}
inline void put_u16(std::uint8_t* p, std::uint16_t v) {
  p[0] = static_cast<std::uint8_t>(v);
  p[1] = static_cast<std::uint8_t>(v >> 8);
}
inline void put_u32(std::uint8_t* p, std::uint32_t v) {
  for (int i = 0; i < 4; ++i) p[i] = static_cast<std::uint8_t>(v >> (8 * i));
}

// A standard data frame with `dlc` bytes (zeroed). Real-time safe.
inline can::Frame frame11(std::uint32_t id, std::uint8_t dlc) {
  can::Frame f;
  f.id = id & cob::id_mask_11;
  f.dlc = dlc;
  return f;
}

}  // namespace omnitwin::canopen
