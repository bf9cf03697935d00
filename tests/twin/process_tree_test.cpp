// Tests twin/process_tree: the process table from /proc (this process and its parent in it,
// one entry read alone, none for a pid that cannot exist; its CPU time grows as it works) and
// the walks over it (descendants
// over generations without zombies; a pid taken again is another process).
#include "twin/process_tree.hpp"

#include <gtest/gtest.h>
#include <unistd.h>

#include <optional>
#include <vector>

namespace omnitwin::twin {
namespace {

TEST(ProcessTree, FindsDescendantsOverGenerationsWithoutZombiesOrStrangers) {
  const std::vector<ProcessEntry> all = {
      {10, 1, 'S', 100}, {11, 10, 'S', 101}, {12, 11, 'R', 102}, {13, 10, 'Z', 103}, {14, 1, 'S', 104}, {15, 13, 'S', 105}};
  std::vector<pid_t> found;
  for (const ProcessEntry& p : descendants_of(10, all)) found.push_back(p.pid);
  // 13 is a zombie: neither it nor what hangs under it in the table counts.
  EXPECT_EQ(found, (std::vector<pid_t>{11, 12}));
  EXPECT_TRUE(alive_in({12, 0, 0, 102}, all));
  EXPECT_FALSE(alive_in({12, 0, 0, 999}, all)) << "a pid taken again is another process";
  EXPECT_FALSE(alive_in({13, 0, 0, 103}, all)) << "a zombie is not alive";
  EXPECT_FALSE(alive_in({16, 0, 0, 106}, all));
}

TEST(ProcessTree, TheTableAndOneEntryHoldThisProcessAndItsParent) {
  const std::vector<ProcessEntry> all = process_table();
  bool self = false;
  for (const ProcessEntry& p : all)
    if (p.pid == ::getpid()) self = p.ppid == ::getppid() && p.start > 0;
  EXPECT_TRUE(self);
  // One entry alone: the same as the table's; none for a pid above the kernel's limit.
  const std::optional<ProcessEntry> me = process_entry(::getpid());
  ASSERT_TRUE(me.has_value());
  EXPECT_TRUE(alive_in(*me, all));
  EXPECT_FALSE(process_entry(1 << 23).has_value());
}

TEST(ProcessTree, AnEntrysCpuTimeGrowsAsTheProcessWorks) {
  const unsigned long long before = process_entry(::getpid())->cpu;
  const unsigned long long tick = static_cast<unsigned long long>(::sysconf(_SC_CLK_TCK));
  volatile unsigned long long sink = 0;
  // Work until the kernel has counted at least five more ticks, or 5 s of work.
  for (int round = 0; round < 5000 && process_entry(::getpid())->cpu < before + 5; ++round)
    for (int i = 0; i < 200000; ++i) sink = sink + static_cast<unsigned long long>(i);
  const unsigned long long after = process_entry(::getpid())->cpu;
  EXPECT_GE(after, before + 5) << "ticks of " << 1.0 / static_cast<double>(tick) << " s";
}

}  // namespace
}  // namespace omnitwin::twin
