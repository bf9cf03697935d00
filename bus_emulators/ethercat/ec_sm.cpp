// bus_emulators/ethercat — SyncManager handshakes (see ec_sm.hpp).
#include "bus_emulators/ethercat/ec_sm.hpp"

#include "bus_emulators/ethercat/ec_frame.hpp"

namespace omnitwin::ethercat {

void SmUnit::configure(const std::uint8_t* r) {
  const std::uint16_t start = get_u16(r);
  const std::uint16_t length = get_u16(r + 2);
  const bool enabled = (r[6] & 0x01) != 0;
  const bool changed = start != reg.start || length != reg.length || r[4] != reg.control ||
                       enabled != reg.enabled;
  reg.start = start;
  reg.length = length;
  reg.control = r[4];
  reg.activate = r[6];
  if (changed) reset();
  reg.enabled = enabled;
}

void SmUnit::reset() {
  full_ = false;
  latest_ = -1;
  ecat_buf_ = 0;
  locked_ = -1;
  writing_ = false;
  irq_write_ = irq_read_ = false;
}

bool SmUnit::ecat_allowed(bool write, bool pd_active) const {
  if (reg.pdi_deactivated()) return false;
  if (reg.mailbox()) {
    if (reg.ecat_writes()) return write && !full_;
    return !write && full_;
  }
  if (!pd_active) return false;
  return write == reg.ecat_writes();
}

void SmUnit::ecat_begin(std::uint32_t a, std::uint32_t n, bool write) {
  if (!reg.buffered()) return;
  if (a <= reg.start && a + n > reg.start) {
    if (write) {
      writing_ = true;
    } else {
      locked_ = latest_ < 0 ? 0 : latest_;
    }
  }
}

std::uint32_t SmUnit::redirect(std::uint32_t a, bool write) const {
  if (!reg.buffered() || a < reg.start || a >= static_cast<std::uint32_t>(reg.start) + reg.length) return a;
  int buf = 0;
  if (write) {
    buf = ecat_buf_;
  } else {
    buf = locked_ >= 0 ? locked_ : (latest_ < 0 ? 0 : latest_);
  }
  return a + static_cast<std::uint32_t>(buf) * reg.length;
}

SmEvent SmUnit::ecat_end(std::uint32_t a, std::uint32_t n, bool write) {
  const std::uint32_t last = static_cast<std::uint32_t>(reg.start) + reg.length - 1;
  if (!(a <= last && a + n > last)) return SmEvent::none;
  if (reg.mailbox()) {
    if (write) {
      full_ = true;
      irq_write_ = true;
      return SmEvent::mailbox_written;
    }
    full_ = false;
    irq_read_ = true;
    return SmEvent::mailbox_read;
  }
  if (write) {
    latest_ = ecat_buf_;
    ecat_buf_ = (latest_ + 1) % 3;  // never the latest one
    writing_ = false;
    irq_write_ = true;
    return SmEvent::buffer_written;
  }
  locked_ = -1;
  irq_read_ = true;
  return SmEvent::buffer_read;
}

void SmUnit::set_full(bool f) { full_ = f; }

int SmUnit::pdi_write_buffer() const {
  for (int b = 0; b < 3; ++b) {
    if (b != latest_ && b != locked_) return b;
  }
  return 0;
}

void SmUnit::pdi_commit(int buffer) { latest_ = buffer; }

std::uint8_t SmUnit::status_byte() const {
  std::uint8_t s = 0;
  if (irq_write_) s |= 0x01;
  if (irq_read_) s |= 0x02;
  if (reg.mailbox()) {
    if (full_) s |= 0x08;
  } else {
    s |= static_cast<std::uint8_t>(((latest_ < 0 ? 3 : latest_) & 3) << 4);
    if (locked_ >= 0) s |= 0x40;
    if (writing_) s |= 0x80;
  }
  return s;
}

}  // namespace omnitwin::ethercat
