// Tests bus_emulators/ethercat/ec_sm: SyncManager decoding and handshakes without an ESC —
// mailbox full/empty permissions, 3-buffer redirection (writer to a free buffer, reader locked on
// the last complete one), status bits and resets on reconfiguration.
#include "bus_emulators/ethercat/ec_sm.hpp"

#include <gtest/gtest.h>

#include "bus_emulators/ethercat/ec_frame.hpp"

namespace omnitwin::ethercat {
namespace {

SmUnit make(std::uint16_t start, std::uint16_t len, std::uint8_t control) {
  std::uint8_t r[8] = {};
  put_u16(r, start);
  put_u16(r + 2, len);
  r[4] = control;
  r[6] = 1;
  SmUnit u;
  u.configure(r);
  return u;
}

TEST(EcSm, DecodesKindAndDirection) {
  const SmUnit mbx = make(0x1000, 128, 0x26);
  EXPECT_TRUE(mbx.reg.enabled);
  EXPECT_TRUE(mbx.reg.mailbox());
  EXPECT_TRUE(mbx.reg.ecat_writes());
  const SmUnit pd = make(0x1100, 4, 0x64);
  EXPECT_TRUE(pd.reg.buffered());
  EXPECT_TRUE(pd.reg.watchdog_trigger());
  EXPECT_TRUE(pd.reg.overlaps(0x1103, 1));
  EXPECT_FALSE(pd.reg.overlaps(0x1104, 4));
  EXPECT_FALSE(pd.reg.overlaps(0x10FC, 4));
}

TEST(EcSm, MailboxHandshake) {
  SmUnit w = make(0x1000, 16, 0x26);
  EXPECT_TRUE(w.ecat_allowed(true, false));
  EXPECT_FALSE(w.ecat_allowed(false, false));
  EXPECT_EQ(w.ecat_end(0x1000, 8, true), SmEvent::none);
  EXPECT_EQ(w.ecat_end(0x1008, 8, true), SmEvent::mailbox_written);
  EXPECT_TRUE(w.full());
  EXPECT_EQ(w.status_byte() & 0x08, 0x08);
  EXPECT_FALSE(w.ecat_allowed(true, false));

  SmUnit r = make(0x1080, 16, 0x22);
  EXPECT_FALSE(r.ecat_allowed(false, true));  // empty
  r.set_full(true);
  EXPECT_TRUE(r.ecat_allowed(false, true));
  EXPECT_FALSE(r.ecat_allowed(true, true));
  EXPECT_EQ(r.ecat_end(0x1080, 16, false), SmEvent::mailbox_read);
  EXPECT_FALSE(r.full());
}

TEST(EcSm, ThreeBuffersRedirectAndLock) {
  SmUnit out = make(0x1100, 4, 0x64);
  EXPECT_FALSE(out.ecat_allowed(true, false));  // below SAFE-OP
  EXPECT_TRUE(out.ecat_allowed(true, true));
  EXPECT_FALSE(out.ecat_allowed(false, true));
  EXPECT_EQ(out.status_byte() & 0x30, 0x30);    // nothing written yet
  out.ecat_begin(0x1100, 4, true);
  EXPECT_EQ(out.redirect(0x1101, true), 0x1101u);
  EXPECT_EQ(out.ecat_end(0x1100, 4, true), SmEvent::buffer_written);
  EXPECT_EQ(out.latest(), 0);
  EXPECT_EQ(out.redirect(0x1101, true), 0x1105u);  // next write into buffer 1
  out.ecat_end(0x1100, 4, true);
  EXPECT_EQ(out.latest(), 1);
  EXPECT_EQ(out.redirect(0x1100, true), 0x1108u);
  EXPECT_EQ(out.redirect(0x1200, true), 0x1200u);  // outside the area

  SmUnit in = make(0x1200, 4, 0x20);
  const int b = in.pdi_write_buffer();
  in.pdi_commit(b);
  in.ecat_begin(0x1200, 2, false);  // lock b
  EXPECT_EQ(in.status_byte() & 0x40, 0x40);
  const int b2 = in.pdi_write_buffer();
  EXPECT_NE(b2, b);
  in.pdi_commit(b2);
  const int b3 = in.pdi_write_buffer();
  EXPECT_NE(b3, b);
  EXPECT_NE(b3, b2);
  EXPECT_EQ(in.redirect(0x1202, false), 0x1202u + 4u * static_cast<std::uint32_t>(b));
  EXPECT_EQ(in.ecat_end(0x1202, 2, false), SmEvent::buffer_read);
  EXPECT_EQ(in.redirect(0x1200, false), 0x1200u + 4u * static_cast<std::uint32_t>(b2));
}

TEST(EcSm, ReconfigurationResets) {
  SmUnit w = make(0x1000, 16, 0x26);
  w.ecat_end(0x1000, 16, true);
  EXPECT_TRUE(w.full());
  std::uint8_t r[8] = {};
  put_u16(r, 0x1000);
  put_u16(r + 2, 16);
  r[4] = 0x26;
  r[6] = 0;  // disable
  w.configure(r);
  EXPECT_FALSE(w.reg.enabled);
  EXPECT_FALSE(w.full());
}

}  // namespace
}  // namespace omnitwin::ethercat
