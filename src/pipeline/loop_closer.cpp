#include "pipeline/loop_closer.hpp"

#include <spdlog/fmt/fmt.h>
#include <spdlog/spdlog.h>

#include <Eigen/Eigenvalues>
#include <algorithm>
#include <chrono>
#include <cmath>
#include <numeric>

#include "core/error.hpp"
#include "core/geometry.hpp"
#include "io/dataset.hpp"
#include "io/g2o_file.hpp"
#include "io/writers.hpp"
#include "parallel/parallel_handoff.hpp"
#include "pipeline/loop_oracle.hpp"
#include "pipeline/loops_writer.hpp"
#include "pipeline/outputs/run_metrics.hpp"
#include "pipeline/outputs/run_result.hpp"
#include "pipeline/pipeline_config.hpp"

namespace loopgate {

namespace {

double ms_since(std::chrono::steady_clock::time_point start) {
  return std::chrono::duration<double, std::milli>(std::chrono::steady_clock::now() - start).count();
}

nlohmann::json stats_json(std::vector<double> values) {
  if (values.empty()) return {{"count", 0}, {"total_ms", 0.0}};
  std::sort(values.begin(), values.end());
  const auto at = [&](double q) {
    return values[std::min(values.size() - 1,
                           static_cast<std::size_t>(q * static_cast<double>(values.size())))];
  };
  return {{"count", values.size()},
          {"p50_ms", at(0.5)},
          {"p90_ms", at(0.9)},
          {"max_ms", values.back()},
          {"total_ms", std::accumulate(values.begin(), values.end(), 0.0)}};
}

}  // namespace

LoopCloser::LoopCloser(const PipelineConfig& config, const Dataset& dataset, std::size_t first_frame,
                       std::size_t last_frame, bool detects)
    : dataset_(dataset),
      first_(first_frame),
      last_(last_frame),
      active_(detects && config.verify.enabled),
      verify_config_(config.verify),
      graph_config_(config.posegraph),
      verifier_(config.verify, dataset.camera()),
      drain_threads_(config.run.threads) {
  if (!active_) return;
  poses_.resize(last_ - first_);
  sigma_m_.assign(last_ - first_, 0.0);
  if (graph_config_.odometry_cov == "odometry") {
    step_cov_.assign(last_ - first_, PoseCov::Zero());
    has_step_cov_.assign(last_ - first_, 0);
  }
  pending_by_frame_.assign(last_ - first_, 0);
  if (!dataset.has_images()) {
    unusable_ = "geometry: the dataset has no images";
  } else if (const auto camera = dataset.camera()) {
    unusable_ = verifier_.unusable_reason(cv::Size(camera->width_px, camera->height_px));
  } else {
    unusable_ = verifier_.unusable_reason(cv::Size(0, 0));
  }
  if (!unusable_.empty()) spdlog::warn("verify: loops are not verified: {}", unusable_);
  worker_ = std::thread([this] { work(); });
}

LoopCloser::~LoopCloser() {
  if (worker_.joinable()) {
    {
      std::lock_guard lock(mutex_);
      stopping_ = true;
    }
    wake_.notify_all();
    worker_.join();
  }
}

void LoopCloser::record_pose(std::size_t frame, const Eigen::Isometry3d& T_w_b, double sigma_m,
                             const std::optional<PoseCov>& step_cov) {
  if (!active_ || frame < first_ || frame >= last_) return;
  poses_[frame - first_] = T_w_b;
  sigma_m_[frame - first_] = sigma_m;
  if (!step_cov_.empty() && step_cov) {
    step_cov_[frame - first_] = *step_cov;
    has_step_cov_[frame - first_] = 1;
  }
}

PoseCov LoopCloser::odometry_edge_cov(std::size_t a, std::size_t b, double scale) const {
  const Eigen::Isometry3d& T_w_a = *poses_[a - first_];
  const Eigen::Isometry3d& T_w_b = *poses_[b - first_];
  const Eigen::Isometry3d T_a_w = T_w_a.inverse();
  if (step_cov_.empty()) return graph_config_.model_cov(T_a_w * T_w_b);
  PoseCov cov = PoseCov::Zero();
  const Eigen::Isometry3d* T_w_prev = &T_w_a;
  for (std::size_t f = a + 1; f <= b; ++f) {
    if (!poses_[f - first_]) continue;
    if (!has_step_cov_[f - first_]) return graph_config_.model_cov(T_a_w * T_w_b);
    const Eigen::Isometry3d& T_w_f = *poses_[f - first_];
    cov = compose_pose_cov(T_a_w * *T_w_prev, cov, T_w_prev->inverse() * T_w_f, step_cov_[f - first_]);
    T_w_prev = &T_w_f;
  }
  return graph_config_.with_floors(scale * cov);
}

double LoopCloser::odometry_cov_scale(const std::vector<LoopResult>& loops, std::size_t span) const {
  if (step_cov_.empty()) return 1.0;
  if (graph_config_.odometry_cov_scale > 0) return graph_config_.odometry_cov_scale;
  // Each recorded frame's covariance relative to the start of its chain of step covariances (a frame without
  // one starts a chain): the odometry's covariance of T_j_i is then step_pose_cov of j's and i's.
  std::vector<std::int64_t> chain(span, -1);
  std::vector<PoseCov> cov(span, PoseCov::Zero());
  std::vector<Eigen::Isometry3d> T_o_f(span, Eigen::Isometry3d::Identity());
  std::int64_t chains = -1;
  std::optional<std::size_t> previous;
  for (std::size_t k = 0; k < span; ++k) {
    if (!poses_[k]) continue;
    if (!previous || !has_step_cov_[k]) {
      chain[k] = ++chains;
    } else {
      const std::size_t p = *previous;
      chain[k] = chain[p];
      T_o_f[k] = T_o_f[p] * (poses_[p]->inverse() * *poses_[k]);
      cov[k] = compose_pose_cov(T_o_f[p], cov[p], poses_[p]->inverse() * *poses_[k], step_cov_[k]);
    }
    previous = k;
  }
  std::vector<LoopInnovation> innovations;
  for (const LoopResult& r : loops) {
    if (r.loop.query < first_ || r.loop.reference < first_) continue;
    const std::size_t i = r.loop.query - first_, j = r.loop.reference - first_;
    if (i >= span || j >= i || chain[i] < 0 || chain[i] != chain[j]) continue;
    LoopInnovation innovation;
    const Eigen::Isometry3d T_j_i = T_o_f[j].inverse() * T_o_f[i];
    innovation.error.head<3>() = r.result.T_j_i.translation() - T_j_i.translation();
    innovation.error.tail<3>() = so3_log(T_j_i.rotation().transpose() * r.result.T_j_i.rotation());
    innovation.odometry_cov = step_pose_cov(T_o_f[j], cov[j], T_o_f[i], cov[i]);
    innovation.loop_cov = r.result.cov;
    innovations.push_back(innovation);
  }
  return odometry_cov_scale_from_loops(innovations, 3, 1e6);
}

std::optional<Eigen::Isometry3d> LoopCloser::pose_of(std::size_t frame) const {
  if (frame < first_ || frame >= last_) return std::nullopt;
  return poses_[frame - first_];
}

void LoopCloser::submit(const Detection& loop) {
  if (!active_) return;
  {
    std::lock_guard lock(mutex_);
    queue_.push_back(loop);
    if (loop.query >= first_ && loop.query < last_) ++pending_by_frame_[loop.query - first_];
  }
  wake_.notify_all();
}

std::optional<std::string> LoopCloser::geometry_cell(std::size_t frame) const {
  if (!active_) return std::string();
  std::lock_guard lock(mutex_);
  if (frame >= first_ && frame < last_ && pending_by_frame_[frame - first_] > 0) return std::nullopt;
  std::string cell;
  for (const LoopResult& r : results_) {
    if (r.loop.query != frame) continue;
    cell += (cell.empty() ? "" : "; ") +
            (r.result.verified ? fmt::format("verified j={} ({} inliers)", r.loop.reference, r.result.inliers)
                               : fmt::format("j={} {}", r.loop.reference, r.result.reason));
  }
  return cell;
}

std::shared_ptr<const OrbFeatures> LoopCloser::features_of(std::size_t frame) {
  if (const auto it = feature_cache_.find(frame); it != feature_cache_.end()) return it->second;
  auto features = std::make_shared<const OrbFeatures>(verifier_.detect(dataset_.load_image(frame)));
  remember_features(frame, features);
  return features;
}

void LoopCloser::remember_features(std::size_t frame, std::shared_ptr<const OrbFeatures> features) {
  feature_cache_.emplace(frame, std::move(features));
  feature_cache_order_.push_back(frame);
  while (feature_cache_order_.size() > static_cast<std::size_t>(verify_config_.feature_cache_frames)) {
    feature_cache_.erase(feature_cache_order_.front());
    feature_cache_order_.pop_front();
  }
}

void LoopCloser::prefetch_features(const std::vector<std::size_t>& frames) {
  if (drain_threads_ < 2) return;
  std::vector<std::size_t> missing;
  for (const std::size_t f : frames)
    if (!feature_cache_.contains(f) && std::find(missing.begin(), missing.end(), f) == missing.end())
      missing.push_back(f);
  if (missing.size() < 2) return;
  // A frame whose image cannot be read is left out: features_of() reads it again and reports why.
  std::vector<std::shared_ptr<const OrbFeatures>> found(missing.size());
  if (!drain_arena_) drain_arena_ = std::make_unique<tbb::task_arena>(drain_threads_);
  drain_arena_->execute([&] {
    parallel_for_with_handoff(missing.size(), [&](std::size_t k) {
      try {
        found[k] = std::make_shared<const OrbFeatures>(verifier_.detect(dataset_.load_image(missing[k])));
      } catch (const std::exception&) {
        found[k] = nullptr;
      }
    });
  });
  for (std::size_t k = 0; k < missing.size(); ++k) {
    if (!found[k]) continue;
    remember_features(missing[k], std::move(found[k]));
    ++drain_prefetched_;
  }
}

bool LoopCloser::odometry_unbroken(std::size_t from, std::size_t to) const {
  if (from < first_ || to >= last_ || from > to) return false;
  for (std::size_t f = from; f <= to; ++f)
    if (!poses_[f - first_]) return false;
  return true;
}

bool LoopCloser::in_skip_window(const Detection& earlier, bool verified, const Detection& later) const {
  const int window =
      verified ? verify_config_.skip_after_verified_frames : verify_config_.skip_after_rejected_frames;
  const auto near = [window](std::size_t a, std::size_t b) {
    return (a > b ? a - b : b - a) <= static_cast<std::size_t>(window);
  };
  return window > 0 && near(earlier.query, later.query) && near(earlier.reference, later.reference);
}

void LoopCloser::extend_chain(std::size_t span) {
  span = std::min(span, poses_.size());
  if (chain_id_.size() >= span) return;
  std::size_t k = chain_id_.size();
  chain_id_.resize(span, -1);
  chain_cov_.resize(span, PoseCov::Zero());
  chain_T_.resize(span, Eigen::Isometry3d::Identity());
  for (; k < span; ++k) {
    if (!poses_[k]) continue;
    if (!chain_previous_ || !has_step_cov_[k]) {
      chain_id_[k] = ++chains_;
    } else {
      const std::size_t p = *chain_previous_;
      const Eigen::Isometry3d T_p_k = poses_[p]->inverse() * *poses_[k];
      chain_id_[k] = chain_id_[p];
      chain_T_[k] = chain_T_[p] * T_p_k;
      chain_cov_[k] = compose_pose_cov(chain_T_[p], chain_cov_[p], T_p_k, step_cov_[k]);
    }
    chain_previous_ = k;
  }
}

double LoopCloser::scale_now() const {
  if (step_cov_.empty()) return 1.0;
  if (graph_config_.odometry_cov_scale > 0) return graph_config_.odometry_cov_scale;
  return odometry_cov_scale_from_loops(innovations_, 3, 1e6);
}

PoseCov LoopCloser::relative_odometry_cov(std::size_t j, std::size_t i, double scale) {
  const Eigen::Isometry3d T_j_i = pose_of(j)->inverse() * *pose_of(i);
  if (step_cov_.empty()) return graph_config_.model_cov(T_j_i);
  const std::size_t a = j - first_, b = i - first_;
  extend_chain(std::max(a, b) + 1);
  if (chain_id_[a] < 0 || chain_id_[a] != chain_id_[b]) return graph_config_.model_cov(T_j_i);
  const PoseCov cov = step_pose_cov(chain_T_[a], chain_cov_[a], chain_T_[b], chain_cov_[b]);
  const double nodes = std::max(1.0, std::floor(static_cast<double>(b > a ? b - a : a - b) /
                                                static_cast<double>(graph_config_.node_every_frames)));
  return scale * cov + nodes * graph_config_.with_floors(PoseCov::Zero());
}

std::optional<LoopCloser::SkipBasis> LoopCloser::skip_basis(const Detection& loop) const {
  const std::size_t lo = std::min(loop.query, loop.reference), hi = std::max(loop.query, loop.reference);
  std::optional<SkipBasis> basis;
  for (const CheckedSpan& c : checked_spans_) {
    const std::size_t overlap_lo = std::max(lo, c.reference), overlap_hi = std::min(hi, c.query);
    const std::size_t shared = overlap_hi > overlap_lo ? overlap_hi - overlap_lo : 0;
    const std::size_t either = std::max(hi, c.query) - std::min(lo, c.reference);
    if (either == 0 || 2 * shared < either) continue;
    const double scale = std::max(basis ? basis->scale : 0.0, c.scale);
    basis = SkipBasis{scale, c.loop_cov};  // the most recent covering edge
  }
  if (!basis) return std::nullopt;
  if (step_cov_.empty() || graph_config_.odometry_cov_scale > 0)
    basis->scale = scale_now();
  else
    basis->scale = std::max(basis->scale, scale_now());
  return basis;
}

void LoopCloser::add_innovation(const LoopResult& r) {
  if (step_cov_.empty() || !r.result.verified || !pose_of(r.loop.query) || !pose_of(r.loop.reference)) return;
  const std::size_t i = r.loop.query - first_, j = r.loop.reference - first_;
  if (j >= i) return;
  extend_chain(i + 1);
  if (chain_id_[i] < 0 || chain_id_[i] != chain_id_[j]) return;
  LoopInnovation innovation;
  const Eigen::Isometry3d T_j_i = chain_T_[j].inverse() * chain_T_[i];
  innovation.error.head<3>() = r.result.T_j_i.translation() - T_j_i.translation();
  innovation.error.tail<3>() = so3_log(T_j_i.rotation().transpose() * r.result.T_j_i.rotation());
  innovation.odometry_cov = step_pose_cov(chain_T_[j], chain_cov_[j], chain_T_[i], chain_cov_[i]);
  innovation.loop_cov = r.result.cov;
  innovations_.push_back(innovation);
  checked_spans_.push_back(
      {r.loop.query, r.loop.reference, odometry_cov_scale_from_loops({innovation}, 1, 1e6), r.result.cov});
}

std::string LoopCloser::skip_reason(const Detection& loop) {
  // A loop the odometry already knows (standing still, hovering, the frames just before a query): an edge as
  // certain as the last one verified over the same odometry would shrink the odometry's own uncertainty of
  // T_j_i, scaled by what the verified loops showed, by less than verify.min_information_gain. Such an edge
  // corrects nothing. A loop over odometry no verified loop has checked is never skipped for its gain.
  if (verify_config_.min_information_gain > 0 && pose_of(loop.query) && pose_of(loop.reference) &&
      loop.reference != loop.query) {
    const std::optional<SkipBasis> basis = skip_basis(loop);
    const PoseCov odometry =
        relative_odometry_cov(loop.reference, loop.query, basis ? basis->scale : scale_now());
    const PoseCov edge = basis ? basis->edge_cov : PoseCov(PoseCov::Identity());
    // The loops of one revisit correct the trajectory together: this one and those before it over the same
    // odometry, each an edge as certain as the last verified.
    std::size_t together = 1;
    const std::size_t lo = std::min(loop.query, loop.reference), hi = std::max(loop.query, loop.reference);
    for (const LoopResult& r : results_) {
      const std::size_t overlap_lo = std::max(lo, r.loop.reference), overlap_hi = std::min(hi, r.loop.query);
      const std::size_t shared = overlap_hi > overlap_lo ? overlap_hi - overlap_lo : 0;
      const std::size_t either = std::max(hi, r.loop.query) - std::min(lo, r.loop.reference);
      if (either > 0 && 2 * shared >= either) ++together;
    }
    const double gain = basis ? loop_information_gain(odometry, edge / static_cast<double>(together)) : 1.0;
    if (gain < verify_config_.min_information_gain) {
      const double sigma_m = std::sqrt(
          std::max(0.0, Eigen::SelfAdjointEigenSolver<Eigen::Matrix3d>(odometry.topLeftCorner<3, 3>())
                            .eigenvalues()
                            .maxCoeff()));
      return fmt::format(
          "skipped: information gain {:.2f} < {} (the odometry's sigma from j to i {:.3f} m, a loop edge's "
          "{:.3f} m)",
          gain, verify_config_.min_information_gain, sigma_m,
          std::sqrt(edge.topLeftCorner<3, 3>().diagonal().maxCoeff()));
    }
  }
  int tried_for_query = 0;
  for (auto it = results_.rbegin(); it != results_.rend(); ++it) {
    const LoopResult& r = *it;
    if (r.skipped) continue;
    if (r.loop.query == loop.query) ++tried_for_query;
    if (in_skip_window(r.loop, r.result.verified, loop))
      return fmt::format("skipped: near ({}, {}) {}", r.loop.query, r.loop.reference,
                         r.result.verified ? "verified" : "rejected");
  }
  if (verify_config_.max_per_query > 0 && tried_for_query >= verify_config_.max_per_query)
    return fmt::format("skipped: {} loop(s) of frame {} already verified", tried_for_query, loop.query);
  return {};
}

bool LoopCloser::would_skip(const Detection& earlier, bool verified, const Detection& later) const {
  return in_skip_window(earlier, verified, later) ||
         (verify_config_.max_per_query > 0 && earlier.query == later.query);
}

std::optional<std::size_t> LoopCloser::neighbour_of(const Detection& loop) const {
  const int k = verify_config_.neighbour_offset_frames;
  const auto shifted = [&](int offset) -> std::optional<std::size_t> {
    const auto n = static_cast<std::int64_t>(loop.reference) + offset;
    if (n < static_cast<std::int64_t>(first_) || n >= static_cast<std::int64_t>(last_)) return std::nullopt;
    return static_cast<std::size_t>(n);
  };
  std::optional<std::size_t> neighbour = shifted(k);
  if (!neighbour || !pose_of(*neighbour) || *neighbour >= loop.query) neighbour = shifted(-k);
  return neighbour;
}

LoopCloser::VerifyJob LoopCloser::prepare(const Detection& loop, bool prefetch) {
  VerifyJob job;
  if (!unusable_.empty()) {
    job.reason = unusable_;
    return job;
  }
  const std::optional<std::size_t> neighbour = neighbour_of(loop);
  if (!neighbour || !pose_of(*neighbour) || !pose_of(loop.reference)) {
    job.reason = fmt::format("geometry: no odometry pose for frame {} or its neighbour", loop.reference);
    return job;
  }
  job.neighbour = *neighbour;
  try {
    // At the end of the stream the pipeline's threads are free: detect the three frames' features at once.
    if (prefetch) prefetch_features({loop.query, loop.reference, *neighbour});
    job.i = features_of(loop.query);
    job.j = features_of(loop.reference);
    job.n = features_of(*neighbour);
    if (job.i->image_size.empty() || job.j->image_size.empty() || job.n->image_size.empty())
      job.reason = "geometry: image missing";
  } catch (const std::exception& e) {
    job.reason = std::string("geometry: ") + e.what();
  }
  return job;
}

VerifyResult LoopCloser::run(const Detection& loop, const VerifyJob& job) const {
  VerifyResult result;
  if (!job.reason.empty()) {
    result.reason = job.reason;
    return result;
  }
  try {
    const std::optional<Eigen::Isometry3d> T_w_bi = pose_of(loop.query);
    const Eigen::Matrix3d R_w_bi = T_w_bi ? Eigen::Matrix3d(T_w_bi->linear()) : Eigen::Matrix3d::Identity();
    // The image geometry agrees; the odometry must too (a copy of the place elsewhere looks the same), when
    // its chain from j to i is whole (no frame lost or re-initialised in between).
    GeometricVerifier::Veto odometry_check;
    if (odometry_unbroken(loop.reference, loop.query)) {
      odometry_check = [&](const VerifyResult& r) {
        return odometry_disagreement(*pose_of(loop.query), *pose_of(loop.reference), r,
                                     sigma_m_[loop.query - first_], sigma_m_[loop.reference - first_],
                                     verify_config_.odometry_chi2);
      };
    }
    result = verifier_.verify(*job.i, *job.j, *pose_of(loop.reference), *job.n, *pose_of(*job.neighbour),
                              T_w_bi ? &R_w_bi : nullptr, odometry_check);
  } catch (const std::exception& e) {
    result = VerifyResult{};
    result.reason = std::string("geometry: ") + e.what();
  }
  return result;
}

LoopCloser::LoopResult LoopCloser::verify_one(const Detection& loop, bool draining) {
  LoopResult out;
  out.loop = loop;
  const std::size_t index = results_.size();  // this loop's submission index
  const auto ahead = verified_ahead_.find(index);
  if (unusable_.empty()) {
    if (std::string why = skip_reason(loop); !why.empty()) {
      // A loop verify_ahead() chose on a wrong guess: one loop after the other would not have verified it.
      if (ahead != verified_ahead_.end()) verified_ahead_.erase(ahead);
      out.result.reason = std::move(why);
      out.skipped = true;
      return out;
    }
  }
  if (draining && unusable_.empty()) ++drain_verified_;
  if (ahead != verified_ahead_.end()) {
    out = std::move(ahead->second);
    verified_ahead_.erase(ahead);
    ++drain_verified_ahead_;
    return out;
  }
  const auto start = std::chrono::steady_clock::now();
  const VerifyJob job = prepare(loop, draining);
  if (job.neighbour) out.neighbour = *job.neighbour;
  out.result = run(loop, job);
  out.verify_ms = ms_since(start);
  return out;
}

void LoopCloser::verify_ahead() {
  if (drain_threads_ < 2 || !unusable_.empty()) return;
  const std::size_t first_index = results_.size();  // the submission index of the queue's front
  if (verified_ahead_.contains(first_index)) return;
  std::vector<Detection> next;
  {
    std::lock_guard lock(mutex_);
    const std::size_t look = std::min(queue_.size(), kVerifyAheadLoops);
    next.assign(queue_.begin(), queue_.begin() + static_cast<std::ptrdiff_t>(look));
  }
  if (next.size() < 2 || !skip_reason(next[0]).empty()) return;
  // Which of the next loops are verified (not skipped) depends on the outcomes of those before them. An
  // outcome not known yet is guessed to be the last one known (a revisit gives runs of verified loops and
  // runs of rejected ones); the loops verified along that guess are verified at once. A wrong guess costs
  // only the work of the loops it chose wrongly: their turn comes, skip_reason() skips them, and verify_one()
  // drops their results. The front is verified whatever the guess (nothing before it is pending).
  bool guess = false;
  for (auto r = results_.rbegin(); r != results_.rend(); ++r) {
    if (r->skipped) continue;
    guess = r->result.verified;
    break;
  }
  std::vector<std::pair<std::size_t, bool>> before;  // loops taken as verified (true) or rejected before k
  std::vector<std::size_t> chosen;
  const std::size_t most = kVerifyAheadPerThread * static_cast<std::size_t>(drain_threads_);
  for (std::size_t k = 0; k < next.size() && chosen.size() < most; ++k) {
    if (!skip_reason(next[k]).empty()) continue;  // skipped whatever the loops before it give
    if (std::any_of(before.begin(), before.end(),
                    [&](const auto& b) { return would_skip(next[b.first], b.second, next[k]); }))
      continue;
    if (const auto known = verified_ahead_.find(first_index + k); known != verified_ahead_.end()) {
      guess = known->second.result.verified;  // computed by an earlier call: known, not guessed
    } else {
      chosen.push_back(k);
    }
    before.emplace_back(k, guess);
  }
  if (chosen.size() < 2) return;
  // Their frames' features at once (prefetch_features), then the verifications at once.
  const auto start = std::chrono::steady_clock::now();
  std::vector<std::size_t> frames;
  for (const std::size_t k : chosen) {
    frames.push_back(next[k].query);
    frames.push_back(next[k].reference);
    if (const std::optional<std::size_t> n = neighbour_of(next[k])) frames.push_back(*n);
  }
  prefetch_features(frames);
  std::vector<VerifyJob> jobs;
  for (const std::size_t k : chosen) jobs.push_back(prepare(next[k], false));  // features cached above
  const double prepare_ms = ms_since(start) / static_cast<double>(chosen.size());
  std::vector<LoopResult> results(chosen.size());
  if (!drain_arena_) drain_arena_ = std::make_unique<tbb::task_arena>(drain_threads_);
  drain_arena_->execute([&] {
    parallel_for_with_handoff(chosen.size(), [&](std::size_t c) {
      const auto run_start = std::chrono::steady_clock::now();
      LoopResult& out = results[c];
      out.loop = next[chosen[c]];
      if (jobs[c].neighbour) out.neighbour = *jobs[c].neighbour;
      out.result = run(out.loop, jobs[c]);
      out.verify_ms = prepare_ms + ms_since(run_start);  // its share of the features, its own verification
    });
  });
  for (std::size_t c = 0; c < chosen.size(); ++c)
    verified_ahead_.emplace(first_index + chosen[c], std::move(results[c]));
}

void LoopCloser::work() {
  for (;;) {
    Detection loop;
    bool draining = false;
    {
      std::unique_lock lock(mutex_);
      wake_.wait(lock, [&] { return stopping_ || !queue_.empty(); });
      if (queue_.empty()) return;  // stopping, nothing left
      loop = queue_.front();
      draining = stopping_;
    }
    if (draining) verify_ahead();
    LoopResult result = verify_one(loop, draining);
    if (result_listener_) result_listener_(loop, result.result);
    if (verify_config_.min_information_gain > 0 && !result.skipped) add_innovation(result);
    bool solve_now = false;
    {
      std::lock_guard lock(mutex_);
      queue_.pop_front();
      if (!result.skipped) ms_by_frame_[loop.query].verify_ms += result.verify_ms;
      results_.push_back(std::move(result));
      const std::size_t verified = static_cast<std::size_t>(std::count_if(
          results_.begin(), results_.end(), [](const LoopResult& r) { return r.result.verified; }));
      solve_now = graph_config_.enabled && graph_config_.optimize_on_loop && queue_.empty() && !stopping_ &&
                  verified > verified_at_last_solve_;
      if (solve_now) verified_at_last_solve_ = verified;
    }
    double solve_ms = 0;
    if (solve_now) {
      try {
        solve_ms = solve(loop.query, false);
      } catch (const std::exception& e) {
        spdlog::warn("posegraph: solve while streaming failed: {}", e.what());
      }
    }
    // The frame's rows (frames.csv, timing.csv) wait until its loop is verified and the solve it started is
    // done, so that timing.csv books that solve on it.
    std::lock_guard lock(mutex_);
    if (solve_now) ms_by_frame_[loop.query].optimize_ms += solve_ms;
    if (loop.query >= first_ && loop.query < last_) --pending_by_frame_[loop.query - first_];
  }
}

LoopCloser::FrameMs LoopCloser::frame_ms(std::size_t frame) const {
  std::lock_guard lock(mutex_);
  const auto it = ms_by_frame_.find(frame);
  return it != ms_by_frame_.end() ? it->second : FrameMs{};
}

double LoopCloser::solve(std::size_t last, bool final) {
  std::vector<LoopResult> loops;
  {
    std::lock_guard lock(mutex_);
    for (const LoopResult& r : results_)
      if (r.result.verified) loops.push_back(r);
  }
  const std::size_t span = std::min(last + 1, last_) - first_;
  std::vector<char> is_node(span, 0);
  const auto every = static_cast<std::size_t>(graph_config_.node_every_frames);
  for (std::size_t k = 0; k < span; ++k) is_node[k] = (k % every == 0) && poses_[k].has_value();
  for (const LoopResult& r : loops) {
    for (const std::size_t f : {r.loop.query, r.loop.reference})
      if (f >= first_ && f - first_ < span && poses_[f - first_]) is_node[f - first_] = 1;
  }
  PoseGraph graph(graph_config_);
  std::vector<std::int64_t> node_of(span, -1);
  std::vector<std::size_t> frames;
  for (std::size_t k = 0; k < span; ++k) {
    if (!is_node[k]) continue;
    node_of[k] = static_cast<std::int64_t>(graph.add_node(*poses_[k]));
    frames.push_back(first_ + k);
  }
  const double scale = odometry_cov_scale(loops, span);
  for (std::size_t n = 1; n < frames.size(); ++n) {
    const Eigen::Isometry3d T_a_b = graph.initial_pose(n - 1).inverse() * graph.initial_pose(n);
    graph.add_edge(n - 1, n, EdgeKind::kOdometry, T_a_b, odometry_edge_cov(frames[n - 1], frames[n], scale));
  }
  // Loop edges (the loop's query and reference frame must both be nodes), keyed by (i, j) for the report.
  std::vector<std::pair<std::pair<std::size_t, std::size_t>, std::size_t>> edge_of_loop;
  for (const LoopResult& r : loops) {
    if (r.loop.query - first_ >= span) continue;
    const std::int64_t a = node_of[r.loop.reference - first_];
    const std::int64_t b = node_of[r.loop.query - first_];
    if (a < 0 || b < 0) continue;
    edge_of_loop.push_back({{r.loop.query, r.loop.reference}, graph.edges().size()});
    graph.add_edge(static_cast<std::size_t>(a), static_cast<std::size_t>(b), EdgeKind::kLoop, r.result.T_j_i,
                   r.result.cov);
  }
  const auto start = std::chrono::steady_clock::now();
  const SolveReport report = graph.optimize(final, final ? 0.0 : graph_config_.max_solve_s);
  const double ms = ms_since(start);
  spdlog::debug(
      "posegraph: {} nodes, {} loop edges ({} outliers), odometry covariance x {:.3g}, {} iterations, cost "
      "{:.3g} -> {:.3g}, {:.1f} ms",
      graph.node_count(), report.loop_edges, report.outliers, scale, report.iterations, report.initial_cost,
      report.final_cost, ms);
  if (!final) {
    solve_ms_.push_back(ms);
    return ms;
  }
  final_solve_ms_ = ms;
  final_report_ = report;
  final_odometry_cov_scale_ = scale;
  nodes_ = frames;
  final_edges_ = graph.edges();
  node_poses_.clear();
  for (std::size_t n = 0; n < graph.node_count(); ++n) node_poses_.push_back(graph.pose(n));
  // Mark the outlier loops (in submission order, like edge_of_loop).
  std::size_t next = 0;
  std::lock_guard lock(mutex_);
  for (LoopResult& r : results_) {
    if (!r.result.verified || next >= edge_of_loop.size()) continue;
    if (edge_of_loop[next].first != std::pair(r.loop.query, r.loop.reference)) continue;
    const PoseGraphEdge& edge = graph.edges().at(edge_of_loop[next++].second);
    r.outlier = edge.outlier;
    r.chi2 = edge.chi2;
  }
  return ms;
}

void LoopCloser::finish() {
  if (!active_) return;
  {
    std::lock_guard lock(mutex_);
    stopping_ = true;
  }
  wake_.notify_all();
  if (worker_.joinable()) worker_.join();
  if (!graph_config_.enabled) return;
  try {
    solve(last_ - 1, true);
  } catch (const std::exception& e) {
    final_solve_error_ = e.what();
    if (final_solve_error_.empty()) final_solve_error_ = "unknown error";
    spdlog::error("posegraph: the final solve failed: {}", final_solve_error_);
    nodes_.clear();
    node_poses_.clear();
    final_edges_.clear();
  }
  std::size_t verified = 0, skipped = 0;
  for (const LoopResult& r : results_) {
    verified += r.result.verified ? 1 : 0;
    skipped += r.skipped ? 1 : 0;
  }
  spdlog::info(
      "loop closure: {} loops, {} verified, {} rejected by geometry, {} skipped, {} outliers in the pose "
      "graph; final solve {:.1f} ms",
      results_.size(), verified, results_.size() - verified - skipped, skipped, final_report_.outliers,
      final_solve_ms_);
  const ReasonCounts counts = reason_counts();
  const auto listed = [](const std::map<std::string, std::size_t>& m) {
    std::string text;
    for (const auto& [key, n] : m) text += fmt::format("{}{} {}", text.empty() ? "" : ", ", key, n);
    return text.empty() ? std::string("none") : text;
  };
  spdlog::info("loop closure: rejected by reason: {}; skipped by reason: {}", listed(counts.rejected),
               listed(counts.skipped));
}

LoopCloser::ReasonCounts LoopCloser::reason_counts() const {
  ReasonCounts counts;
  for (const LoopResult& r : results_) {
    if (r.result.verified) continue;
    ++(r.skipped ? counts.skipped : counts.rejected)[verify_reason_key(r.result.reason)];
  }
  return counts;
}

std::vector<StampedPose> LoopCloser::corrected(const std::vector<StampedPose>& tracked) const {
  return corrected_by(tracked, node_poses_);
}

std::vector<StampedPose> LoopCloser::corrected_by(const std::vector<StampedPose>& tracked,
                                                  const std::vector<Eigen::Isometry3d>& node_poses) const {
  if (nodes_.empty() || node_poses.size() != nodes_.size()) return tracked;
  std::vector<StampedPose> out;
  out.reserve(tracked.size());
  // tracked poses are in frame order; nodes_ too. A frame takes the correction of the last node at or before
  // it (the first node for frames before it): T_corr(f) = T_corr(node) T_odo(node)^-1 T_odo(f).
  std::size_t n = 0;
  for (const StampedPose& pose : tracked) {
    while (n + 1 < nodes_.size() && dataset_.frame_t_ns(nodes_[n + 1]) <= pose.t_ns) ++n;
    const Eigen::Isometry3d& T_odo_node = *poses_[nodes_[n] - first_];
    out.push_back({pose.t_ns, node_poses[n] * T_odo_node.inverse() * pose.T_w_b});
  }
  return out;
}

nlohmann::json LoopCloser::oracle_report(
    const std::vector<StampedPose>& tracked,
    const std::vector<std::pair<std::size_t, std::size_t>>& truth_pairs) const {
  if (!active_ || !graph_config_.enabled) return {{"available", false}, {"why", "no pose graph"}};
  if (!dataset_.has_ground_truth()) return {{"available", false}, {"why", "the dataset has no ground truth"}};
  if (nodes_.size() < 2) return {{"available", false}, {"why", "no final pose-graph solve"}};
  const auto start = std::chrono::steady_clock::now();
  OracleGraph graph;
  graph.frames = nodes_;
  for (const std::size_t frame : nodes_) graph.T_w_b.push_back(*poses_[frame - first_]);
  for (const PoseGraphEdge& e : final_edges_) {
    if (e.kind != EdgeKind::kOdometry) continue;
    graph.odometry.push_back(
        {e.a, e.b, e.T_a_b, (e.sqrt_information.transpose() * e.sqrt_information).inverse()});
  }
  OracleOptions options;
  options.graph = graph_config_;
  OracleResult oracle;
  try {
    oracle = solve_loop_oracle(graph, truth_pairs, dataset_, options);
  } catch (const std::exception& e) {
    return {{"available", false}, {"why", std::string("the oracle's solve failed: ") + e.what()}};
  }
  const auto rmse = [&](const std::vector<StampedPose>& poses) -> std::optional<double> {
    const nlohmann::json accuracy = trajectory_accuracy_json(poses, dataset_);
    if (!accuracy.value("available", false)) return std::nullopt;
    return accuracy.at("rmse_m").get<double>();
  };
  const std::optional<double> odometry = rmse(tracked);
  const std::optional<double> corrected_m = rmse(corrected(tracked));
  const std::optional<double> floor_m = rmse(corrected_by(tracked, oracle.T_w_b));
  if (!odometry || !corrected_m || !floor_m) return {{"available", false}, {"why", "no trajectory accuracy"}};
  nlohmann::json share = nullptr;
  std::string share_why;
  const double attainable_m = *odometry - *floor_m;
  if (oracle.loops == 0) {
    share_why = "no ground-truth revisit between two nodes of the graph";
  } else if (!(attainable_m >= kOracleMinGain * *odometry)) {
    share_why = fmt::format("the oracle gains {:.1f}% < {:.0f}% of the odometry's ATE",
                            *odometry > 0 ? 100.0 * attainable_m / *odometry : 0.0, 100.0 * kOracleMinGain);
  } else {
    share = (*odometry - *corrected_m) / attainable_m;
  }
  return {{"available", true},
          {"ate_odometry_m", *odometry},
          {"ate_corrected_m", *corrected_m},
          {"ate_oracle_m", *floor_m},
          {"share_of_attainable_gain", share},
          {"share_why", share_why},
          {"oracle_loop_edges", oracle.loops},
          {"truth_pairs", truth_pairs.size()},
          {"every_query_frames", options.every},
          {"sigma_position_m", options.sigma_position_m},
          {"sigma_rotation_rad", options.sigma_rotation_rad},
          {"iterations", oracle.iterations},
          {"ms", ms_since(start)}};
}

// loops.csv's verification cells of a loop (also the start of its loop_edges.csv row).
std::vector<std::string> LoopCloser::verification_cells(const LoopResult& r) {
  const Eigen::Vector3d t = r.result.T_j_i.translation();
  const Eigen::Quaterniond q(r.result.T_j_i.rotation());
  const bool v = r.result.verified;
  const auto num = [v](double x) { return v ? format_fixed(x, 6) : std::string(); };
  return std::vector<std::string>{v ? "y" : (r.skipped ? "skipped" : "n"),
                                  std::to_string(r.result.inliers),
                                  r.result.reason,
                                  num(t.x()),
                                  num(t.y()),
                                  num(t.z()),
                                  num(q.x()),
                                  num(q.y()),
                                  num(q.z()),
                                  num(q.w())};
}

void LoopCloser::write_corrected(const std::filesystem::path& out_dir,
                                 const std::vector<StampedPose>& tracked) const {
  if (!final_solve_error_.empty()) return;  // nothing was corrected: no file claims it was
  TumWriter file(out_dir / "trajectory_corrected.tum");
  for (const StampedPose& pose : corrected(tracked)) file.write(pose.t_ns, pose.T_w_b);
  file.close();
}

void LoopCloser::write_graph(const std::filesystem::path& out_dir) const {
  if (!active_ || nodes_.empty()) return;
  G2oGraph file;
  for (const std::size_t frame : nodes_)
    file.vertices.push_back({static_cast<std::int64_t>(frame), *poses_[frame - first_]});
  file.fixed.push_back(static_cast<std::int64_t>(nodes_.front()));
  for (const PoseGraphEdge& e : final_edges_) {
    if (e.outlier) continue;
    file.edges.push_back({static_cast<std::int64_t>(nodes_[e.a]), static_cast<std::int64_t>(nodes_[e.b]),
                          e.T_a_b, e.sqrt_information.transpose() * e.sqrt_information});
  }
  write_g2o(out_dir / "pose_graph.g2o", file);
}

void LoopCloser::write_edges(const std::filesystem::path& out_dir) const {
  if (!active_) return;
  CsvWriter edges(out_dir / "loop_edges.csv", {"i",
                                               "j",
                                               "neighbour",
                                               "verified",
                                               "inliers",
                                               "matches",
                                               "points",
                                               "reason",
                                               "x_m",
                                               "y_m",
                                               "z_m",
                                               "qx",
                                               "qy",
                                               "qz",
                                               "qw",
                                               "sigma_position_m",
                                               "sigma_rotation_rad",
                                               "graph_outlier",
                                               "chi2",
                                               "verify_ms"});
  for (const LoopResult& r : results_) {
    const std::vector<std::string> c = verification_cells(r);
    const bool v = r.result.verified;
    edges.write_row({std::to_string(r.loop.query),
                     std::to_string(r.loop.reference),
                     r.neighbour ? std::to_string(r.neighbour) : "",
                     c[0],
                     c[1],
                     std::to_string(r.result.matches),
                     std::to_string(r.result.points),
                     c[2],
                     c[3],
                     c[4],
                     c[5],
                     c[6],
                     c[7],
                     c[8],
                     c[9],
                     v ? format_fixed(std::sqrt(r.result.cov(0, 0)), 6) : "",
                     v ? format_fixed(std::sqrt(r.result.cov(3, 3)), 6) : "",
                     v ? (r.outlier ? "y" : "n") : "",
                     v ? format_fixed(r.chi2, 3) : "",
                     format_fixed(r.verify_ms, 3)});
  }
  edges.close();
}

void LoopCloser::annotate_loops(LoopsWriter& loops) const {
  if (!active_) return;
  // loops.csv: one row per loop written, in the same order as the loops were submitted.
  if (loops.count() == results_.size()) {
    loops.rewrite_with(
        {"verified", "inliers", "geometry_reason", "x_m", "y_m", "z_m", "qx", "qy", "qz", "qw"},
        [&](std::size_t k) { return verification_cells(results_[k]); });
  }
}

nlohmann::json LoopCloser::summary() const {
  std::size_t verified = 0, tracked = 0, outliers = 0, skipped = 0;
  std::vector<double> verify_ms;
  for (const LoopResult& r : results_) {
    verified += r.result.verified ? 1 : 0;
    tracked += r.result.tracked ? 1 : 0;  // set on verified loops only
    outliers += r.outlier ? 1 : 0;
    skipped += r.skipped ? 1 : 0;
    if (!r.skipped) verify_ms.push_back(r.verify_ms);
  }
  const ReasonCounts counts = reason_counts();
  return {{"enabled", active_},
          {"unusable_reason", unusable_},
          {"loops", results_.size()},
          {"verified", verified},
          {"verified_by_tracking", tracked},
          {"rejected_geometry", results_.size() - verified - skipped},
          {"skipped", skipped},
          {"rejected_by_reason", counts.rejected},
          {"skipped_by_reason", counts.skipped},
          {"graph_outliers", outliers},
          {"graph_nodes", nodes_.size()},
          {"odometry_cov", graph_config_.odometry_cov},
          {"odometry_cov_scale", final_odometry_cov_scale_},
          {"verify", stats_json(verify_ms)},
          {"optimize_streaming", stats_json(solve_ms_)},
          {"end_of_stream",
           {{"loops_verified", drain_verified_},
            {"loops_verified_in_parallel", drain_verified_ahead_},
            {"features_detected_in_parallel", drain_prefetched_}}},
          {"optimize_final",
           {{"ms", final_solve_ms_},
            {"iterations", final_report_.iterations},
            {"initial_cost", final_report_.initial_cost},
            {"final_cost", final_report_.final_cost},
            {"converged", final_report_.converged}}}};
}

nlohmann::json LoopCloser::summary_fields(const std::vector<StampedPose>& tracked) const {
  nlohmann::json closure = summary();
  nlohmann::json corrected;
  if (!final_solve_error_.empty()) {
    corrected = {{"available", false}, {"why", "the final pose-graph solve failed: " + final_solve_error_}};
    closure["final_solve_error"] = final_solve_error_;
  } else {
    corrected = trajectory_accuracy_json(this->corrected(tracked), dataset_);
    if (corrected.value("available", false))
      corrected["poses"] = "odometry poses with status tracking, corrected by the pose graph";
  }
  return {{"loops_verified", closure["verified"]},
          {"loops_rejected_geometry", closure["rejected_geometry"]},
          {"loops_skipped_geometry", closure["skipped"]},
          {"trajectory_accuracy_corrected", std::move(corrected)},
          {"loop_closure", std::move(closure)}};
}

std::string LoopCloser::profile_line() const {
  if (!active_) return {};
  std::vector<double> verify_ms;
  for (const LoopResult& r : results_)
    if (!r.skipped) verify_ms.push_back(r.verify_ms);
  const double verify_total = std::accumulate(verify_ms.begin(), verify_ms.end(), 0.0);
  const double solve_total = std::accumulate(solve_ms_.begin(), solve_ms_.end(), 0.0);
  return fmt::format(
      "loop closure (off the frame path): verify {} loops {:.1f} ms ({:.1f} ms/loop); {} streaming solves "
      "{:.1f} ms; final solve {:.1f} ms\n",
      verify_ms.size(), verify_total,
      verify_ms.empty() ? 0.0 : verify_total / static_cast<double>(verify_ms.size()), solve_ms_.size(),
      solve_total, final_solve_ms_);
}

nlohmann::json correct_after_run(const PipelineConfig& config, const Dataset& dataset, const RunTrack& track,
                                 const std::filesystem::path& run_dir) {
  const auto start = std::chrono::steady_clock::now();
  LoopCloser closer(config, dataset, track.first_frame, track.last_frame, true);
  if (!closer.active()) throw std::logic_error("correct_after_run: verify.enabled is false");
  for (std::size_t k = 0; k < track.tracked_frames.size(); ++k)
    closer.record_pose(track.tracked_frames[k], track.tracked_poses[k].T_w_b, track.tracked_sigma_m[k],
                       k < track.tracked_step_cov.size() ? track.tracked_step_cov[k] : std::nullopt);
  for (const Detection& loop : track.loops) closer.submit(loop);
  closer.finish();
  closer.write_edges(run_dir);
  if (!closer.solve_failure().empty())
    throw DataError(run_dir, "the final pose-graph solve failed (no trajectory_corrected.tum): " +
                                 closer.solve_failure());
  closer.write_graph(run_dir);
  closer.write_corrected(run_dir, track.tracked_poses);
  nlohmann::json fields = closer.summary_fields(track.tracked_poses);
  fields["ms"] = ms_since(start);
  return fields;
}

}  // namespace loopgate
