// dird-seqslam as run methods (src/pipeline/dird_seqslam_methods.cpp), against a reference computed here
// from the stage classes (codes by the causal rule, cosine distances, contrast_search_batch):
//   - the full run's loop closures and every frame's best match are the batch search on every pair beyond
//     the margin;
//   - the gated run's are the batch search on the same distances restricted to the cells it reports;
//   - causal: a run over the first frames gives the whole run's rows restricted to them;
//   - 1 and 2 threads give identical outputs; raw distances (dird_seqslam.standardize off) work the same way;
//   - dird-seqslam takes its descriptors from section dird_seqslam, not from dird / standardize.mode.
#include <gtest/gtest.h>

#include <nlohmann/json.hpp>
#include <set>

#include "core/error.hpp"
#include "io/config.hpp"
#include "pipeline/pipeline.hpp"
#include "pipeline_dird_reference.hpp"
#include "pipeline_fake_dataset.hpp"
#include "stages/dird/dird_codes.hpp"
#include "stages/dird/dird_similarity.hpp"
#include "stages/match/contrast_search.hpp"
#include "test_support.hpp"

namespace loopgate {
namespace {

namespace fs = std::filesystem;
using testing::read_csv;
using testing::read_file;
using testing::RevisitDataset;

constexpr std::size_t kPeriod = 120;
constexpr std::size_t kLaps = 3;

PipelineConfig seqslam_config(RunMode mode, int threads = 2) {
  PipelineConfig config = testing::revisit_config(Detector::kDirdSeqSlam, mode, threads);
  config.dird_seqslam.normalization = DirdNormalization::kL2;
  config.dird_seqslam.resize = DirdResize::kArea;
  config.dird_seqslam.standardize = StandardizeMode::kCausal;
  testing::small_standardize(config.standardize);
  config.dird_seqslam.search.contrast_half_window_frames = 5;
  config.validate();
  return config;
}

using Cell = std::pair<std::int64_t, std::int64_t>;  // (i, j)
using testing::read_cells;

// Distance rows of the first `frames` frames: every pair i - j >= margin, from the reference codes of the
// method's descriptors (raw bytes and L1 when dird_seqslam.standardize is off); rows before the statistics
// are ready are empty.
std::vector<std::vector<DistanceEntry>> reference_rows(const Dataset& dataset, const PipelineConfig& config,
                                                       std::size_t frames) {
  std::vector<std::vector<DistanceEntry>> rows(frames);
  const auto margin = static_cast<std::size_t>(config.match.margin);
  const DirdConfig dird = config.dird_seqslam.descriptor(config.dird);
  const StandardizeConfig standardize = config.dird_seqslam.standardization(config.standardize);
  if (!standardize.enabled()) {
    const DirdExtractor extractor(dird);
    std::vector<Descriptor> raw;
    for (std::size_t k = 0; k < frames; ++k) raw.push_back(extractor.extract(dataset.load_image(k)));
    for (std::size_t i = margin; i < frames; ++i) {
      for (std::size_t j = 0; j + margin <= i; ++j)
        rows[i].push_back({static_cast<std::int64_t>(j), static_cast<double>(l1_distance(raw[i], raw[j]))});
    }
    return rows;
  }
  const auto [codes, ready_frame] = testing::reference_codes(dataset, dird, standardize, frames);
  for (std::size_t i = std::max(ready_frame, margin); i < frames; ++i) {
    for (std::size_t j = 0; j + margin <= i; ++j)
      rows[i].push_back({static_cast<std::int64_t>(j), standard_cosine_distance(codes[i], codes[j])});
  }
  return rows;
}

ContrastOutput reference_search(const std::vector<std::vector<DistanceEntry>>& rows,
                                const PipelineConfig& c) {
  return contrast_search_batch(rows, c.dird_seqslam.search, c.match.sequence_length,
                               ContrastSequenceSearch::Mode::kSingleSequence, c.match.margin);
}

// loops.csv and frames.csv's match column against the reference.
void expect_run_is(const fs::path& out, const ContrastOutput& expected) {
  const auto loops = read_csv(out / "loops.csv");
  ASSERT_EQ(loops.size(), expected.loops.size());
  for (std::size_t k = 0; k < loops.size(); ++k) {
    EXPECT_EQ(std::stoll(loops[k][0]), expected.loops[k].i) << k;
    EXPECT_EQ(std::stoll(loops[k][1]), expected.loops[k].j) << k;
    EXPECT_NEAR(std::stod(loops[k][4]), expected.loops[k].score, 5e-7) << k;  // 6 decimals
  }
  std::vector<std::string> header;
  const auto frames = read_csv(out / "frames.csv", &header);
  const std::size_t frame_col = testing::column_index(header, "frame");
  const std::size_t match_col = testing::column_index(header, "match_frame");
  ASSERT_EQ(frames.size(), expected.frames.size());
  for (std::size_t k = 0; k < frames.size(); ++k) {
    const ContrastVerdict& v = expected.frames[std::stoull(frames[k][frame_col])];
    EXPECT_EQ(frames[k][match_col], v.best_j >= 0 ? std::to_string(v.best_j) : "") << "frame " << k;
  }
}

TEST(PipelineDirdSeqSlam, FullIsTheBatchSearchAndGatedTheSameRestrictedToItsCells) {
  const RevisitDataset dataset(kPeriod, kLaps);
  const std::size_t frames = kPeriod * kLaps;
  const auto out_full = testing::make_temp_dir("pipeline-dseq-full");
  const auto out_gated = testing::make_temp_dir("pipeline-dseq-gated");
  const PipelineConfig full = seqslam_config(RunMode::kFull);
  const PipelineConfig gated = seqslam_config(RunMode::kGated);
  const RunResult result_full = run_pipeline(full, dataset, out_full);
  ASSERT_FALSE(result_full.failed) << result_full.error;
  const RunResult result_gated = run_pipeline(gated, dataset, out_gated);
  ASSERT_FALSE(result_gated.failed) << result_gated.error;

  const auto rows = reference_rows(dataset, full, frames);
  const ContrastOutput expected_full = reference_search(rows, full);
  EXPECT_GT(expected_full.loops.size(), kPeriod);  // laps 2 and 3 revisit lap 1
  expect_run_is(out_full, expected_full);

  const std::set<Cell> cells = read_cells(out_gated / "candidate_cells.csv");
  ASSERT_FALSE(cells.empty());
  std::vector<std::vector<DistanceEntry>> restricted(frames);
  std::size_t restricted_count = 0;
  for (std::size_t i = 0; i < frames; ++i) {
    for (const DistanceEntry& e : rows[i]) {
      if (cells.count({static_cast<std::int64_t>(i), e.j})) {
        restricted[i].push_back(e);
        ++restricted_count;
      }
    }
  }
  const ContrastOutput expected_gated = reference_search(restricted, gated);
  EXPECT_GT(expected_gated.loops.size(), kPeriod);
  expect_run_is(out_gated, expected_gated);

  const auto s_gated = nlohmann::json::parse(read_file(out_gated / "summary.json"));
  EXPECT_EQ(s_gated["method"], "dird-seqslam");
  EXPECT_EQ(s_gated["similarities_computed"].get<std::size_t>(), restricted_count);
  EXPECT_EQ(s_gated["standardize"]["observations"].get<std::size_t>(), frames / 2);
  EXPECT_GT(s_gated["evaluation"]["precision_recall"]["average_precision"].get<double>(), 0.9);
}

TEST(PipelineDirdSeqSlam, CausalAPrefixRunGivesTheWholeRunsRowsRestrictedToIt) {
  const RevisitDataset dataset(kPeriod, kLaps);
  const std::size_t prefix = 2 * kPeriod + 40;
  PipelineConfig config = seqslam_config(RunMode::kFull);
  config.run.frames = ":" + std::to_string(prefix);
  const auto out = testing::make_temp_dir("pipeline-dseq-prefix");
  ASSERT_FALSE(run_pipeline(config, dataset, out).failed);
  auto rows = reference_rows(dataset, config, kPeriod * kLaps);
  rows.resize(prefix);
  expect_run_is(out, reference_search(rows, config));
}

TEST(PipelineDirdSeqSlam, RawDistancesWhenStandardisationIsOff) {
  const RevisitDataset dataset(kPeriod, kLaps);
  PipelineConfig config = seqslam_config(RunMode::kFull);
  config.dird_seqslam.standardize = StandardizeMode::kOff;
  const auto out = testing::make_temp_dir("pipeline-dseq-raw");
  ASSERT_FALSE(run_pipeline(config, dataset, out).failed);
  expect_run_is(out, reference_search(reference_rows(dataset, config, kPeriod * kLaps), config));
  const auto summary = nlohmann::json::parse(read_file(out / "summary.json"));
  EXPECT_FALSE(summary.contains("standardize"));
}

TEST(PipelineDirdSeqSlam, OneAndTwoThreadsGiveIdenticalOutputs) {
  const RevisitDataset dataset(kPeriod, kLaps);
  for (const RunMode mode : {RunMode::kFull, RunMode::kGated}) {
    const auto out1 = testing::make_temp_dir("pipeline-dseq-t1");
    const auto out2 = testing::make_temp_dir("pipeline-dseq-t2");
    ASSERT_FALSE(run_pipeline(seqslam_config(mode, 1), dataset, out1).failed);
    ASSERT_FALSE(run_pipeline(seqslam_config(mode, 2), dataset, out2).failed);
    for (const char* file : {"loops.csv", "frames.csv"})
      EXPECT_EQ(read_file(out1 / file), read_file(out2 / file)) << file << " " << enum_name(mode);
  }
}

TEST(PipelineDirdSeqSlam, TakesItsDescriptorsFromItsOwnSection) {
  // dird / standardize.mode are the DIRD DP's (the paper's descriptor, bit-exact); dird-seqslam's defaults
  // are l2 normalisation, area resize, causal standardisation, whatever those say.
  const PipelineConfig loaded = load_config<PipelineConfig>("", {"run.method=dird-seqslam"});
  EXPECT_EQ(loaded.dird.normalization, DirdNormalization::kLibdird);
  EXPECT_EQ(loaded.standardize.mode, StandardizeMode::kOff);
  const DirdConfig dird = loaded.dird_seqslam.descriptor(loaded.dird);
  EXPECT_EQ(dird.normalization, DirdNormalization::kL2);
  EXPECT_EQ(dird.resize, DirdResize::kArea);
  EXPECT_EQ(loaded.dird_seqslam.standardization(loaded.standardize).mode, StandardizeMode::kCausal);
  // A single sequence streams: batch statistics are refused, naming the key.
  const RevisitDataset dataset(kPeriod, 1);
  PipelineConfig batch = seqslam_config(RunMode::kFull);
  batch.dird_seqslam.standardize = StandardizeMode::kBatch;
  try {
    run_pipeline(batch, dataset, testing::make_temp_dir("pipeline-dseq-batch"));
    FAIL() << "dird_seqslam.standardize batch accepted";
  } catch (const ConfigError& e) {
    EXPECT_NE(std::string(e.what()).find("dird_seqslam.standardize"), std::string::npos) << e.what();
  }
  EXPECT_THROW(load_config<PipelineConfig>("", {"dird_seqslam.resize=bicubic"}), ConfigError);
}

// Compact codes: a full run's rows are the reference's int8 codes turned into sign / ternary / int2 codes
// and compared by their distance, searched in batch (the run codes from the raw descriptor and the cuts of
// its snapshots: the same bits); the summary names the code.
TEST(PipelineDirdSeqSlam, CompactCodesAreTheReferenceCodesReducedAndCompared) {
  const RevisitDataset dataset(kPeriod, kLaps);
  const std::size_t frames = kPeriod * kLaps;
  for (const DirdCode code : {DirdCode::kTernary, DirdCode::kSign, DirdCode::kInt2}) {
    PipelineConfig config = seqslam_config(RunMode::kFull);
    config.dird_seqslam.codes.code = code;
    const auto out = testing::make_temp_dir("pipeline-dseq-compact");
    const RunResult result = run_pipeline(config, dataset, out);
    ASSERT_FALSE(result.failed) << result.error;

    const DirdConfig dird = config.dird_seqslam.descriptor(config.dird);
    const StandardizeConfig standardize = config.dird_seqslam.standardization(config.standardize);
    const auto [codes, ready_frame] = testing::reference_codes(dataset, dird, standardize, frames);
    const std::size_t words = code_words(code);
    std::vector<std::uint64_t> bits(frames * words);
    std::vector<std::int32_t> nonzero(frames);
    for (std::size_t k = 0; k < frames; ++k) {
      nonzero[k] = make_compact_code(config.dird_seqslam.codes, standardize.clamp_sigma, codes[k],
                                     bits.data() + k * words);
    }
    const auto margin = static_cast<std::size_t>(config.match.margin);
    std::vector<std::vector<DistanceEntry>> rows(frames);
    for (std::size_t i = std::max(ready_frame, margin); i < frames; ++i) {
      for (std::size_t j = 0; j + margin <= i; ++j) {
        const std::uint64_t* a = bits.data() + i * words;
        const std::uint64_t* b = bits.data() + j * words;
        const double distance = code == DirdCode::kSign ? sign_code_distance(a, b)
                                : code == DirdCode::kTernary
                                    ? ternary_code_distance(a, nonzero[i], b, nonzero[j])
                                    : int2_code_distance(a, nonzero[i], b, nonzero[j]);
        rows[i].push_back({static_cast<std::int64_t>(j), distance});
      }
    }
    const ContrastOutput expected = reference_search(rows, config);
    EXPECT_GT(expected.loops.size(), kPeriod);
    expect_run_is(out, expected);
    const auto summary = nlohmann::json::parse(read_file(out / "summary.json"));
    EXPECT_EQ(summary["standardize"]["code"], std::string(enum_name(code)));
  }
  // A compact code codes the standardised descriptor: refused without the standardisation, naming the key.
  EXPECT_THROW(load_config<PipelineConfig>("", {"dird_seqslam.code=ternary", "dird_seqslam.standardize=off"}),
               ConfigError);
  EXPECT_THROW(load_config<PipelineConfig>("", {"dird_seqslam.code=binary"}), ConfigError);
}

}  // namespace
}  // namespace loopgate
