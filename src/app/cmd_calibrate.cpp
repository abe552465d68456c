// loopgate calibrate: derives the logistic constants mu and sigma of the DIRD similarity for one dataset,
// normalisation mode and metric from the dataset's own distance distributions (docs/detection.md § The
// paper's matcher; the rule is stated in stages/dird/dird_calibration.hpp) and prints them as a YAML `dird:`
// section.
#include <spdlog/spdlog.h>

#include <CLI/CLI.hpp>
#include <Eigen/Geometry>
#include <cmath>
#include <exception>
#include <filesystem>
#include <fstream>
#include <iostream>
#include <memory>
#include <optional>
#include <sstream>
#include <string>
#include <vector>

#include "app/commands.hpp"
#include "core/error.hpp"
#include "io/config.hpp"
#include "io/dataset.hpp"
#include "io/file_guard.hpp"
#include "io/writers.hpp"
#include "stages/dird/dird_calibration.hpp"
#include "stages/dird/dird_extractor.hpp"
#include "stages/dird/dird_similarity.hpp"

namespace loopgate::app {

namespace {

struct CalibrateOptions {
  std::string dataset;
  std::string normalization = "libdird";
  std::string metric = "l1";
  bool flip_vertical = false;
  int camera = 0;
  int margin = 200;
  int stride = 1;
  double revisit_radius_m = 3.0;
  double max_rotation_deg = 30.0;
  bool ignore_ground_truth = false;
  double tau1 = 0.05;
  double cutoff_quantile = 0.01;
  double mu_quantile = 0.0005;
  std::string out_file;
};

int run_calibrate(const CalibrateOptions& opt) {
  std::error_code ec;
  if (!opt.out_file.empty() && std::filesystem::exists(opt.out_file, ec) &&
      path_inside(opt.out_file, opt.dataset)) {
    throw ConfigError("--out " + opt.out_file + " is a file of the dataset " + opt.dataset +
                      ", whose files are inputs: it would be overwritten; choose another --out");
  }
  OpenOptions open_options;
  open_options.camera_index = opt.camera;
  const std::unique_ptr<Dataset> dataset = open_dataset(opt.dataset, open_options);
  if (!dataset->has_images()) throw DataError(opt.dataset, "the dataset has no images to describe");

  DirdConfig config;
  config.normalization = enum_value<DirdNormalization>(opt.normalization).value();
  config.flip_vertical = opt.flip_vertical;
  config.metric = enum_value<DirdMetric>(opt.metric).value();
  config.tau1 = opt.tau1;
  if (config.l2_metric()) {  // scale-only starting values so the config validates; calibration replaces them
    config.mu = kDirdScaleMuL2;
    config.sigma = kDirdScaleSigmaL2;
  }
  const DirdExtractor extractor(config);
  const DirdSimilarity similarity(config);

  // Descriptors (and ground-truth poses) of every stride-th frame.
  std::vector<std::size_t> frames;
  std::vector<Descriptor> descriptors;
  std::vector<std::optional<Eigen::Isometry3d>> poses;
  const bool use_truth = !opt.ignore_ground_truth && dataset->has_ground_truth();
  for (std::size_t f = 0; f < dataset->frame_count(); f += static_cast<std::size_t>(opt.stride)) {
    frames.push_back(f);
    descriptors.push_back(extractor.extract(dataset->load_image(f)));
    poses.push_back(use_truth ? dataset->ground_truth_T_w_b(f) : std::nullopt);
  }
  spdlog::info("calibrate: {} descriptors of {} frames ({} normalisation, stride {})", descriptors.size(),
               dataset->frame_count(), opt.normalization, opt.stride);

  const double max_rotation_rad = opt.max_rotation_deg * M_PI / 180.0;
  std::vector<double> beyond, revisits;
  for (std::size_t b = 0; b < frames.size(); ++b) {
    for (std::size_t a = 0; a < b; ++a) {
      if (frames[b] - frames[a] < static_cast<std::size_t>(opt.margin)) break;
      const double d = similarity.distance(descriptors[a], descriptors[b]);
      beyond.push_back(d);
      if (poses[a] && poses[b]) {
        const double gap_m = (poses[a]->translation() - poses[b]->translation()).norm();
        const double turn_rad =
            Eigen::AngleAxisd(poses[a]->linear().transpose() * poses[b]->linear()).angle();
        if (gap_m < opt.revisit_radius_m && turn_rad < max_rotation_rad) revisits.push_back(d);
      }
    }
  }
  if (beyond.empty()) {
    throw DataError(opt.dataset, "no frame pairs beyond the safety margin of " + std::to_string(opt.margin) +
                                     " frames (stride " + std::to_string(opt.stride) + ")");
  }
  LogisticCalibrationOptions options;
  options.tau1 = opt.tau1;
  options.cutoff_quantile = opt.cutoff_quantile;
  options.mu_quantile = opt.mu_quantile;
  const LogisticCalibration c = calibrate_logistic(beyond, revisits, options);

  std::ostringstream yaml;
  yaml.precision(8);
  yaml << "# loopgate calibrate " << opt.dataset << " (camera " << opt.camera << ", " << frames.size()
       << " frames of " << dataset->frame_count() << ", stride " << opt.stride << ", margin " << opt.margin
       << " frames)\n";
  yaml << "# rule: " << c.rule << "\n";
  yaml << "# beyond-margin pairs: " << c.beyond_count << ", median distance " << c.beyond_median << "\n";
  if (c.revisit_count > 0) {
    yaml << "# revisits (ground truth < " << opt.revisit_radius_m << " m and < " << opt.max_rotation_deg
         << " deg apart): " << c.revisit_count << ", median distance " << c.revisit_median << "\n";
  } else {
    yaml << "# revisits: none used (" << (use_truth ? "none found in the ground truth" : "no ground truth")
         << ")\n";
  }
  yaml << "# cut-off: sim = " << opt.tau1 << " at distance " << c.cutoff_distance << "\n";
  yaml << "dird:\n";
  yaml << "  normalization: " << opt.normalization << "\n";
  yaml << "  flip_vertical: " << (opt.flip_vertical ? "true" : "false") << "\n";
  yaml << "  metric: " << opt.metric << "\n";
  yaml << "  mu: " << c.mu << "\n";
  yaml << "  sigma: " << c.sigma << "\n";
  yaml << "  tau1: " << opt.tau1 << "\n";
  std::cout << yaml.str();
  if (!opt.out_file.empty()) {  // whole or absent: a temporary name, renamed when complete
    const std::filesystem::path partial = partial_path(opt.out_file);
    std::ofstream out(partial, std::ios::out | std::ios::trunc);
    if (!out) throw DataError(opt.out_file, "cannot open the output file for writing");
    out << yaml.str();
    out.close();
    ec.clear();
    if (out) std::filesystem::rename(partial, opt.out_file, ec);
    if (!out || ec) {
      std::filesystem::remove(partial, ec);
      throw DataError(opt.out_file, "write failed");
    }
  }
  spdlog::debug("calibrate: mu {:.1f}, sigma {:.1f} ({})", c.mu, c.sigma, c.rule);
  return kExitOk;
}

}  // namespace

void add_calibrate_command(CLI::App& app, int& exit_code) {
  auto opt = std::make_shared<CalibrateOptions>();
  CLI::App* cmd = app.add_subcommand(
      "calibrate",
      "Derive the DIRD logistic constants (dird.mu, dird.sigma) for a dataset, normalisation and metric "
      "from its distance distributions. Rule: sim = tau1 at the --cutoff-quantile of the distances of all "
      "frame pairs beyond the safety margin; sim = 0.5 at the median distance of ground-truth revisits "
      "(pairs beyond the margin closer than --revisit-radius-m and --max-rotation-deg), or without ground "
      "truth at the --mu-quantile of the beyond-margin distances. Prints a YAML 'dird:' section (use --out "
      "to save it: log lines may share standard output).");
  cmd->add_option("dataset", opt->dataset, "Dataset directory (EuRoC, KITTI or image folder)")->required();
  cmd->add_option("--normalization", opt->normalization, "libdird|l2")
      ->capture_default_str()
      ->check(CLI::IsMember({"libdird", "l2"}));
  cmd->add_option("--metric", opt->metric, "l1|l2")
      ->capture_default_str()
      ->check(CLI::IsMember({"l1", "l2"}));
  cmd->add_flag("--flip-vertical", opt->flip_vertical, "Read images bottom-up (reference tool)");
  cmd->add_option(
         "--camera", opt->camera,
         "Camera: 0, 1 (EuRoC cam0/cam1, KITTI image_0/image_1), 2, 3 (KITTI colour image_2/image_3)")
      ->capture_default_str()
      ->check(CLI::Range(0, 3));
  cmd->add_option("--margin", opt->margin, "Safety margin in frames (pairs closer in time are not used)")
      ->capture_default_str()
      ->check(CLI::NonNegativeNumber);
  cmd->add_option("--stride", opt->stride, "Use every N-th frame (faster on long datasets)")
      ->capture_default_str()
      ->check(CLI::PositiveNumber);
  cmd->add_option("--revisit-radius-m", opt->revisit_radius_m, "Ground-truth revisit radius in metres")
      ->capture_default_str()
      ->check(CLI::PositiveNumber);
  cmd->add_option("--max-rotation-deg", opt->max_rotation_deg,
                  "Largest rotation between the two poses of a revisit, in degrees")
      ->capture_default_str()
      ->check(CLI::PositiveNumber);
  cmd->add_flag("--ignore-ground-truth", opt->ignore_ground_truth,
                "Use the no-revisit rule even with ground truth");
  cmd->add_option("--tau1", opt->tau1, "Similarity at the cut-off (dird.tau1)")
      ->capture_default_str()
      ->check(CLI::Range(1e-6, 0.499));
  cmd->add_option("--cutoff-quantile", opt->cutoff_quantile,
                  "Quantile of the beyond-margin distances where sim = tau1")
      ->capture_default_str()
      ->check(CLI::Range(1e-6, 0.999));
  cmd->add_option("--mu-quantile", opt->mu_quantile,
                  "Without revisits: quantile of the beyond-margin distances where sim = 0.5")
      ->capture_default_str()
      ->check(CLI::Range(0.0, 0.999));
  cmd->add_option("--out", opt->out_file, "Also write the YAML section to this file");
  cmd->callback([opt, &exit_code]() {
    try {
      exit_code = run_calibrate(*opt);
    } catch (const std::exception& e) {
      spdlog::error("calibrate: {}", e.what());
      exit_code = kExitFailure;
    }
  });
}

}  // namespace loopgate::app
