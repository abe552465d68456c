// KITTI odometry layout reader. DIR holds image_<k>/ (k = camera_index: 0, 1 the grey cameras, 2, 3 the
// colour ones, whose images are converted to grey) with images named by frame number (000000.png ...),
// times.txt (seconds, one row per frame), optional calib.txt (P0..P3: the camera's row P<k>) and ground truth
// as poses.txt, poses/NN.txt or, in the official tree, ../../poses/NN.txt (NN = DIR's name). The body frame
// is camera 0 (KITTI poses are T_w_cam0); the camera's offset from it comes from P<k>. A pose file has 12
// numbers per row (row i is frame i, timed by times.txt), or 13 with a time in seconds first (each row timed
// by itself: the rows need not be one per frame).
//
// Two ways frames are defined:
//  - times.txt inside DIR (the normal layout): one frame per row of times.txt; frame i shows image
//    i (a missing file fails only that frame's load_image).
//  - no times.txt in DIR but one in its parent (a subset folder such as kitti/00/frames, which holds
//    only images 000000, 001000, 002000 of sequence 00): the frames are the image files present, in
//    numeric order, each taking the time, pose and calibration rows of its number from the parent
//    (calib.txt and poses are looked for in DIR first, then in the parent). source_index(frame) gives
//    that number.
// Without calib.txt camera() is empty; with it, the size is that of the first decodable image.
#include <spdlog/spdlog.h>

#include <algorithm>
#include <charconv>
#include <cstdio>
#include <map>

#include "core/error.hpp"
#include "io/csv_formats.hpp"
#include "io/dataset.hpp"
#include "io/file_guard.hpp"
#include "io/loaded_dataset.hpp"
#include "io/trajectory_io.hpp"

namespace loopgate {

namespace {

namespace fs = std::filesystem;

constexpr int kKittiIndexDigits = 6;  // 000000.png

std::optional<std::size_t> frame_number(const fs::path& file) {
  const std::string stem = file.stem().string();
  if (stem.empty() || stem.find_first_not_of("0123456789") != std::string::npos) return std::nullopt;
  std::size_t index = 0;
  const auto [ptr, ec] = std::from_chars(stem.data(), stem.data() + stem.size(), index);
  if (ec != std::errc{} || ptr != stem.data() + stem.size()) return std::nullopt;
  return index;
}

fs::path default_image_name(const fs::path& image_dir, std::size_t index) {
  char name[32];
  std::snprintf(name, sizeof(name), "%0*zu.png", kKittiIndexDigits, index);
  return image_dir / name;
}

std::optional<fs::path> first_existing(const std::vector<fs::path>& candidates) {
  std::error_code ec;
  for (const fs::path& p : candidates) {
    if (fs::exists(p, ec)) require_regular_file(p);  // a FIFO would block open() forever
    if (fs::is_regular_file(p, ec)) return p;
  }
  return std::nullopt;
}

}  // namespace

std::unique_ptr<Dataset> open_kitti(const fs::path& dir, const OpenOptions& options) {
  if (options.camera_index < 0 || options.camera_index > 3) {
    throw ConfigError("camera_index: " + std::to_string(options.camera_index) +
                      ", expected 0..3 (image_0, image_1 grey; image_2, image_3 colour)");
  }
  std::error_code ec;
  if (!fs::is_directory(dir, ec)) throw DataError(dir, "KITTI sequence directory not found");
  const fs::path image_dir = dir / ("image_" + std::to_string(options.camera_index));

  // Where times.txt (and the sequence metadata) live.
  fs::path meta_dir = dir;
  bool subset = false;
  if (fs::exists(dir / "times.txt", ec)) require_regular_file(dir / "times.txt");
  if (!fs::is_regular_file(dir / "times.txt", ec)) {
    const fs::path parent = fs::absolute(dir, ec).parent_path();
    if (fs::is_directory(image_dir, ec) && fs::is_regular_file(parent / "times.txt", ec)) {
      meta_dir = parent;
      subset = true;
    } else {
      throw DataError(
          dir / "times.txt",
          "times.txt not found, expected KITTI layout (image_N/ with times.txt here or one level up)");
    }
  }

  auto d = std::make_unique<io_detail::LoadedDataset>();
  d->layout_name = "kitti";
  d->root_dir = dir;
  io_detail::IssueLog log(options.strict, &d->problems);

  const fs::path times_file = meta_dir / "times.txt";
  const std::vector<std::optional<Timestamp>> times = io_detail::read_kitti_time_rows(times_file, log);
  d->source_time_table = times;

  // Image files by frame number.
  std::map<std::size_t, fs::path> images;
  if (fs::is_directory(image_dir, ec)) {
    for (const fs::path& file : io_detail::list_image_files(image_dir)) {
      const std::optional<std::size_t> index = frame_number(file);
      if (!index) {
        log.report(file, 0, "image name is not a frame number, expected e.g. 000042.png (file ignored)");
      } else if (*index >= times.size()) {
        log.report(file, 0,
                   "image " + std::to_string(*index) + " has no row in " + times_file.string() + " (" +
                       std::to_string(times.size()) + " rows; file ignored)");
      } else if (!images.emplace(*index, file).second) {
        log.report(file, 0,
                   "second image for frame " + std::to_string(*index) + " besides " +
                       images[*index].filename().string() + " (file ignored)");
      }
    }
  }
  d->images_present = !images.empty();

  if (subset) {
    for (const auto& [index, file] : images) {
      if (times[index]) d->frames.push_back(io_detail::FrameEntry{*times[index], file, index});
    }
    spdlog::info("{}: no times.txt here: {} frames are the images present, timed by {}", dir.string(),
                 d->frames.size(), times_file.string());
  } else {
    std::size_t missing = 0;
    std::string rejected;  // the frames whose times.txt row was rejected: a gap in the numbering
    std::size_t rejected_count = 0;
    for (std::size_t i = 0; i < times.size(); ++i) {
      if (!times[i]) {
        if (++rejected_count <= 10) rejected += (rejected.empty() ? "" : ", ") + std::to_string(i);
        continue;
      }
      const auto it = images.find(i);
      d->frames.push_back(io_detail::FrameEntry{
          *times[i], it != images.end() ? it->second : default_image_name(image_dir, i), i});
      if (d->images_present && it == images.end()) ++missing;
    }
    if (rejected_count > 0) {
      spdlog::warn(
          "{}: {} row(s) rejected, so frame(s) {}{} are skipped; every other frame keeps its KITTI number "
          "(its image 000123.png is frame 123 in frames.csv and loops.csv), which shows the gap",
          times_file.string(), rejected_count, rejected, rejected_count > 10 ? ", ..." : "");
    }
    // Another camera's folder here: the user most likely wants that camera (KITTI's colour download has only
    // image_2/ and image_3/).
    std::string other;
    for (int k = 0; k <= 3 && other.empty() && !d->images_present; ++k) {
      const fs::path candidate = image_dir.parent_path() / ("image_" + std::to_string(k));
      if (k != options.camera_index && fs::is_directory(candidate, ec)) other = std::to_string(k);
    }
    if (!d->images_present && !other.empty()) {
      spdlog::warn(
          "{}: no images in {}, but image_{}/ is there: set run.camera_index={} to read it (frames have "
          "timestamps only)",
          dir.string(), image_dir.string(), other, other);
    } else if (!d->images_present) {
      spdlog::info("{}: no images in {}: frames have timestamps only", dir.string(), image_dir.string());
    } else if (missing > 0) {
      spdlog::warn("{}: {} of {} frames have no image file (those frames fail to load)", image_dir.string(),
                   missing, d->frames.size());
    }
  }

  if (d->frames.empty()) {
    throw DataError(subset ? image_dir : times_file,
                    subset ? "no usable frames: no image named by a frame number with a valid time"
                           : "no usable frames, expected one time in seconds per row");
  }

  // Ground truth (T_w_cam0 = T_w_b).
  std::vector<fs::path> pose_candidates = {dir / "poses.txt"};
  if (subset) pose_candidates.push_back(meta_dir / "poses.txt");
  const std::string sequence = fs::absolute(meta_dir, ec).filename().string();
  pose_candidates.push_back(meta_dir / "poses" / (sequence + ".txt"));
  pose_candidates.push_back(fs::absolute(meta_dir, ec).parent_path().parent_path() / "poses" /
                            (sequence + ".txt"));
  if (const auto poses_file = first_existing(pose_candidates)) {
    const auto rows = io_detail::read_kitti_pose_rows(*poses_file, log);
    const bool timed = std::any_of(rows.begin(), rows.end(), [](const auto& r) { return r && r->t_ns; });
    if (timed) {
      // 13 columns: each pose has its own time; it is interpolated to the frame times like EuRoC's.
      for (const auto& row : rows) {
        if (!row) continue;
        GroundTruthState s;
        s.t_ns = *row->t_ns;
        s.T_w_b = row->T_w_cam0;
        d->gt.push_back(s);
      }
      spdlog::info("{}: ground truth from {}, timed by its first column", dir.string(), poses_file->string());
    } else {
      // 12 columns: row i is frame i, timed by times.txt.
      if (rows.size() != times.size()) {
        log.report(*poses_file, 0,
                   std::to_string(rows.size()) + " poses, expected " + std::to_string(times.size()) +
                       " (the rows of " + times_file.string() + ")" +
                       (rows.size() > times.size() ? "; extra poses ignored" : "; ground truth ends early"));
      }
      for (std::size_t i = 0; i < std::min(rows.size(), times.size()); ++i) {
        if (!times[i] || !rows[i]) continue;
        GroundTruthState s;
        s.t_ns = *times[i];
        s.T_w_b = rows[i]->T_w_cam0;
        d->gt.push_back(s);
      }
    }
    spdlog::debug("{}: ground truth from {}", dir.string(), poses_file->string());
  }

  // Calibration.
  std::vector<fs::path> calib_candidates = {dir / "calib.txt"};
  if (subset) calib_candidates.push_back(meta_dir / "calib.txt");
  if (const auto calib_file = first_existing(calib_candidates)) {
    try {
      CameraCalibration camera = read_kitti_calib(*calib_file, options.camera_index);
      std::optional<Timestamp> first;
      std::optional<Timestamp> last;
      std::size_t count = 0;
      for (const auto& t : times) {
        if (!t) continue;
        if (!first) first = t;
        last = t;
        ++count;
      }
      if (count >= 2 && *last > *first) {
        camera.rate_hz = static_cast<double>(count - 1) / ns_to_s(*last - *first);
      }
      d->camera_calibration = camera;
    } catch (const DataError& e) {
      log.report(e.file(), e.line(), e.message() + " (calibration ignored)");
    }
  }

  d->finish();
  io_detail::log_summary(*d);
  return d;
}

}  // namespace loopgate
