// Test support — the veth pair of the EtherCAT transports (bus_emulators/ethercat/transport/
// ec_veth.hpp) under the tests' namespace: raw-socket tests put a master on one end and
// slaves on the other, and skip with unavailable_reason() where pairs cannot be made.
#pragma once

#include "bus_emulators/ethercat/transport/ec_veth.hpp"

namespace omnitwin::testing {
using ethercat::VethPair;
}  // namespace omnitwin::testing
