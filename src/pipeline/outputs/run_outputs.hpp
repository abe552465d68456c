// The sink's outputs: frames.csv (one row per frame, in order; a detecting run holds a row until its
// method's detection of the frame is final), trajectory.tum, timing.csv (a column per stage), the profiler,
// the trace events and the progress line, plus the counters. Serial: the sink calls sink(), then the run
// calls finish() after the drain.
#pragma once

#include <array>
#include <cstdint>
#include <deque>
#include <filesystem>
#include <functional>
#include <optional>
#include <string>
#include <vector>

#include "io/writers.hpp"
#include "pipeline/frame/csv_row.hpp"
#include "pipeline/frame/frame_record.hpp"
#include "pipeline/frame/run_clock.hpp"
#include "pipeline/loops/loop_closer.hpp"
#include "pipeline/methods/detection_method.hpp"
#include "pipeline/outputs/run_counters.hpp"
#include "pipeline/outputs/stage_profiler.hpp"
#include "pipeline/outputs/time_accounting.hpp"

namespace loopgate {

class RunOutputs {
 public:
  // `visual_odometry`: frames.csv gets tracked_features; `total_frames`: for the progress line.
  RunOutputs(const PipelineConfig& config, const std::filesystem::path& out_dir, DetectionMethod& method,
             const SeqIndex& seqs, const RunClock& clock, bool visual_odometry, std::size_t total_frames,
             const LoopCloser* closer = nullptr, bool keep_step_cov = false);

  void open();
  // Called by the sink with the dataset frame of every held row whose detection became final, in order
  // (gate.feedback: every loop of a query frame <= it was submitted). Set before the run starts.
  void set_final_listener(std::function<void(std::size_t frame)> listener) {
    final_listener_ = std::move(listener);
  }
  // The frame leaving the graph: its frames.csv row (or held), trajectory, counters, timing, trace.
  void sink(FrameRecord& r);
  // After the drain (and the method's finish()): every held row, with empty detection cells when the method
  // gave none (a failed run); closes (completes) the files. Returns the files that could not be written,
  // "NAME: why" (each of the three is attempted).
  std::vector<std::string> finish(bool show_final_progress);
  // The producer's track is named; the others by their thread index (TraceWriter::write).
  void write_trace(const std::filesystem::path& file, int producer_thread);
  // trace.json's events (output.trace): the sink adds the stages' spans and the deadline misses; the producer
  // adds the dropped frames and the end of the stream its spans (TraceWriter::add is thread-safe).
  TraceWriter& trace() { return trace_; }

  const RunCounters& counters() const { return counters_; }
  const StageProfiler& profiler() const { return profiler_; }
  const std::vector<StampedPose>& tracked_poses() const { return tracked_poses_; }
  // The frame of each of tracked_poses().
  const std::vector<std::size_t>& tracked_frames() const { return tracked_frames_; }
  // The odometry's position sigma (PoseEstimate::position_sigma_m) of each of tracked_poses().
  const std::vector<double>& tracked_sigma_m() const { return tracked_sigma_m_; }
  // Their step covariances (OdometryOutput::step_cov), kept when the pose graph uses them and loop closure is
  // on (verify.enabled or keep_step_cov; else empty: 288 bytes a frame).
  const std::vector<std::optional<PoseCov>>& tracked_step_cov() const { return tracked_step_cov_; }
  std::uint64_t frames_through() const { return next_seq_; }
  // The time accounting's measurements summed over the frames through the sink.
  const StageTimes& frame_times() const { return frame_times_; }

 private:
  void add_frame_cells(const FrameRecord& r, const std::string& status, const std::string& reason,
                       CsvRow& row) const;
  void add_detection_cells(const std::optional<FrameVerdict>& verdict, CsvRow& row) const;
  bool geometry_column() const { return closer_ && closer_->active(); }
  void write_ready_rows(bool end_of_stream);
  void timing(FrameRecord& r, std::int64_t exit_ns);
  // A timing.csv row; with loop closure active, the frame's verify/optimize cells are appended.
  void write_timing_row(std::vector<std::string> cells, std::size_t frame);
  void show_progress(bool final);

  const PipelineConfig& config_;
  std::filesystem::path out_dir_;
  DetectionMethod& method_;
  const SeqIndex& seqs_;
  const RunClock& clock_;
  bool visual_odometry_;
  std::size_t total_frames_;
  const LoopCloser* closer_;  // frames.csv "geometry": a loop frame's row waits for its verification
  bool show_progress_ = false;
  bool keep_step_cov_ = false;
  std::int64_t last_progress_ns_ = 0;

  CsvWriter frames_csv_;
  CsvWriter timing_csv_;
  TumWriter trajectory_;
  TraceWriter trace_;
  StageProfiler profiler_;
  RunCounters counters_;
  StageTimes frame_times_;                   // time accounting: sums over the frames through the sink
  std::vector<StampedPose> tracked_poses_;   // odometry poses with status tracking (ATE in summary.json)
  std::vector<std::size_t> tracked_frames_;  // the frame of each tracked pose
  std::vector<double> tracked_sigma_m_;      // the position sigma of each tracked pose
  std::vector<std::optional<PoseCov>> tracked_step_cov_;  // verify.enabled only
  std::uint64_t next_seq_ = 0;
  struct HeldRow {  // a frames.csv row waiting for its detection
    std::size_t seq = 0;
    std::size_t frame = 0;
    CsvRow row;
    bool final = false;                   // the method's detection is known (asked once per seq)
    std::optional<FrameVerdict> verdict;  // then: the method's detection
    std::vector<std::string> timing;      // its timing.csv row when loops are verified (waits with it)
  };
  std::deque<HeldRow> held_;
  std::function<void(std::size_t)> final_listener_;
};

}  // namespace loopgate
