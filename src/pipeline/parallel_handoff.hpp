// tbb::parallel_for with the hand-over to and from its tasks made explicit for ThreadSanitizer: the
// scheduler's own synchronisation lives in the uninstrumented oneTBB library, so TSan cannot see that a task
// starts after its spawner prepared the data and that the spawner resumes after every task finished. The
// spawner stores `handoff` with release before the loop and loads it with acquire after; each task loads it
// with acquire first and adds to it with release last (a release sequence, so the final acquire load
// synchronises with every task).
//
// The only access not covered is a task's read of the body object itself (two pointers TBB copied on the
// spawning thread); the TSan suppressions (sanitizer_suppressions.cpp) name this file for exactly that
// (race_top).
#pragma once

#include <tbb/parallel_for.h>

#include <atomic>
#include <cstddef>

namespace loopgate {

// Does nothing; calling it links src/pipeline/sanitizer_suppressions.cpp (the oneTBB suppressions of
// sanitizer builds) into the program.
void sanitizer_suppressions_anchor();

template <class Work>
struct HandoffBody {
  const Work* work;
  std::atomic<int>* handoff;
  void operator()(std::size_t index) const {
    static_cast<void>(handoff->load(std::memory_order_acquire));
    (*work)(index);
    handoff->fetch_add(1, std::memory_order_release);
  }
};

// Calls work(i) for i in [0, count), in parallel.
template <class Work>
void parallel_for_with_handoff(std::size_t count, const Work& work) {
  sanitizer_suppressions_anchor();
  std::atomic<int> handoff{0};
  handoff.store(1, std::memory_order_release);
  tbb::parallel_for(std::size_t{0}, count, HandoffBody<Work>{&work, &handoff});
  static_cast<void>(handoff.load(std::memory_order_acquire));
}

}  // namespace loopgate
