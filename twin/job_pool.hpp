// twin layer — N independent jobs on a few threads, for the commands that run many scenarios
// (`check`, `sweep`): each lockstep run is isolated on its own bus, so they may run at once.
// Not real-time code.
#pragma once

#include <algorithm>
#include <atomic>
#include <cstddef>
#include <thread>
#include <vector>

namespace omnitwin::twin {

// The number of jobs to run at once: `requested`, or the machine's cores when it is 0.
inline int jobs_or_cores(int requested) {
  return requested > 0 ? requested : std::max(1, static_cast<int>(std::thread::hardware_concurrency()));
}

// Calls job(i) for i = 0 … n−1 on up to `jobs` threads (the caller's among them), in order of i
// as threads free up; no new job starts once *stop is set. job must be safe to call
// concurrently for distinct i.
template <class Job>
void run_jobs(std::size_t n, int jobs, const std::atomic<bool>* stop, Job&& job) {
  std::atomic<std::size_t> next{0};
  const auto worker = [&] {
    for (std::size_t i = next++; i < n && !(stop && stop->load()); i = next++) job(i);
  };
  std::vector<std::thread> pool;
  for (int j = 1; j < std::min<int>(jobs, static_cast<int>(n)); ++j) pool.emplace_back(worker);
  worker();
  for (std::thread& t : pool) t.join();
}

}  // namespace omnitwin::twin
