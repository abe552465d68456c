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

// Where times.txt (and the sequence's metadata) live: `dir`, or one level up when `dir` holds only a subset
// of the images (image_N/ here, times.txt in the parent).
struct KittiPlace {
  fs::path meta_dir;
  bool subset = false;
};

KittiPlace locate_times(const fs::path& dir, const fs::path& image_dir) {
  std::error_code ec;
  KittiPlace place{dir, false};
  if (fs::exists(dir / "times.txt", ec)) require_regular_file(dir / "times.txt");
  if (fs::is_regular_file(dir / "times.txt", ec)) return place;
  const fs::path parent = fs::absolute(dir, ec).parent_path();
  if (fs::is_directory(image_dir, ec) && fs::is_regular_file(parent / "times.txt", ec)) {
    place.meta_dir = parent;
    place.subset = true;
    return place;
  }
  throw DataError(
      dir / "times.txt",
      "times.txt not found, expected KITTI layout (image_N/ with times.txt here or one level up)");
}

// The image files of `image_dir` by frame number; names that are not a frame number of times.txt, and second
// images of a frame, are reported and ignored.
std::map<std::size_t, fs::path> index_images(const fs::path& image_dir, const fs::path& times_file,
                                             std::size_t time_rows, io_detail::IssueLog& log) {
  std::map<std::size_t, fs::path> images;
  std::error_code ec;
  if (!fs::is_directory(image_dir, ec)) return images;
  for (const fs::path& file : io_detail::list_image_files(image_dir)) {
    const std::optional<std::size_t> index = frame_number(file);
    if (!index) {
      log.report(file, 0, "image name is not a frame number, expected e.g. 000042.png (file ignored)");
    } else if (*index >= time_rows) {
      log.report(file, 0,
                 "image " + std::to_string(*index) + " has no row in " + times_file.string() + " (" +
                     std::to_string(time_rows) + " rows; file ignored)");
    } else if (!images.emplace(*index, file).second) {
      log.report(file, 0,
                 "second image for frame " + std::to_string(*index) + " besides " +
                     images[*index].filename().string() + " (file ignored)");
    }
  }
  return images;
}

// A whole sequence: one frame per valid times.txt row (its image, or the default name when it is missing),
// with warnings for rejected rows, missing images and images found under another camera's folder.
void add_sequence_frames(io_detail::LoadedDataset& d, const std::vector<std::optional<Timestamp>>& times,
                         const std::map<std::size_t, fs::path>& images, const fs::path& dir,
                         const fs::path& image_dir, const fs::path& times_file, int camera_index) {
  std::size_t missing = 0;
  std::string rejected;  // the frames whose times.txt row was rejected: a gap in the numbering
  std::size_t rejected_count = 0;
  for (std::size_t i = 0; i < times.size(); ++i) {
    if (!times[i]) {
      if (++rejected_count <= 10) rejected += (rejected.empty() ? "" : ", ") + std::to_string(i);
      continue;
    }
    const auto it = images.find(i);
    d.frames.push_back(io_detail::FrameEntry{
        *times[i], it != images.end() ? it->second : default_image_name(image_dir, i), i});
    if (d.images_present && it == images.end()) ++missing;
  }
  if (rejected_count > 0) {
    spdlog::warn(
        "{}: {} row(s) rejected, so frame(s) {}{} are skipped; every other frame keeps its KITTI number "
        "(its image 000123.png is frame 123 in frames.csv and loops.csv), which shows the gap",
        times_file.string(), rejected_count, rejected, rejected_count > 10 ? ", ..." : "");
  }
  // Another camera's folder here: the user most likely wants that camera (KITTI's colour download has only
  // image_2/ and image_3/).
  std::error_code ec;
  std::string other;
  for (int k = 0; k <= 3 && other.empty() && !d.images_present; ++k) {
    const fs::path candidate = image_dir.parent_path() / ("image_" + std::to_string(k));
    if (k != camera_index && fs::is_directory(candidate, ec)) other = std::to_string(k);
  }
  if (!d.images_present && !other.empty()) {
    spdlog::warn(
        "{}: no images in {}, but image_{}/ is there: set run.camera_index={} to read it (frames have "
        "timestamps only)",
        dir.string(), image_dir.string(), other, other);
  } else if (!d.images_present) {
    spdlog::info("{}: no images in {}: frames have timestamps only", dir.string(), image_dir.string());
  } else if (missing > 0) {
    spdlog::warn("{}: {} of {} frames have no image file (those frames fail to load)", image_dir.string(),
                 missing, d.frames.size());
  }
}

// Ground truth (T_w_cam0 = T_w_b) from the first poses file found: 13 columns carry their own times, 12
// columns are row i = frame i, timed by times.txt.
void read_ground_truth(io_detail::LoadedDataset& d, const std::vector<fs::path>& candidates,
                       const std::vector<std::optional<Timestamp>>& times, const fs::path& times_file,
                       const fs::path& dir, io_detail::IssueLog& log) {
  const auto poses_file = first_existing(candidates);
  if (!poses_file) return;
  const auto rows = io_detail::read_kitti_pose_rows(*poses_file, log);
  const bool timed = std::any_of(rows.begin(), rows.end(), [](const auto& r) { return r && r->t_ns; });
  if (timed) {
    // 13 columns: each pose has its own time; it is interpolated to the frame times like EuRoC's.
    for (const auto& row : rows) {
      if (!row) continue;
      GroundTruthState s;
      s.t_ns = *row->t_ns;
      s.T_w_b = row->T_w_cam0;
      d.gt.push_back(s);
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
      d.gt.push_back(s);
    }
  }
  spdlog::debug("{}: ground truth from {}", dir.string(), poses_file->string());
}

// The camera of `camera_index` from the first calib.txt found, its rate from the valid frame times; a bad
// file is reported and ignored.
void read_calibration(io_detail::LoadedDataset& d, const std::vector<fs::path>& candidates,
                      const std::vector<std::optional<Timestamp>>& times, int camera_index,
                      io_detail::IssueLog& log) {
  const auto calib_file = first_existing(candidates);
  if (!calib_file) return;
  try {
    CameraCalibration camera = read_kitti_calib(*calib_file, camera_index);
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
    d.camera_calibration = camera;
  } catch (const DataError& e) {
    log.report(e.file(), e.line(), e.message() + " (calibration ignored)");
  }
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
  const KittiPlace place = locate_times(dir, image_dir);
  const fs::path& meta_dir = place.meta_dir;
  const bool subset = place.subset;

  auto d = std::make_unique<io_detail::LoadedDataset>();
  d->layout_kind = DatasetLayout::kKitti;
  d->root_dir = dir;
  io_detail::IssueLog log(options.strict, &d->problems);

  const fs::path times_file = meta_dir / "times.txt";
  const std::vector<std::optional<Timestamp>> times = io_detail::read_kitti_time_rows(times_file, log);
  d->source_time_table = times;

  const std::map<std::size_t, fs::path> images = index_images(image_dir, times_file, times.size(), log);
  d->images_present = !images.empty();

  if (subset) {
    for (const auto& [index, file] : images) {
      if (times[index]) d->frames.push_back(io_detail::FrameEntry{*times[index], file, index});
    }
    spdlog::info("{}: no times.txt here: {} frames are the images present, timed by {}", dir.string(),
                 d->frames.size(), times_file.string());
  } else {
    add_sequence_frames(*d, times, images, dir, image_dir, times_file, options.camera_index);
  }

  if (d->frames.empty()) {
    throw DataError(subset ? image_dir : times_file,
                    subset ? "no usable frames: no image named by a frame number with a valid time"
                           : "no usable frames, expected one time in seconds per row");
  }

  std::vector<fs::path> pose_candidates = {dir / "poses.txt"};
  if (subset) pose_candidates.push_back(meta_dir / "poses.txt");
  const std::string sequence = fs::absolute(meta_dir, ec).filename().string();
  pose_candidates.push_back(meta_dir / "poses" / (sequence + ".txt"));
  pose_candidates.push_back(fs::absolute(meta_dir, ec).parent_path().parent_path() / "poses" /
                            (sequence + ".txt"));
  read_ground_truth(*d, pose_candidates, times, times_file, dir, log);

  std::vector<fs::path> calib_candidates = {dir / "calib.txt"};
  if (subset) calib_candidates.push_back(meta_dir / "calib.txt");
  read_calibration(*d, calib_candidates, times, options.camera_index, log);

  d->finish();
  io_detail::log_summary(*d);
  return d;
}

}  // namespace loopgate
