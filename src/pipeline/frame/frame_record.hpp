// What travels through the graph: one FrameRecord per released frame, owned by the run (created by the
// producer, destroyed by the sink), and the stage names the profiler and the trace use.
#pragma once

#include <array>
#include <atomic>
#include <cstddef>
#include <cstdint>
#include <memory>
#include <opencv2/core/mat.hpp>
#include <string>
#include <vector>

#include "core/types.hpp"
#include "stages/odometry/odometry_source.hpp"
#include "stages/sync/imu_sync.hpp"

namespace loopgate {

enum Stage : std::size_t { kSync, kDecode, kOdometry, kGate, kDescribe, kMatch, kSink, kStageCount };
constexpr std::array<const char*, kStageCount> kStageNames = {"sync",     "decode", "odometry", "gate",
                                                              "describe", "match",  "sink"};

struct StageStamp {
  std::int64_t enter_ns = 0;
  std::int64_t exit_ns = 0;
  int thread = -1;
};

struct FrameRecord {
  std::uint64_t seq = 0;  // contiguous over the released frames
  std::size_t frame = 0;  // dataset frame index
  std::size_t label = 0;  // the frame's number in the outputs (SeqIndex::label)
  Timestamp t_ns = 0;
  std::int64_t release_ns = 0;   // run clock
  std::int64_t deadline_ns = 0;  // 0: no deadline (rate max)
  SyncedImu imu;
  bool imu_synced = false;
  bool needs_pixels = false;  // decode this frame now (decided by sync)
  bool decoded = false;
  cv::Mat image;
  // The odometry source's per-image work (OdometrySource::prepare), done in the decode node and handed to
  // the odometry node, which drops it; its thread CPU time, booked as odometry (time_accounting.hpp).
  std::shared_ptr<const PreparedImage> prepared;
  std::int64_t odometry_in_decode_cpu_ns = 0;
  OdometryOutput odometry;
  bool has_pose = false;
  std::vector<std::string> warnings;
  std::vector<std::string> errors;
  std::array<StageStamp, kStageCount> stamps{};
  // The run's time accounting (time_accounting.hpp), in thread CPU time: each node body's on its thread
  // (written by the body), other threads' in the parallel loops of the body (parallel_handoff.hpp), and the
  // images decoded inside this frame's describe (past frames read again, or its own image when decode did not
  // read it), summed over the threads that read them; and the similarities computed inside its describe
  // (full DIRD computes most of a row there, where rows run in parallel), which are matching.
  std::array<std::int64_t, kStageCount> cpu_ns{};
  std::array<std::atomic<std::int64_t>, kStageCount> parallel_cpu_ns{};
  std::atomic<std::int64_t> reread_cpu_ns{0};
  std::int64_t match_in_describe_cpu_ns = 0;

  // A pose the odometry estimated for this frame, which the gate, the loop closer and trajectory.tum use:
  // status tracking. An initialising source reports the identity until it has a state, and a lost frame
  // carries the last good pose: neither is an estimate of this frame.
  bool usable_pose() const { return has_pose && odometry.pose.status == OdometryStatus::kTracking; }

  // The hand-over between nodes goes through TBB's scheduler, whose synchronisation ThreadSanitizer
  // cannot see (uninstrumented library); each node body starts with acquire() and ends with release()
  // so that the happens-before edge is explicit (it also orders what a body wrote elsewhere, e.g. a
  // method's per-frame state).
  mutable std::atomic<int> handoff{0};
  void acquire() const { static_cast<void>(handoff.load(std::memory_order_acquire)); }
  void release() const { handoff.fetch_add(1, std::memory_order_release); }
};

// Messages carry the sequence number by value (the sequencers read it without touching the record).
struct FrameMsg {
  std::uint64_t seq = 0;
  FrameRecord* record = nullptr;
};

// Where each sequence number's frame is: written by the producer before the frame is released
// (preallocated for every frame the run may release), read by any stage after that.
// frame(): the dataset frame index (what the dataset is asked for); label(): the frame's number in the
// outputs, its identity in the dataset (Dataset::source_index: the KITTI image number, the EuRoC data row),
// which a rejected input row does not shift. Both are equal unless rows were rejected or the
// dataset is a subset folder.
class SeqIndex {
 public:
  explicit SeqIndex(std::size_t capacity) : frame_(capacity), label_(capacity), t_ns_(capacity) {}
  void set(std::size_t seq, std::size_t frame, Timestamp t_ns, std::size_t label) {
    frame_.at(seq) = frame;
    label_.at(seq) = label;
    t_ns_.at(seq) = t_ns;
  }
  void set(std::size_t seq, std::size_t frame, Timestamp t_ns) { set(seq, frame, t_ns, frame); }
  std::size_t frame(std::int64_t seq) const { return frame_.at(static_cast<std::size_t>(seq)); }
  std::size_t label(std::int64_t seq) const { return label_.at(static_cast<std::size_t>(seq)); }
  Timestamp t_ns(std::int64_t seq) const { return t_ns_.at(static_cast<std::size_t>(seq)); }
  std::size_t capacity() const { return frame_.size(); }

 private:
  std::vector<std::size_t> frame_;
  std::vector<std::size_t> label_;
  std::vector<Timestamp> t_ns_;
};

}  // namespace loopgate
