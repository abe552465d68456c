// Private: the one concrete Dataset. The layout readers (euroc_dataset.cpp, kitti_dataset.cpp,
// folder_dataset.cpp) fill its fields when opening; afterwards it is immutable, so every const
// accessor, load_image included, is safe to call from several threads at once.
#pragma once

#include <filesystem>
#include <optional>
#include <string>
#include <vector>

#include "io/dataset.hpp"

namespace loopgate::io_detail {

struct FrameEntry {
  Timestamp t_ns = 0;
  std::filesystem::path image;  // absolute or root-relative path of the image file
  std::size_t source_index = 0;
};

class LoadedDataset final : public Dataset {
 public:
  // Filled by the layout readers, then finish() is called once.
  std::string layout_name;
  std::filesystem::path root_dir;
  std::vector<FrameEntry> frames;
  bool images_present = false;
  std::vector<ImuSample> imu;
  bool imu_present = false;
  std::vector<GroundTruthState> gt;
  std::optional<CameraCalibration> camera_calibration;
  std::optional<ImuCalibration> imu_calib;
  std::vector<DataIssue> problems;
  // Where the expected image size comes from when the calibration gives it ("cam0/sensor.yaml").
  std::string calibration_size_source;
  // The sequence's frame times by source index when the layout has a table of them (KITTI times.txt); empty:
  // source_times() is made from the frames.
  std::vector<std::optional<Timestamp>> source_time_table;

  // Fixes the reference image size: the calibration's when it has one (calibration_size_source set),
  // else that of the first frame whose image decodes (a few frames are probed). Sets the camera size
  // when the calibration has none. Also notes whether IMU samples are time-sorted.
  void finish();

  std::string layout() const override { return layout_name; }
  const std::filesystem::path& root() const override { return root_dir; }
  std::size_t frame_count() const override { return frames.size(); }
  Timestamp frame_t_ns(std::size_t frame) const override { return frames.at(frame).t_ns; }
  std::size_t source_index(std::size_t frame) const override { return frames.at(frame).source_index; }
  bool has_images() const override { return images_present; }
  std::filesystem::path image_path(std::size_t frame) const override { return frames.at(frame).image; }
  cv::Mat load_image(std::size_t frame) const override;
  bool has_imu() const override { return imu_present; }
  const std::vector<ImuSample>& imu_samples() const override { return imu; }
  std::span<const ImuSample> imu_between(Timestamp t_begin_ns, Timestamp t_end_ns) const override;
  bool has_ground_truth() const override { return !gt.empty(); }
  std::optional<Eigen::Isometry3d> ground_truth_T_w_b(std::size_t frame) const override;
  const std::vector<GroundTruthState>& ground_truth() const override { return gt; }
  std::optional<CameraCalibration> camera() const override { return camera_calibration; }
  std::optional<ImuCalibration> imu_calibration() const override { return imu_calib; }
  const std::vector<DataIssue>& issues() const override { return problems; }
  std::vector<std::optional<Timestamp>> source_times() const override {
    return source_time_table.empty() ? Dataset::source_times() : source_time_table;
  }

 private:
  // Decodes without the size check; throws DataError naming the frame and file.
  cv::Mat decode(std::size_t frame) const;

  int expected_width_px_ = 0;  // 0: unknown (no frame decodes)
  int expected_height_px_ = 0;
  std::string expected_size_source_;
  bool imu_sorted_ = true;
};

// Image files directly inside `dir` (png, jpg/jpeg, pgm/ppm, bmp, tif/tiff; any case), in natural order:
// runs of digits compare by value, so "img2.png" < "img10.png".
std::vector<std::filesystem::path> list_image_files(const std::filesystem::path& dir);
bool is_image_file(const std::filesystem::path& file);

// Logs a one-line summary of an opened dataset (spdlog info).
void log_summary(const LoadedDataset& dataset);

}  // namespace loopgate::io_detail
