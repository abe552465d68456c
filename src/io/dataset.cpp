#include "io/dataset.hpp"

#include <spdlog/spdlog.h>

#include <algorithm>
#include <cctype>
#include <cstdint>
#include <fstream>
#include <map>
#include <opencv2/imgcodecs.hpp>
#include <opencv2/imgproc.hpp>
#include <stdexcept>
#include <string_view>

#include "core/error.hpp"
#include "core/geometry.hpp"
#include "io/loaded_dataset.hpp"
#include "io/png_grey.hpp"

namespace loopgate {

std::string DataIssue::to_string() const {
  std::string text = file.string();
  if (line > 0) {
    text += ':';
    text += std::to_string(line);
  }
  text += ": ";
  text += message;
  return text;
}

std::span<const ImuSample> Dataset::imu_between(Timestamp t_begin_ns, Timestamp t_end_ns) const {
  const std::vector<ImuSample>& samples = imu_samples();
  std::size_t begin = 0;
  while (begin < samples.size() && samples[begin].t_ns < t_begin_ns) ++begin;
  std::size_t end = begin;
  while (end < samples.size() && samples[end].t_ns < t_end_ns) ++end;
  return std::span<const ImuSample>(samples).subspan(begin, end - begin);
}

std::vector<std::optional<Timestamp>> Dataset::source_times() const {
  std::vector<std::optional<Timestamp>> times;
  for (std::size_t frame = 0; frame < frame_count(); ++frame) {
    const std::size_t index = source_index(frame);
    if (index >= times.size()) times.resize(index + 1);
    times[index] = frame_t_ns(frame);
  }
  return times;
}

void image_codecs_ready() {
  static const bool ready = [] {
    std::vector<unsigned char> png;
    const cv::Mat pixel(1, 1, CV_8UC1, cv::Scalar(0));
    return cv::imencode(".png", pixel, png) && !cv::imdecode(png, cv::IMREAD_UNCHANGED).empty();
  }();
  if (!ready)
    throw std::runtime_error("OpenCV cannot encode and decode PNG images (imgcodecs without libpng?)");
}

cv::Mat to_8bit_samples(const cv::Mat& image, const std::filesystem::path& file, const std::string& where) {
  if (image.depth() == CV_8U) return image;
  if (image.depth() == CV_16U) {
    cv::Mat eight;
    image.convertTo(eight, CV_8U, 1.0 / 257.0);  // full range: 65535 -> 255, rounded
    return eight;
  }
  throw DataError(
      file,
      (where.empty() ? "" : where + ": ") + "image has " + std::to_string(image.elemSize1() * 8) + "-bit " +
          (image.depth() == CV_16S || image.depth() == CV_32S || image.depth() == CV_8S ? "signed integer"
                                                                                        : "floating-point") +
          " samples, expected 8-bit or 16-bit unsigned");
}

namespace io_detail {

namespace {

// Frames probed for the reference image size when the calibration does not give it, spread evenly over the
// sequence: the majority size wins, so that one odd frame (frame 0 of another size) does not make every
// other frame "the wrong size".
constexpr std::size_t kSizeProbeFrames = 15;

// Width and height from a PNG's IHDR chunk (no decoding); nullopt when `file` is not a PNG.
std::optional<std::pair<int, int>> png_size(const std::filesystem::path& file) {
  std::ifstream in(file, std::ios::binary);
  unsigned char header[24] = {};
  if (!in.read(reinterpret_cast<char*>(header), sizeof(header))) return std::nullopt;
  static constexpr unsigned char kSignature[12] = {0x89, 'P', 'N', 'G', '\r', '\n', 0x1a, '\n', 0, 0, 0, 13};
  if (!std::equal(std::begin(kSignature), std::end(kSignature), header) ||
      std::string_view(reinterpret_cast<const char*>(header + 12), 4) != "IHDR")
    return std::nullopt;
  const auto be32 = [&](int at) {
    return (std::uint32_t{header[at]} << 24) | (std::uint32_t{header[at + 1]} << 16) |
           (std::uint32_t{header[at + 2]} << 8) | std::uint32_t{header[at + 3]};
  };
  const std::uint32_t width = be32(16), height = be32(20);
  if (width == 0 || height == 0 || width > 1u << 20 || height > 1u << 20) return std::nullopt;
  return std::pair{static_cast<int>(width), static_cast<int>(height)};
}

bool natural_less(const std::string& a, const std::string& b) {
  std::size_t i = 0;
  std::size_t j = 0;
  while (i < a.size() && j < b.size()) {
    const bool da = std::isdigit(static_cast<unsigned char>(a[i])) != 0;
    const bool db = std::isdigit(static_cast<unsigned char>(b[j])) != 0;
    if (da && db) {
      std::size_t ie = i;
      while (ie < a.size() && std::isdigit(static_cast<unsigned char>(a[ie]))) ++ie;
      std::size_t je = j;
      while (je < b.size() && std::isdigit(static_cast<unsigned char>(b[je]))) ++je;
      // Compare by value: strip leading zeros, then longer is larger, then lexicographic.
      std::size_t is = i;
      while (is + 1 < ie && a[is] == '0') ++is;
      std::size_t js = j;
      while (js + 1 < je && b[js] == '0') ++js;
      if (ie - is != je - js) return ie - is < je - js;
      const int c = a.compare(is, ie - is, b, js, je - js);
      if (c != 0) return c < 0;
      if (ie - i != je - j) return ie - i < je - j;  // same value: fewer leading zeros first
      i = ie;
      j = je;
    } else {
      if (a[i] != b[j]) return a[i] < b[j];
      ++i;
      ++j;
    }
  }
  return a.size() - i < b.size() - j;
}

}  // namespace

bool is_image_file(const std::filesystem::path& file) {
  std::string ext = file.extension().string();
  std::transform(ext.begin(), ext.end(), ext.begin(), [](unsigned char c) { return std::tolower(c); });
  return ext == ".png" || ext == ".jpg" || ext == ".jpeg" || ext == ".pgm" || ext == ".ppm" ||
         ext == ".bmp" || ext == ".tif" || ext == ".tiff";
}

std::vector<std::filesystem::path> list_image_files(const std::filesystem::path& dir) {
  std::vector<std::filesystem::path> files;
  std::error_code ec;
  for (std::filesystem::directory_iterator it(dir, ec), end; !ec && it != end; it.increment(ec)) {
    if (is_image_file(it->path()) && it->is_regular_file(ec)) files.push_back(it->path());
  }
  if (ec) throw DataError(dir, "cannot list directory: " + ec.message());
  std::sort(files.begin(), files.end(), [](const auto& a, const auto& b) {
    return natural_less(a.filename().string(), b.filename().string());
  });
  return files;
}

void log_summary(const LoadedDataset& d) {
  spdlog::info(
      "{} dataset {}: {} frames{}, {} IMU samples, {} ground-truth poses, camera calibration {}{}",
      enum_name(d.layout_kind), d.root_dir.string(), d.frames.size(),
      d.images_present ? "" : " (images absent)", d.imu.size(), d.gt.size(),
      d.camera_calibration ? "yes" : "no",
      d.problems.empty() ? std::string() : ", " + std::to_string(d.problems.size()) + " problems skipped");
  if (!d.images_present && !d.frames.empty()) {
    spdlog::info(
        "{}: the image files are absent; timestamps, IMU, ground truth and calibration are available",
        d.root_dir.string());
  }
}

void LoadedDataset::finish() {
  if (!calibration_size_source.empty() && camera_calibration && camera_calibration->width_px > 0) {
    expected_width_px_ = camera_calibration->width_px;
    expected_height_px_ = camera_calibration->height_px;
    expected_size_source_ = calibration_size_source;
  } else if (images_present && !frames.empty()) {
    // The majority size of frames spread over the sequence (PNG headers are read, other files decoded).
    struct Probe {
      std::size_t frame;
      std::pair<int, int> size;
    };
    std::vector<Probe> probes;
    const std::size_t count = std::min(frames.size(), kSizeProbeFrames);
    for (std::size_t k = 0; k < count; ++k) {
      const std::size_t i = count == 1 ? 0 : k * (frames.size() - 1) / (count - 1);
      if (!image_reader) {
        std::error_code ec;
        if (!std::filesystem::is_regular_file(frames[i].image, ec)) continue;
        if (auto size = png_size(frames[i].image)) {
          probes.push_back({i, *size});
          continue;
        }
      }
      try {
        const cv::Mat image = decode(i);
        probes.push_back({i, {image.cols, image.rows}});
      } catch (const DataError& e) {
        spdlog::warn("{}", e.what());
      }
    }
    std::map<std::pair<int, int>, std::size_t> votes;
    for (const Probe& p : probes) ++votes[p.size];
    const Probe* chosen = nullptr;
    for (const Probe& p : probes) {  // most votes; on a tie, the size of the earliest frame
      if (!chosen || votes[p.size] > votes[chosen->size]) chosen = &p;
    }
    if (chosen) {
      expected_width_px_ = chosen->size.first;
      expected_height_px_ = chosen->size.second;
      expected_size_source_ = "most frames (" + std::to_string(votes[chosen->size]) + " of " +
                              std::to_string(probes.size()) + " probed, e.g. frame " +
                              std::to_string(chosen->frame) + " (" +
                              frames[chosen->frame].image.filename().string() + "))";
      std::string odd;
      for (const Probe& p : probes) {
        if (p.size == chosen->size) continue;
        odd += (odd.empty() ? "" : ", ") + std::string("frame ") + std::to_string(p.frame) + " (" +
               frames[p.frame].image.filename().string() + ") is " + std::to_string(p.size.first) + "x" +
               std::to_string(p.size.second);
      }
      if (!odd.empty()) {
        spdlog::warn("{}: images are {}x{} like {}; {}: frames of another size fail to load",
                     root_dir.string(), expected_width_px_, expected_height_px_, expected_size_source_, odd);
      }
    }
    if (camera_calibration && camera_calibration->width_px == 0) {
      camera_calibration->width_px = expected_width_px_;
      camera_calibration->height_px = expected_height_px_;
    }
  }
  imu_sorted_ = std::is_sorted(imu.begin(), imu.end(),
                               [](const ImuSample& a, const ImuSample& b) { return a.t_ns < b.t_ns; });
}

cv::Mat LoadedDataset::decode(std::size_t frame) const {
  const FrameEntry& entry = frames.at(frame);
  const std::string where = "frame " + std::to_string(entry.source_index);  // its number, as in frames.csv
  if (!images_present)
    throw DataError(entry.image, where + ": image absent (this dataset has no image files)");
  if (image_reader) return image_reader(frame);
  std::error_code ec;
  if (!std::filesystem::is_regular_file(entry.image, ec))
    throw DataError(entry.image, where + ": image file missing");
  std::ifstream in(entry.image, std::ios::binary | std::ios::ate);
  const std::streamoff size = in ? static_cast<std::streamoff>(in.tellg()) : -1;
  if (size < 0) throw DataError(entry.image, where + ": cannot read image file");
  std::vector<unsigned char> bytes(static_cast<std::size_t>(size));
  in.seekg(0);
  if (size > 0 && !in.read(reinterpret_cast<char*>(bytes.data()), size)) {
    throw DataError(entry.image, where + ": cannot read image file");
  }
  // 8-bit grey PNGs (EuRoC, TUM-VI, rendered) the fast way; every other file, or anything unexpected in
  // one, the general way (the same pixels; io/png_grey.hpp).
  if (cv::Mat grey = decode_png_grey8(bytes.data(), bytes.size()); !grey.empty()) return grey;
  cv::Mat image;
  image_codecs_ready();
  try {
    if (!bytes.empty()) image = cv::imdecode(bytes, cv::IMREAD_UNCHANGED);
  } catch (const cv::Exception& e) {
    throw DataError(entry.image, where + ": cannot decode image (" + e.what() + ")");
  }
  if (image.empty()) {
    throw DataError(entry.image, where + ": cannot decode image, expected an 8-bit PNG, JPEG or PGM file");
  }
  return to_grey_8bit(image, entry.image, where);
}

cv::Mat to_grey_8bit(const cv::Mat& image, const std::filesystem::path& file, const std::string& where) {
  const cv::Mat eight = to_8bit_samples(image, file, where);
  if (eight.channels() == 1) return eight;
  cv::Mat grey;
  if (eight.channels() == 3) {
    cv::cvtColor(eight, grey, cv::COLOR_BGR2GRAY);
  } else if (eight.channels() == 4) {
    cv::cvtColor(eight, grey, cv::COLOR_BGRA2GRAY);
  } else {
    throw DataError(file, where + ": image has " + std::to_string(eight.channels()) +
                              " channels, expected grey, RGB or RGBA");
  }
  return grey;
}

cv::Mat LoadedDataset::load_image(std::size_t frame) const {
  cv::Mat image = decode(frame);
  if (expected_width_px_ > 0 && (image.cols != expected_width_px_ || image.rows != expected_height_px_)) {
    throw DataError(frames[frame].image,
                    "frame " + std::to_string(frames[frame].source_index) + ": image is " +
                        std::to_string(image.cols) + "x" + std::to_string(image.rows) + ", expected " +
                        std::to_string(expected_width_px_) + "x" + std::to_string(expected_height_px_) +
                        " like " + expected_size_source_);
  }
  return image;
}

std::span<const ImuSample> LoadedDataset::imu_between(Timestamp t_begin_ns, Timestamp t_end_ns) const {
  if (!imu_sorted_) return Dataset::imu_between(t_begin_ns, t_end_ns);
  const auto by_time = [](const ImuSample& s, Timestamp t) { return s.t_ns < t; };
  const auto begin = std::lower_bound(imu.begin(), imu.end(), t_begin_ns, by_time);
  const auto end = t_end_ns <= t_begin_ns ? begin : std::lower_bound(begin, imu.end(), t_end_ns, by_time);
  return std::span<const ImuSample>(begin, end);
}

std::optional<Eigen::Isometry3d> LoadedDataset::ground_truth_T_w_b(std::size_t frame) const {
  const Timestamp t_ns = frames.at(frame).t_ns;
  if (gt.empty() || t_ns < gt.front().t_ns || t_ns > gt.back().t_ns) return std::nullopt;
  const auto after = std::upper_bound(gt.begin(), gt.end(), t_ns,
                                      [](Timestamp t, const GroundTruthState& s) { return t < s.t_ns; });
  const GroundTruthState& a = *(after - 1);  // a.t_ns <= t_ns (t_ns >= front)
  if (a.t_ns == t_ns || after == gt.end()) return a.T_w_b;
  return interpolate_pose(StampedPose{a.t_ns, a.T_w_b}, StampedPose{after->t_ns, after->T_w_b}, t_ns);
}

}  // namespace io_detail

std::unique_ptr<Dataset> open_dataset(const std::filesystem::path& dir, const OpenOptions& options) {
  namespace fs = std::filesystem;
  std::error_code ec;
  if (!fs::exists(dir, ec)) throw DataError(dir, "dataset directory not found");
  if (!fs::is_directory(dir, ec)) {
    if (dir.extension() == ".bag") return open_rosbag(dir, options);
    throw DataError(dir, "expected a dataset directory or a ROS1 .bag file, found another file");
  }
  if (fs::is_directory(dir / "mav0", ec) || fs::is_directory(dir / "cam0", ec) ||
      fs::is_directory(dir / "imu0", ec)) {
    return open_euroc(dir, options);
  }
  // KITTI sequences and image folders carry their calibration in their own form (calib.txt) or none.
  const auto no_calibration_file = [&](const char* layout) {
    if (!options.calibration_file.empty())
      throw DataError(options.calibration_file,
                      "--calibration / dataset.calibration: a Kalibr camera chain is read for EuRoC / TUM-VI "
                      "trees and ROS1 bags; " +
                          dir.string() + " is " + layout);
  };
  for (const char* camera : {"image_0", "image_1", "image_2", "image_3"}) {
    if (fs::is_directory(dir / camera, ec)) {
      no_calibration_file("a KITTI sequence (its calibration is calib.txt)");
      return open_kitti(dir, options);
    }
  }
  if (!io_detail::list_image_files(dir).empty()) {
    no_calibration_file("an image folder (no camera model is used)");
    return open_image_folder(dir, options);
  }
  if (fs::is_regular_file(dir / "times.txt", ec)) {
    no_calibration_file("a KITTI sequence (its calibration is calib.txt)");
    return open_kitti(dir, options);
  }
  throw DataError(
      dir,
      "no dataset found: expected mav0/ or cam0/ (EuRoC), image_0/ .. image_3/ or times.txt (KITTI), "
      "or image files (png, jpg, pgm)");
}

}  // namespace loopgate
