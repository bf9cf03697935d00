// twin layer — one twin per bus on this host (bus_claim.hpp says why). The claim is a
// listening abstract Unix stream socket: bind() fails with EADDRINUSE while another process
// holds it, and a connect() to it tells that process's pid (SO_PEERCRED of a listener is the
// process that called listen()).
#include "twin/bus_claim.hpp"

#include <sys/socket.h>
#include <sys/un.h>
#include <unistd.h>

#include <cerrno>
#include <cstring>
#include <functional>

#include <fmt/format.h>

namespace omnitwin::twin {

namespace {

// The address of `name` in the abstract namespace (a leading NUL, no file).
socklen_t abstract_address(const std::string& name, sockaddr_un& a) {
  std::memset(&a, 0, sizeof a);
  a.sun_family = AF_UNIX;
  std::memcpy(a.sun_path + 1, name.data(), name.size());
  return static_cast<socklen_t>(offsetof(sockaddr_un, sun_path) + 1 + name.size());
}

// The pid of the process listening on `name`, or -1. Non-blocking: the holder never accepts,
// so a full queue of earlier lookups answers EAGAIN instead of waiting for the holder's end
// (a third refused run hung until the first ended; found in review).
pid_t holder_of(const std::string& name) {
  const int fd = ::socket(AF_UNIX, SOCK_STREAM | SOCK_CLOEXEC | SOCK_NONBLOCK, 0);
  if (fd < 0) return -1;
  sockaddr_un a;
  const socklen_t len = abstract_address(name, a);
  pid_t pid = -1;
  if (::connect(fd, reinterpret_cast<const sockaddr*>(&a), len) == 0) {
    ucred c{};
    socklen_t cl = sizeof c;
    if (::getsockopt(fd, SOL_SOCKET, SO_PEERCRED, &c, &cl) == 0) pid = c.pid;
  }
  ::close(fd);
  return pid;
}

}  // namespace

std::string bus_claim_name(const std::string& key) {
  std::string name = "omnitwin-bus " + key;
  constexpr std::size_t kMax = sizeof(sockaddr_un::sun_path) - 1;
  if (name.size() > kMax) name = fmt::format("omnitwin-bus #{:016x}", std::hash<std::string>{}(key));
  return name;
}

BusClaim::BusClaim(const std::string& key) : key_(key) {
  fd_ = ::socket(AF_UNIX, SOCK_STREAM | SOCK_CLOEXEC, 0);
  if (fd_ < 0) throw std::runtime_error(fmt::format("cannot claim the bus {}: socket: {}", key, std::strerror(errno)));
  const std::string name = bus_claim_name(key);
  sockaddr_un a;
  const socklen_t len = abstract_address(name, a);
  // A long queue: every refused run's lookup stays in it (never accepted) until the holder ends.
  if (::bind(fd_, reinterpret_cast<const sockaddr*>(&a), len) != 0 || ::listen(fd_, SOMAXCONN) != 0) {
    const int e = errno;
    ::close(fd_);
    fd_ = -1;
    if (e != EADDRINUSE) throw std::runtime_error(fmt::format("cannot claim the bus {}: {}", key, std::strerror(e)));
    const pid_t pid = holder_of(name);
    throw BusInUse(fmt::format("{} is in use by another twin ({}): two twins on one bus would each answer the "
                               "other's master; give this run a bus of its own (bus.transport)",
                               key, pid > 0 ? fmt::format("pid {}", pid) : std::string("its pid unknown")),
                   pid);
  }
}

void claim_interfaces(std::vector<std::unique_ptr<BusClaim>>& claims, const std::vector<std::string>& specs) {
  for (const std::string& spec : specs) {
    if (!spec.starts_with("raw:")) continue;
    const std::string key = spec.substr(0, spec.find('?'));
    bool held = false;
    for (const auto& c : claims) held = held || c->key() == key;
    if (!held) claims.push_back(std::make_unique<BusClaim>(key));
  }
}

BusClaim::~BusClaim() {
  if (fd_ >= 0) ::close(fd_);
}

}  // namespace omnitwin::twin
