// The per-frame input work of a run, one object per node: IMU sync (serial), image decode (parallel) with
// the recently decoded images kept for describe, and odometry (serial). Bad data in one frame goes into
// that frame's errors / warnings; the run goes on.
#pragma once

#include <atomic>
#include <cstddef>
#include <deque>
#include <memory>
#include <mutex>
#include <opencv2/core/mat.hpp>
#include <utility>

#include "pipeline/frame/frame_record.hpp"
#include "pipeline/pipeline_config.hpp"
#include "stages/odometry/odometry_source.hpp"
#include "stages/sync/imu_sync.hpp"

namespace loopgate {

class Dataset;

// Images by sequence number for the describe work: the current frame's decoded pixels, a bounded cache of
// the most recently decoded frames (run.image_cache_frames), else a re-read through the dataset's random
// access. Thread-safe.
class ImageSource {
 public:
  ImageSource(const Dataset& dataset, const SeqIndex& seqs);

  // Keeps the `frames` most recently decoded images for read_again() (0, the default: none). Called by the
  // method that reads past frames, before the run starts.
  void keep_recent(std::size_t frames) { cache_frames_ = frames; }

  // Decodes frame `seq` for the decode node (keeps it in the cache). Throws DataError.
  cv::Mat decode(std::size_t seq);
  // The image of `seq` for a describe request: from the cache, else read again (counted). Throws DataError.
  cv::Mat read_again(std::size_t seq);

  std::size_t reads_for_description() const { return reads_.load(); }
  std::size_t cache_hits() const { return hits_.load(); }
  const Dataset& dataset() const { return dataset_; }

 private:
  const Dataset& dataset_;
  const SeqIndex& seqs_;
  std::size_t cache_frames_ = 0;
  std::mutex mutex_;
  std::deque<std::pair<std::size_t, cv::Mat>> cache_;  // (seq, image), oldest first
  std::atomic<std::size_t> reads_{0};
  std::atomic<std::size_t> hits_{0};
};

class FrameSteps {
 public:
  // `decode_pixels_for_describe`: the detection method needs every frame's pixels in describe.
  FrameSteps(const PipelineConfig& config, const Dataset& dataset, std::unique_ptr<OdometrySource> odometry,
             ImageSource& images, bool decode_pixels_for_describe);

  void sync(FrameRecord& r);      // serial, in order
  void decode(FrameRecord& r);    // parallel
  void odometry(FrameRecord& r);  // serial, in order

  const OdometrySource& odometry_source() const { return *odometry_; }
  const ImuSynchronizer* synchronizer() const { return synchronizer_.get(); }

 private:
  const Dataset& dataset_;
  ImageSource& images_;
  std::unique_ptr<OdometrySource> odometry_;
  std::unique_ptr<ImuSynchronizer> synchronizer_;
  bool decode_every_frame_ = false;
  bool have_last_sync_t_ = false;
  Timestamp last_sync_t_ns_ = 0;
  std::mutex sync_mutex_, odometry_mutex_;
};

void add_message(std::vector<std::string>& list, std::string message);

}  // namespace loopgate
