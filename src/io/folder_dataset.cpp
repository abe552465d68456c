// Image folder reader for appearance-only sets (e.g. Nordland): every image file directly in DIR, in
// natural order (img2 before img10). Frame times come from an optional DIR/times.txt (seconds, one row
// per image, strictly increasing); without it frame i is at i / OpenOptions::folder_rate_hz seconds.
// No IMU, no ground truth, no calibration.
#include <spdlog/spdlog.h>

#include <cmath>

#include "core/error.hpp"
#include "io/csv_formats.hpp"
#include "io/dataset.hpp"
#include "io/file_guard.hpp"
#include "io/loaded_dataset.hpp"

namespace loopgate {

std::unique_ptr<Dataset> open_image_folder(const std::filesystem::path& dir, const OpenOptions& options) {
  namespace fs = std::filesystem;
  if (!std::isfinite(options.folder_rate_hz) || !(options.folder_rate_hz > 0)) {
    throw ConfigError("folder_rate_hz: " + std::to_string(options.folder_rate_hz) + ", expected > 0");
  }
  std::error_code ec;
  if (!fs::is_directory(dir, ec)) throw DataError(dir, "image folder not found");

  auto d = std::make_unique<io_detail::LoadedDataset>();
  d->layout_name = "folder";
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
  } else {
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
