// Process resources of a run (CPU time, peak RSS), a small stable thread index for the trace, and the
// observer that lets the run wait until every TBB worker has left its arena before the graph is torn down.
#pragma once

#include <sys/resource.h>
#include <tbb/task_arena.h>
#include <tbb/task_scheduler_observer.h>

#include <atomic>
#include <chrono>
#include <thread>

namespace loopgate {

inline constexpr auto kWorkerLeaveTimeout = std::chrono::milliseconds(2000);

inline int thread_index() {  // small stable index per thread, for the trace tracks
  static std::atomic<int> next{0};
  thread_local const int index = next.fetch_add(1);
  return index;
}

inline double cpu_seconds() {
  rusage usage{};
  ::getrusage(RUSAGE_SELF, &usage);
  const auto seconds = [](const timeval& tv) {
    return static_cast<double>(tv.tv_sec) + 1e-6 * static_cast<double>(tv.tv_usec);
  };
  return seconds(usage.ru_utime) + seconds(usage.ru_stime);
}

inline double peak_rss_mb() {
  rusage usage{};
  ::getrusage(RUSAGE_SELF, &usage);
  return static_cast<double>(usage.ru_maxrss) / 1024.0;  // KiB on Linux
}

// Counts the worker threads inside the arena: before the graph is torn down the run waits until every worker
// left, so that the acquire of the last exit orders what the workers did (visibly for ThreadSanitizer too).
inline std::atomic<int> g_workers_inside{0};

class WorkerExitObserver : public tbb::task_scheduler_observer {
 public:
  explicit WorkerExitObserver(tbb::task_arena& arena) : tbb::task_scheduler_observer(arena) { observe(true); }
  ~WorkerExitObserver() override { observe(false); }
  void on_scheduler_entry(bool is_worker) override {
    if (is_worker) g_workers_inside.fetch_add(1, std::memory_order_acq_rel);
  }
  void on_scheduler_exit(bool is_worker) override {
    if (is_worker) g_workers_inside.fetch_sub(1, std::memory_order_acq_rel);
  }
  bool wait_until_all_left(std::chrono::milliseconds timeout) const {
    const auto deadline = std::chrono::steady_clock::now() + timeout;
    while (g_workers_inside.load(std::memory_order_acquire) > 0) {
      if (std::chrono::steady_clock::now() > deadline) return false;
      std::this_thread::sleep_for(std::chrono::microseconds(200));
    }
    return true;
  }
};

}  // namespace loopgate
