// Test support: open a serial device the way a plain serial program does (raw mode, 8 data
// bits, no parity, 2 stop bits, receiver on, modem lines ignored), for the tests that talk to
// the emulated TML drives through their pseudo-terminal.
#pragma once

#include <fcntl.h>
#include <termios.h>
#include <unistd.h>

#include <string>

namespace omnitwin::testing {

// The open descriptor, or -1 when the device cannot be opened or configured. `speed` is a
// termios constant such as B9600.
inline int open_raw_serial_8n2(const std::string& path, speed_t speed) {
  const int fd = open(path.c_str(), O_RDWR | O_NOCTTY);
  if (fd < 0) return -1;
  termios tio{};
  bool ok = tcgetattr(fd, &tio) == 0;
  cfmakeraw(&tio);
  tio.c_cflag |= CS8 | CSTOPB | CLOCAL | CREAD;
  tio.c_cflag &= ~PARENB;
  ok = ok && cfsetspeed(&tio, speed) == 0 && tcsetattr(fd, TCSANOW, &tio) == 0;
  if (!ok) close(fd);
  return ok ? fd : -1;
}

}  // namespace omnitwin::testing
