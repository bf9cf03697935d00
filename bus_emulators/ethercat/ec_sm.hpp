// bus_emulators/ethercat — SyncManagers: the ESC's guards over process RAM areas.
//
// Two kinds (control byte bits 1:0): mailbox (10b, one buffer with a full/empty handshake) and
// buffered (00b, three buffers: the reader always gets the last complete buffer, the writer
// never blocks). Direction (bits 3:2): 01b = the master (ECAT) writes, 00b = the master reads.
// Mailbox: a master write of the last byte marks it full (status bit 3); writes while full are
// refused; reads of an ECAT-read mailbox are refused while empty, reading the last byte empties
// it. Buffered: ECAT writes go to a free buffer which becomes "latest" when its last byte is
// written; an ECAT read locks the latest buffer at its first byte until its last byte.
// The three buffers live in physical RAM at start, start + length and start + 2 × length, as on
// real ESCs. SmUnit holds the state; the Esc moves the bytes.
#pragma once

#include <cstdint>

namespace omnitwin::ethercat {

struct SyncManager {
  std::uint16_t start = 0, length = 0;
  std::uint8_t control = 0, status = 0;
  bool enabled = false;
  std::uint8_t activate = 0, pdi_control = 0;  // 0x0806/0x0807 + 8·i

  bool mailbox() const { return (control & 0x03) == 0x02; }
  bool buffered() const { return (control & 0x03) == 0x00; }
  bool ecat_writes() const { return (control & 0x0C) == 0x04; }
  bool watchdog_trigger() const { return (control & 0x40) != 0; }
  // 0x0807 bit 0: the PDI (the firmware) deactivated this SM; the ECAT side sees it enabled in
  // 0x0806 but every access to its area is refused (no data, no WKC).
  bool pdi_deactivated() const { return (pdi_control & 0x01) != 0; }
  bool active() const { return enabled && !pdi_deactivated(); }
  bool overlaps(std::uint32_t a, std::uint32_t n) const {
    return length != 0 && a < static_cast<std::uint32_t>(start) + length && start < a + n;
  }
};

enum class SmEvent : std::uint8_t { none, mailbox_written, mailbox_read, buffer_written, buffer_read };

class SmUnit {
 public:
  SyncManager reg;

  // Decodes the 8 register bytes (start, length, control, -, activate, -); resets the handshake
  // state when the SM becomes enabled or its area changes. Real-time safe.
  void configure(const std::uint8_t* regs);
  void reset();  // empty mailbox, no buffers written

  // May an ECAT access in this direction touch the area? pd_active: the AL state allows
  // process data (SAFE-OP/OP).
  bool ecat_allowed(bool write, bool pd_active) const;
  // Before the bytes move: an ECAT read of a buffered SM that includes its first byte locks the
  // latest buffer; a write that includes the first byte marks the write buffer in use.
  void ecat_begin(std::uint32_t a, std::uint32_t n, bool write);
  // Physical address of byte `a` of the area for an ECAT access in this direction.
  std::uint32_t redirect(std::uint32_t a, bool write) const;
  // After the bytes moved: the handshake event, if the access included the last byte.
  SmEvent ecat_end(std::uint32_t a, std::uint32_t n, bool write);

  // PDI side.
  bool full() const { return full_; }
  void set_full(bool f);
  int latest() const { return latest_; }
  // Buffered, ECAT-read SM: the buffer the PDI writes next (not latest, not the locked one);
  // commit() makes it the latest.
  int pdi_write_buffer() const;
  void pdi_commit(int buffer);

  std::uint8_t status_byte() const;

 private:
  bool full_ = false;      // mailbox full
  int latest_ = -1;        // buffered: last complete buffer (-1 none)
  int ecat_buf_ = 0;       // buffered, ECAT writes: the buffer being written
  int locked_ = -1;        // buffered, ECAT reads: the buffer being read
  bool writing_ = false;   // first byte written, last not yet
  bool irq_write_ = false, irq_read_ = false;
};

}  // namespace omnitwin::ethercat
