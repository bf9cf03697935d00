// bus_emulators/tml — the RS-232 pseudo-terminal transport adapter (see tml_pty.hpp).
#include "bus_emulators/tml/tml_pty.hpp"

#include <fcntl.h>
#include <poll.h>
#include <termios.h>
#include <unistd.h>

#include <algorithm>
#include <cerrno>
#include <climits>
#include <cstdlib>
#include <ctime>
#include <stdexcept>
#include <system_error>

namespace omnitwin::tml {

namespace {

[[noreturn]] void fail(const char* what) { throw std::system_error(errno, std::generic_category(), what); }

// The termios constant of a standard rate (0: none; the pty ignores the rate anyway).
speed_t speed_of(std::uint32_t baud) {
  switch (baud) {
    case 9600: return B9600;
    case 19200: return B19200;
    case 38400: return B38400;
    case 57600: return B57600;
    case 115200: return B115200;
    default: return 0;
  }
}

DriveLinkConfig link_config(const TmlDrive& d, std::uint32_t baud) {
  const Protocol p = d.setup().protocol;
  if (p != Protocol::rs232 && p != Protocol::rs485)
    throw std::invalid_argument("tml::TmlPty: the drive's protocol must be RS-232 or RS-485");
  return DriveLinkConfig{p == Protocol::rs232 ? Link::rs232 : Link::rs485, d.setup().axis, d.setup().groups, baud};
}

// Raw 8 data bits, 2 stop bits, no parity, at the rate; no echo, no line editing.
void make_raw(int fd, std::uint32_t baud) {
  termios tio{};
  if (tcgetattr(fd, &tio) != 0) fail("tcgetattr");
  cfmakeraw(&tio);
  tio.c_cflag = (tio.c_cflag & ~(CSIZE | PARENB)) | CS8 | CSTOPB | CLOCAL | CREAD;
  if (const speed_t s = speed_of(baud); s != 0) cfsetspeed(&tio, s);
  if (tcsetattr(fd, TCSANOW, &tio) != 0) fail("tcsetattr");
}

}  // namespace

TmlPty::TmlPty(TmlDrive& drive, std::uint32_t baud)
    : drive_(drive),
      baud_(baud),
      link_(link_config(drive, baud), [this](std::uint8_t b, std::int64_t end_ns) { queue(b, end_ns); },
            [this](const Message& m, std::int64_t t) {
              if (from_host_) from_host_(m, t);
              else drive_.on_message(m, t);
            }) {
  // Open the pair, unlock the slave, keep one slave descriptor so the line stays up.
  master_ = posix_openpt(O_RDWR | O_NOCTTY | O_NONBLOCK);
  if (master_ < 0) fail("posix_openpt");
  if (grantpt(master_) != 0 || unlockpt(master_) != 0) fail("grantpt/unlockpt");
  const char* name = ptsname(master_);
  if (name == nullptr) fail("ptsname");
  slave_path_ = name;
  link_.set_groups([this] { return drive_.groups(); });
  slave_keep_ = open(name, O_RDWR | O_NOCTTY);
  if (slave_keep_ < 0) fail("open pty slave");
  make_raw(slave_keep_, baud);
  // The drive's answers go out through the link (after its 'O').
  drive_.set_sender([this](const Message& m, SimTime t) { link_.send(m, t); });
}

void TmlPty::add_drop(TmlDrive& drive) {
  if (drive_.setup().protocol != Protocol::rs485 || drive.setup().protocol != Protocol::rs485)
    throw std::invalid_argument("tml::TmlPty: several drives share a line only on RS-485");
  auto link = std::make_unique<SerialDriveLink>(
      link_config(drive, baud_), [this](std::uint8_t b, std::int64_t end_ns) { queue(b, end_ns); },
      [&drive](const Message& m, std::int64_t t) { drive.on_message(m, t); });
  SerialDriveLink* l = link.get();
  l->set_groups([&drive] { return drive.groups(); });
  drive.set_sender([l](const Message& m, SimTime t) { l->send(m, t); });
  drops_.push_back(std::move(link));
  drop_drives_.push_back(&drive);
}

TmlPty::~TmlPty() {
  drive_.set_sender(nullptr);
  for (TmlDrive* d : drop_drives_) d->set_sender(nullptr);
  if (slave_keep_ >= 0) close(slave_keep_);
  if (master_ >= 0) close(master_);
}

std::int64_t TmlPty::monotonic_ns() {
  timespec ts{};
  clock_gettime(CLOCK_MONOTONIC, &ts);
  return static_cast<std::int64_t>(ts.tv_sec) * 1'000'000'000 + ts.tv_nsec;
}

void TmlPty::queue(std::uint8_t b, std::int64_t due_ns) {
  if (size_ == kQueue) {
    ++stats_.dropped_out;
    return;
  }
  out_[(head_ + size_) % kQueue] = Out{b, due_ns};
  ++size_;
}

std::int64_t TmlPty::next_due() const { return size_ == 0 ? INT64_MAX : out_[head_].due_ns; }

void TmlPty::flush(std::int64_t now_ns) {
  // Write the run of bytes whose stop bits have ended.
  std::array<std::uint8_t, 256> chunk{};
  std::size_t n = 0;
  while (n < size_ && n < chunk.size() && out_[(head_ + n) % kQueue].due_ns <= now_ns) {
    chunk[n] = out_[(head_ + n) % kQueue].byte;
    ++n;
  }
  if (n == 0) return;
  const ssize_t w = write(master_, chunk.data(), n);
  if (w <= 0) return;  // the pty's buffer is full: try again later
  head_ = (head_ + static_cast<std::size_t>(w)) % kQueue;
  size_ -= static_cast<std::size_t>(w);
  stats_.bytes_out += static_cast<std::uint64_t>(w);
}

void TmlPty::service(std::int64_t now_ns) {
  // Host → drive: everything the host has written by now.
  std::array<std::uint8_t, 256> buf{};
  for (;;) {
    const ssize_t r = read(master_, buf.data(), buf.size());
    if (r <= 0) break;  // EAGAIN: nothing more; EIO: no host has the line open
    stats_.bytes_in += static_cast<std::uint64_t>(r);
    for (ssize_t i = 0; i < r; ++i) {
      link_.on_byte(buf[static_cast<std::size_t>(i)], now_ns);
      for (auto& d : drops_) d->on_byte(buf[static_cast<std::size_t>(i)], now_ns);
    }
  }
  // Drive → host: the bytes that are due.
  flush(now_ns);
}

void TmlPty::wait(std::int64_t now_ns, std::int64_t max_wait_ns) const {
  std::int64_t wait_ns = max_wait_ns;
  if (size_ != 0) wait_ns = std::max<std::int64_t>(0, std::min(wait_ns, next_due() - now_ns));
  pollfd p{master_, POLLIN, 0};
  const timespec ts{static_cast<time_t>(wait_ns / 1'000'000'000), static_cast<long>(wait_ns % 1'000'000'000)};
  ppoll(&p, 1, &ts, nullptr);
}

}  // namespace omnitwin::tml
