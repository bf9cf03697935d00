// controller layer — helpers shared by omni-master and omni-pc; see program_support.hpp.
#include "controller/program_support.hpp"

#include <signal.h>
#include <sys/signalfd.h>

namespace omnitwin::controller {

std::string normalize_iface(const std::string& iface) {
  return iface.find(':') == std::string::npos ? "socketcan:" + iface : iface;
}

int open_signal_fd() {
  sigset_t set;
  sigemptyset(&set);
  sigaddset(&set, SIGINT);
  sigaddset(&set, SIGTERM);
  ::sigprocmask(SIG_BLOCK, &set, nullptr);
  return ::signalfd(-1, &set, SFD_CLOEXEC | SFD_NONBLOCK);
}

}  // namespace omnitwin::controller
