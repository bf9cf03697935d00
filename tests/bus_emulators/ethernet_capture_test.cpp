// Tests bus_emulators/ethernet_capture: the capture file both Ethernet-framed buses derive
// their writers from. A record shorter than 60 bytes is zero-padded to 60, a whole Ethernet
// frame over 1514 bytes is refused and counted, records are counted per direction, and the
// file keeps its .part name until close() renames it, readable by libpcap as Ethernet.
#include "bus_emulators/ethernet_capture.hpp"

#include <gtest/gtest.h>
#include <pcap/pcap.h>

#include <filesystem>
#include <vector>

#include "tests/support/temp_dir.hpp"

namespace omnitwin::bus_emulators {
namespace {

// The derived writers' view: a frame built in place, then recorded.
struct Writer : EthernetCapture {
  using EthernetCapture::EthernetCapture;
  bool put(std::size_t size, std::int64_t t, int dir) {
    for (std::size_t i = 0; i < size; ++i) frame()[i] = 0xAB;
    return record(size, t, dir);
  }
  using EthernetCapture::write_ethernet;
  using EthernetCapture::written_in;
};

TEST(EthernetCapture, PadsCountsRefusesAndRenamesOnClose) {
  omnitwin::testing::TempDir dir("omnitwin-ethcap");
  const std::string path = (dir / "bus.pcap").string();
  {
    Writer w(path, 4096, false);
    EXPECT_TRUE(std::filesystem::exists(w.part_path()));
    EXPECT_FALSE(std::filesystem::exists(path)) << "not under its final name before close";
    ASSERT_TRUE(w.put(20, 1'000, 0));
    ASSERT_TRUE(w.put(100, 2'000, 1));
    EXPECT_FALSE(w.write_ethernet(std::vector<std::uint8_t>(1515, 0), 3'000, 0));
    EXPECT_EQ(w.refused(), 1u);
    EXPECT_EQ(w.written_in(0), 1u);
    EXPECT_EQ(w.written_in(1), 1u);
    EXPECT_EQ(w.written(), 2u);
    ASSERT_TRUE(w.close());
    EXPECT_TRUE(w.ok());
  }
  char err[PCAP_ERRBUF_SIZE];
  pcap_t* p = pcap_open_offline_with_tstamp_precision(path.c_str(), PCAP_TSTAMP_PRECISION_NANO, err);
  ASSERT_NE(p, nullptr) << err;
  EXPECT_EQ(pcap_datalink(p), DLT_EN10MB);
  pcap_pkthdr* h = nullptr;
  const u_char* data = nullptr;
  ASSERT_EQ(pcap_next_ex(p, &h, &data), 1);
  EXPECT_EQ(h->caplen, 60u) << "padded to the Ethernet minimum";
  EXPECT_EQ(data[19], 0xAB);
  EXPECT_EQ(data[20], 0x00);
  EXPECT_EQ(h->ts.tv_usec, 1'000) << "nanosecond stamps";
  ASSERT_EQ(pcap_next_ex(p, &h, &data), 1);
  EXPECT_EQ(h->caplen, 100u);
  EXPECT_NE(pcap_next_ex(p, &h, &data), 1);
  pcap_close(p);
}

}  // namespace
}  // namespace omnitwin::bus_emulators
