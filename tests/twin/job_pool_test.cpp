// Tests twin/job_pool: run_jobs calls every job once on up to N threads, starts none after the
// stop flag, and hands an exception a job lets out (on a worker or the caller's thread) back to
// the caller after every thread has ended, instead of ending the process.
#include "twin/job_pool.hpp"

#include <gtest/gtest.h>

#include <atomic>
#include <stdexcept>
#include <vector>

namespace omnitwin::twin {
namespace {

TEST(JobPool, EveryJobRunsOnce) {
  std::vector<std::atomic<int>> calls(100);
  run_jobs(calls.size(), 4, nullptr, [&](std::size_t i) { ++calls[i]; });
  for (const auto& c : calls) EXPECT_EQ(c.load(), 1);
}

TEST(JobPool, NoJobStartsAfterTheStop) {
  std::atomic<bool> stop{false};
  std::atomic<int> ran{0};
  run_jobs(100, 2, &stop, [&](std::size_t i) {
    ++ran;
    if (i == 3) stop = true;
  });
  EXPECT_LT(ran.load(), 10);
}

// A job that throws, on whichever thread: the exception reaches the caller once the pool has
// ended (a std::thread that lets one out calls std::terminate; found in review).
TEST(JobPool, AnExceptionOfAJobReachesTheCaller) {
  for (int jobs : {1, 2, 4}) {
    std::atomic<int> after{0};
    try {
      run_jobs(50, jobs, nullptr, [&](std::size_t i) {
        if (i == 5) throw std::runtime_error("job 5");
        if (i > 30) ++after;
      });
      ADD_FAILURE() << "no exception with " << jobs << " jobs";
    } catch (const std::runtime_error& e) {
      EXPECT_STREQ(e.what(), "job 5");
    }
    EXPECT_LT(after.load(), 20) << "jobs kept starting after the failure";
  }
}

}  // namespace
}  // namespace omnitwin::twin
