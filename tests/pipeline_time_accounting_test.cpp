// The time accounting's booking (pipeline/time_accounting.hpp): images read inside describe move from
// describe to decode and similarities computed there to match, the odometry's image preparation in decode
// goes to rest (the odometry's part), parallel helpers' CPU time joins their stage,
// the method's end-of-stream work is match and the rest of the end of the stream is rest; the parts add up to
// the total, which holds every stage's time; and parallel loops report their helpers' CPU time.
#include <gtest/gtest.h>
#include <tbb/task_arena.h>

#include <atomic>
#include <chrono>
#include <mutex>
#include <set>
#include <thread>

#include "parallel/parallel_handoff.hpp"
#include "pipeline/outputs/time_accounting.hpp"

namespace loopgate {
namespace {

TEST(TimeAccounting, BooksEachKindOfWorkOnce) {
  StageTimes m;
  m.cpu_ms = {1.0, 10.0, 3.0, 2.0, 40.0, 20.0, 4.0};  // sync decode odometry gate describe match sink
  m.parallel_ms[kDescribe] = 15.0;
  m.parallel_ms[kMatch] = 5.0;
  m.decode_in_describe_ms = 12.0;
  m.match_in_describe_ms = 7.0;
  m.odometry_in_decode_ms = 0.5;             // the odometry's image pyramid, built in the decode node
  const EndOfStreamTime end{6.0, 2.5, 3.0};  // the method's finish: 6 ms + 2.5 ms on helpers; 3 ms after it
  const TimeParts t = account_time(m, end);
  EXPECT_DOUBLE_EQ(t.decode_ms, 10.0 - 0.5 + 12.0);
  EXPECT_DOUBLE_EQ(t.describe_ms, 40.0 + 15.0 - 12.0 - 7.0);
  EXPECT_DOUBLE_EQ(t.match_ms, 20.0 + 5.0 + 7.0 + 6.0 + 2.5);
  EXPECT_DOUBLE_EQ(t.rest_ms, 1.0 + 3.0 + 0.5 + 2.0 + 4.0 + 3.0);
  EXPECT_DOUBLE_EQ(t.odometry_in_decode_ms, 0.5);
  EXPECT_DOUBLE_EQ(t.total_ms, t.decode_ms + t.describe_ms + t.match_ms + t.rest_ms);
  EXPECT_DOUBLE_EQ(t.total_ms, 80.0 + 20.0 + 6.0 + 2.5 + 3.0);  // stages + helpers + end of stream
  EXPECT_DOUBLE_EQ(t.parallel_ms, 22.5);
  EXPECT_DOUBLE_EQ(t.decode_in_describe_ms, 12.0);
  const auto json = time_accounting_json(m, end);
  EXPECT_DOUBLE_EQ(json["total_ms"].get<double>(), t.total_ms);
  EXPECT_DOUBLE_EQ(json["stages_cpu_ms"]["describe"].get<double>(), 40.0);
  EXPECT_DOUBLE_EQ(json["end_of_stream_cpu_ms"].get<double>(), 9.0);
  EXPECT_TRUE(json.contains("unit"));
  // A frame's parts (no end of stream), and the sum over frames.
  StageTimes sum = m;
  sum += m;
  EXPECT_DOUBLE_EQ(account_time(sum).total_ms, 2 * account_time(m).total_ms);
}

// A frame record's measurements in ms.
TEST(TimeAccounting, StageTimesOfAFrame) {
  FrameRecord r;
  r.cpu_ns[kDescribe] = 2'000'000;
  r.parallel_cpu_ns[kDescribe].store(500'000);
  r.reread_cpu_ns.store(250'000);
  r.match_in_describe_cpu_ns = 1'000'000;
  r.cpu_ns[kDecode] = 3'000'000;
  r.odometry_in_decode_cpu_ns = 1'000'000;
  const StageTimes t = stage_times(r);
  EXPECT_DOUBLE_EQ(t.odometry_in_decode_ms, 1.0);
  EXPECT_DOUBLE_EQ(t.cpu_ms[kDescribe], 2.0);
  EXPECT_DOUBLE_EQ(t.parallel_ms[kDescribe], 0.5);
  EXPECT_DOUBLE_EQ(t.decode_in_describe_ms, 0.25);
  EXPECT_DOUBLE_EQ(t.match_in_describe_ms, 1.0);
  EXPECT_DOUBLE_EQ(account_time(t).describe_ms, 1.25);
  EXPECT_DOUBLE_EQ(account_time(t).match_ms, 1.0);
  EXPECT_DOUBLE_EQ(account_time(t).decode_ms, 3.0 - 1.0 + 0.25);
  EXPECT_DOUBLE_EQ(account_time(t).rest_ms, 1.0);
}

// A loop started inside a ParallelTimeScope adds to its counter exactly the time of the tasks other threads
// ran (none when the caller ran them all); outside a scope nothing is counted, and the scope restores the
// previous counter.
TEST(TimeAccounting, ParallelLoopsCountTheirHelpersTime) {
  tbb::task_arena arena(2);
  std::atomic<std::int64_t> outer_ns{0}, counted_ns{0};
  std::mutex mutex;
  std::set<std::thread::id> threads;
  std::thread::id caller;
  arena.execute([&] {
    caller = std::this_thread::get_id();
    const ParallelTimeScope outer(&outer_ns);
    {
      const ParallelTimeScope scope(&counted_ns);
      parallel_for_with_handoff(64, [&](std::size_t) {
        // CPU work (a sleep would take no CPU time): ~0.1 ms.
        const std::int64_t start_ns = thread_cpu_ns();
        while (thread_cpu_ns() - start_ns < 100'000) {
        }
        const std::lock_guard lock(mutex);
        threads.insert(std::this_thread::get_id());
      });
    }
    EXPECT_EQ(t_parallel_time_ns, &outer_ns);
  });
  EXPECT_EQ(outer_ns.load(), 0);
  if (threads.size() > 1) {
    EXPECT_GT(counted_ns.load(), 0);
  } else {
    ASSERT_EQ(*threads.begin(), caller);
    EXPECT_EQ(counted_ns.load(), 0);
  }
  EXPECT_EQ(t_parallel_time_ns, nullptr);
  std::atomic<int> calls{0};
  parallel_for_with_handoff(8, [&](std::size_t) { calls.fetch_add(1); });  // no scope: nothing to count
  EXPECT_EQ(calls.load(), 8);
}

}  // namespace
}  // namespace loopgate
