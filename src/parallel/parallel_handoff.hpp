// tbb::parallel_for with the hand-over to and from its tasks made explicit for ThreadSanitizer: the
// scheduler's own synchronisation lives in the uninstrumented oneTBB library, so TSan cannot see that a task
// starts after its spawner prepared the data and that the spawner resumes after every task finished. The
// spawner stores `handoff` with release before the loop and loads it with acquire after; each task loads it
// with acquire first and adds to it with release last (a release sequence, so the final acquire load
// synchronises with every task).
//
// The only access not covered is a task's read of the body object itself (one pointer TBB copied on the
// spawning thread); the TSan suppressions (src/sanitizer_suppressions.cpp) name this file for exactly that
// (race_top).
//
// Time accounting: a loop started while a ParallelTimeScope is active on the calling thread adds to the
// scope's counter the CPU time that *other* threads spent in its tasks (the caller's own share is in the
// caller's CPU time already), so that a node body's work is its own thread's CPU time plus that counter.
#pragma once

#include <tbb/parallel_for.h>

#include <atomic>
#include <cstddef>
#include <cstdint>
#include <thread>

#include "core/thread_cpu_time.hpp"

namespace loopgate {

// The counter that parallel loops started on this thread add their helpers' CPU time to, ns (nullptr: none).
inline thread_local std::atomic<std::int64_t>* t_parallel_time_ns = nullptr;

// Sets the calling thread's counter for its lifetime (the pipeline: one per node body), restoring the
// previous one (a thread waiting in a loop may run another node's body meanwhile).
class ParallelTimeScope {
 public:
  explicit ParallelTimeScope(std::atomic<std::int64_t>* counter_ns) : previous_(t_parallel_time_ns) {
    t_parallel_time_ns = counter_ns;
  }
  ~ParallelTimeScope() { t_parallel_time_ns = previous_; }
  ParallelTimeScope(const ParallelTimeScope&) = delete;
  ParallelTimeScope& operator=(const ParallelTimeScope&) = delete;

 private:
  std::atomic<std::int64_t>* previous_;
};

// What the tasks of one loop share, written by the spawner before its release store of `handoff`. The body
// that TBB copies holds only the pointer to it: that pointer is the one read TSan cannot order (suppressed by
// naming this file), and every other read comes after the task's acquire load.
template <class Work>
struct HandoffShared {
  const Work* work;
  std::thread::id caller;
  std::atomic<std::int64_t>* helpers_ns;  // nullptr: not timed
  std::atomic<int> handoff{0};
};

template <class Work>
struct HandoffBody {
  HandoffShared<Work>* shared;
  void operator()(std::size_t index) const {
    HandoffShared<Work>& s = *shared;
    static_cast<void>(s.handoff.load(std::memory_order_acquire));
    if (s.helpers_ns != nullptr && std::this_thread::get_id() != s.caller) {
      const std::int64_t start_ns = thread_cpu_ns();
      (*s.work)(index);
      s.helpers_ns->fetch_add(thread_cpu_ns() - start_ns, std::memory_order_relaxed);
    } else {
      (*s.work)(index);
    }
    s.handoff.fetch_add(1, std::memory_order_release);
  }
};

// Calls work(i) for i in [0, count), in parallel.
template <class Work>
void parallel_for_with_handoff(std::size_t count, const Work& work) {
  HandoffShared<Work> shared{&work, std::this_thread::get_id(), t_parallel_time_ns};
  shared.handoff.store(1, std::memory_order_release);
  tbb::parallel_for(std::size_t{0}, count, HandoffBody<Work>{&shared});
  static_cast<void>(shared.handoff.load(std::memory_order_acquire));
}

}  // namespace loopgate
