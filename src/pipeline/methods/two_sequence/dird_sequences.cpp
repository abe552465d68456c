#include "pipeline/methods/two_sequence/dird_sequences.hpp"

#include <spdlog/fmt/fmt.h>

#include <algorithm>
#include <optional>

namespace loopgate {

bool DirdSequences::describe(SequenceSide side, std::size_t k, const cv::Mat* image) {
  Descriptor& descriptor = side == SequenceSide::kReference ? reference_[k] : query_[k];
  if (!image) {
    std::fill(descriptor.begin(), descriptor.end(), std::uint8_t{0});
    return false;
  }
  extractor_.extract(*image, descriptor);
  return true;
}

CodedSequence code_sequence(const std::vector<Descriptor>& descriptors,
                            const std::vector<std::uint8_t>& valid, const StandardizeConfig& config) {
  CodedSequence out;
  const std::size_t n = descriptors.size();
  if (!config.enabled()) {
    out.codes = descriptors;
    out.norms.assign(n, 0.0);  // unused by the raw distances
    out.statistics = "raw";
    return out;
  }
  std::vector<Descriptor> described;
  for (std::size_t k = 0; k < n; ++k)
    if (valid[k]) described.push_back(descriptors[k]);
  out.codes.resize(n);
  out.norms.assign(n, 0.0);
  if (described.empty()) return out;
  std::optional<CausalStandardizer> causal;
  if (config.mode == StandardizeMode::kCausal) {
    causal.emplace(observations_config(config));
    const auto every = static_cast<std::size_t>(config.observe_every);
    for (std::size_t k = 0; k < n; k += every) {
      if (valid[k]) causal->observe(static_cast<std::int64_t>(k), descriptors[k]);
    }
    if (!causal->ready()) {
      out.note = fmt::format(
          "{} observations are fewer than the causal warm-up of {}: the sequence's batch statistics are used",
          causal->observations(), observations_config(config).warm_up);
      causal.reset();
    }
  }
  const Standardization batch = causal ? Standardization{} : standardization_of(described, config);
  out.statistics = causal ? "causal" : "batch";
  for (std::size_t k = 0; k < n; ++k) {
    if (!valid[k]) continue;
    const Standardization& statistics = causal ? causal->statistics_for(static_cast<std::int64_t>(k)) : batch;
    statistics.apply(descriptors[k], out.codes[k]);
    out.norms[k] = standard_norm(out.codes[k]);
  }
  return out;
}

nlohmann::json standardize_json(const StandardizeConfig& standardize, const CodedSequence& reference,
                                const CodedSequence& query) {
  nlohmann::json out = {{"mode", enum_name(standardize.mode)},
                        {"distance", enum_name(standardize.distance)},
                        {"reference_statistics", reference.statistics},
                        {"query_statistics", query.statistics}};
  nlohmann::json notes = nlohmann::json::array();
  if (!reference.note.empty()) notes.push_back("reference: " + reference.note);
  if (!query.note.empty()) notes.push_back("query: " + query.note);
  if (!notes.empty()) out["notes"] = notes;
  return out;
}

}  // namespace loopgate
