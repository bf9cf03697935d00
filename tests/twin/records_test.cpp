// Tests the record writers (twin/records.cpp): CSV bytes are exact and deterministic, the
// CSV and JSON files appear under their final names only when complete (temp + rename),
// the event log is line-formatted and flushed per line, and unwritable places or a full
// disk give a std::runtime_error naming the path.
#include <gtest/gtest.h>
#include <unistd.h>

#include <chrono>
#include <cmath>
#include <filesystem>
#include <fstream>
#include <sstream>
#include <vector>

#include "tests/support/eventually.hpp"
#include "twin/records.hpp"

namespace omnitwin::twin {
namespace {

namespace fs = std::filesystem;

std::string read_all(const fs::path& p) {
  std::ifstream in(p, std::ios::binary);
  std::stringstream ss;
  ss << in.rdbuf();
  return ss.str();
}

// A fresh directory under /tmp per test, removed afterwards.
class RecordsTest : public ::testing::Test {
 protected:
  void SetUp() override {
    const auto* info = ::testing::UnitTest::GetInstance()->current_test_info();
    dir_ = fs::temp_directory_path() /
           ("omnitwin_records_" + std::to_string(::getpid()) + "_" + info->name());
    fs::remove_all(dir_);
    fs::create_directories(dir_);
  }
  void TearDown() override { fs::remove_all(dir_); }

  fs::path dir_;
};

TEST_F(RecordsTest, CsvBytesAreExact) {
  {
    CsvWriter csv(dir_.string(), "trajectory.csv", {"t", "x", "y"});
    csv.row(std::vector<double>{0, 1.5, -2});
    csv.row(std::vector<double>{0.1, 1.0 / 3.0, 1e-12});
    csv.row(std::vector<double>{1234567890123.0, -0.000125, 42});
    EXPECT_EQ(csv.rows(), 3u);
    csv.close();
  }
  EXPECT_EQ(read_all(dir_ / "trajectory.csv"),
            "t,x,y\n"
            "0,1.5,-2\n"
            "0.1,0.3333333333,1e-12\n"
            "1.23456789e+12,-0.000125,42\n");
}

// The writer thread formats the rows (CsvEncoder) from 64 KiB hand-overs that end wherever
// stdio cut its buffer, so most rows arrive in two pieces: every line must still be the
// printf "%.10g" of its values, in order, with nothing lost or doubled.
TEST_F(RecordsTest, CsvRowsSplitAcrossHandOversAreFormattedWhole) {
  std::string expected = "t,a,b\n";
  {
    CsvWriter csv(dir_.string(), "long.csv", {"t", "a", "b"});
    char line[128];
    for (int i = 0; i < 60000; ++i) {  // 1.5 MB staged: about 23 hand-overs
      const double v[3] = {i * 0.001, std::sin(i * 0.37) * 1e3, 1.0 / (i + 3)};
      ASSERT_TRUE(csv.row(std::span<const double>(v, 3)));
      std::snprintf(line, sizeof line, "%.10g,%.10g,%.10g\n", v[0], v[1], v[2]);
      expected += line;
    }
    csv.close();
  }
  EXPECT_TRUE(read_all(dir_ / "long.csv") == expected);
  EXPECT_EQ(read_all(dir_ / "long.csv").size(), expected.size());
}

TEST_F(RecordsTest, CsvIdenticalInputsGiveIdenticalBytes) {
  for (const char* name : {"a.csv", "b.csv"}) {
    CsvWriter csv(dir_.string(), name, {"t", "v"});
    for (int i = 0; i < 100; ++i) csv.row(std::vector<double>{i * 0.01, std::sin(i * 0.1)});
  }
  EXPECT_EQ(read_all(dir_ / "a.csv"), read_all(dir_ / "b.csv"));
  EXPECT_FALSE(read_all(dir_ / "a.csv").empty());
}

TEST_F(RecordsTest, CsvLivesUnderTempNameUntilClose) {
  CsvWriter csv(dir_.string(), "trajectory.csv", {"t"});
  csv.row(std::vector<double>{1});
  csv.flush();
  EXPECT_TRUE(fs::exists(dir_ / ".trajectory.csv.part"));
  EXPECT_FALSE(fs::exists(dir_ / "trajectory.csv"));
  csv.close();
  EXPECT_FALSE(fs::exists(dir_ / ".trajectory.csv.part"));
  EXPECT_EQ(read_all(dir_ / "trajectory.csv"), "t\n1\n");
  csv.close();  // idempotent
}

TEST_F(RecordsTest, CsvTakesAWholePathToo) {
  {
    CsvWriter csv((dir_ / "p.csv").string(), {"a"});
    csv.row(std::vector<double>{-0.5});
  }
  EXPECT_EQ(read_all(dir_ / "p.csv"), "a\n-0.5\n");
}

TEST_F(RecordsTest, CsvDestructorRenames) {
  { CsvWriter csv(dir_.string(), "x.csv", {"a", "b"}); }
  EXPECT_EQ(read_all(dir_ / "x.csv"), "a,b\n");
  EXPECT_FALSE(fs::exists(dir_ / ".x.csv.part"));
}

TEST_F(RecordsTest, CsvHeaderCellsAreQuotedWhenNeeded) {
  { CsvWriter csv(dir_.string(), "q.csv", {"x,y", "say \"hi\""}); }
  EXPECT_EQ(read_all(dir_ / "q.csv"), "\"x,y\",\"say \"\"hi\"\"\"\n");
}

TEST_F(RecordsTest, CsvRowWidthMustMatchHeader) {
  CsvWriter csv(dir_.string(), "w.csv", {"a", "b"});
  EXPECT_THROW(csv.row(std::vector<double>{1}), std::invalid_argument);
}

TEST_F(RecordsTest, UnwritableDirectoryNamesThePath) {
  const std::string missing = (dir_ / "no" / "such" / "dir").string();
  try {
    CsvWriter csv(missing, "t.csv", {"a"});
    FAIL() << "no error";
  } catch (const std::runtime_error& e) {
    EXPECT_NE(std::string(e.what()).find(missing), std::string::npos) << e.what();
  }
  // A regular file where the directory should be.
  std::ofstream(dir_ / "plain").put('x');
  EXPECT_THROW(CsvWriter((dir_ / "plain").string(), "t.csv", {"a"}), std::runtime_error);
  EXPECT_THROW(EventLog((dir_ / "plain" / "events.log").string()), std::runtime_error);
  EXPECT_THROW(write_json_atomic((dir_ / "plain" / "m.json").string(), {{"a", 1}}), std::runtime_error);
}

TEST_F(RecordsTest, FullDiskIsAnError) {
  // /dev/full accepts the open and fails every write with ENOSPC once data reaches it.
  if (!fs::exists("/dev/full")) GTEST_SKIP() << "no /dev/full";
  CheckedFile f("/dev/full", "wb");
  f.write("some bytes");
  try {
    f.flush();
    FAIL() << "flush to /dev/full succeeded";
  } catch (const std::runtime_error& e) {
    EXPECT_NE(std::string(e.what()).find("/dev/full"), std::string::npos) << e.what();
  }
  EXPECT_TRUE(f.failed());
}

TEST_F(RecordsTest, JsonIsPrettyAndAtomic) {
  const nlohmann::json j = {{"scenario", "thesis_line"}, {"platform", {{"iae_x_cm", 1.5}}}};
  const fs::path p = dir_ / "metrics.json";
  std::ofstream(p) << "old";
  write_json_atomic(p.string(), j);
  EXPECT_EQ(read_all(p), j.dump(2) + "\n");
  EXPECT_EQ(nlohmann::json::parse(read_all(p)), j);
  EXPECT_FALSE(fs::exists(dir_ / ".metrics.json.part"));
  EXPECT_NE(read_all(p).find("\n  \"platform\": {\n    \"iae_x_cm\": 1.5\n  }"), std::string::npos);
}

TEST_F(RecordsTest, EventLogLinesAndPerLineFlush) {
  EventLog log((dir_ / "events.log").string());
  log.log(1.5, "fault", "wheel 2 slips");
  // Readable before close under its temporary name (every line is committed and reaches the
  // file within the write-behind period); the final name appears only when it is complete.
  const std::string first = "    1.500000  fault       wheel 2 slips\n";
  EXPECT_TRUE(omnitwin::testing::eventually([&] { return read_all(dir_ / ".events.log.part") == first; }))
      << read_all(dir_ / ".events.log.part");
  EXPECT_FALSE(fs::exists(dir_ / "events.log"));
  log.log(12.25, "expectation", "line one\nline two");
  log.close();
  EXPECT_EQ(read_all(dir_ / "events.log"),
            "    1.500000  fault       wheel 2 slips\n"
            "   12.250000  expectation  line one line two\n");
  EXPECT_EQ(log.path(), (dir_ / "events.log").string());
}

}  // namespace
}  // namespace omnitwin::twin

namespace omnitwin::twin {
namespace {

// On the run's cyclic path a full disk is a status, not an exception: row() and log()
// return false with the reason, the CSV is never renamed to its final name, and close()
// says it was left incomplete. The temp file is made a link to /dev/full (ENOSPC on write).
TEST(RecordsFullDisk, RowAndLogReturnFalseAndTheCsvIsNeverPublished) {
  if (!std::filesystem::exists("/dev/full")) GTEST_SKIP() << "no /dev/full on this machine";
  const std::filesystem::path dir =
      std::filesystem::temp_directory_path() / ("omnitwin-full-" + std::to_string(::getpid()));
  std::filesystem::create_directories(dir);
  std::filesystem::create_symlink("/dev/full", dir / ".t.csv.part");
  {
    CsvWriter csv((dir / "t.csv").string(), {"a", "b"});
    // Write-behind: rows reach the writer thread in 64 KiB hand-overs; its first write meets
    // ENOSPC, and a later row reports it.
    bool ok = true;
    const auto deadline = std::chrono::steady_clock::now() + std::chrono::seconds(5);
    for (int i = 0; ok && std::chrono::steady_clock::now() < deadline; ++i)
      ok = csv.row(std::vector<double>{i * 0.5, -1.0 / 3.0});
    EXPECT_FALSE(ok) << "writes to /dev/full never failed";
    EXPECT_NE(csv.error().find("t.csv"), std::string::npos) << csv.error();
    EXPECT_THROW(csv.close(), std::runtime_error);
  }
  EXPECT_FALSE(std::filesystem::exists(dir / "t.csv"));
  std::filesystem::create_symlink("/dev/full", dir / ".events.log.part");
  {
    EventLog log((dir / "events.log").string());
    // Write-behind: the writer thread meets ENOSPC within its period, a later line reports it.
    EXPECT_TRUE(omnitwin::testing::eventually([&] { return !log.log(1.0, "start", "x"); }));
    EXPECT_FALSE(log.error().empty());
    EXPECT_THROW(log.close(), std::runtime_error);
  }
  EXPECT_FALSE(std::filesystem::exists(dir / "events.log"));
  std::filesystem::remove_all(dir);
}

}  // namespace
}  // namespace omnitwin::twin
