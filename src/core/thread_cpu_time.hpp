// The calling thread's CPU time (CLOCK_THREAD_CPUTIME_ID), the unit of the run's time accounting
// (time_accounting.hpp): unlike wall time it does not grow while the thread waits or is preempted by other
// processes on a loaded machine.
#pragma once

#include <time.h>

#include <cstdint>

namespace loopgate {

inline std::int64_t thread_cpu_ns() {
  timespec ts{};
  ::clock_gettime(CLOCK_THREAD_CPUTIME_ID, &ts);
  return static_cast<std::int64_t>(ts.tv_sec) * 1'000'000'000 + ts.tv_nsec;
}

}  // namespace loopgate
