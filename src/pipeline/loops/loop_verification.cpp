// The loop closer's verification of one loop (loop_closer.hpp): its frames' ORB features (cached, prefetched
// at the end of the stream), the verifier with the odometry check, and the verification ahead of the queue.
#include <spdlog/fmt/fmt.h>
#include <spdlog/spdlog.h>

#include <Eigen/Eigenvalues>
#include <algorithm>
#include <chrono>
#include <cmath>

#include "io/dataset.hpp"
#include "parallel/parallel_handoff.hpp"
#include "pipeline/loops/loop_closer.hpp"
#include "pipeline/loops/loop_timing.hpp"

namespace loopgate {

using loop_internal::ms_since;

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
  if (unusable_) {
    job.reason = unusable_;
    return job;
  }
  const std::optional<std::size_t> neighbour = neighbour_of(loop);
  if (!neighbour || !pose_of(*neighbour) || !pose_of(loop.reference)) {
    job.reason =
        VerifyNote{VerifyReason::kNoOdometryPose,
                   fmt::format("geometry: no odometry pose for frame {} or its neighbour", loop.reference)};
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
      job.reason = VerifyNote{VerifyReason::kImageMissing, "geometry: image missing"};
  } catch (const std::exception& e) {  // an image that cannot be read
    job.reason = VerifyNote{VerifyReason::kImageMissing, std::string("geometry: ") + e.what()};
  }
  return job;
}

VerifyResult LoopCloser::run(const Detection& loop, const VerifyJob& job) const {
  VerifyResult result;
  if (job.reason) {
    result.reject(*job.reason);
    return result;
  }
  try {
    const std::optional<Eigen::Isometry3d> T_w_bi = pose_of(loop.query);
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
                              T_w_bi ? &*T_w_bi : nullptr, odometry_check);
  } catch (const std::exception& e) {
    result = VerifyResult{};
    result.reject({VerifyReason::kOther, std::string("geometry: ") + e.what()});
  }
  return result;
}

LoopCloser::LoopResult LoopCloser::verify_one(const Detection& loop, bool draining) {
  LoopResult out;
  out.loop = loop;
  const std::size_t index = results_.size();  // this loop's submission index
  const auto ahead = verified_ahead_.find(index);
  if (!unusable_) {
    if (std::optional<VerifyNote> why = skip_reason(loop)) {
      // A loop verify_ahead() chose on a wrong guess: one loop after the other would not have verified it.
      if (ahead != verified_ahead_.end()) verified_ahead_.erase(ahead);
      out.result.reject(std::move(*why));
      out.skipped = true;
      return out;
    }
  }
  if (draining && !unusable_) ++drain_verified_;
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
  if (drain_threads_ < 2 || unusable_) return;
  const std::size_t first_index = results_.size();  // the submission index of the queue's front
  if (verified_ahead_.contains(first_index)) return;
  std::vector<Detection> next;
  {
    std::lock_guard lock(mutex_);
    const std::size_t look = std::min(queue_.size(), kVerifyAheadLoops);
    next.assign(queue_.begin(), queue_.begin() + static_cast<std::ptrdiff_t>(look));
  }
  if (next.size() < 2 || skip_reason(next[0])) return;
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
    if (skip_reason(next[k])) continue;  // skipped whatever the loops before it give
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

}  // namespace loopgate
