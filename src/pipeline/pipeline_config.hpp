// The top-level configuration of `loopgate run`: one struct per section, each with fields()/validate()
// (see io/config.hpp). To add a section (e.g. DirdConfig "dird", MatchConfig "match"): add a member and
// one line in sections(); YAML loading, --set overrides, printing and the JSON echo follow.
#pragma once

#include <cstddef>
#include <optional>
#include <span>
#include <string>
#include <utility>

#include "core/enum_names.hpp"
#include "core/revisit_rule.hpp"
#include "io/dataset.hpp"
#include "stages/dird/dird_codes.hpp"
#include "stages/dird/dird_config.hpp"
#include "stages/dird/dird_online_scale.hpp"
#include "stages/dird/viewpoint.hpp"
#include "stages/gate/gate_config.hpp"
#include "stages/match/contrast_search.hpp"
#include "stages/match/match_config.hpp"
#include "stages/odometry/odometry_source.hpp"
#include "stages/posegraph/pose_graph.hpp"
#include "stages/seqslam/seqslam_config.hpp"
#include "stages/sync/imu_sync.hpp"
#include "stages/verify/geometric_verifier.hpp"

namespace loopgate {

// run.mode: "gated" (the paper's method): the pose gate finds candidate areas and DIRD descriptors and
// similarities are computed only inside them (past frames re-read on demand), then sequence match and NMS;
// "full": DIRD on every frame and its similarity against every earlier frame beyond match.margin, same
// sequence match and NMS (the paper's pure-DIRD baseline); "odometry": sync, decode, odometry only.
// With run.method seqslam, gated and full choose gated SeqSLAM (docs/seqslam-gated.md) or full SeqSLAM.
enum class RunMode { kGated, kFull, kOdometry };
inline constexpr EnumName<RunMode> kRunModeNames[] = {
    {RunMode::kGated, "gated"}, {RunMode::kFull, "full"}, {RunMode::kOdometry, "odometry"}};
constexpr std::span<const EnumName<RunMode>> enum_names(RunMode) {
  return kRunModeNames;
}

// run.method: "dird" (the paper's detector, in the chosen mode), "seqslam" (the SeqSLAM baseline with the
// OpenSeqSLAM defaults of section seqslam, in the chosen mode: full = every frame, gated = only inside the
// candidate areas; its score is the ratio best/second, lower is better) or "dird-seqslam" (DIRD descriptors,
// standardised by default, matched by SeqSLAM's contrast enhancement and sequence search: the method robust
// to day/night and seasons, section dird_seqslam and docs/illumination.md; score = mean z, higher is
// better).
enum class Detector { kDird, kSeqSlam, kDirdSeqSlam };
inline constexpr EnumName<Detector> kDetectorNames[] = {
    {Detector::kDird, "dird"}, {Detector::kSeqSlam, "seqslam"}, {Detector::kDirdSeqSlam, "dird-seqslam"}};
constexpr std::span<const EnumName<Detector>> enum_names(Detector) {
  return kDetectorNames;
}

// run.decode: "lazy" (only frames a later stage needs pixels of now) or "all".
enum class DecodePolicy { kLazy, kAll };
inline constexpr EnumName<DecodePolicy> kDecodePolicyNames[] = {{DecodePolicy::kLazy, "lazy"},
                                                                {DecodePolicy::kAll, "all"}};
constexpr std::span<const EnumName<DecodePolicy>> enum_names(DecodePolicy) {
  return kDecodePolicyNames;
}

struct RunConfig {
  std::string dataset;                        // dataset folder (the --dataset flag overrides it)
  RunMode mode = RunMode::kGated;             // gated | full | odometry (see RunMode)
  Detector method = Detector::kDird;          // dird | seqslam | dird-seqslam (see Detector), gated or full
  std::string rate = "max";                   // "max" (as fast as the graph drains) or R > 0 (R x real time)
  int threads = 2;                            // worker threads of the graph
  int max_in_flight = 8;                      // limiter: frames inside the graph at once
  std::string frames;                         // "A:B" frame indices [A, B), "A:" or ":B"; empty = all
  DecodePolicy decode = DecodePolicy::kLazy;  // lazy | all
  bool strict = false;  // open the dataset strictly (first bad row fails) instead of leniently
  // Which camera: 0, 1 (EuRoC cam0 / cam1, KITTI grey image_0 / image_1), 2, 3 (KITTI colour image_2 /
  // image_3)
  int camera_index = 0;
  double deadline_ms = 0;  // rate mode: time a frame may take from release to sink; 0 = frame period
  // gated mode: decoded images of the most recent frames kept for describe (a new candidate area asks for
  // the descriptors of the rows just behind the current frame); older frames are read again from the
  // dataset. 0 = no cache. Memory: this many images.
  int image_cache_frames = 64;
  // The method registry's row that run.method named (`run.method: dird-seqslam-gated`), set when the config
  // is loaded; empty when run.method is a detector word, whose row follows from the detector, run.mode and
  // standardize.mode (methods/method_registry.hpp). Not a key of its own: the echo shows the row's words.
  std::string method_row;

  // The keys, in order, for loading, printing and the JSON echo (Self is RunConfig or const RunConfig).
  template <class Self, class V>
  static void fields(Self& self, V&& v) {
    v("dataset", self.dataset);
    v("mode", self.mode);
    v("method", self.method);
    v("rate", self.rate);
    v("threads", self.threads);
    v("max_in_flight", self.max_in_flight);
    v("frames", self.frames);
    v("decode", self.decode);
    v("strict", self.strict);
    v("camera_index", self.camera_index);
    v("deadline_ms", self.deadline_ms);
    v("image_cache_frames", self.image_cache_frames);
  }
  void validate() const;

  bool detects_loops() const { return mode != RunMode::kOdometry; }
  bool seqslam() const { return method == Detector::kSeqSlam; }
  bool dird_seqslam() const { return method == Detector::kDirdSeqSlam; }
  // nullopt for "max", else the rate factor R.
  std::optional<double> rate_factor() const;
  // [first, last) clamped to frame_count; throws ConfigError when the range is empty or malformed.
  std::pair<std::size_t, std::size_t> frame_range(std::size_t frame_count) const;
};

// Section dataset: how inputs that are not folders are read. A ROS1 bag (run.dataset ending in .bag,
// docs/datasets.md): the topics of the images (sensor_msgs/Image or CompressedImage) and of the IMU
// (sensor_msgs/Imu; empty = no IMU), EuRoC's by default, and the folder in EuRoC ASL layout that holds the
// calibration and ground truth a bag does not carry (cam0/sensor.yaml, imu0/sensor.yaml,
// state_groundtruth_estimate0/data.csv; empty = the folder beside the bag named like it without ".bag", when
// there is one). calibration: a Kalibr camera-IMU chain file used for the camera instead of the one found in
// an EuRoC / TUM-VI tree or a bag's ASL folder (empty = found there). A relative path is relative to the
// YAML file that names it, or to the working directory when given on the command line.
struct DatasetConfig {
  std::string bag_image_topic = "/cam0/image_raw";
  std::string bag_imu_topic = "/imu0";
  std::string bag_asl_dir;
  std::string calibration;

  // The keys, in order, for loading, printing and the JSON echo (Self is DatasetConfig or const
  // DatasetConfig).
  template <class Self, class V>
  static void fields(Self& self, V&& v) {
    v("bag_image_topic", self.bag_image_topic);
    v("bag_imu_topic", self.bag_imu_topic);
    v("bag_asl_dir", self.bag_asl_dir);
    v("calibration", self.calibration);
  }
  void validate() const;
};

// output.progress: the progress line on stderr when it is a terminal ("auto"), always ("on") or never
// ("off").
enum class Progress { kAuto, kOn, kOff };
inline constexpr EnumName<Progress> kProgressNames[] = {
    {Progress::kAuto, "auto"}, {Progress::kOn, "on"}, {Progress::kOff, "off"}};
constexpr std::span<const EnumName<Progress>> enum_names(Progress) {
  return kProgressNames;
}

struct OutputConfig {
  bool trace = false;                   // write trace.json (Chrome trace-event format, opens in Perfetto)
  Progress progress = Progress::kAuto;  // auto (when stderr is a terminal) | on | off
  int flush_every = 100;                // frames between flushes of the streamed CSV/TUM files

  // The keys, in order, for loading, printing and the JSON echo (Self is OutputConfig or const OutputConfig).
  template <class Self, class V>
  static void fields(Self& self, V&& v) {
    v("trace", self.trace);
    v("progress", self.progress);
    v("flush_every", self.flush_every);
  }
  void validate() const;
};

// eval.plane: the distances of the ground truth in the x-z plane (KITTI's camera frame), x-y, 3-D, or "auto"
// (x-z for the KITTI layout, 3-D otherwise).
enum class TruthPlane { kAuto, kXz, kXy, kXyz };
inline constexpr EnumName<TruthPlane> kTruthPlaneNames[] = {
    {TruthPlane::kAuto, "auto"}, {TruthPlane::kXz, "xz"}, {TruthPlane::kXy, "xy"}, {TruthPlane::kXyz, "xyz"}};
constexpr std::span<const EnumName<TruthPlane>> enum_names(TruthPlane) {
  return kTruthPlaneNames;
}

// Evaluation of the detections against the dataset's ground truth (when it has one), docs/evaluation.md.
struct EvalConfig {
  // Ground-truth loops: query i is positive when some j <= i - truth_gap_frames lies within
  // truth_radius_m of it (r_true), distances in `plane`: "xz" (KITTI camera frame), "xy", "xyz", or
  // "auto" (xz for the KITTI layout, xyz otherwise).
  double truth_radius_m = 2.0;
  int truth_gap_frames = 20;
  TruthPlane plane = TruthPlane::kAuto;
  // r_accept: a detection (i, j) is a true positive when the ground-truth positions of i and j are at
  // most this far apart (in `plane`); 0 = truth_radius_m.
  double accept_radius_m = 0.0;
  // A revisit needs travel in between: a true loop, and a true detection, also needs at least this
  // much ground-truth path (3-D, summed frame to frame) between query and reference, so that hovering or
  // standing still within truth_radius_m is not a loop (on an EuRoC flight many "positives" within 0.2 m and
  // 20 frames are the drone hovering; on KITTI 00, 21 are the car stopped). 2 m: what the simulator's
  // euroc-mh05 preset uses, and below the smallest loop of a drone in a room; 0 = no such rule (the former
  // behaviour). Not used with truth_pairs_file. Key min_travel_m.
  RevisitRule revisit{2.0};
  // Two-sequence runs of aligned sequences (reference frame k and query frame k show the same place, e.g.
  // Nordland): a loop (query i, reference j) is correct when |i - j| <= this; -1 = not aligned, no check.
  int aligned_tolerance_frames = -1;
  // Loop ground truth as published (KITTI, EuRoC, RTAB-Map samples): a file of (query, reference) pairs of
  // 0-based frame numbers, the numbers frames.csv shows (eval/loop_files.hpp read_truth_pairs). When set, it
  // replaces the positions rule above (truth_radius_m, truth_gap_frames, plane, accept_radius_m): query i is
  // positive when it has a listed pair, a detection is true when its pair is listed; it needs no ground-truth
  // poses (appearance-only datasets). Relative paths are relative to the working directory. Empty =
  // positions.
  std::string truth_pairs_file;

  // The keys, in order, for loading, printing and the JSON echo (Self is EvalConfig or const EvalConfig).
  template <class Self, class V>
  static void fields(Self& self, V&& v) {
    v("truth_radius_m", self.truth_radius_m);
    v("truth_gap_frames", self.truth_gap_frames);
    v("plane", self.plane);
    v("accept_radius_m", self.accept_radius_m);
    v("min_travel_m", self.revisit.min_travel_m);
    v("aligned_tolerance_frames", self.aligned_tolerance_frames);
    v("truth_pairs_file", self.truth_pairs_file);
  }
  void validate() const;
  double effective_accept_radius_m() const { return accept_radius_m > 0 ? accept_radius_m : truth_radius_m; }
};

// Section dird_seqslam: the descriptors dird-seqslam compares and its search. The DIRD section keeps the
// paper's descriptor (libdird normalisation, nearest-neighbour resize: bit-exact with the reference, with
// the logistic constants calibrated for it); dird-seqslam's default is the one measured best across day,
// night and seasons (docs/illumination.md): l2 normalisation (no invalid pixels in dark regions), area resize
// (sensor noise averaged before sampling) and causal standardisation (per-dimension statistics of the recent
// frames). Needs no logistic constants: the search's score is in units of the local spread of distances.
struct DirdSeqSlamConfig {
  // replaces dird.normalization for this method: libdird | l2
  DirdNormalization normalization = DirdNormalization::kL2;
  DirdResize resize = DirdResize::kArea;  // replaces dird.resize: nearest | area
  // off | causal | batch (two sequences only): replaces standardize.mode for this method; the statistics
  // parameters (window, warm_up, refresh_every, observe_every, distance, clamp_sigma, min_stddev) are those
  // of section standardize.
  StandardizeMode standardize = StandardizeMode::kCausal;
  DirdCodeConfig codes;  // keys code, ternary_threshold_sigma, int2_threshold_sigma (docs/codes.md)
  ContrastSearchConfig search;
  // Viewpoint tolerance: keys viewpoint_* (stages/dird/viewpoint.hpp, docs/viewpoint.md).
  ViewpointConfig viewpoint;

  template <class Self, class V>
  static void fields(Self& self, V&& v) {
    v("normalization", self.normalization);
    v("resize", self.resize);
    v("standardize", self.standardize);
    DirdCodeConfig::fields(self.codes, v);
    ContrastSearchConfig::fields(self.search, v);
    ViewpointConfig::fields(self.viewpoint, v);
  }
  void validate() const;

  // The DIRD configuration its descriptors are extracted with, and the standardisation they get.
  DirdConfig descriptor(const DirdConfig& dird) const {
    DirdConfig out = dird;
    out.normalization = normalization;
    out.resize = resize;
    return out;
  }
  StandardizeConfig standardization(const StandardizeConfig& standardize_section) const {
    StandardizeConfig out = standardize_section;
    out.mode = standardize;
    return out;
  }
};

inline SeqSlamConfig single_sequence_seqslam() {
  SeqSlamConfig config;
  config.exclusion = SeqSlamExclusionKind::kPast;
  config.exclusion_margin_frames = 200;
  return config;
}

struct PipelineConfig {
  RunConfig run;
  DatasetConfig dataset;
  SyncConfig sync;
  OdometryConfig odometry;
  EkfConfig ekf;  // the `ekf` odometry source (stages/ekf/ekf_config.hpp)
  GateConfig gate;
  DirdConfig dird;
  MatchConfig match;
  // Descriptor standardisation (docs/standardize.md) of the DIRD DP methods (run.method dird): off = raw
  // DIRD bytes; causal (single sequence) or batch (two sequences: each its own statistics) = z-scored codes
  // compared by cosine or L1. dird-seqslam chooses its own (dird_seqslam.standardize) and takes the
  // statistics parameters of this section.
  StandardizeConfig standardize;
  // The logistic's scale: off = dird.mu / dird.sigma (raw) or standard_default_scale() (standardised);
  // online = OnlineScale, from the distances seen so far.
  OnlineScaleConfig scale;
  // SeqSLAM (run.method seqslam). A single run is matched against itself: reference rows closer than
  // exclusion_margin_frames before the query are excluded ("past"); set the margin like match.margin.
  SeqSlamConfig seqslam = single_sequence_seqslam();
  // run.method dird-seqslam: its descriptors (DIRD with its own normalisation, resize and standardisation)
  // and the contrast enhancement and sequence search (stages/match/contrast_search.hpp); its sequence
  // length is match.sequence_length, its margin match.margin.
  DirdSeqSlamConfig dird_seqslam;
  // Loop closures that correct the trajectory: geometric verification of every accepted loop and
  // the pose graph they feed (trajectory_corrected.tum, loop_edges.csv).
  VerifyConfig verify;
  PoseGraphConfig posegraph;
  EvalConfig eval;
  OutputConfig output;

  // The sections, in order, for loading, printing and the JSON echo (Self is PipelineConfig or const
  // PipelineConfig).
  template <class Self, class V>
  static void sections(Self& self, V&& v) {
    v("run", self.run);
    v("dataset", self.dataset);
    v("sync", self.sync);
    v("odometry", self.odometry);
    v("ekf", self.ekf);
    v("gate", self.gate);
    v("dird", self.dird);
    v("match", self.match);
    v("standardize", self.standardize);
    v("scale", self.scale);
    v("seqslam", self.seqslam);
    v("dird_seqslam", self.dird_seqslam);
    v("verify", self.verify);
    v("posegraph", self.posegraph);
    v("eval", self.eval);
    v("output", self.output);
  }
  // odometry.source none gives no poses: the modes and options that need them are errors (the same check
  // for `auto` resolving to none is made when the dataset is known, pipeline/odometry_factory.hpp).
  void validate_odometry_none() const;
  // gate.feedback needs verified loops (verify.enabled); that they exist while the stream runs is the
  // method's row's to say (validate_method, pipeline/methods/method_registry.hpp).
  void validate_gate_feedback() const;
  // How the datasets of this run are opened (run.strict, run.camera_index, section dataset).
  OpenOptions open_options() const;
  void validate() const {
    run.validate();
    dataset.validate();
    sync.validate();
    odometry.validate();
    ekf.validate();
    gate.validate();
    dird.validate();
    match.validate();
    standardize.validate();
    scale.validate();
    seqslam.validate();
    dird_seqslam.validate();
    verify.validate();
    posegraph.validate();
    if (run.mode == RunMode::kGated) gate.validate_for_sequence_length(match.sequence_length);
    validate_odometry_none();
    validate_gate_feedback();
    eval.validate();
    output.validate();
  }
};

}  // namespace loopgate
