// bus_emulators/ethercat/transport — EtherCAT over UDP (`udp:HOST[:PORT]`, port 0x88A4 = 34980
// by default): the UDP payload is the PDU (EtherCAT header and datagrams, unchanged), as the
// EtherCAT standard carries it in UDP/IP.
//
// slaves: one socket bound to HOST:PORT (HOST may be a wildcard such as 0.0.0.0 or ::); each
// reply goes to the sender of the last PDU received. master: one socket bound to an ephemeral
// port of the same address family, sending to HOST:PORT; it accepts replies from any sender
// (nobody else knows the ephemeral port). HOST may be numeric (IPv4, IPv6 in brackets) or a
// name, resolved once when opening.
//
// One datagram per system call each way (one frame per cycle: nothing to batch). Datagrams too
// short to be a PDU, or whose EtherCAT header declares more bytes than arrived, are dropped and
// counted in dropped_malformed; other EtherCAT frame types in dropped_foreign.
#pragma once

// The frame buses' shared UDP transport (bus_emulators/udp_pair_transport.hpp) with EtherCAT's
// PDUs and check_pdu() (EtherCAT's traits: ec_transport_mem.hpp).
#include "bus_emulators/ethercat/transport/ec_transport_mem.hpp"
#include "bus_emulators/udp_pair_transport.hpp"

namespace omnitwin::ethercat {

using UdpTransport = bus_emulators::UdpPairTransport<EcFrameTraits>;

}  // namespace omnitwin::ethercat
