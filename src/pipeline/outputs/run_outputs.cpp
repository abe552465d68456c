#include "pipeline/outputs/run_outputs.hpp"

#include <spdlog/fmt/fmt.h>
#include <unistd.h>

#include <algorithm>
#include <cmath>
#include <cstdio>
#include <stdexcept>

namespace loopgate {

namespace {

constexpr std::size_t kMaxMessagesPerFrame = 4;  // per-frame reasons kept in frames.csv
constexpr double kProgressPeriodS = 0.25;

std::string join_messages(const std::vector<std::string>& messages) {
  std::string out;
  const std::size_t shown = std::min(messages.size(), kMaxMessagesPerFrame);
  for (std::size_t i = 0; i < shown; ++i) out += (i ? "; " : "") + messages[i];
  if (messages.size() > shown) out += fmt::format("; ... {} more", messages.size() - shown);
  return out;
}

}  // namespace

RunOutputs::RunOutputs(const PipelineConfig& config, const std::filesystem::path& out_dir,
                       DetectionMethod& method, const SeqIndex& seqs, const RunClock& clock,
                       bool visual_odometry, std::size_t total_frames, const LoopCloser* closer,
                       bool keep_step_cov)
    : config_(config),
      out_dir_(out_dir),
      method_(method),
      seqs_(seqs),
      clock_(clock),
      visual_odometry_(visual_odometry),
      total_frames_(total_frames),
      closer_(closer),
      profiler_({kStageNames.begin(), kStageNames.end()}, total_frames) {
  const Progress progress = config.output.progress;
  show_progress_ = progress == Progress::kOn || (progress == Progress::kAuto && ::isatty(STDERR_FILENO));
  keep_step_cov_ = config.posegraph.enabled &&
                   config.posegraph.odometry_cov == PoseGraphOdometryCov::kOdometry &&
                   (config.verify.enabled || keep_step_cov);
  // At most one entry a frame: reserved, so that they do not keep up to twice their entries and copy them as
  // they grow (reserved pages not written take no memory).
  tracked_poses_.reserve(total_frames);
  tracked_frames_.reserve(total_frames);
  tracked_sigma_m_.reserve(total_frames);
  if (keep_step_cov_) tracked_step_cov_.reserve(total_frames);
}

// frames.csv: the frame, its pose (x..qw, sigma_m = sqrt of the largest eigenvalue of the position
// covariance), odometry status, IMU samples, decode, status and reason; the method's columns; a detecting
// run's descriptor, detection, match_frame, match_score and detection_reason.
void RunOutputs::add_frame_cells(const FrameRecord& r, const std::string& status, const std::string& reason,
                                 CsvRow& row) const {
  row.add("seq", std::to_string(r.seq));
  row.add("frame", std::to_string(r.label));
  row.add("t_ns", std::to_string(r.t_ns));
  row.add("t_s", format_fixed(ns_to_s(r.t_ns), 9));
  const PoseEstimate& pose = r.odometry.pose;
  const Eigen::Vector3d p = pose.T_w_b.translation();
  const Eigen::Quaterniond q(pose.T_w_b.rotation());
  const auto cell = [&](double value) { return r.has_pose ? format_fixed(value, 9) : std::string(); };
  row.add("x_m", cell(p.x()));
  row.add("y_m", cell(p.y()));
  row.add("z_m", cell(p.z()));
  row.add("qx", cell(q.x()));
  row.add("qy", cell(q.y()));
  row.add("qz", cell(q.z()));
  row.add("qw", cell(q.w()));
  row.add("sigma_m", cell(r.has_pose ? pose.position_sigma_m() : 0.0));
  row.add("odom_status", r.has_pose ? to_string(pose.status) : "none");
  row.add("imu_samples", std::to_string(r.imu.samples.size()));
  row.add("decoded", r.decoded ? "y" : "n");
  row.add("status", status);
  row.add("reason", reason);
  if (visual_odometry_)  // features the tracker followed into this image
    row.add("tracked_features", r.has_pose ? std::to_string(std::max(0, r.odometry.tracked_features)) : "");
  method_.add_frame_cells(r, row);
}

void RunOutputs::add_detection_cells(const std::optional<FrameVerdict>& verdict, CsvRow& row) const {
  const FrameDetection* d = verdict ? &verdict->detection : nullptr;
  const bool has_match = d && d->match >= 0;
  row.add("descriptor", verdict ? (verdict->described ? "y" : "n") : "");
  row.add("detection", d ? d->label : "");
  row.add("match_frame", has_match ? std::to_string(seqs_.label(d->match)) : "");
  row.add("match_score", has_match ? format_fixed(d->score, 6) : "");
  row.add("detection_reason", d ? d->reason : "");
}

void RunOutputs::open() {
  std::filesystem::create_directories(out_dir_);
  CsvRow header;
  add_frame_cells(FrameRecord{}, "", "", header);
  if (method_.detects()) add_detection_cells(std::nullopt, header);
  if (method_.detects() && geometry_column()) header.add("geometry", "");
  frames_csv_.open(out_dir_ / "frames.csv", header.names());
  std::vector<std::string> timing_columns = {"seq", "frame"};
  for (const char* name : kStageNames) timing_columns.push_back(std::string(name) + "_ms");
  timing_columns.emplace_back("latency_ms");
  timing_columns.emplace_back("total_ms");
  // The frame's parts of the time accounting (time_accounting.hpp, thread CPU time).
  for (const char* part : {"decode_cpu_ms", "describe_cpu_ms", "match_cpu_ms", "rest_cpu_ms"})
    timing_columns.emplace_back(part);
  if (method_.detects() && geometry_column()) {  // off the frame's path: not in total_ms
    timing_columns.emplace_back("loop_verify_ms");
    timing_columns.emplace_back("loop_optimize_ms");
  }
  timing_csv_.open(out_dir_ / "timing.csv", timing_columns);
  trajectory_.open(out_dir_ / "trajectory.tum");
}

void RunOutputs::sink(FrameRecord& r) {
  const std::int64_t cpu_start_ns = thread_cpu_ns();
  if (r.seq != next_seq_) {
    throw std::logic_error(fmt::format("sink received seq {} while expecting {}", r.seq, next_seq_));
  }
  ++next_seq_;
  const std::string status = !r.errors.empty() ? "error" : !r.warnings.empty() ? "warning" : "ok";
  std::vector<std::string> messages = r.errors;
  messages.insert(messages.end(), r.warnings.begin(), r.warnings.end());
  const std::string reason = join_messages(messages);

  CsvRow row;
  add_frame_cells(r, status, reason, row);
  if (method_.detects()) {
    HeldRow held;
    held.seq = static_cast<std::size_t>(r.seq);
    held.frame = r.frame;
    held.row = std::move(row);
    held_.push_back(std::move(held));
    write_ready_rows(false);
  } else {
    frames_csv_.write_row(row.values());
  }
  // trajectory.tum holds only the poses the odometry estimated: the identity an initialising
  // filter reports and a lost frame's last good pose are not estimates of this frame.
  if (r.usable_pose()) {
    const PoseEstimate& pose = r.odometry.pose;
    trajectory_.write(r.t_ns, pose.T_w_b);
    tracked_frames_.push_back(r.frame);
    tracked_poses_.push_back({r.t_ns, pose.T_w_b});
    tracked_sigma_m_.push_back(pose.position_sigma_m());
    if (keep_step_cov_) tracked_step_cov_.push_back(r.odometry.step_cov);
  }
  counters_.count(r, status, reason);
  r.image.release();

  const std::int64_t exit_ns = clock_.now_ns();
  r.stamps[kSink].exit_ns = exit_ns;
  r.cpu_ns[kSink] = thread_cpu_ns() - cpu_start_ns;
  if (r.deadline_ns > 0 && exit_ns > r.deadline_ns) {
    ++counters_.deadline_misses;
    if (config_.output.trace) {
      trace_.add(TraceEvent{"deadline miss", "replay", 1e-3 * static_cast<double>(exit_ns), 0,
                            r.stamps[kSink].thread, static_cast<std::int64_t>(r.seq),
                            static_cast<std::int64_t>(r.label), 'i',
                            fmt::format("left the graph {:.3f} ms after its deadline",
                                        1e-6 * static_cast<double>(exit_ns - r.deadline_ns))});
    }
  }
  timing(r, exit_ns);
  if (counters_.processed % static_cast<std::size_t>(config_.output.flush_every) == 0) {
    frames_csv_.flush();
    timing_csv_.flush();
    trajectory_.flush();
  }
  if (show_progress_ && exit_ns - last_progress_ns_ > static_cast<std::int64_t>(kProgressPeriodS * 1e9)) {
    last_progress_ns_ = exit_ns;
    show_progress(false);
  }
}

// timing.csv (service time per stage, end-to-end latency, their sum, the time accounting's per-frame parts),
// the profiler, the time accounting's sums and the trace.
void RunOutputs::timing(FrameRecord& r, std::int64_t exit_ns) {
  std::vector<std::string> cells = {std::to_string(r.seq), std::to_string(r.label)};
  double total_ms = 0;
  const StageTimes frame_times = stage_times(r);
  frame_times_ += frame_times;
  const TimeParts parts = account_time(frame_times);
  std::int64_t previous_exit_ns = r.release_ns;
  for (std::size_t s = 0; s < kStageCount; ++s) {
    const StageStamp& stamp = r.stamps[s];
    const double service_ms = 1e-6 * static_cast<double>(stamp.exit_ns - stamp.enter_ns);
    const double wait_ms = 1e-6 * static_cast<double>(stamp.enter_ns - previous_exit_ns);
    previous_exit_ns = stamp.exit_ns;
    profiler_.add(s, service_ms, wait_ms);
    total_ms += service_ms;
    cells.push_back(format_fixed(service_ms, 4));
    if (config_.output.trace) {
      trace_.add(TraceEvent{kStageNames[s],
                            "stage",
                            1e-3 * static_cast<double>(stamp.enter_ns),
                            1e-3 * static_cast<double>(stamp.exit_ns - stamp.enter_ns),
                            stamp.thread,
                            static_cast<std::int64_t>(r.seq),
                            static_cast<std::int64_t>(r.label),
                            'X',
                            {}});
    }
  }
  const double latency_ms = 1e-6 * static_cast<double>(exit_ns - r.release_ns);
  profiler_.add_latency(latency_ms);
  cells.push_back(format_fixed(latency_ms, 4));
  cells.push_back(format_fixed(total_ms, 4));
  for (const double ms : {parts.decode_ms, parts.describe_ms, parts.match_ms, parts.rest_ms})
    cells.push_back(format_fixed(ms, 4));
  if (method_.detects() && geometry_column() && !held_.empty() && held_.back().seq == r.seq) {
    held_.back().timing = std::move(cells);  // written with its frames.csv row, after its verification
  } else {
    write_timing_row(std::move(cells), r.frame);
  }
}

void RunOutputs::write_timing_row(std::vector<std::string> cells, std::size_t frame) {
  if (method_.detects() && geometry_column()) {
    const LoopCloser::FrameMs ms = closer_->frame_ms(frame);
    cells.push_back(format_fixed(ms.verify_ms, 4));
    cells.push_back(format_fixed(ms.optimize_ms, 4));
  }
  timing_csv_.write_row(cells);
}

// Writes the held frames.csv rows whose detection is final, in order. At the end of the stream a row
// without one (a failed run) is written with empty detection cells.
void RunOutputs::write_ready_rows(bool end_of_stream) {
  // The detections first, in order, also behind a row that waits for its loops' verification: the verdicts
  // final now are published (final_listener_) whether or not their rows can be written yet.
  for (HeldRow& held : held_) {
    if (held.final) continue;
    held.verdict = method_.detection(held.seq);
    if (!held.verdict && !end_of_stream) break;
    held.final = true;
    if (held.verdict && final_listener_) final_listener_(held.frame);
  }
  while (!held_.empty()) {
    HeldRow& held = held_.front();
    if (!held.final) return;
    const std::optional<FrameVerdict>& verdict = held.verdict;
    // A loop frame's row also waits for the verification of its loops (the loop closer's worker).
    std::optional<std::string> geometry;
    if (geometry_column()) {
      geometry = closer_->geometry_cell(held.frame);
      if (!geometry && !end_of_stream) return;
    }
    if (verdict) counters_.count(verdict->detection.outcome);
    add_detection_cells(verdict, held.row);
    if (geometry_column()) held.row.add("geometry", geometry.value_or(""));
    frames_csv_.write_row(held.row.values());
    if (!held.timing.empty()) write_timing_row(std::move(held.timing), held.frame);
    held_.pop_front();
  }
}

std::vector<std::string> RunOutputs::finish(bool show_final_progress) {
  std::vector<std::string> errors;
  const auto attempt = [&](const char* name, auto&& step) {
    try {
      step();
    } catch (const std::exception& e) {
      errors.push_back(std::string(name) + ": " + e.what());
    }
  };
  attempt("frames.csv", [&] {
    try {
      if (method_.detects()) write_ready_rows(true);
      frames_csv_.close();
    } catch (...) {
      frames_csv_.abandon();
      throw;
    }
  });
  if (show_progress_ && show_final_progress) show_progress(true);
  attempt("timing.csv", [&] { timing_csv_.close(); });
  attempt("trajectory.tum", [&] { trajectory_.close(); });
  return errors;
}

void RunOutputs::write_trace(const std::filesystem::path& file, int producer_thread) {
  trace_.name_thread(producer_thread, "producer, end of stream");
  trace_.write(file);
}

void RunOutputs::show_progress(bool final) {
  const double elapsed_s = 1e-9 * static_cast<double>(clock_.now_ns());
  const std::size_t processed = counters_.processed;
  const double fps = elapsed_s > 0 ? static_cast<double>(processed) / elapsed_s : 0.0;
  const double rtf = elapsed_s > 0 ? counters_.data_s() / elapsed_s : 0.0;
  const double eta_s =
      fps > 0 ? static_cast<double>(total_frames_ - std::min(total_frames_, processed)) / fps : 0.0;
  const std::string line = fmt::format("\r[run] {}/{} frames  {:.1f} frames/s  rtf {:.2f}x  ETA {:.0f} s   ",
                                       processed, total_frames_, fps, rtf, eta_s);
  std::fputs(line.c_str(), stderr);
  if (final) std::fputs("\n", stderr);
  std::fflush(stderr);
}

}  // namespace loopgate
