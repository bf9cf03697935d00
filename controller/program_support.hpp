// controller layer — small helpers shared by the master-side programs (omni-master, omni-pc):
// how they name an interface and how they hear SIGINT/SIGTERM without a global flag.
#pragma once

#include <string>

namespace omnitwin::controller {

// "can0" means "socketcan:can0"; anything with a scheme ("udp:…", "mem:…") is a transport
// spec as it is. Not real-time safe.
std::string normalize_iface(const std::string& iface);

// Blocks SIGINT/SIGTERM for the process and returns a signalfd (non-blocking, close-on-exec)
// that becomes readable when one arrives; -1 if the kernel refuses. Set-up only.
int open_signal_fd();

}  // namespace omnitwin::controller
