// Tests bus_emulators/ethercat/transport/ec_pcap: the capture file as libpcap reads it back
// (link type Ethernet, nanosecond timestamps from SimTime, the out frame from the master MAC
// to broadcast, the returned frame with the marked source, padding to 60 bytes, raw frames
// kept as they are), the file being valid after flush() while still open and after
// destruction, the .part file holding the capture until close() renames it, a full disk
// leaving no file under the final name and an error naming it, and tshark decoding a written
// session as EtherCAT with the right command names and no malformed packets.
#include "bus_emulators/ethercat/transport/ec_pcap.hpp"

#include "tests/bus_emulators/small_tmpfs.hpp"
#include "tests/support/temp_dir.hpp"
#include "tests/support/capture_count.hpp"
#include "tests/support/eventually.hpp"

#include <gtest/gtest.h>
#include <pcap/pcap.h>

#include <array>
#include <cerrno>
#include <cstdio>
#include <cstring>
#include <filesystem>
#include <string>
#include <vector>

namespace omnitwin::ethercat {
namespace {

using omnitwin::testing::TempDir;
using omnitwin::testing::lines_of;

struct Record {
  std::int64_t t_ns = 0;
  std::vector<std::uint8_t> bytes;
};

// Every record of a capture, read with libpcap (nanosecond precision); fails the test when the
// file cannot be opened. `link` gets the link type.
std::vector<Record> read_capture(const std::filesystem::path& p, int* link = nullptr) {
  char err[PCAP_ERRBUF_SIZE] = {};
  pcap_t* pc = pcap_open_offline_with_tstamp_precision(p.c_str(), PCAP_TSTAMP_PRECISION_NANO, err);
  EXPECT_NE(pc, nullptr) << err;
  std::vector<Record> out;
  if (!pc) return out;
  if (link) *link = pcap_datalink(pc);
  pcap_pkthdr* h = nullptr;
  const u_char* data = nullptr;
  int rc = 0;
  while ((rc = pcap_next_ex(pc, &h, &data)) == 1) {
    EXPECT_EQ(h->caplen, h->len);
    out.push_back({std::int64_t{h->ts.tv_sec} * 1'000'000'000 + h->ts.tv_usec, {data, data + h->caplen}});
  }
  EXPECT_EQ(rc, PCAP_ERROR_BREAK) << "the file ends inside a record: " << pcap_geterr(pc);
  pcap_close(pc);
  return out;
}

// Output of a shell command, or nullopt when it could not run.
std::optional<std::string> run(const std::string& cmd) {
  FILE* p = ::popen(cmd.c_str(), "r");
  if (!p) return std::nullopt;
  std::string out;
  std::array<char, 512> buf{};
  while (std::fgets(buf.data(), static_cast<int>(buf.size()), p)) out += buf.data();
  if (::pclose(p) != 0) return std::nullopt;
  return out;
}

bool have_tshark() { return run("command -v tshark >/dev/null 2>&1 && echo yes").value_or("") == "yes\n"; }

std::vector<std::uint8_t> pdu(std::initializer_list<std::tuple<Cmd, std::uint16_t, std::uint16_t, std::uint16_t>> dgs) {
  std::vector<std::uint8_t> buf(kMaxPdu);
  PduBuilder b(buf);
  std::uint8_t idx = 0;
  for (const auto& [cmd, adp, ado, len] : dgs) EXPECT_GE(b.add(cmd, idx++, adp, ado, len), 0);
  buf.resize(b.finish());
  return buf;
}

// The returned form of a PDU: every datagram's WKC set to `wkc`.
std::vector<std::uint8_t> returned(std::vector<std::uint8_t> p, std::uint16_t wkc) {
  PduView v;
  EXPECT_EQ(parse_pdu(p, v), PduError::ok);
  for (std::size_t i = 0; i < v.count; ++i) v.datagrams[i].set_wkc(wkc);
  return p;
}

TEST(EcPcap, RecordsAreEthernetFramesBothWaysWithSimTimeStamps) {
  TempDir dir("ec-pcap");
  const auto path = dir / "a.pcap";
  const auto out = pdu({{Cmd::brd, 0, 0x0130, 2}});
  const auto back = returned(out, 2);
  {
    PcapWriter w(path.string());
    EXPECT_TRUE(w.write(out, 1'000'000'123, Direction::out));
    EXPECT_TRUE(w.write(back, 1'000'050'000, Direction::back));
    EXPECT_EQ(w.written(), 2u);
    EXPECT_EQ(w.written(Direction::out), 1u);
    EXPECT_EQ(w.written(Direction::back), 1u);
  }
  int link = 0;
  const auto recs = read_capture(path, &link);
  EXPECT_EQ(link, 1);  // LINKTYPE_ETHERNET
  ASSERT_EQ(recs.size(), 2u);
  EXPECT_EQ(recs[0].t_ns, 1'000'000'123);
  EXPECT_EQ(recs[1].t_ns, 1'000'050'000);
  std::vector<std::uint8_t> e0 = {0xff, 0xff, 0xff, 0xff, 0xff, 0xff, 0x00, 0x00, 0x5e, 0x00, 0x53, 0x01, 0x88, 0xa4};
  e0.insert(e0.end(), out.begin(), out.end());
  e0.resize(60, 0);
  EXPECT_EQ(recs[0].bytes, e0);
  std::vector<std::uint8_t> e1 = {0xff, 0xff, 0xff, 0xff, 0xff, 0xff, 0x02, 0x00, 0x5e, 0x00, 0x53, 0x01, 0x88, 0xa4};
  e1.insert(e1.end(), back.begin(), back.end());
  e1.resize(60, 0);
  EXPECT_EQ(recs[1].bytes, e1);
}

TEST(EcPcap, MasterMacLargePdusRawFramesAndNegativeTimes) {
  TempDir dir("ec-pcap");
  const auto path = dir / "b.pcap";
  PcapWriter::Options o;
  o.master_mac = {0x00, 0x1b, 0x21, 0x0a, 0x0b, 0x0c};
  PcapWriter w(path.string(), o);
  const auto big = pdu({{Cmd::lrw, 0, 0, 1000}});
  EXPECT_TRUE(w.write(big, 5, Direction::out));
  std::vector<std::uint8_t> raw = {1, 2, 3, 4, 5, 6, 7, 8, 9, 10, 11, 12, 0x88, 0xa4, 0x0e, 0x10};
  EXPECT_TRUE(w.write_frame(raw, -1, Direction::back));  // 1 ns before the epoch
  std::vector<std::uint8_t> too_big(kMaxPdu + 1);
  EXPECT_FALSE(w.write(too_big, 6, Direction::out));
  EXPECT_EQ(w.refused(), 1u);
  w.close();
  EXPECT_FALSE(w.is_open());
  EXPECT_FALSE(w.write(big, 7, Direction::out));
  const auto recs = read_capture(path);
  ASSERT_EQ(recs.size(), 2u);
  ASSERT_EQ(recs[0].bytes.size(), 14 + big.size());  // no padding needed
  EXPECT_EQ(recs[0].bytes[6], 0x00);
  EXPECT_EQ(recs[0].bytes[7], 0x1b);
  EXPECT_TRUE(std::equal(big.begin(), big.end(), recs[0].bytes.begin() + 14));
  EXPECT_EQ(recs[1].t_ns, -1);
  ASSERT_EQ(recs[1].bytes.size(), 60u);
  EXPECT_TRUE(std::equal(raw.begin(), raw.end(), recs[1].bytes.begin()));
  EXPECT_EQ(recs[1].bytes[59], 0);
}

// Issue 20: records with the addresses a raw transport saw: out as given, back with the
// slaves' marking of the source.
TEST(EcPcap, RecordsCarryTheWireAddressesWhenGiven) {
  TempDir dir("ec-pcap");
  const auto path = dir / "w.pcap";
  PcapWriter w(path.string());
  const Mac dst = {0xff, 0xff, 0xff, 0xff, 0xff, 0xff}, src = {0x01, 0x01, 0x01, 0x01, 0x01, 0x01};  // SOEM's
  const auto p = pdu({{Cmd::brd, 0, 0, 2}});
  EXPECT_TRUE(w.write(p, 1, Direction::out, dst, src));
  EXPECT_TRUE(w.write(p, 2, Direction::back, dst, src));
  w.close();
  const auto recs = read_capture(path);
  ASSERT_EQ(recs.size(), 2u);
  EXPECT_TRUE(std::equal(dst.begin(), dst.end(), recs[0].bytes.begin()));
  EXPECT_TRUE(std::equal(src.begin(), src.end(), recs[0].bytes.begin() + 6));
  EXPECT_EQ(recs[1].bytes[6], 0x03);  // 01 | 02
  EXPECT_EQ(recs[1].bytes[7], 0x01);
}

TEST(EcPcap, FileIsValidAfterEveryFlushWhileOpen) {
  TempDir dir("ec-pcap");
  const auto path = dir / "c.pcap";
  PcapWriter w(path.string());
  const std::string part = w.part_path();
  // The header, then each flush, reaches the .part file within the writer's period.
  EXPECT_TRUE(omnitwin::testing::eventually([&] { return omnitwin::testing::capture_records(part) == 0; }));
  const auto p = pdu({{Cmd::fprd, 0x1001, 0x0130, 2}});
  for (int i = 0; i < 10; ++i) w.write(p, i * 1'000'000, Direction::out);
  ASSERT_TRUE(w.flush());
  EXPECT_TRUE(omnitwin::testing::eventually([&] { return omnitwin::testing::capture_records(part) == 10; }));
  for (int i = 0; i < 5; ++i) w.write(p, 20'000'000 + i, Direction::back);
  ASSERT_TRUE(w.flush());
  EXPECT_TRUE(omnitwin::testing::eventually([&] { return omnitwin::testing::capture_records(part) == 15; }));
}

TEST(EcPcap, FinalNameAppearsOnlyOnClose) {
  TempDir dir("ec-pcap");
  const auto path = dir / "bus-ethercat.pcap";
  std::filesystem::path part;
  {
    PcapWriter w(path.string());
    part = w.part_path();
    EXPECT_EQ(part, dir / ".bus-ethercat.pcap.part");
    w.write(pdu({{Cmd::brd, 0, 0x0130, 2}}), 1, Direction::out);
    ASSERT_TRUE(w.flush());
    EXPECT_FALSE(std::filesystem::exists(path));
    EXPECT_TRUE(omnitwin::testing::eventually([&] { return omnitwin::testing::capture_records(part.string()) == 1; }));
  }  // the destructor closes and renames
  EXPECT_FALSE(std::filesystem::exists(part));
  EXPECT_EQ(read_capture(path).size(), 1u);
  // A new writer removes the old capture at once: it must not pass for the new run's.
  PcapWriter again(path.string());
  EXPECT_FALSE(std::filesystem::exists(path));
  EXPECT_TRUE(again.close());
  EXPECT_TRUE(again.ok());
  EXPECT_TRUE(read_capture(path).empty());
}

// A 64 KiB tmpfs fills after about a thousand 60-byte frames: a disk that is full. The
// writer buffers, so the failure shows at a flush; from then on nothing is written.
TEST(EcPcap, AFullDiskLeavesNoFinalFileAndAnErrorNamingIt) {
  omnitwin::testing::SmallTmpfs disk("64k");
  if (!disk.mounted()) GTEST_SKIP() << disk.skip_reason();
  const auto path = disk / "bus-ethercat.pcap";
  PcapWriter::Options o;
  o.buffer_bytes = 4096;
  PcapWriter w(path.string(), o);
  const auto p = pdu({{Cmd::lrw, 0, 0, 12}});
  int ticks = 0;
  for (bool ok = true; ok && ticks < 100'000; ++ticks) ok = w.write(p, ticks, Direction::out) && w.flush();
  ASSERT_LT(ticks, 100'000) << "the full disk was never noticed";
  EXPECT_FALSE(w.ok());
  EXPECT_FALSE(w.write(p, 0, Direction::back));
  EXPECT_FALSE(w.flush());
  EXPECT_NE(w.error().find(path.string()), std::string::npos) << w.error();
  EXPECT_NE(w.error().find(std::strerror(ENOSPC)), std::string::npos) << w.error();
  EXPECT_FALSE(w.close());
  EXPECT_FALSE(std::filesystem::exists(path));
  EXPECT_FALSE(std::filesystem::exists(w.part_path()));
  EXPECT_NE(w.error(), "");
}

TEST(EcPcap, FlushEachFrameWritesThroughWithoutFlushCalls) {
  TempDir dir("ec-pcap");
  const auto path = dir / "d.pcap";
  PcapWriter::Options o;
  o.flush_each_frame = true;
  PcapWriter w(path.string(), o);
  w.write(pdu({{Cmd::brd, 0, 0x0130, 2}}), 1, Direction::out);
  EXPECT_TRUE(omnitwin::testing::eventually([&] { return omnitwin::testing::capture_records(w.part_path()) == 1; }));
}

TEST(EcPcap, OpeningAMissingFolderThrowsNamingThePath) {
  try {
    PcapWriter w("/nonexistent-folder-ec/x.pcap");
    FAIL() << "opened";
  } catch (const std::runtime_error& e) {
    EXPECT_NE(std::string(e.what()).find("/nonexistent-folder-ec/x.pcap"), std::string::npos) << e.what();
  }
}

TEST(EcPcap, TsharkDecodesASessionAsEtherCatWithoutMalformedPackets) {
  if (!have_tshark()) GTEST_SKIP() << "tshark is not installed";
  TempDir dir("ec-pcap");
  const auto path = dir / "session.pcap";
  // A start-up-like session: count slaves, read AL status, set a station address, read and
  // write registers, cyclic LRW, and a frame of several datagrams.
  const std::vector<std::vector<std::uint8_t>> outs = {
      pdu({{Cmd::brd, 0, 0x0000, 2}}),
      pdu({{Cmd::aprd, 0, 0x0130, 2}}),
      pdu({{Cmd::apwr, 0, 0x0010, 2}}),
      pdu({{Cmd::fprd, 0x1001, 0x0130, 2}}),
      pdu({{Cmd::fpwr, 0x1001, 0x0120, 2}}),
      pdu({{Cmd::lrw, 0x0000, 0x0001, 12}}),
      pdu({{Cmd::lrd, 0, 0x0001, 8}, {Cmd::armw, 0, 0x0910, 8}, {Cmd::bwr, 0, 0x0900, 4}}),
  };
  const std::vector<std::string> names = {"BRD", "APRD", "APWR", "FPRD", "FPWR", "LRW", "LRD"};
  {
    PcapWriter w(path.string());
    SimTime t = 0;
    for (const auto& p : outs) {
      w.write(p, t, Direction::out);
      w.write(returned(p, 1), t + 20'000, Direction::back);
      t += 1'000'000;
    }
  }
  const auto fields = run("tshark -r " + path.string() +
                          " -T fields -E separator=/t -e frame.protocols -e eth.src -e ecat.cmd -e _ws.malformed "
                          "-e _ws.col.Info 2>/dev/null");
  ASSERT_TRUE(fields) << "tshark failed";
  const auto lines = lines_of(*fields);
  ASSERT_EQ(lines.size(), 2 * outs.size()) << *fields;
  for (std::size_t i = 0; i < lines.size(); ++i) {
    const std::string& l = lines[i];
    SCOPED_TRACE(l);
    EXPECT_NE(l.find("eth:ethertype:ecatf:ecat"), std::string::npos);
    EXPECT_EQ(l.find("malformed"), std::string::npos);
    EXPECT_NE(l.find(i % 2 == 0 ? "00:00:5e:00:53:01" : "02:00:5e:00:53:01"), std::string::npos);
    EXPECT_NE(l.find("'" + names[i / 2] + "'"), std::string::npos);
  }
  // The command bytes of the multi-datagram frame, in order.
  EXPECT_NE(lines[12].find("0x0a,0x0d,0x08"), std::string::npos) << lines[12];
  EXPECT_NE(lines[12].find("3 Cmds, 'LRD': len 8, 'ARMW': len 8, 'BWR': len 4"), std::string::npos) << lines[12];
  // And nothing anywhere that tshark flags as malformed or as an error.
  const auto bad = run("tshark -r " + path.string() + " -Y '_ws.malformed || _ws.expert.severity >= error' 2>/dev/null | wc -l");
  ASSERT_TRUE(bad);
  EXPECT_EQ(*bad, "0\n");
}

}  // namespace
}  // namespace omnitwin::ethercat
