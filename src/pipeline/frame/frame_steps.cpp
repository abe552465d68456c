#include "pipeline/frame/frame_steps.hpp"

#include <spdlog/fmt/fmt.h>
#include <spdlog/spdlog.h>

#include <memory>
#include <utility>

#include "core/error.hpp"
#include "core/thread_cpu_time.hpp"
#include "io/dataset.hpp"

namespace loopgate {

void add_message(std::vector<std::string>& list, std::string message) {
  list.push_back(std::move(message));
}

ImageSource::ImageSource(const Dataset& dataset, const SeqIndex& seqs) : dataset_(dataset), seqs_(seqs) {}

cv::Mat ImageSource::decode(std::size_t seq) {
  cv::Mat image = dataset_.load_image(seqs_.frame(static_cast<std::int64_t>(seq)));
  if (cache_frames_ > 0) {
    std::lock_guard lock(mutex_);
    cache_.emplace_back(seq, image);  // shares the pixels (reference counted)
    while (cache_.size() > cache_frames_) cache_.pop_front();
  }
  return image;
}

cv::Mat ImageSource::read_again(std::size_t seq) {
  {
    std::lock_guard lock(mutex_);
    for (const auto& [cached_seq, image] : cache_) {
      if (cached_seq == seq) {
        hits_.fetch_add(1, std::memory_order_relaxed);
        return image;
      }
    }
  }
  cv::Mat image = dataset_.load_image(seqs_.frame(static_cast<std::int64_t>(seq)));
  reads_.fetch_add(1, std::memory_order_relaxed);
  return image;
}

FrameSteps::FrameSteps(const PipelineConfig& config, const Dataset& dataset,
                       std::unique_ptr<OdometrySource> odometry, ImageSource& images,
                       bool decode_pixels_for_describe)
    : dataset_(dataset), images_(images), odometry_(std::move(odometry)) {
  bool decode_all = config.run.decode == DecodePolicy::kAll;
  if (decode_all && !dataset.has_images()) {
    spdlog::warn("run.decode is 'all' but dataset {} has no images: nothing to decode",
                 dataset.root().string());
    decode_all = false;
  }
  decode_every_frame_ = decode_all || odometry_->needs_images() || decode_pixels_for_describe;
  if (dataset.has_imu())
    synchronizer_ = std::make_unique<ImuSynchronizer>(dataset.imu_samples(), config.sync);
}

void FrameSteps::sync(FrameRecord& r) {
  std::lock_guard lock(sync_mutex_);
  r.needs_pixels = decode_every_frame_;
  if (!synchronizer_) return;
  if (have_last_sync_t_ && r.t_ns <= last_sync_t_ns_) {
    add_message(r.errors,
                fmt::format("frame time {:.6f} s does not increase: IMU not synced", ns_to_s(r.t_ns)));
    return;
  }
  have_last_sync_t_ = true;
  last_sync_t_ns_ = r.t_ns;
  r.imu = synchronizer_->next(r.t_ns);
  r.imu_synced = true;
  for (const auto& message : r.imu.report.messages) add_message(r.warnings, message);
}

void FrameSteps::decode(FrameRecord& r) {
  if (!r.needs_pixels) return;
  try {
    r.image = images_.decode(static_cast<std::size_t>(r.seq));
    r.decoded = true;
  } catch (const DataError& e) {
    add_message(r.errors, std::string("image: ") + e.what());
    return;
  }
  // The odometry's per-image work that needs no earlier frame (the ekf tracker's pyramid) runs here, where
  // frames run in parallel, instead of on the odometry node's serial path.
  if (odometry_->needs_images()) {
    const std::int64_t start_ns = thread_cpu_ns();
    r.prepared = odometry_->prepare(r.image);
    r.odometry_in_decode_cpu_ns = thread_cpu_ns() - start_ns;
  }
}

void FrameSteps::odometry(FrameRecord& r) {
  if (!odometry_->estimates_poses()) return;  // odometry.source none: no pose, nothing to report
  std::lock_guard lock(odometry_mutex_);
  OdometryInput input;
  input.frame = r.frame;
  input.t_ns = r.t_ns;
  if (odometry_->needs_ground_truth()) input.T_w_b_true = dataset_.ground_truth_T_w_b(r.frame);
  input.imu = r.imu_synced ? &r.imu.samples : nullptr;
  input.image = r.decoded ? &r.image : nullptr;
  // Taken out of the record: the pyramid is not needed after this frame's tracking.
  const std::shared_ptr<const PreparedImage> prepared = std::move(r.prepared);
  input.prepared = prepared.get();
  try {
    r.odometry = odometry_->process(input);
    r.has_pose = true;
  } catch (const DataError& e) {
    add_message(r.errors, std::string("odometry: ") + e.what());
    return;
  }
  if (r.odometry.pose.status != OdometryStatus::kTracking) {
    add_message(r.warnings, fmt::format("odometry {}{}{}", to_string(r.odometry.pose.status),
                                        r.odometry.reason.empty() ? "" : ": ", r.odometry.reason));
  }
}

}  // namespace loopgate
