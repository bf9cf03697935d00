// Tests bus_emulators/mechatrolink3/m3_pcap: the capture file as libpcap reads it back (link
// type Ethernet, nanosecond timestamps from SimTime, one record per frame in both directions,
// each the Ethernet frame m3::encapsulate() builds, counted per direction), corrupted frames
// recorded as they are and oversized ones refused, Ethernet frames written as they are, the
// .part file valid after flush() and renamed to the final name only on close, a full disk
// leaving no file under the final name; and tshark with tools/wireshark/mechatrolink3.lua
// decoding every frame type, the command names of a VELCTRL command and its response, a bad
// FCS, a bad or disagreeing data length and a UDP datagram, without Lua errors or malformed
// packets.
#include "bus_emulators/mechatrolink3/m3_pcap.hpp"

#include "tests/bus_emulators/small_tmpfs.hpp"
#include "tests/support/mujoco_fixture.hpp"
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
#include <optional>
#include <string>
#include <vector>

namespace omnitwin::m3 {
namespace {

using omnitwin::testing::TempDir;
using omnitwin::testing::lines_of;
using Bytes = std::vector<std::uint8_t>;

struct Record {
  std::int64_t t_ns = 0;
  Bytes bytes;
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

// Output of a shell command, or nullopt when it could not run or failed.
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

// A valid frame: n data bytes 0x10, 0x11, … with `head` over the first ones.
Bytes frame(FrameType type, std::uint8_t dst, std::uint8_t src, std::size_t n, Bytes head = {}) {
  Bytes data(n);
  for (std::size_t i = 0; i < n; ++i) data[i] = static_cast<std::uint8_t>(0x10 + i);
  std::copy(head.begin(), head.begin() + static_cast<std::ptrdiff_t>(std::min(head.size(), n)), data.begin());
  FrameSpec s{dst, src, type, 5, false, data};
  Bytes out(kMaxFrame);
  out.resize(encode(s, out));
  EXPECT_FALSE(out.empty()) << to_string(type) << " with " << n << " bytes";
  return out;
}

// A 48-byte command (or response) with its main code and subcommand code set.
Bytes command48(FrameType type, std::uint8_t dst, std::uint8_t src, std::uint8_t code, std::uint8_t sub) {
  Bytes head(33, 0);
  head[0] = code;
  head[1] = 0x01;  // WDT
  head[32] = sub;
  return frame(type, dst, src, 48, head);
}

struct Sample {
  Bytes bytes;
  Direction dir;
  std::string name;
};

// One frame of every type, valid lengths, as a start-up and a cycle would send them.
std::vector<Sample> every_type() {
  const std::uint8_t s1 = 0x03, s2 = 0x04;
  return {
      {frame(FrameType::detect, s1, kC1Master, 0), Direction::out, "DETECT"},
      {frame(FrameType::detect_reply, kC1Master, s1, 8), Direction::back, "DETECT_RPL"},
      {frame(FrameType::delay_request, s1, kC1Master, 0), Direction::out, "DLY_REQ"},
      {frame(FrameType::delay_reply, kC1Master, s1, 0), Direction::back, "DLY_RPL"},
      {frame(FrameType::cycle_notify, kBroadcast, kC1Master, 16), Direction::out, "CYC_NOTIFY"},
      {frame(FrameType::comm_start, kBroadcast, kC1Master, 8), Direction::out, "COMM_START"},
      {frame(FrameType::sync, kBroadcast, kC1Master, 8), Direction::out, "SYNC"},
      {command48(FrameType::cyclic_command, s1, kC1Master, 0x3C, 0x40), Direction::out, "CMD"},
      {command48(FrameType::cyclic_response, kC1Master, s1, 0x3C, 0x40), Direction::back, "RSP"},
      {frame(FrameType::event_command, s2, kC1Master, 64, {0x03}), Direction::out, "EVT_CMD"},
      {frame(FrameType::event_response, kC1Master, s2, 64, {0x03}), Direction::back, "EVT_RSP"},
  };
}

Bytes encapsulated(const Bytes& m3) {
  Bytes out(kMaxEthFrame);
  out.resize(encapsulate(m3, out));
  return out;
}

TEST(M3Pcap, EveryFrameTypeBothWaysAsEncapsulatedEthernetWithSimTimeStamps) {
  TempDir dir("m3-pcap");
  const auto path = dir / "a.pcap";
  const auto samples = every_type();
  {
    PcapWriter w(path.string());
    for (std::size_t i = 0; i < samples.size(); ++i)
      EXPECT_TRUE(w.write_frame(samples[i].bytes, 1'000'000'007 + 12'345 * std::int64_t(i), samples[i].dir));
    EXPECT_EQ(w.written(), samples.size());
    EXPECT_EQ(w.written(Direction::out), 7u);
    EXPECT_EQ(w.written(Direction::back), 4u);
    EXPECT_EQ(w.refused(), 0u);
  }
  int link = 0;
  const auto recs = read_capture(path, &link);
  EXPECT_EQ(link, PcapWriter::kLinkType);
  ASSERT_EQ(recs.size(), samples.size());
  for (std::size_t i = 0; i < recs.size(); ++i) {
    SCOPED_TRACE(samples[i].name);
    EXPECT_EQ(recs[i].t_ns, 1'000'000'007 + 12'345 * std::int64_t(i));
    EXPECT_EQ(recs[i].bytes, encapsulated(samples[i].bytes));
    EXPECT_GE(recs[i].bytes.size(), kMinEthFrame);
  }
}

TEST(M3Pcap, CorruptedFramesAreKeptOversizedRefusedEthernetFramesAsTheyAre) {
  TempDir dir("m3-pcap");
  const auto path = dir / "b.pcap";
  PcapWriter w(path.string());
  Bytes bad = frame(FrameType::sync, kBroadcast, kC1Master, 8);
  bad[7] ^= 0x01;  // a bit flipped on the line: decode() refuses it, the capture keeps it
  EXPECT_TRUE(w.write_frame(bad, 5, Direction::out));
  const Bytes raw = {1, 2, 3, 4, 5, 6, 7, 8, 9, 10, 11, 12, 0x88, 0xB5, 0xFF, 0x01};
  EXPECT_TRUE(w.write_ethernet(raw, -1, Direction::back));  // 1 ns before the epoch
  EXPECT_FALSE(w.write_frame(Bytes(kMaxFrame + 1), 6, Direction::out));
  EXPECT_FALSE(w.write_frame(Bytes(1), 6, Direction::out));
  EXPECT_FALSE(w.write_ethernet(Bytes(kMaxEthFrame + 1), 6, Direction::back));
  EXPECT_EQ(w.refused(), 3u);
  EXPECT_EQ(w.written(), 2u);
  EXPECT_TRUE(w.close());
  EXPECT_FALSE(w.is_open());
  EXPECT_FALSE(w.write_frame(bad, 7, Direction::out));
  const auto recs = read_capture(path);
  ASSERT_EQ(recs.size(), 2u);
  Bytes good = frame(FrameType::sync, kBroadcast, kC1Master, 8);
  Bytes expected = encapsulated(good);
  expected[kEthHeaderSize + 7] ^= 0x01;
  EXPECT_EQ(recs[0].bytes, expected);
  EXPECT_EQ(recs[1].t_ns, -1);
  ASSERT_EQ(recs[1].bytes.size(), kMinEthFrame);
  EXPECT_TRUE(std::equal(raw.begin(), raw.end(), recs[1].bytes.begin()));
  EXPECT_EQ(recs[1].bytes.back(), 0);
}

TEST(M3Pcap, FileIsValidAfterEveryFlushWhileOpen) {
  TempDir dir("m3-pcap");
  PcapWriter w((dir / "c.pcap").string());
  const std::string part = w.part_path();
  // The header, then each flush, reaches the .part file within the writer's period.
  EXPECT_TRUE(omnitwin::testing::eventually([&] { return omnitwin::testing::capture_records(part) == 0; }));
  const Bytes sync = frame(FrameType::sync, kBroadcast, kC1Master, 8);
  for (int i = 0; i < 10; ++i) w.write_frame(sync, i * 1'000'000, Direction::out);
  ASSERT_TRUE(w.flush());
  EXPECT_TRUE(omnitwin::testing::eventually([&] { return omnitwin::testing::capture_records(part) == 10; }));
  const Bytes rsp = frame(FrameType::cyclic_response, kC1Master, 0x03, 16);
  for (int i = 0; i < 5; ++i) w.write_frame(rsp, 20'000'000 + i, Direction::back);
  ASSERT_TRUE(w.flush());
  EXPECT_TRUE(omnitwin::testing::eventually([&] { return omnitwin::testing::capture_records(part) == 15; }));
}

TEST(M3Pcap, FinalNameAppearsOnlyOnClose) {
  TempDir dir("m3-pcap");
  const auto path = dir / "bus-m3.pcap";
  std::filesystem::path part;
  {
    PcapWriter w(path.string());
    part = w.part_path();
    EXPECT_EQ(part, dir / ".bus-m3.pcap.part");
    w.write_frame(frame(FrameType::sync, kBroadcast, kC1Master, 8), 1, Direction::out);
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
TEST(M3Pcap, AFullDiskLeavesNoFinalFileAndAnErrorNamingIt) {
  omnitwin::testing::SmallTmpfs disk("64k");
  if (!disk.mounted()) GTEST_SKIP() << disk.skip_reason();
  const auto path = disk / "bus-m3.pcap";
  PcapWriter::Options o;
  o.buffer_bytes = 4096;
  PcapWriter w(path.string(), o);
  const Bytes cmd = frame(FrameType::cyclic_command, 0x03, kC1Master, 16);
  int ticks = 0;
  for (bool ok = true; ok && ticks < 100'000; ++ticks) ok = w.write_frame(cmd, ticks, Direction::out) && w.flush();
  ASSERT_LT(ticks, 100'000) << "the full disk was never noticed";
  EXPECT_FALSE(w.ok());
  EXPECT_FALSE(w.write_frame(cmd, 0, Direction::back));
  EXPECT_FALSE(w.flush());
  EXPECT_NE(w.error().find(path.string()), std::string::npos) << w.error();
  EXPECT_NE(w.error().find(std::strerror(ENOSPC)), std::string::npos) << w.error();
  EXPECT_FALSE(w.close());
  EXPECT_FALSE(std::filesystem::exists(path));
  EXPECT_FALSE(std::filesystem::exists(w.part_path()));
  EXPECT_NE(w.error(), "");
}

TEST(M3Pcap, FlushEachFrameWritesThroughWithoutFlushCalls) {
  TempDir dir("m3-pcap");
  PcapWriter::Options o;
  o.flush_each_frame = true;
  PcapWriter w((dir / "d.pcap").string(), o);
  w.write_frame(frame(FrameType::sync, kBroadcast, kC1Master, 8), 1, Direction::out);
  EXPECT_TRUE(omnitwin::testing::eventually([&] { return omnitwin::testing::capture_records(w.part_path()) == 1; }));
}

TEST(M3Pcap, OpeningAMissingFolderThrowsNamingThePath) {
  try {
    PcapWriter w("/nonexistent-folder-m3/x.pcap");
    FAIL() << "opened";
  } catch (const std::runtime_error& e) {
    EXPECT_NE(std::string(e.what()).find("/nonexistent-folder-m3/x.pcap"), std::string::npos) << e.what();
  }
}

// ---- the dissector -----------------------------------------------------------------------

void put_u16be(Bytes& b, std::size_t at, std::uint16_t v) {
  b[at] = static_cast<std::uint8_t>(v >> 8);
  b[at + 1] = static_cast<std::uint8_t>(v & 0xFF);
}

// The frame in a UDP datagram (port 34997 both ways) in IPv4 in Ethernet.
Bytes udp_datagram(const Bytes& m3) {
  Bytes b(14 + 20 + 8);
  b[5] = 0x01, b[11] = 0x02, b[12] = 0x08;          // MACs 00..01 and 00..02, IPv4
  b[14] = 0x45, b[22] = 64, b[23] = 17;             // version/IHL, TTL, UDP
  put_u16be(b, 16, static_cast<std::uint16_t>(20 + 8 + m3.size()));
  const std::array<std::uint8_t, 8> ips = {192, 0, 2, 1, 192, 0, 2, 2};
  std::copy(ips.begin(), ips.end(), b.begin() + 26);
  std::uint32_t sum = 0;
  for (std::size_t i = 14; i < 34; i += 2) sum += (b[i] << 8) | b[i + 1];
  while (sum >> 16) sum = (sum & 0xFFFF) + (sum >> 16);
  put_u16be(b, 24, static_cast<std::uint16_t>(~sum));
  put_u16be(b, 34, kUdpPort);
  put_u16be(b, 36, kUdpPort);
  put_u16be(b, 38, static_cast<std::uint16_t>(8 + m3.size()));  // UDP checksum 0: none
  b.insert(b.end(), m3.begin(), m3.end());
  return b;
}

// Frames a faulty line delivers: a bad FCS, a data length the type does not allow (valid
// FCS), fewer bytes than the data length says, and a data length over 64.
std::vector<Bytes> bad_frames() {
  Bytes bad_fcs = frame(FrameType::sync, kBroadcast, kC1Master, 8);
  bad_fcs.back() ^= 0x80;
  Bytes bad_len = frame(FrameType::cycle_notify, kBroadcast, kC1Master, 16);
  bad_len[3] = static_cast<std::uint8_t>(FrameType::sync);
  const std::uint32_t c = fcs(std::span(bad_len).first(bad_len.size() - kFcsSize));
  for (int i = 0; i < 4; ++i) bad_len[bad_len.size() - 4 + i] = static_cast<std::uint8_t>(c >> (8 * i));
  Bytes truncated = command48(FrameType::cyclic_command, 0x03, kC1Master, 0x3C, 0x00);
  truncated.resize(30);
  Bytes too_long = {0x03, kC1Master, 0x00, 0x02, 200, 1, 2, 3, 4};
  return {bad_fcs, bad_len, truncated, too_long};
}

// Writes every_type(), bad_frames() and one UDP datagram (a VELCTRL command) to `path`.
void write_session(const std::filesystem::path& path) {
  PcapWriter w(path.string());
  SimTime t = 0;
  for (const Sample& s : every_type()) w.write_frame(s.bytes, t += 10'000, s.dir);
  for (const Bytes& b : bad_frames()) w.write_frame(b, t += 10'000, Direction::out);
  w.write_ethernet(udp_datagram(frame(FrameType::cyclic_command, 0x03, kC1Master, 8, {0x3C})), t += 10'000,
                   Direction::out);
  ASSERT_TRUE(w.close()) << w.error();
}

std::string tshark(const std::filesystem::path& capture, const std::string& args) {
  return "tshark -X lua_script:" + omnitwin::testing::source_path("tools/wireshark/mechatrolink3.lua") + " -r " +
         capture.string() + " " + args;
}

TEST(M3Pcap, TsharkDecodesEveryFrameTypeCommandNamesAndBadFrames) {
  if (!have_tshark()) GTEST_SKIP() << "tshark is not installed";
  TempDir dir("m3-pcap");
  const auto path = dir / "session.pcap";
  write_session(path);
  const auto fields = run(tshark(path, "-T fields -E separator=/t -e frame.protocols -e m3.fcs.status "
                                       "-e _ws.col.Info 2>/dev/null"));
  ASSERT_TRUE(fields) << "tshark failed (is the Lua script loading?)";
  const auto lines = lines_of(*fields);
  const auto samples = every_type();
  ASSERT_EQ(lines.size(), samples.size() + bad_frames().size() + 1) << *fields;
  for (std::size_t i = 0; i < samples.size(); ++i) {
    SCOPED_TRACE(lines[i]);
    EXPECT_NE(lines[i].find("eth:ethertype:m3\t1\t" + samples[i].name + " "), std::string::npos);
  }
  EXPECT_NE(lines[0].find("DETECT C1 master → slave 1 seq 5"), std::string::npos) << lines[0];
  EXPECT_NE(lines[7].find("CMD C1 master → slave 1 seq 5 VELCTRL + SVPRM_RD"), std::string::npos) << lines[7];
  EXPECT_NE(lines[8].find("RSP slave 1 → C1 master seq 5 VELCTRL + SVPRM_RD"), std::string::npos) << lines[8];
  EXPECT_NE(lines[9].find("EVT_CMD C1 master → slave 2 seq 5 ID_RD"), std::string::npos) << lines[9];
  const std::size_t b = samples.size();
  EXPECT_NE(lines[b].find("\t0\tSYNC C1 master → broadcast seq 5 [bad FCS]"), std::string::npos) << lines[b];
  EXPECT_NE(lines[b + 1].find("\t1\tSYNC C1 master → broadcast seq 5 [bad data length]"), std::string::npos)
      << lines[b + 1];
  EXPECT_NE(lines[b + 2].find("[truncated]"), std::string::npos) << lines[b + 2];
  EXPECT_NE(lines[b + 3].find("[bad data length]"), std::string::npos) << lines[b + 3];
  EXPECT_NE(lines[b + 4].find("udp:m3\t1\tCMD C1 master → slave 1 seq 5 VELCTRL"), std::string::npos)
      << lines[b + 4];
}

TEST(M3Pcap, TsharkShowsBadFramesAsExpertErrorsNeverAsLuaErrorsOrMalformed) {
  if (!have_tshark()) GTEST_SKIP() << "tshark is not installed";
  TempDir dir("m3-pcap");
  const auto path = dir / "session.pcap";
  write_session(path);
  const auto tree = run(tshark(path, "-V 2>&1"));
  ASSERT_TRUE(tree) << "tshark failed";
  EXPECT_EQ(tree->find("Lua Error"), std::string::npos) << *tree;
  EXPECT_EQ(tree->find("Malformed"), std::string::npos) << *tree;
  EXPECT_NE(tree->find("Bad FCS 0x"), std::string::npos) << *tree;
  EXPECT_NE(tree->find("Command code: VELCTRL (0x3c)"), std::string::npos) << *tree;
  EXPECT_NE(tree->find("RCMD (command code echoed): VELCTRL (0x3c)"), std::string::npos) << *tree;
  // Exactly the four bad frames carry an error; the bad FCS is one of them.
  const auto errors = run(tshark(path, "-Y '_ws.expert.severity >= error' 2>/dev/null | wc -l"));
  ASSERT_TRUE(errors);
  EXPECT_EQ(*errors, "4\n");
  const auto fcs_bad = run(tshark(path, "-Y 'm3.fcs.bad' -T fields -e frame.number 2>/dev/null"));
  ASSERT_TRUE(fcs_bad);
  EXPECT_EQ(*fcs_bad, std::to_string(every_type().size() + 1) + "\n");
}

}  // namespace
}  // namespace omnitwin::m3
