// What the DIRD run methods compute, recomputed from the stage classes for the pipeline tests: every frame's
// raw descriptor, and its codes by the causal rule (CausalStandardizer over the observed frames,
// seq % observe_every == 0), as docs/standardize.md states them.
#pragma once

#include <cstddef>
#include <vector>

#include "io/dataset.hpp"
#include "pipeline/pipeline_config.hpp"
#include "stages/dird/dird_extractor.hpp"
#include "stages/dird/dird_standardize.hpp"

namespace loopgate::testing {

struct ReferenceCodes {
  std::vector<Descriptor> codes;  // frames [0, frames)
  // The first frame whose row may be computed: the frame that completes the warm-up (a row before it would
  // need that later frame's statistics).
  std::size_t ready_frame = 0;
};

inline ReferenceCodes reference_codes(const Dataset& dataset, const DirdConfig& dird,
                                      const StandardizeConfig& standardize, std::size_t frames) {
  const DirdExtractor extractor(dird);
  std::vector<Descriptor> raw;
  for (std::size_t k = 0; k < frames; ++k) raw.push_back(extractor.extract(dataset.load_image(k)));
  CausalStandardizer standardizer(observations_config(standardize));
  const auto every = static_cast<std::size_t>(standardize.observe_every);
  for (std::size_t k = 0; k < frames; ++k) {
    if (k % every == 0) standardizer.observe(static_cast<std::int64_t>(k), raw[k]);
  }
  ReferenceCodes out;
  out.codes.resize(frames);
  for (std::size_t k = 0; k < frames; ++k)
    out.codes[k] = standardizer.statistics_for(static_cast<std::int64_t>(k)).apply(raw[k]);
  out.ready_frame = static_cast<std::size_t>(observations_config(standardize).warm_up - 1) * every;
  return out;
}

}  // namespace loopgate::testing
