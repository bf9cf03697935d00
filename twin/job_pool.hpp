// twin layer — N independent jobs on a few threads, for the commands that run many scenarios
// (`check`, `sweep`): each lockstep run is isolated on its own bus, so they may run at once.
// Not real-time code.
#pragma once

#include <algorithm>
#include <atomic>
#include <cstddef>
#include <exception>
#include <mutex>
#include <thread>
#include <vector>

namespace omnitwin::twin {

// The number of jobs to run at once: `requested`, or the machine's cores when it is 0.
inline int jobs_or_cores(int requested) {
  return requested > 0 ? requested : std::max(1, static_cast<int>(std::thread::hardware_concurrency()));
}

// Calls job(i) for i = 0 … n−1 on up to `jobs` threads (the caller's among them), in order of i
// as threads free up; no new job starts once *stop is set. job must be safe to call
// concurrently for distinct i. An exception a job lets out stops further jobs and is rethrown
// here once every thread has ended (the first one; an exception leaving a std::thread, or the
// caller's leaving with threads unjoined, would end the process).
template <class Job>
void run_jobs(std::size_t n, int jobs, const std::atomic<bool>* stop, Job&& job) {
  std::atomic<std::size_t> next{0};
  std::atomic<bool> failed{false};
  std::exception_ptr first;
  std::mutex first_mutex;
  const auto worker = [&] {
    try {
      for (std::size_t i = next++; i < n && !(stop && stop->load()) && !failed; i = next++) job(i);
    } catch (...) {
      const std::lock_guard lock(first_mutex);
      if (!first) first = std::current_exception();
      failed = true;
    }
  };
  std::vector<std::thread> pool;
  for (int j = 1; j < std::min<int>(jobs, static_cast<int>(n)); ++j) pool.emplace_back(worker);
  worker();
  for (std::thread& t : pool) t.join();
  if (first) std::rethrow_exception(first);
}

}  // namespace omnitwin::twin
