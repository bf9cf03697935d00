// twin layer — `omnitwin`, the command people and CI call: a launcher that links nothing but
// libc, so it is running within a millisecond of exec.
//
// The CLI itself (`omnitwin-cli`, main.cpp) links MuJoCo, libav*, OSMesa and Cyclone DDS:
// about 160 shared libraries, which the dynamic loader takes tens of milliseconds to map
// before main() can install a signal handler. A SIGINT or SIGTERM in that window would kill
// the process by the signal instead of ending a run honestly (exit 3). So this launcher
// blocks both signals and execs the CLI beside it: a blocked signal stays pending across
// execve, and the CLI unblocks them once its handlers are in place, which delivers any that
// came in the meantime to the handler.
#include <limits.h>
#include <signal.h>
#include <unistd.h>

#include <cerrno>
#include <cstdio>
#include <cstring>
#include <string>

int main(int argc, char** argv) {
  // From here on until the CLI's handlers exist, SIGINT/SIGTERM wait.
  sigset_t block;
  sigemptyset(&block);
  sigaddset(&block, SIGINT);
  sigaddset(&block, SIGTERM);
  sigprocmask(SIG_BLOCK, &block, nullptr);
  // The CLI lives beside this program (build tree and install alike).
  char self[PATH_MAX];
  const ssize_t n = ::readlink("/proc/self/exe", self, sizeof self - 1);
  std::string cli = "omnitwin-cli";
  if (n > 0) {
    const std::string exe(self, static_cast<std::size_t>(n));
    cli = exe.substr(0, exe.rfind('/') + 1) + "omnitwin-cli";
  }
  (void)argc;
  ::execv(cli.c_str(), argv);
  std::fprintf(stderr, "omnitwin: cannot start %s: %s\n", cli.c_str(), std::strerror(errno));
  return 3;
}
