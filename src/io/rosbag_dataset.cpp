// ROS1 bag reader: EuRoC and TUM-VI publish their sequences as bags too.
//   frames        the messages of OpenOptions::bag_image_topic (sensor_msgs/Image: mono8, bgr8, rgb8, bgra8,
//                 rgba8; sensor_msgs/CompressedImage: whatever OpenCV decodes), timed by header.stamp; a
//                 frame's number is the position of its message on the topic
//   IMU           the sensor_msgs/Imu messages of OpenOptions::bag_imu_topic (header.stamp, angular velocity,
//                 linear acceleration); none when the topic is empty
//   calibration,  read from a folder in EuRoC ASL layout (OpenOptions::bag_asl_dir, else the folder beside
//   the ground truth  bag named like it without ".bag"): cam<k>/sensor.yaml, imu0/sensor.yaml,
//                 state_groundtruth_estimate0/data.csv, as open_euroc reads them; a bag carries none of them
// Opening indexes the image topic (every message's header, not its pixels: the whole topic is read once) and
// reads the IMU; images are read again from the bag when a frame is decoded (bag/bag_reader.hpp: a rosbag
// MessageInstance per frame), so a gated run re-reads any past frame without holding the images in memory.
// Image problems found in the headers (unknown encoding, signed samples, a size the data does not hold) and
// header stamps out of order are table problems like a bad row: the first one is the error in strict mode,
// lenient mode skips those frames and records them (and fails when more than half of them are bad).
#include <spdlog/spdlog.h>

#include <algorithm>
#include <bit>
#include <cstdint>
#include <memory>
#include <string>
#include <utility>
#include <vector>

#include "core/error.hpp"
#include "io/csv_text.hpp"
#include "io/dataset.hpp"
#include "io/file_guard.hpp"
#include "io/loaded_dataset.hpp"
#include "io/png_grey.hpp"
#include "io/time_order.hpp"

#if LOOPGATE_WITH_ROSBAG
#include <opencv2/imgcodecs.hpp>
#include <opencv2/imgproc.hpp>

#include "bag/bag_reader.hpp"
#endif

namespace loopgate {

namespace fs = std::filesystem;

bool rosbag_support_built() {
  return LOOPGATE_WITH_ROSBAG != 0;
}

#if !LOOPGATE_WITH_ROSBAG

std::unique_ptr<Dataset> open_rosbag(const fs::path& bag_file, const OpenOptions&) {
  throw DataError(
      bag_file,
      "this loopgate was built without ROS1 bag support (CMake option LOOPGATE_WITH_ROSBAG=OFF, its "
      "default when librosbag-storage-dev or libsensor-msgs-dev is missing); install them "
      "(scripts/setup.sh) and rebuild with -DLOOPGATE_WITH_ROSBAG=ON, or use the sequence in EuRoC ASL "
      "layout");
}

#else

namespace {

// The sensor_msgs/Image encodings read; colour is converted to grey like a colour PNG, 16-bit unsigned
// samples are scaled to 8 bits like a 16-bit PNG (to_8bit_samples, io/dataset.hpp).
struct Encoding {
  const char* name;
  int channels;
  int to_grey;  // cv::cvtColor code, -1 for grey
  int bytes;    // per sample: 1 or 2 (16-bit unsigned, byte order from is_bigendian)
};
constexpr Encoding kEncodings[] = {
    {"mono8", 1, -1, 1},
    {"8UC1", 1, -1, 1},
    {"bgr8", 3, cv::COLOR_BGR2GRAY, 1},
    {"rgb8", 3, cv::COLOR_RGB2GRAY, 1},
    {"bgra8", 4, cv::COLOR_BGRA2GRAY, 1},
    {"rgba8", 4, cv::COLOR_RGBA2GRAY, 1},
    {"mono16", 1, -1, 2},
    {"16UC1", 1, -1, 2},
    {"bgr16", 3, cv::COLOR_BGR2GRAY, 2},
    {"rgb16", 3, cv::COLOR_RGB2GRAY, 2},
    {"bgra16", 4, cv::COLOR_BGRA2GRAY, 2},
    {"rgba16", 4, cv::COLOR_RGBA2GRAY, 2},
};
constexpr const char* kEncodingList = "mono8, bgr8, rgb8, bgra8, rgba8 or their 16-bit forms (mono16, ...)";
// Signed samples are not an image of light: refused.
constexpr const char* kSigned[] = {"16SC1", "8SC1"};

const Encoding* find_encoding(const std::string& name) {
  for (const Encoding& e : kEncodings)
    if (name == e.name) return &e;
  return nullptr;
}

// What makes an image message unusable, from its header alone; empty when it can be decoded. (The pixels of a
// CompressedImage are checked when it is decoded.)
std::string image_problem(const bag::ImageInfo& info) {
  if (!info.read_error.empty()) return info.read_error;
  if (info.compressed) {
    return info.data_bytes == 0 ? "CompressedImage with no data (format '" + info.encoding + "')" : "";
  }
  for (const char* name : kSigned) {
    if (info.encoding == name) {
      return "image has signed integer samples (encoding '" + info.encoding + "'), expected " + kEncodingList;
    }
  }
  const Encoding* encoding = find_encoding(info.encoding);
  if (!encoding) return "unknown encoding " + quote_excerpt(info.encoding) + ", expected " + kEncodingList;
  if (info.width == 0 || info.height == 0) {
    return "image is " + std::to_string(info.width) + "x" + std::to_string(info.height);
  }
  const std::size_t row_bytes =
      std::size_t{info.width} * static_cast<std::size_t>(encoding->channels * encoding->bytes);
  if (info.step < row_bytes) {
    return "step " + std::to_string(info.step) + " bytes is less than a row of " +
           std::to_string(info.width) + " " + info.encoding + " pixels (" + std::to_string(row_bytes) +
           " bytes)";
  }
  const std::size_t needed = std::size_t{info.step} * info.height;
  if (info.data_bytes < needed) {
    return "data holds " + std::to_string(info.data_bytes) +
           " bytes, expected step x height = " + std::to_string(info.step) + " x " +
           std::to_string(info.height) + " = " + std::to_string(needed);
  }
  return "";
}

// Decodes message `message` of the indexed topic as 8-bit grey; throws DataError naming the bag and message.
cv::Mat read_grey(const bag::BagReader& reader, const std::string& topic, std::size_t message) {
  const std::string where = topic + " message " + std::to_string(message);
  bag::RawImage raw;
  try {
    raw = reader.read_image(message);
  } catch (const bag::BagError& e) {
    throw DataError(reader.file(), e.message());
  }
  if (const std::string problem = image_problem(raw.info); !problem.empty())
    throw DataError(reader.file(), where + ": " + problem);
  if (raw.info.compressed) {
    if (cv::Mat grey = decode_png_grey8(raw.data.data(), raw.data.size()); !grey.empty()) return grey;
    cv::Mat image;
    image_codecs_ready();
    try {
      image = cv::imdecode(raw.data, cv::IMREAD_UNCHANGED);
    } catch (const cv::Exception& e) {
      throw DataError(reader.file(), where + ": cannot decode the CompressedImage (" + e.what() + ")");
    }
    if (image.empty()) {
      throw DataError(reader.file(), where + ": cannot decode the CompressedImage (format " +
                                         quote_excerpt(raw.info.encoding) + "), expected PNG or JPEG data");
    }
    return io_detail::to_grey_8bit(image, reader.file(), where);
  }
  const Encoding* known = find_encoding(raw.info.encoding);
  if (known == nullptr)  // image_problem() refused it already; kept for the compiler's flow analysis
    throw DataError(reader.file(), where + ": unknown encoding " + quote_excerpt(raw.info.encoding));
  const Encoding& encoding = *known;
  const int type = encoding.bytes == 2 ? CV_16UC(encoding.channels) : CV_8UC(encoding.channels);
  cv::Mat samples = cv::Mat(static_cast<int>(raw.info.height), static_cast<int>(raw.info.width), type,
                            raw.data.data(), raw.info.step)
                        .clone();
  constexpr bool kHostBigEndian = std::endian::native == std::endian::big;
  if (encoding.bytes == 2 && raw.info.big_endian != kHostBigEndian) {
    for (int r = 0; r < samples.rows; ++r) {
      auto* row = samples.ptr<std::uint16_t>(r);
      for (int k = 0; k < samples.cols * samples.channels(); ++k)
        row[k] = static_cast<std::uint16_t>((row[k] >> 8) | (row[k] << 8));
    }
  }
  cv::Mat grey = samples;
  if (encoding.to_grey >= 0) cv::cvtColor(samples, grey, encoding.to_grey);
  return to_8bit_samples(grey, reader.file(), where);
}

// The problems of a topic's messages, reported in message order (the first is the error in strict mode).
class TopicProblems {
 public:
  TopicProblems(const fs::path& bag_file, std::string topic)
      : bag_file_(bag_file), topic_(std::move(topic)) {}
  void add(std::size_t message, const std::string& problem) { problems_.emplace_back(message, problem); }
  // Messages kept in strictly increasing header.stamp order; the others are problems.
  template <class T>
  std::vector<io_detail::TimedRow<T> > keep_increasing(std::vector<io_detail::TimedRow<T> > rows) {
    return io_detail::keep_increasing_rows(
        std::move(rows), "header.stamp", false, "message",
        [&](const io_detail::TimedRow<T>& row, const std::string& message, bool out_of_order) {
          add(row.line, out_of_order
                            ? message +
                                  ", expected strictly increasing times: this message is out of order "
                                  "with the messages around it"
                            : message);
        });
  }
  // Reports them as one table of `messages` rows (io_detail::IssueLog::end_table).
  void report(io_detail::IssueLog& log, std::size_t messages) {
    std::stable_sort(problems_.begin(), problems_.end(),
                     [](const auto& a, const auto& b) { return a.first < b.first; });
    log.begin_table();
    for (const auto& [message, problem] : problems_)
      log.report(bag_file_, 0, topic_ + " message " + std::to_string(message) + ": " + problem);
    log.end_table(bag_file_, messages, topic_);
  }

 private:
  fs::path bag_file_;
  std::string topic_;
  std::vector<std::pair<std::size_t, std::string> > problems_;
};

// The folder of calibration and ground truth that goes with the bag (empty path: none).
fs::path asl_dir_for(const fs::path& bag_file, const OpenOptions& options) {
  std::error_code ec;
  if (!options.bag_asl_dir.empty()) {
    if (!fs::is_directory(options.bag_asl_dir, ec)) {
      throw DataError(
          options.bag_asl_dir,
          "dataset.bag_asl_dir: not a folder, expected the EuRoC ASL folder (mav0/ with "
          "cam0/sensor.yaml, imu0/sensor.yaml, state_groundtruth_estimate0/data.csv) of the bag " +
              bag_file.string());
    }
    return options.bag_asl_dir;
  }
  fs::path beside = bag_file;
  beside.replace_extension();
  return fs::is_directory(beside, ec) ? beside : fs::path{};
}

// The camera and topic options of a bag: run.camera_index 0 or 1, an image topic, and a topic that names its
// camera (/cam0/image_raw) naming the camera whose calibration is read.
void check_bag_options(const OpenOptions& options) {
  if (options.camera_index != 0 && options.camera_index != 1) {
    throw ConfigError("camera_index: " + std::to_string(options.camera_index) + ", expected 0 or 1");
  }
  if (options.bag_image_topic.empty()) {
    throw ConfigError(
        "dataset.bag_image_topic: empty, expected the topic of the images (e.g. /cam0/image_raw)");
  }
  // A topic that names its camera (/cam0/image_raw) must be the camera whose calibration is read
  // (run.camera_index): otherwise cam0's images would be paired with cam1's calibration.
  for (std::size_t at = 0; at < options.bag_image_topic.size();) {
    const std::size_t end = std::min(options.bag_image_topic.find('/', at), options.bag_image_topic.size());
    const std::string part = options.bag_image_topic.substr(at, end - at);
    if (part.size() == 4 && part.rfind("cam", 0) == 0 && part[3] >= '0' && part[3] <= '9' &&
        part[3] - '0' != options.camera_index) {
      throw ConfigError("dataset.bag_image_topic '" + options.bag_image_topic + "' is camera " + part[3] +
                        "'s images, and run.camera_index is " + std::to_string(options.camera_index) +
                        " (cam" + std::to_string(options.camera_index) +
                        "'s calibration): set dataset.bag_image_topic=/cam" +
                        std::to_string(options.camera_index) + "/image_raw, or run.camera_index=" + part[3]);
    }
    at = end + 1;
  }
}

// The IMU samples of `imu_topic`, in strictly increasing header.stamp order (the others reported).
void read_bag_imu(bag::BagReader& reader, const fs::path& bag_file, const std::string& imu_topic,
                  io_detail::IssueLog& log, io_detail::LoadedDataset& d) {
  std::vector<bag::ImuRecord> records;
  try {
    records = reader.read_imu(imu_topic);
  } catch (const bag::BagError& e) {
    throw DataError(bag_file, e.message() + " (dataset.bag_imu_topic; empty = no IMU)");
  }
  TopicProblems imu_problems(bag_file, imu_topic);
  std::vector<io_detail::TimedRow<ImuSample> > samples;
  for (std::size_t k = 0; k < records.size(); ++k) {
    const bag::ImuRecord& r = records[k];
    if (!r.read_error.empty()) {
      imu_problems.add(k, r.read_error);
      continue;
    }
    ImuSample s;
    s.t_ns = r.header_t_ns;
    s.gyro_radps = Eigen::Vector3d(r.angular_velocity_radps[0], r.angular_velocity_radps[1],
                                   r.angular_velocity_radps[2]);
    s.accel_mps2 = Eigen::Vector3d(r.linear_acceleration_mps2[0], r.linear_acceleration_mps2[1],
                                   r.linear_acceleration_mps2[2]);
    samples.push_back({k, s.t_ns, s});
  }
  for (auto& row : imu_problems.keep_increasing(std::move(samples))) d.imu.push_back(row.value);
  imu_problems.report(log, records.size());
  d.imu_present = true;
}

}  // namespace

std::unique_ptr<Dataset> open_rosbag(const fs::path& bag_file, const OpenOptions& options) {
  check_bag_options(options);
  std::error_code ec;
  if (!fs::exists(bag_file, ec)) throw DataError(bag_file, "bag file not found");
  require_regular_file(bag_file);

  auto d = std::make_unique<io_detail::LoadedDataset>();
  d->layout_kind = DatasetLayout::kRosbag;
  d->root_dir = bag_file;
  io_detail::IssueLog log(options.strict, &d->problems);

  std::shared_ptr<bag::BagReader> reader;
  std::vector<bag::ImageInfo> infos;
  try {
    reader = std::make_shared<bag::BagReader>(bag_file.string());
    infos = reader->index_images(options.bag_image_topic);
  } catch (const bag::BagError& e) {
    throw DataError(bag_file, e.message());
  }
  const std::string& topic = options.bag_image_topic;
  if (infos.empty()) throw DataError(bag_file, "topic " + topic + " has no messages");

  // Frames: the messages whose headers make a usable image, in strictly increasing header.stamp order.
  TopicProblems frame_problems(bag_file, topic);
  std::vector<io_detail::TimedRow<std::size_t> > rows;  // line and value: the message's position on the topic
  for (std::size_t k = 0; k < infos.size(); ++k) {
    if (const std::string problem = image_problem(infos[k]); !problem.empty()) {
      frame_problems.add(k, problem);
    } else {
      rows.push_back({k, infos[k].header_t_ns, k});
    }
  }
  std::vector<std::size_t> messages;  // frame -> its message on the topic
  for (const auto& row : frame_problems.keep_increasing(std::move(rows))) {
    d->frames.push_back(io_detail::FrameEntry{row.t_ns, bag_file, row.value});
    messages.push_back(row.value);
  }
  frame_problems.report(log, infos.size());
  if (d->frames.empty()) throw DataError(bag_file, "topic " + topic + ": no usable image message");
  d->images_present = true;
  d->image_reader = [reader, topic, messages](std::size_t frame) {
    return read_grey(*reader, topic, messages.at(frame));
  };

  if (!options.bag_imu_topic.empty()) read_bag_imu(*reader, bag_file, options.bag_imu_topic, log, *d);

  // Calibration and ground truth: the bag has none; an EuRoC ASL folder gives them.
  if (const fs::path asl = asl_dir_for(bag_file, options); !asl.empty()) {
    const fs::path mav = fs::is_directory(asl / "mav0", ec) ? asl / "mav0" : asl;
    io_detail::read_euroc_calibration(asl, mav, options.camera_index, options.calibration_file, log, *d);
    io_detail::read_euroc_ground_truth(asl, mav, log, *d);
    spdlog::info(
        "{}: calibration and ground truth from {} (camera calibration {}, IMU calibration {}, {} "
        "ground-truth poses)",
        bag_file.string(), mav.string(), d->camera_calibration ? "yes" : "no", d->imu_calib ? "yes" : "no",
        d->gt.size());
  } else if (!options.calibration_file.empty()) {
    // No ASL folder, but a Kalibr chain named by the user: the calibration from it (and the IMU file beside
    // it), no ground truth.
    const fs::path folder = options.calibration_file.parent_path().empty()
                                ? fs::path(".")
                                : options.calibration_file.parent_path();
    io_detail::read_euroc_calibration(folder, folder, options.camera_index, options.calibration_file, log,
                                      *d);
  } else {
    spdlog::info(
        "{}: no calibration or ground truth (a bag carries none): set dataset.bag_asl_dir to the sequence's "
        "EuRoC ASL folder, or put it beside the bag as {}",
        bag_file.string(), fs::path(bag_file).replace_extension().string());
  }

  d->finish();
  io_detail::log_summary(*d);
  return d;
}

#endif

}  // namespace loopgate
