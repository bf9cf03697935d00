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
#include <string.h>
#include <unistd.h>

#include <cerrno>
#include <cstdio>

int main(int argc, char** argv) {
  // From here on until the CLI's handlers exist, SIGINT/SIGTERM wait.
  sigset_t block;
  sigemptyset(&block);
  sigaddset(&block, SIGINT);
  sigaddset(&block, SIGTERM);
  sigprocmask(SIG_BLOCK, &block, nullptr);
  // The CLI lives beside this program (build tree and install alike). Plain C buffers: no
  // libstdc++, whose loading alone took longer than the window this program closes.
  static const char kCli[] = "omnitwin-cli";
  char cli[PATH_MAX + sizeof kCli] = "omnitwin-cli";
  const ssize_t n = ::readlink("/proc/self/exe", cli, PATH_MAX);
  if (n > 0) {
    cli[n] = '\0';
    char* slash = strrchr(cli, '/');
    strcpy(slash ? slash + 1 : cli, kCli);
  } else {
    strcpy(cli, kCli);
  }
  (void)argc;
  ::execv(cli, argv);
  std::fprintf(stderr, "omnitwin: cannot start %s: %s\n", cli, strerror(errno));
  return 3;
}
