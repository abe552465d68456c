// parallel_for_with_handoff (src/parallel/parallel_handoff.hpp): every index once, on the arena's threads,
// the calling thread taking part; an exception stops the loop and comes back once every task ended; loops
// nest.
#include "parallel/parallel_handoff.hpp"

#include <gtest/gtest.h>
#include <tbb/task_arena.h>

#include <atomic>
#include <chrono>
#include <cstddef>
#include <mutex>
#include <set>
#include <stdexcept>
#include <thread>
#include <vector>

#include "core/thread_cpu_time.hpp"

namespace loopgate {
namespace {

void spin_cpu_ns(std::int64_t ns) {
  const std::int64_t start_ns = thread_cpu_ns();
  while (thread_cpu_ns() - start_ns < ns) {
  }
}

TEST(ParallelHandoff, RunsEveryIndexOnceOnOneAndTwoThreads) {
  for (const int threads : {1, 2}) {
    tbb::task_arena arena(threads);
    for (const std::size_t count :
         {std::size_t{0}, std::size_t{1}, std::size_t{2}, std::size_t{3}, std::size_t{1000}}) {
      std::vector<std::atomic<int>> calls(count);
      arena.execute([&] { parallel_for_with_handoff(count, [&](std::size_t i) { calls[i].fetch_add(1); }); });
      for (std::size_t i = 0; i < count; ++i)
        ASSERT_EQ(calls[i].load(), 1) << "index " << i << " of " << count << ", " << threads << " thread(s)";
    }
  }
}

TEST(ParallelHandoff, UsesTheArenasThreadsAndTheCaller) {
  tbb::task_arena arena(2);
  std::mutex mutex;
  std::set<std::thread::id> threads;
  std::thread::id caller;
  arena.execute([&] {
    caller = std::this_thread::get_id();
    parallel_for_with_handoff(64, [&](std::size_t) {
      spin_cpu_ns(200'000);
      const std::lock_guard lock(mutex);
      threads.insert(std::this_thread::get_id());
    });
  });
  EXPECT_TRUE(threads.contains(caller));
  EXPECT_LE(threads.size(), 2U);
}

// The exception of one index comes back to the caller; no task is still running when it does, and the
// indices not yet started are not run.
TEST(ParallelHandoff, AnExceptionStopsTheLoopAndIsRethrownAfterEveryTaskEnded) {
  tbb::task_arena arena(2);
  std::atomic<int> running{0};
  std::atomic<int> ran{0};
  arena.execute([&] {
    EXPECT_THROW(parallel_for_with_handoff(10'000,
                                           [&](std::size_t i) {
                                             running.fetch_add(1);
                                             ran.fetch_add(1);
                                             spin_cpu_ns(20'000);
                                             running.fetch_sub(1);
                                             if (i == 5) throw std::runtime_error("index 5");
                                           }),
                 std::runtime_error);
  });
  EXPECT_EQ(running.load(), 0);
  EXPECT_LT(ran.load(), 10'000);
  EXPECT_GE(ran.load(), 6);
}

TEST(ParallelHandoff, LoopsNest) {
  tbb::task_arena arena(2);
  std::vector<std::atomic<int>> calls(16 * 16);
  arena.execute([&] {
    parallel_for_with_handoff(16, [&](std::size_t a) {
      parallel_for_with_handoff(16, [&](std::size_t b) { calls[a * 16 + b].fetch_add(1); });
    });
  });
  for (std::size_t k = 0; k < calls.size(); ++k) ASSERT_EQ(calls[k].load(), 1) << "index " << k;
}

}  // namespace
}  // namespace loopgate
