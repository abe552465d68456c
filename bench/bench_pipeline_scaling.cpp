// The cost of loop detection as the map grows (the paper's Fig. 8 at 100x its 4 541 frames): the
// whole pipeline (run_pipeline: the graph, the gate, DIRD, the DP + NMS, every output) over a synthetic drive
// held in memory, where images add nothing but their descriptors' cost:
//
//   route   an avenue driven east at 1 m per frame; every cycle it drives `advance_m` of new avenue plus the
//           `revisit_m` already driven at the end of the previous cycle, then goes round a block (north
//           `block_m`, west `revisit_m`, south `block_m`) and drives the last `revisit_m` again, in the same
//           direction: a genuine revisit of `revisit_m` frames every (advance_m + 2 revisit_m + 2 block_m)
//           frames (460 with the defaults), and the route never comes back anywhere else.
//   images  `image_width_px` x `image_height_px` grey: a window onto the street's facade, a random texture
//           fixed per street and position, shifted by 1/16 of the width per metre (neighbouring frames
//           overlap as when driving, though DIRD finds them as different as unrelated places), plus noise
//           that differs per pass.
//   poses   odometry from a TUM file written here: the truth plus a bounded, slowly varying offset
//           (`odometry_offset_m`), with a constant covariance (odometry.file_sigma2_a_m2, b = 0): the
//           uncertainty of an odometry corrected by its loops or localised in a map, so that the gate's
//           threshold is the same at frame 100 000 as at frame 1 000. (Open-loop drift odometry grows its
//           covariance with the distance travelled, and the gate's threshold with it.)
//   DIRD    the logistic calibrated on the first `calibrate_frames` frames (dird_calibration.hpp's rule, the
//           revisits being the pairs beyond the margin at the same place, within 0.5 m).
//
// Usage (a program that prints figures, not a Google Benchmark; bench/scaling.sh runs it at several sizes
// and makes the table and the plot):
//   build/release/bench_pipeline_scaling --frames 100000 --mode gated --out /tmp/scaling/gated-100000
//       [--threads 2] [--advance-m 200] [--revisit-m 100] [--block-m 30] [--image-width-px 64]
//       [--image-height-px 32] [--calibrate-frames 1400] [--odometry-offset-m 0.5] [--set
//       section.key=value]...
// Writes OUT/odometry.tum and the run's folder OUT/run (timing.csv, frames.csv, summary.json, ...) and prints
// one line of figures.
#include <spdlog/spdlog.h>

#include <Eigen/Geometry>
#include <algorithm>
#include <cmath>
#include <cstdio>
#include <cstdlib>
#include <filesystem>
#include <fstream>
#include <map>
#include <opencv2/core.hpp>
#include <opencv2/imgproc.hpp>
#include <stdexcept>
#include <string>
#include <vector>

#include "io/config.hpp"
#include "io/dataset.hpp"
#include "pipeline/pipeline.hpp"
#include "stages/dird/dird_calibration.hpp"
#include "stages/dird/dird_extractor.hpp"
#include "stages/dird/dird_similarity.hpp"

namespace loopgate {
namespace {

namespace fs = std::filesystem;

struct ScalingOptions {
  std::size_t frames = 10'000;
  std::string mode = "gated";
  std::string out_dir;
  int threads = 2;
  int advance_m = 200;
  int revisit_m = 100;
  int block_m = 30;
  int image_width_px = 64;
  int image_height_px = 32;
  std::size_t calibrate_frames = 1400;
  double odometry_offset_m = 0.5;
  std::vector<std::string> overrides;
};

// Where frame k is (1 m per frame) and what it shows.
struct RoutePoint {
  Eigen::Vector2d p_w_m;
  double heading_rad = 0;
  std::uint64_t street = 0;  // the facade's seed
  long along_m = 0;          // position along the street (the facade's window)
  std::uint64_t pass = 0;    // differs between two passes of the same place (the noise's seed)
};

class ScalingRoute {
 public:
  explicit ScalingRoute(const ScalingOptions& o)
      : advance_(o.advance_m), revisit_(o.revisit_m), block_(o.block_m) {}

  std::size_t cycle_frames() const { return static_cast<std::size_t>(advance_ + 2 * revisit_ + 2 * block_); }

  RoutePoint at(std::size_t frame) const {
    const std::size_t cycle = frame / cycle_frames();
    auto k = static_cast<long>(frame % cycle_frames());
    const double x0 = static_cast<double>(cycle) * advance_;  // the previous cycle's last revisit_ metres
    RoutePoint r;
    r.pass = frame;
    const long avenue = advance_ + revisit_;  // cycle 0 drives the first revisit_ metres for the first time
    if (k < avenue) {                         // east along the avenue (y = 0)
      r.p_w_m = {x0 + static_cast<double>(k), 0.0};
      r.heading_rad = 0.0;
      r.street = 1;
      r.along_m = static_cast<long>(x0) + k;
      return r;
    }
    k -= avenue;
    const double x_end = x0 + static_cast<double>(avenue);
    const std::uint64_t leg_base = 4 * (cycle + 1);  // three streets of its own per cycle
    if (k < block_) {                                // north
      r.p_w_m = {x_end, static_cast<double>(k)};
      r.heading_rad = M_PI / 2;
      r.street = leg_base;
      r.along_m = k;
      return r;
    }
    k -= block_;
    if (k < revisit_) {  // west, one street north of the avenue
      r.p_w_m = {x_end - static_cast<double>(k), static_cast<double>(block_)};
      r.heading_rad = M_PI;
      r.street = leg_base + 1;
      r.along_m = k;
      return r;
    }
    k -= revisit_;  // south, back to the avenue at x_end - revisit_: the next cycle drives it again
    r.p_w_m = {x_end - static_cast<double>(revisit_), static_cast<double>(block_ - k)};
    r.heading_rad = -M_PI / 2;
    r.street = leg_base + 2;
    r.along_m = k;
    return r;
  }

 private:
  int advance_, revisit_, block_;
};

Eigen::Isometry3d pose_of(const RoutePoint& r) {
  Eigen::Isometry3d T = Eigen::Isometry3d::Identity();
  T.translation() = Eigen::Vector3d(r.p_w_m.x(), r.p_w_m.y(), 0.0);
  T.linear() = Eigen::AngleAxisd(r.heading_rad, Eigen::Vector3d::UnitZ()).toRotationMatrix();
  return T;
}

// The drive as a Dataset: 10 Hz, images generated on demand, ground truth, no IMU.
class ScalingDataset : public Dataset {
 public:
  ScalingDataset(const ScalingOptions& o) : options_(o), route_(o), root_("/synthetic/scaling") {}

  DatasetLayout layout() const override { return DatasetLayout::kMemory; }
  const fs::path& root() const override { return root_; }
  std::size_t frame_count() const override { return options_.frames; }
  Timestamp frame_t_ns(std::size_t frame) const override {
    return 1'000'000'000 + static_cast<Timestamp>(frame) * 100'000'000;
  }
  bool has_images() const override { return true; }
  fs::path image_path(std::size_t frame) const override {
    return root_ / ("frame_" + std::to_string(frame) + ".png");
  }
  // The facade: cells kCellPx wide, kFacadeRows values high, each a hash of (street, cell, row); the
  // image at metre m shows the cells from kCellsPerMetre * m on, magnified to the image size.
  cv::Mat load_image(std::size_t frame) const override {
    const RoutePoint r = route_.at(frame);
    constexpr int kFacadeRows = 8, kCellsPerMetre = 1;
    const int cells = std::max(2, options_.image_width_px / kCellPx);
    cv::Mat small(kFacadeRows, cells, CV_8UC1);
    for (int c = 0; c < cells; ++c) {
      const auto cell = static_cast<std::uint64_t>(kCellsPerMetre * r.along_m + c);
      for (int row = 0; row < kFacadeRows; ++row) {
        const std::uint64_t h =
            mix(r.street * 0x9e3779b97f4a7c15ull ^ mix(cell * 16 + static_cast<std::uint64_t>(row)));
        small.at<std::uint8_t>(row, c) = static_cast<std::uint8_t>(h >> 56);
      }
    }
    cv::Mat image;
    cv::resize(small, image, cv::Size(options_.image_width_px, options_.image_height_px), 0, 0,
               cv::INTER_LINEAR);
    cv::Mat noise(image.size(), CV_16SC1);
    cv::RNG noise_rng(0x51ed27ull * (r.pass + 1));
    noise_rng.fill(noise, cv::RNG::UNIFORM, -6, 7);
    cv::Mat noisy;
    image.convertTo(noisy, CV_16SC1);
    noisy += noise;
    noisy.convertTo(image, CV_8UC1);  // saturating
    return image;
  }
  bool has_imu() const override { return false; }
  const std::vector<ImuSample>& imu_samples() const override { return no_imu_; }
  bool has_ground_truth() const override { return true; }
  std::optional<Eigen::Isometry3d> ground_truth_T_w_b(std::size_t frame) const override {
    if (frame >= options_.frames) return std::nullopt;
    return pose_of(route_.at(frame));
  }
  const std::vector<GroundTruthState>& ground_truth() const override { return no_states_; }
  std::optional<CameraCalibration> camera() const override { return std::nullopt; }
  std::optional<ImuCalibration> imu_calibration() const override { return std::nullopt; }
  const std::vector<DataIssue>& issues() const override { return no_issues_; }

  const ScalingRoute& route() const { return route_; }

 private:
  static constexpr int kCellPx = 4;
  static std::uint64_t mix(std::uint64_t x) {  // splitmix64's finaliser
    x = (x ^ (x >> 30)) * 0xbf58476d1ce4e5b9ull;
    x = (x ^ (x >> 27)) * 0x94d049bb133111ebull;
    return x ^ (x >> 31);
  }
  ScalingOptions options_;
  ScalingRoute route_;
  fs::path root_;
  std::vector<ImuSample> no_imu_;
  std::vector<GroundTruthState> no_states_;
  std::vector<DataIssue> no_issues_;
};

// The odometry: truth plus a bounded offset that turns slowly (one turn per 5 000 m).
void write_odometry(const ScalingDataset& dataset, double offset_m, const fs::path& file) {
  std::ofstream out(file);
  out.precision(17);
  for (std::size_t k = 0; k < dataset.frame_count(); ++k) {
    const Eigen::Isometry3d T = *dataset.ground_truth_T_w_b(k);
    const double phase = 2.0 * M_PI * static_cast<double>(k) / 5000.0;
    const Eigen::Vector3d p =
        T.translation() + offset_m * Eigen::Vector3d(std::cos(phase), std::sin(phase), 0);
    const Eigen::Quaterniond q(T.linear());
    out << 1e-9 * static_cast<double>(dataset.frame_t_ns(k)) << ' ' << p.x() << ' ' << p.y() << ' ' << p.z()
        << ' ' << q.x() << ' ' << q.y() << ' ' << q.z() << ' ' << q.w() << '\n';
  }
  if (!out) throw std::runtime_error("cannot write " + file.string());
}

// dird.mu / dird.sigma from the first `frames` frames: pairs beyond the margin, and the true revisits among
// them (the same place: within 0.5 m).
LogisticCalibration calibrate(const ScalingDataset& dataset, const DirdConfig& dird, std::size_t frames,
                              int margin) {
  frames = std::min(frames, dataset.frame_count());
  const DirdExtractor extractor(dird);
  const DirdSimilarity similarity(dird);
  std::vector<Descriptor> d(frames);
  for (std::size_t k = 0; k < frames; ++k) extractor.extract(dataset.load_image(k), d[k]);
  std::vector<double> beyond, revisits;
  for (std::size_t i = 0; i < frames; ++i) {
    for (std::size_t j = 0; j + static_cast<std::size_t>(margin) <= i; ++j) {
      const double distance = similarity.distance(d[i], d[j]);
      beyond.push_back(distance);
      const double apart_m = (dataset.route().at(i).p_w_m - dataset.route().at(j).p_w_m).norm();
      if (apart_m < 0.5) revisits.push_back(distance);
    }
  }
  if (beyond.empty()) throw std::runtime_error("--calibrate-frames: no pair beyond match.margin");
  return calibrate_logistic(beyond, revisits, LogisticCalibrationOptions{dird.tau1});
}

ScalingOptions parse(int argc, char** argv) {
  ScalingOptions o;
  const auto value = [&](int& k) -> std::string {
    if (k + 1 >= argc) throw std::invalid_argument(std::string(argv[k]) + " needs a value");
    return argv[++k];
  };
  for (int k = 1; k < argc; ++k) {
    const std::string a = argv[k];
    if (a == "--frames")
      o.frames = std::stoul(value(k));
    else if (a == "--mode")
      o.mode = value(k);
    else if (a == "--out")
      o.out_dir = value(k);
    else if (a == "--threads")
      o.threads = std::stoi(value(k));
    else if (a == "--advance-m")
      o.advance_m = std::stoi(value(k));
    else if (a == "--revisit-m")
      o.revisit_m = std::stoi(value(k));
    else if (a == "--block-m")
      o.block_m = std::stoi(value(k));
    else if (a == "--image-width-px")
      o.image_width_px = std::stoi(value(k));
    else if (a == "--image-height-px")
      o.image_height_px = std::stoi(value(k));
    else if (a == "--calibrate-frames")
      o.calibrate_frames = std::stoul(value(k));
    else if (a == "--odometry-offset-m")
      o.odometry_offset_m = std::stod(value(k));
    else if (a == "--set")
      o.overrides.push_back(value(k));
    else
      throw std::invalid_argument("unknown option " + a + " (see the comment at the top of " __FILE__ ")");
  }
  if (o.out_dir.empty()) throw std::invalid_argument("--out DIR is required");
  if (o.frames < 1000) throw std::invalid_argument("--frames: at least 1000");
  if (o.advance_m < 1 || o.revisit_m < 1 || o.block_m < 1 || o.image_width_px < 8 || o.image_height_px < 8)
    throw std::invalid_argument("route lengths must be >= 1 m and images >= 8 px");
  return o;
}

int run(const ScalingOptions& o) {
  const fs::path out_dir = o.out_dir;
  fs::create_directories(out_dir);
  const ScalingDataset dataset(o);
  const fs::path odometry = out_dir / "odometry.tum";
  write_odometry(dataset, o.odometry_offset_m, odometry);
  std::vector<std::string> settings = {"run.mode=" + o.mode,
                                       "run.rate=max",
                                       "run.threads=" + std::to_string(o.threads),
                                       "output.progress=off",
                                       "odometry.source=file",
                                       "odometry.file=" + odometry.string(),
                                       "odometry.file_sigma2_a_m2=1.0",
                                       "odometry.file_sigma2_b_m2_per_m=0",
                                       "odometry.file_rot_sigma2_b_rad2_per_m=0",
                                       "gate.beta_m=2.0",
                                       "eval.truth_radius_m=2",
                                       "eval.accept_radius_m=4"};
  settings.insert(settings.end(), o.overrides.begin(), o.overrides.end());
  PipelineConfig config = load_config<PipelineConfig>("", settings);
  const LogisticCalibration c = calibrate(dataset, config.dird, o.calibrate_frames, config.match.margin);
  settings.push_back("dird.mu=" + std::to_string(c.mu));
  settings.push_back("dird.sigma=" + std::to_string(c.sigma));
  settings.insert(settings.end(), o.overrides.begin(), o.overrides.end());  // the user's word last
  config = load_config<PipelineConfig>("", settings);
  spdlog::info("scaling: {} frames, {} mode, cycle {} frames; DIRD mu {:.1f} sigma {:.1f} ({})", o.frames,
               o.mode, dataset.route().cycle_frames(), config.dird.mu, config.dird.sigma, c.rule);
  const RunResult result = run_pipeline(config, dataset, out_dir / "run");
  if (result.failed) {
    spdlog::error("scaling: the run failed: {}", result.error);
    return 1;
  }
  const auto& s = result.summary;
  const auto& pr = s["evaluation"].value("precision_recall", nlohmann::json::object());
  std::printf(
      "scaling: frames %zu mode %s wall_s %.2f peak_rss_mb %.1f descriptors %zu similarities %zu loops %zu "
      "average_precision %.3f recall_at_100 %.3f cycle_frames %zu\n",
      result.frames_processed, o.mode.c_str(), result.wall_s, result.peak_rss_mb,
      s.value("descriptors_computed", std::size_t{0}), s.value("similarities_computed", std::size_t{0}),
      s.value("loops", std::size_t{0}), pr.value("average_precision", 0.0), pr.value("recall_at_100", 0.0),
      dataset.route().cycle_frames());
  return 0;
}

}  // namespace
}  // namespace loopgate

int main(int argc, char** argv) {
  try {
    return loopgate::run(loopgate::parse(argc, argv));
  } catch (const std::exception& e) {
    std::fprintf(stderr, "bench_pipeline_scaling: %s\n", e.what());
    return 2;
  }
}
