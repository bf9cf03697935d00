// bus_emulators/ethercat/transport — in-process EtherCAT transport (`mem:NAME`), for tests and
// for running the master and the emulated chain inside one process: the frame buses' shared
// in-process pair (bus_emulators/mem_pair_transport.hpp, which says how it behaves) with
// EtherCAT's PDUs: up to kMaxPdu bytes, checked by check_pdu() on receipt (other EtherCAT
// frame types are dropped_foreign, what cannot be a PDU dropped_malformed).
#pragma once

#include "bus_emulators/ethercat/ec_frame.hpp"
#include "bus_emulators/ethercat/transport/ec_transport.hpp"
#include "bus_emulators/mem_pair_transport.hpp"

namespace omnitwin::ethercat {

// EtherCAT for the frame buses' shared transports (in-process pair, UDP).
struct EcFrameTraits {
  using Base = EcTransport;
  using Role = ethercat::Role;
  using Error = TransportError;
  static constexpr std::size_t kMaxFrame = kMaxPdu, kMinFrame = 0, kDefaultCapacity = 64;
  static const char* role_name(Role r) { return to_string(r); }
  static std::size_t end_of(Role r) { return r == Role::master ? 0 : 1; }
  static bus_emulators::FrameVerdict check(const std::uint8_t* data, std::size_t n, std::size_t& size) noexcept {
    switch (check_pdu(data, n, size)) {
      case PduCheck::ok: return bus_emulators::FrameVerdict::ok;
      case PduCheck::foreign: return bus_emulators::FrameVerdict::foreign;
      case PduCheck::malformed: break;
    }
    return bus_emulators::FrameVerdict::malformed;
  }
};

using MemTransport = bus_emulators::MemPairTransport<EcFrameTraits>;

}  // namespace omnitwin::ethercat
