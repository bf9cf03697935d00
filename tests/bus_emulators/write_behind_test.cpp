// Tests bus_emulators/write_behind: the FILE* whose bytes a thread of its own writes to disk.
// Every byte arrives in order through fwrite/commit/close; committed bytes reach the file
// within the writer's period without close, and only whole commits do (a reader never sees
// half a record); a write error (ENOSPC on /dev/full) shows at a later commit and at close; a
// path that cannot be opened gives false and errno; and the point of it all: a file whose
// writes block (a FIFO nobody reads) does not block the caller, which keeps writing at memory
// speed until close() waits for the reader.
#include "bus_emulators/write_behind.hpp"

#include <gtest/gtest.h>
#include <sys/stat.h>

#include <chrono>
#include <filesystem>
#include <fstream>
#include <sstream>
#include <string>
#include <thread>

#include "tests/support/eventually.hpp"
#include "tests/support/temp_dir.hpp"

namespace omnitwin::bus_emulators {
namespace {

using namespace std::chrono_literals;
using omnitwin::testing::eventually;

std::string slurp(const std::filesystem::path& p) {
  std::ifstream in(p, std::ios::binary);
  std::ostringstream s;
  s << in.rdbuf();
  return s.str();
}

// Line i of a deterministic text, so order and completeness can be checked.
std::string line(int i) { return "row " + std::to_string(i) + ",0.123456789,-42\n"; }

void put(WriteBehindFile& f, const std::string& text) {
  ASSERT_EQ(std::fwrite(text.data(), 1, text.size(), f.stream()), text.size());
}

TEST(WriteBehind, EveryByteArrivesInOrderAndFsyncOnCloseSucceeds) {
  omnitwin::testing::TempDir dir("omnitwin-wb");
  const auto path = dir / "a.csv";
  WriteBehindFile f;
  ASSERT_TRUE(f.open(path.string(), "wb", WriteBehindOptions{.fsync_on_close = true}));
  std::string expected;
  for (int i = 0; i < 200000; ++i) {  // ~5 MB: many hand-overs and periods
    put(f, line(i));
    expected += line(i);
    if (i % 1000 == 0) {
      ASSERT_TRUE(f.commit());
    }
  }
  ASSERT_EQ(f.close(), 0);
  EXPECT_FALSE(f.is_open());
  EXPECT_EQ(f.close(), 0);  // idempotent
  EXPECT_EQ(slurp(path), expected);
}

TEST(WriteBehind, CommittedBytesReachTheFileWithinThePeriodAndOnlyWholeCommits) {
  omnitwin::testing::TempDir dir("omnitwin-wb");
  const auto path = dir / "b.log";
  WriteBehindFile f;
  ASSERT_TRUE(f.open(path.string(), "wb", WriteBehindOptions{.period = 5ms}));
  std::setvbuf(f.stream(), nullptr, _IONBF, 0);  // every fwrite goes straight to staging
  put(f, "one event\n");
  ASSERT_TRUE(f.commit());
  EXPECT_TRUE(eventually([&] { return slurp(path) == "one event\n"; })) << slurp(path);
  // Half a record, not committed: it stays in memory however long one waits.
  put(f, "second ev");
  std::this_thread::sleep_for(50ms);  // ten periods
  EXPECT_EQ(slurp(path), "one event\n");
  put(f, "ent\n");
  ASSERT_TRUE(f.commit());
  EXPECT_TRUE(eventually([&] { return slurp(path) == "one event\nsecond event\n"; })) << slurp(path);
  ASSERT_EQ(f.close(), 0);
}

TEST(WriteBehind, AppendModeKeepsWhatIsThere) {
  omnitwin::testing::TempDir dir("omnitwin-wb");
  const auto path = dir / "c.txt";
  std::ofstream(path) << "first\n";
  WriteBehindFile f;
  ASSERT_TRUE(f.open(path.string(), "ab"));
  std::fputs("second\n", f.stream());
  ASSERT_EQ(f.close(), 0);
  EXPECT_EQ(slurp(path), "first\nsecond\n");
}

TEST(WriteBehind, AFullDiskShowsAtALaterCommitAndAtClose) {
  WriteBehindFile f;
  ASSERT_TRUE(f.open("/dev/full", "wb", WriteBehindOptions{.period = 1ms}));
  // The first bytes are accepted into memory; once the thread's write(2) failed, the next
  // commit says so with the system's code.
  errno = 0;
  EXPECT_TRUE(eventually([&] {
    std::fputs(line(1).c_str(), f.stream());
    return !f.commit();
  })) << "ENOSPC never reached the caller";
  EXPECT_EQ(errno, ENOSPC);
  errno = 0;
  EXPECT_EQ(f.close(), EOF);
  EXPECT_EQ(errno, ENOSPC);
}

TEST(WriteBehind, AnUnopenablePathGivesFalseAndErrno) {
  WriteBehindFile f;
  errno = 0;
  EXPECT_FALSE(f.open("/nonexistent-omnitwin-dir/x.csv", "wb"));
  EXPECT_EQ(errno, ENOENT);
  EXPECT_FALSE(f.is_open());
  EXPECT_EQ(f.stream(), nullptr);
  EXPECT_FALSE(f.commit());
}

TEST(WriteBehind, AFileThatBlocksDoesNotBlockTheCaller) {
  omnitwin::testing::TempDir dir("omnitwin-wb");
  const auto fifo = dir / "stalled";
  ASSERT_EQ(::mkfifo(fifo.c_str(), 0600), 0);
  // A reader that does not read yet: the pipe holds 64 KiB, then write(2) blocks.
  const int rd = ::open(fifo.c_str(), O_RDONLY | O_NONBLOCK);
  ASSERT_GE(rd, 0);
  WriteBehindFile f;
  ASSERT_TRUE(f.open(fifo.string(), "wb"));
  std::string expected;
  const auto t0 = std::chrono::steady_clock::now();
  for (int i = 0; i < 40000; ++i) {  // ~1 MB, 16× what the pipe holds
    put(f, line(i));
    ASSERT_TRUE(f.commit());
    expected += line(i);
  }
  const double caller_s = std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count();
  // Plain stdio would block here until someone reads; write-behind took it into memory.
  EXPECT_LT(caller_s, 2.0);
  // Now read everything while close() waits for the writer thread to deliver it.
  std::string got;
  std::thread reader([&] {
    ::fcntl(rd, F_SETFL, 0);  // blocking from here
    char buf[65536];
    for (;;) {
      const ssize_t n = ::read(rd, buf, sizeof buf);
      if (n <= 0) break;  // end of file once the writer closed
      got.append(buf, static_cast<std::size_t>(n));
    }
  });
  EXPECT_EQ(f.close(), 0);
  reader.join();
  ::close(rd);
  EXPECT_EQ(got.size(), expected.size());
  EXPECT_TRUE(got == expected);
}

}  // namespace
}  // namespace omnitwin::bus_emulators
