// bus_emulators/mechatrolink3/transport — M-III over UDP (`udp:HOST[:PORT]`, port 0x88B5 = 34997
// by default): one frame per datagram, exactly the frame (header, information field, FCS), no
// padding. The emulation's choice (docs/protocols/mechatrolink3.md, "Encapsulations"): the
// M-III data link is not IP, but UDP lets the master and the slaves run in separate processes
// without privileges, as EtherCAT over UDP does for the EtherCAT bus.
//
// slaves: one socket bound to HOST:PORT (HOST may be a wildcard such as 0.0.0.0 or ::; PORT 0
// binds a free port, which local_port() and spec() name); each response goes to the sender of
// the last frame received. master: one socket bound to an ephemeral port of the same address
// family, sending to HOST:PORT; it accepts frames from any sender (nobody else knows the
// ephemeral port). HOST may be numeric (IPv4, IPv6 in brackets) or a name, resolved once when
// opening.
//
// One datagram per system call each way. Datagrams that cannot be a frame (see
// m3_transport.hpp) are dropped and counted in dropped_malformed; bytes after the frame are
// trimmed; a bad FCS is the receiving station's business and passes.
#pragma once

// The frame buses' shared UDP transport (bus_emulators/udp_pair_transport.hpp) with M-III
// frames and check_frame() (M-III's traits: m3_transport_mem.hpp).
#include "bus_emulators/mechatrolink3/transport/m3_transport_mem.hpp"
#include "bus_emulators/udp_pair_transport.hpp"

namespace omnitwin::m3 {

using UdpTransport = bus_emulators::UdpPairTransport<M3FrameTraits>;

}  // namespace omnitwin::m3
