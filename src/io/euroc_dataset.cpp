// EuRoC ASL layout reader: DIR/mav0/... or DIR pointing at mav0.
//   cam<k>/data.csv (+ cam<k>/data/*.png, may be absent), cam<k>/sensor.yaml   required / optional
//   imu0/data.csv, imu0/sensor.yaml                                             optional
//   state_groundtruth_estimate0/data.csv (+ sensor.yaml T_BS)                   optional
//   mocap0/data.csv (+ sensor.yaml T_BS), TUM-VI                                optional
//   ../camchain-imucam.yaml, ../imu.yaml (or dso/...), Kalibr, TUM-VI            optional
// Ground truth is the body (= IMU for EuRoC) pose: when the ground-truth sensor.yaml has a T_BS that is
// not the identity, the estimated sensor pose T_w_s is turned into T_w_b = T_w_s * T_BS^-1.
// Without state_groundtruth_estimate0/data.csv, TUM-VI's mocap0/data.csv (t_ns, p_xyz, q_wxyz: TUM-VI gives
// the pose of the IMU, its motion-capture marker frame moved to the IMU with their calibration, so it is the
// body pose as it is; a mocap0/sensor.yaml T_BS other than the identity is applied like the ground truth's),
// else a TUM file "groundtruth_tum.txt" beside mav0/ (as in the shared V1_01_easy_micro excerpt) or inside
// it. Calibration without cam<k>/sensor.yaml or imu0/sensor.yaml: Kalibr files (kalibr_calibration.hpp) in
// the tree's root (the folder holding mav0/) or its dso/ folder, as TUM-VI ships them: camchain-imucam.yaml
// (Kalibr's own name camchain-imucam-<bag>.yaml, OpenVINS' kalibr_imucam_chain.yaml) or camchain.yaml for the
// camera, imu.yaml (imu-<bag>.yaml, OpenVINS' kalibr_imu_chain.yaml) or imu_config.yaml for the IMU.
#include <spdlog/spdlog.h>

#include <algorithm>

#include "core/error.hpp"
#include "io/csv_formats.hpp"
#include "io/dataset.hpp"
#include "io/file_guard.hpp"
#include "io/kalibr_calibration.hpp"
#include "io/loaded_dataset.hpp"
#include "io/trajectory_io.hpp"

namespace loopgate {

namespace {

namespace fs = std::filesystem;

// Reads an optional calibration file: in lenient mode a malformed one is recorded and skipped.
template <class Read>
auto read_optional_yaml(const fs::path& file, io_detail::IssueLog& log, Read&& read)
    -> std::optional<decltype(read(file))> {
  std::error_code ec;
  if (fs::exists(file, ec)) require_regular_file(file);  // a FIFO would block open() forever
  if (!fs::is_regular_file(file, ec)) {
    spdlog::debug("{}: absent", file.string());
    return std::nullopt;
  }
  try {
    return read(file);
  } catch (const DataError& e) {
    log.report(e.file(), e.line(), e.message() + " (calibration ignored)");
    return std::nullopt;
  }
}

bool is_identity(const Eigen::Isometry3d& T) {
  return T.matrix().isApprox(Eigen::Matrix4d::Identity(), 0.0);
}

// The first of `names` that is a file in one of `dirs` (in that order).
std::optional<fs::path> first_file(const std::vector<fs::path>& dirs,
                                   std::initializer_list<const char*> names) {
  std::error_code ec;
  for (const fs::path& dir : dirs) {
    for (const char* name : names) {
      const std::string pattern = name;
      const std::size_t star = pattern.find('*');
      std::vector<fs::path> candidates;
      if (star == std::string::npos) {
        candidates.push_back(dir / name);
      } else if (fs::is_directory(dir, ec)) {
        // "camchain-imucam*.yaml": Kalibr names its outputs after the bag (camchain-imucam-<bag>.yaml).
        const std::string head = pattern.substr(0, star), tail = pattern.substr(star + 1);
        for (const auto& entry : fs::directory_iterator(dir, ec)) {
          const std::string file = entry.path().filename().string();
          if (file.size() >= head.size() + tail.size() && file.starts_with(head) && file.ends_with(tail))
            candidates.push_back(entry.path());
        }
        std::sort(candidates.begin(), candidates.end());
        if (candidates.size() > 1)
          spdlog::warn("{}: {} files match {}: {} is used", dir.string(), candidates.size(), pattern,
                       candidates.front().filename().string());
      }
      for (const fs::path& file : candidates) {
        if (fs::exists(file, ec)) require_regular_file(file);  // a FIFO would block open() forever
        if (fs::is_regular_file(file, ec)) return file;
      }
    }
  }
  return std::nullopt;
}

// Where Kalibr files are looked for: the tree's root (the folder holding mav0/, also when `dir` is mav0
// itself) and its dso/ folder (TUM-VI).
std::vector<fs::path> kalibr_dirs(const fs::path& dir, const fs::path& mav) {
  fs::path root = dir;
  if (mav == dir) {
    std::error_code ec;
    fs::path absolute = fs::absolute(dir, ec).lexically_normal();
    if (absolute.filename().empty()) absolute = absolute.parent_path();
    if (absolute.filename() == "mav0") root = absolute.parent_path();
  }
  return {root, root / "dso"};
}

// Moves ground truth given for a sensor frame to the body frame when the sensor.yaml beside it has a T_BS
// that is not the identity.
void apply_sensor_T_BS(const fs::path& gt_dir, io_detail::IssueLog& log, std::vector<GroundTruthState>& gt) {
  const auto T_BS = read_optional_yaml(gt_dir / "sensor.yaml", log,
                                       [](const fs::path& f) { return io_detail::read_yaml_T_BS(f); });
  if (!T_BS || is_identity(*T_BS)) return;
  const Eigen::Isometry3d T_s_b = T_BS->inverse();
  for (GroundTruthState& s : gt) s.T_w_b = s.T_w_b * T_s_b;
  spdlog::info("{}: ground truth moved from its sensor frame to the body frame (T_BS not identity)",
               (gt_dir / "data.csv").string());
}

}  // namespace

namespace io_detail {

void read_euroc_calibration(const fs::path& dir, const fs::path& mav, int camera_index,
                            const fs::path& calibration_file, IssueLog& log, LoadedDataset& d) {
  std::error_code ec;
  const std::string cam_name = "cam" + std::to_string(camera_index);
  const fs::path cam_dir = mav / cam_name;
  std::vector<fs::path> kalibr = kalibr_dirs(dir, mav);
  if (!calibration_file.empty()) {
    // Named by the user: used whatever the tree holds, and an unusable file is an error, not a skip.
    if (!fs::exists(calibration_file, ec))
      throw DataError(calibration_file,
                      "calibration file not found (--calibration / dataset.calibration: a Kalibr "
                      "camchain-imucam*.yaml or OpenVINS kalibr_imucam_chain.yaml)");
    require_regular_file(calibration_file);
    d.camera_calibration = read_kalibr_camchain(calibration_file, camera_index);
    d.calibration_size_source = calibration_file.filename().string() + " " + cam_name + ".resolution";
    spdlog::info("{}: camera calibration from {} (--calibration)", dir.string(), calibration_file.string());
    kalibr.insert(kalibr.begin(),
                  calibration_file.parent_path().empty() ? fs::path(".") : calibration_file.parent_path());
  } else if (fs::exists(cam_dir / "sensor.yaml", ec)) {
    d.camera_calibration = read_optional_yaml(cam_dir / "sensor.yaml", log,
                                              [](const fs::path& f) { return read_euroc_camera_yaml(f); });
    if (d.camera_calibration) d.calibration_size_source = cam_name + "/sensor.yaml resolution";
  } else if (const auto chain =
                 first_file(kalibr, {"camchain-imucam.yaml", "camchain-imucam*.yaml",
                                     "kalibr_imucam_chain.yaml", "camchain.yaml", "camchain-*.yaml"})) {
    d.camera_calibration = read_optional_yaml(
        *chain, log, [&](const fs::path& f) { return read_kalibr_camchain(f, camera_index); });
    if (d.camera_calibration) {
      d.calibration_size_source = chain->filename().string() + " " + cam_name + ".resolution";
      spdlog::info("{}: no {}/sensor.yaml: camera calibration from Kalibr {}", dir.string(), cam_name,
                   chain->string());
    }
  }
  if (fs::exists(mav / "imu0" / "sensor.yaml", ec)) {
    d.imu_calib = read_optional_yaml(mav / "imu0" / "sensor.yaml", log,
                                     [](const fs::path& f) { return read_euroc_imu_yaml(f); });
  } else if (const auto imu_yaml =
                 first_file(kalibr, {"imu.yaml", "imu-*.yaml", "kalibr_imu_chain.yaml", "imu_config.yaml"})) {
    d.imu_calib = read_optional_yaml(*imu_yaml, log, [](const fs::path& f) { return read_kalibr_imu(f); });
    if (d.imu_calib) {
      spdlog::info("{}: no imu0/sensor.yaml: IMU calibration from Kalibr {}", dir.string(),
                   imu_yaml->string());
    }
  }
}

void read_euroc_ground_truth(const fs::path& dir, const fs::path& mav, IssueLog& log, LoadedDataset& d) {
  std::error_code ec;
  const fs::path gt_dir = mav / "state_groundtruth_estimate0";
  const fs::path mocap_dir = mav / "mocap0";
  if (fs::exists(gt_dir / "data.csv", ec)) {
    d.gt = read_euroc_groundtruth(gt_dir / "data.csv", log);
    apply_sensor_T_BS(gt_dir, log, d.gt);
  } else if (fs::exists(mocap_dir / "data.csv", ec)) {
    d.gt = read_mocap_groundtruth(mocap_dir / "data.csv", log);
    apply_sensor_T_BS(mocap_dir, log, d.gt);
    spdlog::info("{}: ground truth from {} (TUM-VI motion capture, the IMU's pose)", dir.string(),
                 (mocap_dir / "data.csv").string());
  } else {
    for (const fs::path& tum : {mav.parent_path() / "groundtruth_tum.txt", mav / "groundtruth_tum.txt"}) {
      if (fs::exists(tum, ec)) require_regular_file(tum);
      if (!fs::is_regular_file(tum, ec)) continue;
      for (const StampedPose& pose : read_tum(tum, log)) {
        GroundTruthState s;
        s.t_ns = pose.t_ns;
        s.T_w_b = pose.T_w_b;
        d.gt.push_back(s);
      }
      spdlog::info("{}: ground truth from {}", dir.string(), tum.string());
      break;
    }
  }
}

}  // namespace io_detail

std::unique_ptr<Dataset> open_euroc(const fs::path& dir, const OpenOptions& options) {
  if (options.camera_index != 0 && options.camera_index != 1) {
    throw ConfigError(
        "camera_index: " + std::to_string(options.camera_index) +
        ", expected 0 or 1 for the EuRoC layout (cam0, cam1; 2 and 3 are KITTI's colour cameras)");
  }
  std::error_code ec;
  if (!fs::is_directory(dir, ec)) throw DataError(dir, "EuRoC dataset directory not found");
  const fs::path mav = fs::is_directory(dir / "mav0", ec) ? dir / "mav0" : dir;
  const std::string cam_name = "cam" + std::to_string(options.camera_index);
  const fs::path cam_dir = mav / cam_name;
  if (!fs::is_directory(cam_dir, ec)) {
    throw DataError(cam_dir,
                    "camera directory not found, expected EuRoC layout mav0/" + cam_name + "/data.csv");
  }

  auto d = std::make_unique<io_detail::LoadedDataset>();
  d->layout_kind = DatasetLayout::kEuroc;
  d->root_dir = dir;
  io_detail::IssueLog log(options.strict, &d->problems);

  // Frames.
  const std::vector<EurocImageEntry> entries = io_detail::read_euroc_camera_csv(cam_dir / "data.csv", log);
  if (entries.empty()) {
    throw DataError(cam_dir / "data.csv", "no usable frames, expected rows of 'timestamp [ns],filename'");
  }
  const fs::path data_dir = cam_dir / "data";
  const bool data_dir_present = fs::is_directory(data_dir, ec);
  std::size_t missing = 0;
  d->frames.reserve(entries.size());
  for (std::size_t i = 0; i < entries.size(); ++i) {
    // The frame's number is its data row (rows rejected before it keep their numbers: a gap, not a shift).
    d->frames.push_back(
        io_detail::FrameEntry{entries[i].t_ns, data_dir / entries[i].filename, entries[i].index});
    if (data_dir_present && !fs::is_regular_file(d->frames.back().image, ec)) ++missing;
  }
  d->images_present = data_dir_present && missing < entries.size();
  if (!d->images_present) {
    spdlog::info("{}: no images ({} absent): frames have timestamps only", cam_dir.string(),
                 data_dir_present ? "every listed file is" : "data/ is");
  } else if (missing > 0) {
    spdlog::warn("{}: {} of {} images listed in data.csv are missing (those frames fail to load)",
                 data_dir.string(), missing, entries.size());
  }

  // Calibration: the EuRoC sensor.yaml files, else Kalibr files (TUM-VI).
  io_detail::read_euroc_calibration(dir, mav, options.camera_index, options.calibration_file, log, *d);

  // IMU.
  const fs::path imu_csv = mav / "imu0" / "data.csv";
  if (fs::exists(imu_csv, ec)) {
    d->imu = io_detail::read_euroc_imu(imu_csv, log);
    d->imu_present = true;
  }

  // Ground truth.
  io_detail::read_euroc_ground_truth(dir, mav, log, *d);

  d->finish();
  io_detail::log_summary(*d);
  return d;
}

}  // namespace loopgate
