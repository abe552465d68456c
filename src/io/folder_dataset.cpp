// Image folder reader for appearance-only sets (e.g. Nordland): every image file directly in DIR, in
// natural order (img2 before img10). Frame times come from an optional DIR/times.txt (seconds, one row
// per image, strictly increasing); without it, from the file names when they are 19-digit integers
// (nanosecond times, as EuRoC and TUM-VI name their images: 1403636579763555584.png), else frame i is at i /
// OpenOptions::folder_rate_hz seconds. In a folder of nanosecond names (more than half of its images), an
// image named otherwise, or a second image of the same time, is a problem (strict: the error; lenient: the
// file is skipped and every other image keeps its number, its position in the folder). No IMU, no ground
// truth, no calibration.
#include <spdlog/spdlog.h>

#include <charconv>
#include <cmath>
#include <optional>

#include "core/error.hpp"
#include "io/csv_formats.hpp"
#include "io/dataset.hpp"
#include "io/file_guard.hpp"
#include "io/loaded_dataset.hpp"

namespace loopgate {

namespace {

constexpr std::size_t kNsNameDigits = 19;  // nanoseconds since 1970: 19 digits from 2001 to 2286

// The time of an image named by 19 digits of nanoseconds, else nullopt. A leading 0 makes the name a
// zero-padded frame number, not a time (it would time the frames 1 ns apart, in 1970).
std::optional<Timestamp> ns_name(const std::filesystem::path& file) {
  const std::string stem = file.stem().string();
  if (stem.size() != kNsNameDigits || stem.front() == '0' ||
      stem.find_first_not_of("0123456789") != std::string::npos) {
    return std::nullopt;
  }
  Timestamp t_ns = 0;
  const auto [ptr, ec] = std::from_chars(stem.data(), stem.data() + stem.size(), t_ns);
  if (ec != std::errc{} || ptr != stem.data() + stem.size()) return std::nullopt;  // beyond int64
  return t_ns;
}

// Frames timed by their nanosecond names; false (nothing added) when at most half of the names are such.
bool frames_from_ns_names(const std::vector<std::filesystem::path>& files, io_detail::IssueLog& log,
                          io_detail::LoadedDataset& d) {
  std::vector<std::optional<Timestamp>> times;
  std::size_t named = 0;
  for (const auto& file : files) {
    times.push_back(ns_name(file));
    if (times.back()) ++named;
  }
  if (named == 0 || 2 * named <= files.size()) return false;
  // Natural order is time order for names of equal length; equal stems (a.png, a.jpg) are the one problem
  // left.
  std::string example;  // a good name, for the message about the others
  for (std::size_t i = 0; i < files.size() && example.empty(); ++i) {
    if (times[i]) example = files[i].filename().string();
  }
  for (std::size_t i = 0; i < files.size(); ++i) {
    if (!times[i]) {
      log.report(files[i], 0,
                 "image name is not a 19-digit nanosecond time like the other " + std::to_string(named) +
                     " of " + std::to_string(files.size()) + " images (e.g. " + example +
                     "), so it has no time (file ignored)");
      continue;
    }
    if (!d.frames.empty() && *times[i] <= d.frames.back().t_ns) {
      log.report(files[i], 0,
                 "second image for time " + std::to_string(*times[i]) + " ns besides " +
                     d.frames.back().image.filename().string() + " (file ignored)");
      continue;
    }
    d.frames.push_back(io_detail::FrameEntry{*times[i], files[i], i});
  }
  spdlog::info("{}: frame times from the image names (19-digit nanoseconds) of {} images",
               d.root_dir.string(), d.frames.size());
  return true;
}

}  // namespace

std::unique_ptr<Dataset> open_image_folder(const std::filesystem::path& dir, const OpenOptions& options) {
  namespace fs = std::filesystem;
  if (!std::isfinite(options.folder_rate_hz) || !(options.folder_rate_hz > 0)) {
    throw ConfigError("folder_rate_hz: " + std::to_string(options.folder_rate_hz) + ", expected > 0");
  }
  std::error_code ec;
  if (!fs::is_directory(dir, ec)) throw DataError(dir, "image folder not found");

  auto d = std::make_unique<io_detail::LoadedDataset>();
  d->layout_kind = DatasetLayout::kFolder;
  d->root_dir = dir;
  io_detail::IssueLog log(options.strict, &d->problems);

  const std::vector<fs::path> files = io_detail::list_image_files(dir);
  if (files.empty()) throw DataError(dir, "no image files, expected png, jpg or pgm images");
  d->images_present = true;

  const fs::path times_file = dir / "times.txt";
  if (fs::exists(times_file, ec)) require_regular_file(times_file);  // a FIFO would block open() forever
  if (fs::is_regular_file(times_file, ec)) {
    const std::vector<std::optional<Timestamp>> times = io_detail::read_kitti_time_rows(times_file, log);
    if (times.size() != files.size()) {
      log.report(times_file, 0,
                 std::to_string(times.size()) + " rows, expected one per image (" +
                     std::to_string(files.size()) + " images)" +
                     (times.size() < files.size() ? "; images without a time ignored" : ""));
    }
    std::size_t rejected = 0;
    for (std::size_t i = 0; i < std::min(times.size(), files.size()); ++i) {
      if (times[i]) {
        d->frames.push_back(io_detail::FrameEntry{*times[i], files[i], i});
      } else {
        ++rejected;
      }
    }
    if (rejected > 0) {
      spdlog::warn(
          "{}: {} row(s) rejected, so those images are skipped; every other image keeps its number (its "
          "position in the folder) in frames.csv and loops.csv, which shows the gap",
          times_file.string(), rejected);
    }
  } else if (!frames_from_ns_names(files, log, *d)) {
    for (std::size_t i = 0; i < files.size(); ++i) {
      d->frames.push_back(
          io_detail::FrameEntry{s_to_ns(static_cast<double>(i) / options.folder_rate_hz), files[i], i});
    }
    spdlog::info("{}: no times.txt, frames at {} Hz", dir.string(), options.folder_rate_hz);
  }

  d->finish();
  io_detail::log_summary(*d);
  return d;
}

}  // namespace loopgate
