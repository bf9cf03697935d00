// twin layer — where the twin's slaves and the master process meet on a frame bus (EtherCAT,
// MECHATROLINK-III): the scenario's transport choice turned into the slaves' spec and the
// master's --iface, with the veth pair made for the run when one is asked for.
//
// auto: a veth pair of the run's own (as root), else UDP on loopback: in lockstep on a free
// port, so that concurrent runs never share a line; in realtime on the bus's documented port,
// so that others can join. raw:IFACE answers on IFACE and gives the master `master_iface`.
// udp:… and mem:… are used as given; for them the master's --iface is the opened transport's
// canonical spec (a free port then named), which the caller fills in after opening.
// Set-up only: may create interfaces (throws std::runtime_error when `ip` refuses).
#pragma once

#include <memory>
#include <string>

namespace omnitwin::ethercat {
class VethPair;
}

namespace omnitwin::twin {

struct LineTransport {
  std::string slaves_spec;   // what the twin opens (Role::slaves)
  std::string master_iface;  // what the master is given; "" = the opened transport's spec
  std::shared_ptr<ethercat::VethPair> veth;  // the pair made for the run, deleted with the last owner
};

// spec: auto | veth | raw:IFACE | udp:HOST:PORT | mem:NAME; realtime_udp: the documented UDP
// spec used by `auto` in realtime when no veth pair can be made.
LineTransport choose_line_transport(const std::string& spec, const std::string& master_iface, bool lockstep,
                                    const std::string& realtime_udp);

}  // namespace omnitwin::twin
