// twin layer — where slaves and master meet on a frame bus; see line_transport.hpp.
#include "twin/line_transport.hpp"

#include "bus_emulators/ethercat/transport/ec_veth.hpp"

namespace omnitwin::twin {

LineTransport choose_line_transport(const std::string& spec, const std::string& master_iface, bool lockstep,
                                    const std::string& realtime_udp) {
  std::string s = spec;
  if (s == "auto") s = !ethercat::VethPair::unavailable_reason() ? "veth" : (lockstep ? "udp:127.0.0.1:0" : realtime_udp);
  LineTransport t;
  if (s == "veth") {
    t.veth = std::make_shared<ethercat::VethPair>();
    // Fixed addresses from the documentation range (RFC 7042) instead of the kernel's random
    // ones: captures show the addresses the frames carry and stay byte-identical across runs,
    // and the first byte's bit 1 is clear, so the slaves' marking of returned frames shows.
    t.veth->set_address(t.veth->a(), "00:00:5e:00:53:10");
    t.veth->set_address(t.veth->b(), "00:00:5e:00:53:11");
    t.slaves_spec = "raw:" + t.veth->b();
    t.master_iface = "raw:" + t.veth->a();
  } else if (s.starts_with("raw:")) {
    t.slaves_spec = s;
    t.master_iface = master_iface.starts_with("raw:") ? master_iface : "raw:" + master_iface;
  } else {
    t.slaves_spec = s;
  }
  return t;
}

}  // namespace omnitwin::twin
