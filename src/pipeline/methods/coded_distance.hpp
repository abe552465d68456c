// The distance of two DIRD frames on their codes (docs/standardize.md), one rule for every method that
// compares codes: raw descriptors (standardize.mode off) by L1, or L2 with dird.metric l2; standardised codes
// by cosine (norms precomputed with standard_norm()) or L1, as standardize.distance says. Used by the
// single-sequence distances (DirdDistances) and by the two-sequence forms of dird and dird-seqslam.
#pragma once

#include "stages/dird/dird_extractor.hpp"
#include "stages/dird/dird_similarity.hpp"
#include "stages/dird/dird_standardize.hpp"

namespace loopgate {

inline double coded_distance(const DirdConfig& dird, const StandardizeConfig& standardize,
                             const Descriptor& a, double norm_a, const Descriptor& b, double norm_b) {
  if (!standardize.enabled()) {
    return dird.l2_metric() ? l2_distance(a, b) : static_cast<double>(l1_distance(a, b));
  }
  if (standardize.cosine()) return standard_cosine_distance(a, norm_a, b, norm_b);
  return static_cast<double>(l1_distance(a, b));
}

}  // namespace loopgate
