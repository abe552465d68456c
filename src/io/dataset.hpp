// One random-access interface over every dataset layout loopgate reads (EuRoC ASL, KITTI odometry,
// a plain image folder). Metadata (timestamps, IMU, ground truth, calibration) is loaded when the
// dataset is opened; images are decoded on demand by index, so any past frame can be re-read.
#pragma once

#include <cstddef>
#include <filesystem>
#include <memory>
#include <opencv2/core/mat.hpp>
#include <optional>
#include <span>
#include <string>
#include <vector>

#include "core/enum_names.hpp"
#include "core/types.hpp"

namespace loopgate {

// Which reader opened a dataset (summary.json's dataset.layout); memory: frames made in memory by a test or a
// benchmark.
enum class DatasetLayout { kEuroc, kKitti, kFolder, kRosbag, kMemory };
inline constexpr EnumName<DatasetLayout> kDatasetLayoutNames[] = {{DatasetLayout::kEuroc, "euroc"},
                                                                  {DatasetLayout::kKitti, "kitti"},
                                                                  {DatasetLayout::kFolder, "folder"},
                                                                  {DatasetLayout::kRosbag, "rosbag"},
                                                                  {DatasetLayout::kMemory, "memory"}};
constexpr std::span<const EnumName<DatasetLayout>> enum_names(DatasetLayout) {
  return kDatasetLayoutNames;
}

// A problem found in the input that did not stop the dataset from opening (lenient mode):
// which file, which line (0 if none), and what was wrong.
struct DataIssue {
  std::filesystem::path file;
  std::size_t line = 0;
  std::string message;
  std::string to_string() const;  // "FILE:LINE: MESSAGE"
};

struct OpenOptions {
  // strict: the first bad row throws DataError. lenient: bad rows are skipped and recorded in
  // Dataset::issues(); out-of-order or duplicate samples and rows are among them (the rows kept are the
  // longest run of strictly increasing times). A file with more than half of its rows bad fails in both
  // modes.
  bool strict = true;
  // Which camera: 0 or 1 (EuRoC cam0 / cam1, KITTI grey image_0 / image_1), 2 or 3 (KITTI colour image_2 /
  // image_3, with calib.txt's P2 / P3; images are converted to grey).
  int camera_index = 0;
  // Image folder only: frame period when no timestamps file is present.
  double folder_rate_hz = 1.0;
  // ROS1 bag only (open_rosbag): the topics of the images (sensor_msgs/Image or CompressedImage) and of the
  // IMU (sensor_msgs/Imu; empty = no IMU), and the folder in EuRoC ASL layout whose calibration and ground
  // truth go with the bag (empty = the folder beside the bag named like it without ".bag", when present).
  std::string bag_image_topic = "/cam0/image_raw";
  std::string bag_imu_topic = "/imu0";
  std::filesystem::path bag_asl_dir;
  // EuRoC / TUM-VI trees and ROS1 bags: a Kalibr camera-IMU chain (camchain-imucam-<bag>.yaml, OpenVINS'
  // kalibr_imucam_chain.yaml) used for the camera instead of what the tree holds; its folder is searched
  // first for the Kalibr IMU file (imu-<bag>.yaml, kalibr_imu_chain.yaml). Empty = find both in the tree.
  std::filesystem::path calibration_file;
};

class Dataset {
 public:
  virtual ~Dataset() = default;

  virtual DatasetLayout layout() const = 0;
  virtual const std::filesystem::path& root() const = 0;

  virtual std::size_t frame_count() const = 0;
  virtual Timestamp frame_t_ns(std::size_t frame) const = 0;

  // False when the layout lists frames but the image files are absent (e.g. real MH_05 here).
  virtual bool has_images() const = 0;
  virtual std::filesystem::path image_path(std::size_t frame) const = 0;
  // Decodes frame `frame` as 8-bit grey (colour is converted). Throws DataError naming the file and
  // frame when it is missing, unreadable, or not of the size of the first frame.
  virtual cv::Mat load_image(std::size_t frame) const = 0;

  virtual bool has_imu() const = 0;
  // All samples in file order (strictly increasing time: out-of-order rows are rejected when opening).
  virtual const std::vector<ImuSample>& imu_samples() const = 0;

  virtual bool has_ground_truth() const = 0;
  // Ground-truth body pose at frame `frame`, interpolated (linear + slerp) to the frame time;
  // nullopt outside the ground-truth time span.
  virtual std::optional<Eigen::Isometry3d> ground_truth_T_w_b(std::size_t frame) const = 0;
  virtual const std::vector<GroundTruthState>& ground_truth() const = 0;

  virtual std::optional<CameraCalibration> camera() const = 0;
  virtual std::optional<ImuCalibration> imu_calibration() const = 0;

  // Problems recorded in lenient mode (empty in strict mode).
  virtual const std::vector<DataIssue>& issues() const = 0;

  // Optional queries: the defaults suit a dataset without frame numbers, sensors or ground truth of its own.

  // Index of frame `frame` in the original sequence: the KITTI image number (a subset folder such as
  // kitti/00/frames holds images 0, 1000, 2000 -> frames 0, 1, 2), else `frame` itself.
  virtual std::size_t source_index(std::size_t frame) const { return frame; }
  // IMU samples with t_begin_ns <= t_ns < t_end_ns as a view into imu_samples(). With time-sorted
  // samples (always so in strict mode) this is exact; when a lenient file had out-of-order samples it is
  // the file-order run from the first sample at or after t_begin_ns up to (excluding) the first later
  // one at or after t_end_ns, i.e. what a streaming consumer would see.
  virtual std::span<const ImuSample> imu_between(Timestamp t_begin_ns, Timestamp t_end_ns) const;
  // The time of every frame of the original sequence, by source index: element k is the time of the frame
  // whose source_index() is k (nullopt when there is none). KITTI gives every row of times.txt, also in a
  // subset folder that holds only a few of the images. This times a trajectory with one pose per frame of the
  // sequence and no times of its own (a 12-column KITTI pose file as odometry.file).
  virtual std::vector<std::optional<Timestamp>> source_times() const;
};

// The sample rule of every image reader and of `describe`: 8-bit images as they are; 16-bit unsigned ones
// (TUM-VI's PNGs, mono16 bag messages) scaled to 8 bits over the full range (v / 257, rounded: 65535 -> 255);
// anything else (signed, floating point) is a DataError naming `file` and `where` (e.g. "frame 12"; empty:
// none).
cv::Mat to_8bit_samples(const cv::Mat& image, const std::filesystem::path& file, const std::string& where);

// Call before any cv::imread / imdecode / imencode / imwrite that may run on more than one thread. OpenCV
// builds its table of codecs in a function-local static on first use; from a worker thread that first use
// races, as far as ThreadSanitizer can see, with every other thread's use, because the guard's fast path is
// inlined in the uninstrumented library. This initialises the table once inside a static of ours (an encode
// and a decode of a 1x1 PNG), whose guard ThreadSanitizer does see, so every caller is ordered after the
// table was built. Cheap after the first call (one guard check).
void image_codecs_ready();

// Opens `dir`, detecting the layout: EuRoC (mav0/ or cam0/ inside), KITTI (image_0/ .. image_3/ or
// times.txt), else an image folder; a file ending in .bag is a ROS1 bag (open_rosbag). Throws DataError
// naming the path when nothing usable is there.
std::unique_ptr<Dataset> open_dataset(const std::filesystem::path& dir, const OpenOptions& options = {});

std::unique_ptr<Dataset> open_euroc(const std::filesystem::path& dir, const OpenOptions& options = {});
std::unique_ptr<Dataset> open_kitti(const std::filesystem::path& dir, const OpenOptions& options = {});
std::unique_ptr<Dataset> open_image_folder(const std::filesystem::path& dir, const OpenOptions& options = {});
// A ROS1 bag (io/rosbag_dataset.cpp): frames are the messages of options.bag_image_topic, timed by their
// header.stamp and decoded on demand (any frame again, in any order); IMU from options.bag_imu_topic;
// calibration and ground truth from options.bag_asl_dir read as an EuRoC ASL tree. Throws DataError naming
// the bag (and the topic and message) for what it cannot use, and when this build has no bag support.
std::unique_ptr<Dataset> open_rosbag(const std::filesystem::path& bag_file, const OpenOptions& options = {});
// Whether this build reads ROS1 bags (CMake option LOOPGATE_WITH_ROSBAG).
bool rosbag_support_built();

}  // namespace loopgate
