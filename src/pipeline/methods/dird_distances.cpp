#include "pipeline/methods/dird_distances.hpp"

#include <spdlog/fmt/fmt.h>

#include <algorithm>
#include <cmath>
#include <limits>
#include <stdexcept>

#include "io/dataset.hpp"
#include "parallel/parallel_handoff.hpp"
#include "pipeline/frame/frame_steps.hpp"
#include "pipeline/methods/coded_distance.hpp"
#include "stages/dird/dird_similarity.hpp"

namespace loopgate {

DirdDistances::DirdDistances(const MethodContext& context, const DirdConfig& dird,
                             const StandardizeConfig& standardize, const DirdCodeConfig& codes)
    : context_(context),
      dird_(dird),
      standardize_(standardize),
      extractor_(dird),
      raw_(context.capacity),
      codes_(new Descriptor[context.capacity]),
      norms_(context.capacity, 0.0),
      coded_(context.capacity, 0),
      code_config_(codes) {
  if (codes.compact() && !standardize.enabled())
    throw std::invalid_argument("DirdDistances: a compact code needs the standardisation");
  if (standardize.enabled()) {
    if (codes.compact()) {
      coder_.emplace(observations_config(standardize), codes);
    } else {
      standardizer_.emplace(observations_config(standardize));
    }
    observe_every_ = static_cast<std::size_t>(standardize.observe_every);
  }
  if (codes.compact()) {
    compact_.emplace(codes, standardize.clamp_sigma, context.capacity);
    pending_.resize(context.capacity);
  }
}

void DirdDistances::describe(std::size_t seq, const cv::Mat* image) {
  if (image && code_config_.compact()) {
    auto raw = std::make_unique<Descriptor>();
    extractor_.extract(*image, *raw);
    pending_.at(seq) = std::move(raw);
    descriptors_computed_.fetch_add(1, std::memory_order_relaxed);
  } else if (image) {
    extractor_.extract(*image, raw_.slot(seq));
    descriptors_computed_.fetch_add(1, std::memory_order_relaxed);
  }
  raw_.publish(seq, image != nullptr);
}

void DirdDistances::begin_frame(std::size_t seq) {
  if (released_) throw std::logic_error("DirdDistances: a frame begun after release_codes()");
  if (observed_frame(seq) && valid(seq)) {
    if (coder_) {
      coder_->observe(static_cast<std::int64_t>(seq), raw(seq));
    } else {
      standardizer_->observe(static_cast<std::int64_t>(seq), raw(seq));
    }
    if (statistics_ready() && !waiting_.empty()) {
      for (const std::size_t k : waiting_) code(k);
      waiting_.clear();
    }
  }
  // Compact codes: no later observation changes this frame's codes (the causal rule), so it is coded now
  // and its raw descriptor dropped.
  if (compact_ && raw_.state(seq) != DescriptorStore::State::kEmpty) code(seq);
}

const Descriptor& DirdDistances::raw(std::size_t seq) const {
  if (!code_config_.compact()) return raw_.descriptor(seq);
  if (!pending_.at(seq)) throw std::logic_error(fmt::format("raw descriptor of seq {} already dropped", seq));
  return *pending_[seq];
}

std::size_t DirdDistances::distance_range(std::size_t seq, std::size_t j_begin, std::size_t j_end,
                                          std::vector<DistanceEntry>& out) {
  if (released_) throw std::logic_error("DirdDistances: distances asked after release_codes()");
  if (j_begin >= j_end || !code(seq)) return 0;
  for (std::size_t j = j_begin; j < j_end; ++j) {
    if (raw_.state(j) == DescriptorStore::State::kEmpty) {
      throw std::logic_error(fmt::format("distance of seq {}: earlier seq {} not described yet", seq, j));
    }
    code(j);
  }
  const std::size_t count = j_end - j_begin;
  distances_.assign(count, std::numeric_limits<double>::quiet_NaN());
  const auto block_distances = [&](std::size_t block) {
    const std::size_t begin = block * kBlock, end = std::min(count, begin + kBlock);
    if (compact_) {  // one pass over the block's rows of the code matrix
      compact_->distances(seq, j_begin + begin, j_begin + end, coded_.data(), distances_.data() + begin);
      return;
    }
    for (std::size_t k = begin; k < end; ++k) {
      const std::size_t j = j_begin + k;
      if (coded_[j]) distances_[k] = distance(seq, j);
    }
  };
  const std::size_t blocks = (count + kBlock - 1) / kBlock;
  if (blocks > 1) {
    parallel_for_with_handoff(blocks, block_distances);
  } else {
    block_distances(0);
  }
  std::size_t compared = 0;
  for (std::size_t k = 0; k < count; ++k) {
    if (std::isnan(distances_[k])) continue;
    ++compared;
    out.push_back({static_cast<std::int64_t>(j_begin + k), distances_[k]});
  }
  distances_computed_ += compared;
  return compared;
}

bool DirdDistances::code(std::size_t seq) {
  if (released_) throw std::logic_error("DirdDistances: coding asked after release_codes()");
  if (coded_[seq]) return true;
  if (!valid(seq)) return false;
  if (!standardized()) {
    codes_[seq] = raw_.descriptor(seq);
  } else if (compact_ && coder_->ready()) {
    compact_->set(seq, *coder_, static_cast<std::int64_t>(seq), raw(seq));
    pending_[seq].reset();
  } else if (!statistics_ready()) {
    if (std::find(waiting_.begin(), waiting_.end(), seq) == waiting_.end()) {
      waiting_.push_back(seq);
      ++frames_before_statistics_;
    }
    return false;
  } else {
    standardizer_->standardize(static_cast<std::int64_t>(seq), raw(seq), codes_[seq]);
    if (standardize_.cosine()) norms_[seq] = standard_norm(codes_[seq]);
  }
  coded_[seq] = 1;
  ++frames_coded_;
  return true;
}

double DirdDistances::distance(std::size_t a, std::size_t b) const {
  if (compact_) return compact_->distance(a, b);
  return coded_distance(dird_, standardize_, codes_[a], norms_[a], codes_[b], norms_[b]);
}

bool DirdDistances::code_like(std::size_t seq, const Descriptor& raw, Descriptor& code, double& norm) {
  if (code_config_.compact()) throw std::logic_error("DirdDistances::code_like: not with a compact code");
  if (!coded_[seq]) return false;
  norm = 0.0;
  if (!standardizer_) {
    code = raw;
    return true;
  }
  standardizer_->standardize(static_cast<std::int64_t>(seq), raw, code);
  if (standardize_.cosine()) norm = standard_norm(code);
  return true;
}

double DirdDistances::distance_to(const Descriptor& code, double norm, std::size_t j) const {
  if (!standardizer_) {
    return dird_.l2_metric() ? l2_distance(code, codes_[j])
                             : static_cast<double>(l1_distance(code, codes_[j]));
  }
  if (standardize_.cosine()) return standard_cosine_distance(code, norm, codes_[j], norms_[j]);
  return static_cast<double>(l1_distance(code, codes_[j]));
}

void DirdDistances::release_codes() {
  if (!compact_ || released_) return;
  released_summary_ = summary();
  released_ = true;
  compact_.reset();
  coder_.reset();
  std::vector<std::unique_ptr<Descriptor>>().swap(pending_);
}

nlohmann::json DirdDistances::summary() const {
  if (released_) return released_summary_;
  if (!standardized()) return nlohmann::json::object();
  if (compact_) {
    return {{"standardize",
             {{"mode", enum_name(standardize_.mode)},
              {"code", enum_name(code_config_.code)},
              {"code_bytes", compact_->bytes_per_code()},
              {"observations", coder_->observations()},
              {"snapshots", coder_->snapshots()},
              {"snapshot_bytes", coder_->snapshot_bytes()},
              {"frames_coded", frames_coded_},
              {"frames_before_statistics", frames_before_statistics_}}}};
  }
  return {{"standardize",
           {{"mode", enum_name(standardize_.mode)},
            {"distance", enum_name(standardize_.distance)},
            {"observations", standardizer_->observations()},
            {"snapshots", standardizer_->snapshots()},
            {"frames_coded", frames_coded_},
            {"frames_before_statistics", frames_before_statistics_}}}};
}

std::pair<std::size_t, Descriptor> DirdDistances::example_descriptor(std::optional<std::int64_t> seq) const {
  const Dataset& dataset = context_.images.dataset();
  if (seq && code_config_.compact()) {
    // Its raw descriptor was dropped once coded: described again from the dataset.
    const std::size_t frame = context_.seqs.frame(*seq);
    return {frame, extractor_.extract(dataset.load_image(frame))};
  }
  if (seq) return {context_.seqs.frame(*seq), raw_.descriptor(static_cast<std::size_t>(*seq))};
  const std::size_t frame = dataset.frame_count() / 2;
  return {frame, extractor_.extract(dataset.load_image(frame))};
}

}  // namespace loopgate
