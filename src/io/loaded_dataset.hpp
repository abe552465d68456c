// Private: the one concrete Dataset. The layout readers (euroc_dataset.cpp, kitti_dataset.cpp,
// folder_dataset.cpp) fill its fields when opening; afterwards it is immutable, so every const
// accessor, load_image included, is safe to call from several threads at once.
#pragma once

#include <filesystem>
#include <functional>
#include <optional>
#include <string>
#include <vector>

#include "io/dataset.hpp"

namespace loopgate::io_detail {

class IssueLog;

struct FrameEntry {
  Timestamp t_ns = 0;
  std::filesystem::path image;  // absolute or root-relative path of the image file
  std::size_t source_index = 0;
};

class LoadedDataset final : public Dataset {
 public:
  // Filled by the layout readers, then finish() is called once.
  DatasetLayout layout_kind = DatasetLayout::kFolder;
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
  // When set, images come from it instead of the files frames[].image (a ROS1 bag: frames[].image is then
  // the bag file). It decodes frame `frame` as 8-bit grey without the size check and throws DataError naming
  // the frame; it must be safe to call from several threads at once.
  std::function<cv::Mat(std::size_t frame)> image_reader;
  // The sequence's frame times by source index when the layout has a table of them (KITTI times.txt); empty:
  // source_times() is made from the frames.
  std::vector<std::optional<Timestamp>> source_time_table;

  // Fixes the reference image size: the calibration's when it has one (calibration_size_source set),
  // else that of the first frame whose image decodes (a few frames are probed). Sets the camera size
  // when the calibration has none. Also notes whether IMU samples are time-sorted.
  void finish();

  DatasetLayout layout() const override { return layout_kind; }
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

// `image` as 8-bit grey: grey is kept, BGR / BGRA converted; another depth or channel count throws DataError
// naming `file` and `where` ("frame 12"), in the words every reader uses for it.
cv::Mat to_grey_8bit(const cv::Mat& image, const std::filesystem::path& file, const std::string& where);

// The calibration and the ground truth of an EuRoC ASL tree `dir` (its mav0/ is `mav`, or `dir` itself when
// it holds cam0/ ...), as open_euroc reads them; what is absent stays unset. Calibration:
// cam<camera_index>/sensor.yaml (camera_calibration, calibration_size_source) and imu0/sensor.yaml
// (imu_calib), else Kalibr files in `dir` or its dso/ (TUM-VI). A `calibration_file` (OpenOptions) replaces
// the camera's and adds its folder first to the Kalibr search for the IMU's. Ground truth (gt):
// state_groundtruth_estimate0/data.csv, else TUM-VI's mocap0/data.csv (each moved to the body frame by its
// sensor.yaml T_BS), else a TUM file groundtruth_tum.txt beside or inside `mav`.
void read_euroc_calibration(const std::filesystem::path& dir, const std::filesystem::path& mav,
                            int camera_index, const std::filesystem::path& calibration_file, IssueLog& log,
                            LoadedDataset& d);
void read_euroc_ground_truth(const std::filesystem::path& dir, const std::filesystem::path& mav,
                             IssueLog& log, LoadedDataset& d);

// Image files directly inside `dir` (png, jpg/jpeg, pgm/ppm, bmp, tif/tiff; any case), in natural order:
// runs of digits compare by value, so "img2.png" < "img10.png".
std::vector<std::filesystem::path> list_image_files(const std::filesystem::path& dir);
bool is_image_file(const std::filesystem::path& file);

// Logs a one-line summary of an opened dataset (spdlog info).
void log_summary(const LoadedDataset& dataset);

}  // namespace loopgate::io_detail
