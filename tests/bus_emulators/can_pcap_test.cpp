// Tests bus_emulators/can/can_pcap: the file libpcap reads back (link type, nanosecond
// timestamps, SocketCAN records), tshark's decode of standard, extended, remote and error
// frames with no expert warnings of malformed packets, direction selection, a writer killed
// mid-run leaving a readable .part file with every frame written before the kill (and nothing
// under the final name), the final name appearing only on close, a stale capture removed at
// open, and a full disk leaving no file under the final name and an error naming it.
#include "bus_emulators/can/can_pcap.hpp"

#include "tests/bus_emulators/small_tmpfs.hpp"
#include "tests/support/capture_count.hpp"
#include "tests/support/eventually.hpp"

#include <gtest/gtest.h>
#include <pcap/pcap.h>

#include <signal.h>
#include <sys/wait.h>
#include <unistd.h>

#include <cerrno>
#include <cstdio>
#include <cstring>
#include <filesystem>
#include <fstream>
#include <sstream>
#include <string>
#include <vector>

namespace omnitwin::can {
namespace {

namespace fs = std::filesystem;

struct Record {
  std::int64_t ts_ns;
  std::vector<std::uint8_t> bytes;
};

// Reads a capture back through libpcap (independent of our writer's code).
std::vector<Record> read_back(const std::string& path, int* linktype = nullptr) {
  char err[PCAP_ERRBUF_SIZE];
  pcap_t* p = pcap_open_offline_with_tstamp_precision(path.c_str(), PCAP_TSTAMP_PRECISION_NANO, err);
  EXPECT_NE(p, nullptr) << err;
  if (!p) return {};
  if (linktype) *linktype = pcap_datalink(p);
  std::vector<Record> out;
  pcap_pkthdr* h = nullptr;
  const u_char* data = nullptr;
  while (pcap_next_ex(p, &h, &data) == 1)
    out.push_back({std::int64_t{h->ts.tv_sec} * 1'000'000'000 + h->ts.tv_usec, {data, data + h->caplen}});
  pcap_close(p);
  return out;
}

class CanPcap : public ::testing::Test {
 protected:
  void SetUp() override {
    dir_ = fs::temp_directory_path() / ("omnitwin_can_pcap_" + std::to_string(::getpid()) + "_" +
                                        ::testing::UnitTest::GetInstance()->current_test_info()->name());
    fs::create_directories(dir_);
  }
  void TearDown() override { fs::remove_all(dir_); }
  std::string file(const std::string& name) const { return (dir_ / name).string(); }
  fs::path dir_;
};

Frame error_frame() {
  Frame e;
  e.kind = FrameKind::error;
  e.id = 0x004;  // CAN_ERR_CTRL
  e.dlc = 8;
  e.data = {0, 0x04, 0, 0, 0, 0, 0, 0};  // data[1] = CAN_ERR_CTRL_RX_WARNING
  return e;
}

std::vector<Frame> sample() {
  return {make_data(0x000, {0x02, 0x00}), make_data(0x1ABCDEF0, {1, 2, 3, 4, 5, 6, 7, 8}, true), make_remote(0x701, 1),
          error_frame(), make_data(0x7FF, {})};
}

TEST_F(CanPcap, LibpcapReadsBackSocketCanRecordsWithNanosecondTimestamps) {
  const std::string path = file("a.pcap");
  {
    PcapWriter w(path);
    std::int64_t t = 1'700'000'000'123'456'789LL;
    for (const Frame& f : sample()) ASSERT_TRUE(w.write(f, t += 1001));
    EXPECT_EQ(w.written(), sample().size());
  }
  int lt = 0;
  const auto recs = read_back(path, &lt);
  EXPECT_EQ(lt, 227);  // LINKTYPE_CAN_SOCKETCAN
  ASSERT_EQ(recs.size(), sample().size());
  EXPECT_EQ(recs[0].ts_ns, 1'700'000'000'123'457'790LL);  // nanoseconds survive
  EXPECT_EQ(recs[1].ts_ns - recs[0].ts_ns, 1001);
  // struct can_frame, can_id big-endian.
  EXPECT_EQ(recs[0].bytes, (std::vector<std::uint8_t>{0, 0, 0, 0, 2, 0, 0, 0, 0x02, 0x00, 0, 0, 0, 0, 0, 0}));
  EXPECT_EQ(recs[1].bytes, (std::vector<std::uint8_t>{0x9A, 0xBC, 0xDE, 0xF0, 8, 0, 0, 0, 1, 2, 3, 4, 5, 6, 7, 8}));
  EXPECT_EQ(recs[2].bytes, (std::vector<std::uint8_t>{0x40, 0, 0x07, 0x01, 1, 0, 0, 0, 0, 0, 0, 0, 0, 0, 0, 0}));
  EXPECT_EQ(recs[3].bytes, (std::vector<std::uint8_t>{0x20, 0, 0, 0x04, 8, 0, 0, 0, 0, 0x04, 0, 0, 0, 0, 0, 0}));
}

TEST_F(CanPcap, DirectionSelectionAndCounts) {
  const std::string path = file("tx.pcap");
  PcapWriter::Options o;
  o.record_rx = false;
  PcapWriter w(path, o);
  EXPECT_TRUE(w.write(make_data(1, {1}), 1, Direction::rx));  // filtered out, not an error
  EXPECT_TRUE(w.write(make_data(2, {2}), 2, Direction::tx));
  EXPECT_EQ(w.written(Direction::tx), 1u);
  EXPECT_EQ(w.written(Direction::rx), 0u);
  w.close();
  EXPECT_FALSE(w.is_open());
  EXPECT_FALSE(w.write(make_data(3, {}), 3));
  ASSERT_EQ(read_back(path).size(), 1u);
  EXPECT_THROW(PcapWriter(file("no/such/dir/x.pcap")), std::runtime_error);
}

TEST_F(CanPcap, AKilledWriterLeavesAReadablePartFileAndNoFinalFile) {
  const std::string path = file("killed.pcap");
  const pid_t pid = ::fork();
  ASSERT_GE(pid, 0);
  if (pid == 0) {
    PcapWriter w(path);
    for (int i = 0; i < 3; ++i) w.write(make_data(static_cast<std::uint32_t>(0x100 + i), {static_cast<std::uint8_t>(i)}), i);
    // The file is write-behind: what was flushed one writer period (20 ms) before a kill is kept.
    ::usleep(500'000);  // a loaded CI machine may be slow to run the writer thread
    ::raise(SIGKILL);  // harsher than SIGINT: no handler, no destructor, no atexit
    ::_exit(0);
  }
  int st = 0;
  ::waitpid(pid, &st, 0);
  ASSERT_TRUE(WIFSIGNALED(st));
  EXPECT_FALSE(fs::exists(path)) << "a killed capture must not pass for a complete one";
  const auto recs = read_back(file(".killed.pcap.part"));
  ASSERT_EQ(recs.size(), 3u);
  EXPECT_EQ(recs[2].bytes[3], 0x02);
  EXPECT_EQ(recs[2].bytes[8], 2);
}

TEST_F(CanPcap, FinalNameAppearsOnlyOnClose) {
  const std::string path = file("bus-can.pcap");
  PcapWriter::Options o;
  o.flush_each_packet = false;
  PcapWriter w(path, o);
  EXPECT_EQ(w.part_path(), file(".bus-can.pcap.part"));
  ASSERT_TRUE(w.write(make_data(0x181, {1, 2}), 10));
  ASSERT_TRUE(w.flush());
  EXPECT_FALSE(fs::exists(path));
  // A reader can follow the .part file: each flush reaches it within the writer's period.
  EXPECT_TRUE(omnitwin::testing::eventually([&] { return omnitwin::testing::capture_records(w.part_path()) == 1; }));
  EXPECT_TRUE(w.close());
  EXPECT_TRUE(w.ok());
  EXPECT_EQ(w.error(), "");
  EXPECT_FALSE(fs::exists(file(".bus-can.pcap.part")));
  EXPECT_EQ(read_back(path).size(), 1u);
  EXPECT_TRUE(w.close());  // idempotent
}

TEST_F(CanPcap, AStaleCaptureIsRemovedWhenANewOneOpens) {
  const std::string path = file("bus-can.pcap");
  { PcapWriter old(path); old.write(make_data(1, {1}), 1); }
  ASSERT_TRUE(fs::exists(path));
  PcapWriter w(path);
  EXPECT_FALSE(fs::exists(path)) << "the previous run's capture must not pass for this run's";
}

// A 64 KiB tmpfs fills after about 2000 records: a disk that is full.
TEST_F(CanPcap, AFullDiskLeavesNoFinalFileAndAnErrorNamingIt) {
  omnitwin::testing::SmallTmpfs disk("64k");
  if (!disk.mounted()) GTEST_SKIP() << disk.skip_reason();
  const std::string path = (disk / "bus-can.pcap").string();
  PcapWriter w(path);
  int accepted = 0;
  while (accepted < 100'000 && w.write(make_data(0x181, {1, 2, 3, 4, 5, 6, 7, 8}), accepted)) ++accepted;
  ASSERT_LT(accepted, 100'000) << "the full disk was never noticed";
  EXPECT_GT(accepted, 100);
  EXPECT_FALSE(w.ok());
  EXPECT_FALSE(w.write(make_data(0x181, {}), 0)) << "writes stop after a failure";
  EXPECT_FALSE(w.flush());
  EXPECT_NE(w.error().find(path), std::string::npos) << w.error();
  EXPECT_NE(w.error().find(std::strerror(ENOSPC)), std::string::npos) << w.error();
  EXPECT_FALSE(w.close());
  EXPECT_FALSE(fs::exists(path));
  EXPECT_FALSE(fs::exists(w.part_path())) << "the partial capture is removed, freeing the disk";
  EXPECT_FALSE(w.ok());  // the status outlives close()
}

// ---- tshark ------------------------------------------------------------------------------

bool have_tshark() { return std::system("command -v tshark >/dev/null 2>&1") == 0; }

std::string run(const std::string& cmd) {
  std::string out;
  FILE* p = ::popen(cmd.c_str(), "r");
  if (!p) return out;
  char buf[4096];
  std::size_t n;
  while ((n = std::fread(buf, 1, sizeof buf, p)) > 0) out.append(buf, n);
  ::pclose(p);
  return out;
}

TEST_F(CanPcap, TsharkDecodesEveryFrameKindWithoutExpertErrors) {
  if (!have_tshark()) GTEST_SKIP() << "skipped: tshark is not installed (apt-get install tshark)";
  const std::string path = file("t.pcap");
  {
    PcapWriter w(path);
    std::int64_t t = 5'000'000'000LL;
    for (const Frame& f : sample()) w.write(f, t += 1'000'000);
  }
  // AUTOSAR NM / Signal PDU / I-PduM heuristics claim some payloads (e.g. id 0x000); turn
  // them off so that the payload shows as plain data.
  const std::string fields = run("tshark -r " + path +
                                 " --disable-protocol autosar-nm --disable-protocol signal_pdu --disable-protocol ipdum"
                                 " -T fields -E separator=, -e can.id -e can.flags.xtd -e can.flags.rtr -e can.flags.err"
                                 " -e can.len -e data.data 2>/dev/null");
  // Booleans print as True/False or 1/0 depending on the Wireshark version: normalise.
  std::string norm;
  for (std::istringstream in(fields); !in.eof();) {
    std::string line;
    std::getline(in, line);
    if (line.empty()) continue;
    for (const char* t : {"True", "False"}) {
      for (std::size_t at; (at = line.find(t)) != std::string::npos;) line.replace(at, std::strlen(t), t[0] == 'T' ? "1" : "0");
    }
    norm += line + "\n";
  }
  EXPECT_EQ(norm,
            "0,0,0,0,2,0200\n"
            "448585456,1,0,0,8,0102030405060708\n"  // 0x1ABCDEF0
            "1793,0,1,0,1,00\n"                     // 0x701 remote, DLC 1 (Wireshark shows len bytes)
            ",,,1,8,\n"                             // error frame: decoded as can.err.*, not can.id
            "2047,0,0,0,0,\n")
      << fields;
  // The error frame's class is decoded from the id and data[1].
  const std::string err = run("tshark -r " + path + " -Y can.flags.err -T fields -e can.err.ctrl -e can.err.ctrl.rx_warning 2>/dev/null");
  EXPECT_NE(err.find('1'), std::string::npos) << err;
  // No malformed-packet (or any warning/error) expert infos.
  const std::string expert = run("tshark -r " + path + " -q -z expert 2>&1");
  EXPECT_EQ(expert.find("Malformed"), std::string::npos) << expert;
  EXPECT_EQ(expert.find("Error"), std::string::npos) << expert;
  EXPECT_EQ(expert.find("Warning"), std::string::npos) << expert;
  const std::string count = run("tshark -r " + path + " 2>/dev/null | wc -l");
  EXPECT_EQ(std::stoi(count), 5);
}

}  // namespace
}  // namespace omnitwin::can
