// bus_emulators/tml — THE TRANSPORT ADAPTER of an emulated IDM drive's RS-232 port (seed 003
// chapter 3): a pseudo-terminal pair whose slave side a plain serial program (the master program,
// minicom, a test) opens like /dev/ttyS0. It lives beside the protocol cores (it is the only
// file of tml/ that touches file descriptors and the monotonic clock) and is compiled into
// omnitwin_tml because the build globs only tml/*.cpp (not a transport/ sub-folder).
//
// Bytes the host writes are read from the pty master and fed to tml_serial's SerialDriveLink
// (acknowledgement 'O', SYNC-byte echo, checksum checks), whose messages go to the TmlDrive;
// the drive's answers and type C messages go back through the link. Outgoing bytes carry the
// 8N2 timing of the configured baud rate: each is written to the master when its stop bits end
// (LineTx's end times), so a host sees the pace of a real line. The caller owns the clock:
// service(now) and wait(now, ...) take CLOCK_MONOTONIC ns (monotonic_ns()) and the caller steps
// the drive with the same clock. Not real-time safe (system calls); no allocation after set-up.
#pragma once

#include <array>
#include <cstdint>
#include <functional>
#include <memory>
#include <string>
#include <vector>

#include "bus_emulators/tml/tml_drive.hpp"
#include "bus_emulators/tml/tml_serial.hpp"

namespace omnitwin::tml {

struct PtyStats {
  std::uint64_t bytes_in = 0, bytes_out = 0, dropped_out = 0;  // dropped: output queue full
};

class TmlPty {
 public:
  // Opens the pair (posix_openpt, grantpt, unlockpt; raw 8N2 at `baud`) and wires `drive`
  // (protocol rs232 or rs485) to it. Throws std::system_error / std::invalid_argument (set-up).
  TmlPty(TmlDrive& drive, std::uint32_t baud);
  ~TmlPty();
  TmlPty(const TmlPty&) = delete;
  TmlPty& operator=(const TmlPty&) = delete;

  // RS-485 multi-drop: another drive on the same line (the first drive's and this one's
  // protocol must be rs485; std::invalid_argument otherwise). Every drive's link hears every
  // byte; only the addressed drive acknowledges and answers, group and axis 0 messages are
  // acknowledged by nobody (tml_serial). The line is half duplex: the host sends one command at
  // a time and type B never goes to a group or axis 0 on RS-485, so two drives never talk at
  // once; if a host breaks that rule their bytes interleave, as they would collide on a real
  // line. Set-up.
  void add_drop(TmlDrive& drive);

  // A relay axis (tml_relay): messages from the host go to `from_host` instead of the drive
  // (the relay hands its own axis's to the drive). Set-up.
  void set_host_sink(std::function<void(const Message&, std::int64_t)> from_host) { from_host_ = std::move(from_host); }
  // A message for the host onto the line (the relay's answers from CAN). Real-time safe.
  void to_host(const Message& m, std::int64_t now_ns) { link_.send(m, now_ns); }

  // The path a serial program opens (e.g. /dev/pts/7).
  const std::string& slave_path() const { return slave_path_; }
  // Reads what the host wrote (each byte received at now_ns), feeds the link, and writes every
  // queued byte whose stop bits have ended by now_ns [CLOCK_MONOTONIC ns].
  void service(std::int64_t now_ns);
  // Blocks until host input arrives, the next queued byte is due, or max_wait_ns passed.
  void wait(std::int64_t now_ns, std::int64_t max_wait_ns) const;
  // When the next queued byte is due; INT64_MAX when none.
  std::int64_t next_due() const;
  static std::int64_t monotonic_ns();

  std::uint64_t checksum_errors() const { return link_.rx_stats().bad_checksums; }
  const RxStats& rx_stats() const { return link_.rx_stats(); }
  const DriveLinkStats& link_stats() const { return link_.stats(); }
  const PtyStats& stats() const { return stats_; }

 private:
  struct Out { std::uint8_t byte; std::int64_t due_ns; };
  std::function<void(const Message&, std::int64_t)> from_host_;  // empty: straight to the drive
  static constexpr std::size_t kQueue = 4096;
  void queue(std::uint8_t b, std::int64_t due_ns);
  void flush(std::int64_t now_ns);

  TmlDrive& drive_;
  std::uint32_t baud_;
  int master_ = -1, slave_keep_ = -1;  // slave_keep_: keeps the line open between host sessions
  std::string slave_path_;
  SerialDriveLink link_;
  std::vector<std::unique_ptr<SerialDriveLink>> drops_;  // RS-485: the other drives' links
  std::vector<TmlDrive*> drop_drives_;
  std::array<Out, kQueue> out_{};
  std::size_t head_ = 0, size_ = 0;
  PtyStats stats_;
};

}  // namespace omnitwin::tml
