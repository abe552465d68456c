// Two-sequence mode (`loopgate run --reference DIR --query DIR`, dird.md §5): DIRD and SeqSLAM over a
// reference and a query sequence, frames.csv / loops.csv / summary.json, and the PR evaluation against
// the aligned ground truth (eval.aligned_tolerance_frames).
#include <gtest/gtest.h>

#include <algorithm>
#include <atomic>
#include <cmath>
#include <csignal>
#include <cstdio>
#include <map>
#include <nlohmann/json.hpp>
#include <set>
#include <string>
#include <vector>

#include "core/error.hpp"
#include "core/stop_request.hpp"
#include "io/config.hpp"
#include "io/dataset.hpp"
#include "pipeline/methods/method_registry.hpp"
#include "pipeline/methods/two_sequence/two_sequence_method.hpp"
#include "pipeline/two_sequence.hpp"
#include "pipeline_fake_dataset.hpp"
#include "stages/dird/dird_extractor.hpp"
#include "stages/dird/dird_similarity.hpp"
#include "test_support.hpp"

namespace loopgate {
namespace {

using testing::read_csv;
using testing::read_file;
using testing::RevisitDataset;

using testing::column_index;

constexpr std::size_t kPeriod = 120;

PipelineConfig dird_config() {
  PipelineConfig config;
  config.run.threads = 2;
  config.output.progress = Progress::kOff;
  config.match.margin = 30;
  config.match.sequence_length = 10;
  config.match.tau3 = 0.05;
  config.match.nms_half_window = 20;
  return config;
}

PipelineConfig seqslam_config(int threads = 2) {
  PipelineConfig config;
  config.run.method = Detector::kSeqSlam;
  config.run.threads = threads;
  config.output.progress = Progress::kOff;
  config.eval.aligned_tolerance_frames = 1;
  // config.seqslam keeps the single-sequence default (exclusion "past", margin 200): two-sequence mode
  // must replace it by "none", else nothing could match.
  return config;
}

TEST(PipelineTwoSequence, QueryFindsItsAlignedReference) {
  const RevisitDataset reference(kPeriod, 1, 0);
  RevisitDataset query(kPeriod, 1, 12345);  // same places, other noise
  query.corrupt_frames = {50};
  PipelineConfig config = dird_config();
  config.eval.aligned_tolerance_frames = 1;
  const auto out = testing::make_temp_dir("pipeline-two-seq");
  const TwoSequenceResult result = run_two_sequences(config, reference, query, out);
  EXPECT_EQ(result.reference_frames, kPeriod);
  EXPECT_EQ(result.query_frames, kPeriod);
  ASSERT_GT(result.loops, 0u);
  const auto loops = read_csv(out / "loops.csv");
  ASSERT_EQ(loops.size(), result.loops);
  std::set<long> loop_queries;
  for (const auto& row : loops) {
    EXPECT_LE(std::abs(std::stol(row[0]) - std::stol(row[1])), 1) << row[0];
    loop_queries.insert(std::stol(row[0]));
  }
  std::vector<std::string> header;
  const auto rows = read_csv(out / "frames.csv", &header);
  ASSERT_EQ(rows.size(), kPeriod);
  const std::size_t match = column_index(header, "match_frame");
  std::size_t best_aligned = 0;
  for (std::size_t q = 0; q < rows.size(); ++q) {
    EXPECT_EQ(rows[q][0], std::to_string(q));
    if (!rows[q][match].empty() && std::abs(std::stol(rows[q][match]) - static_cast<long>(q)) <= 1) {
      ++best_aligned;
    }
  }
  EXPECT_EQ(rows[50][column_index(header, "descriptor")], "n");
  EXPECT_EQ(rows[50][column_index(header, "status")], "error");
  EXPECT_GE(best_aligned, kPeriod * 8 / 10);
  const nlohmann::json& summary = result.summary;
  EXPECT_EQ(summary["aligned"]["loops_within_tolerance"].get<std::size_t>(), result.loops);
  EXPECT_EQ(summary["similarities_computed"].get<std::size_t>(), kPeriod * (kPeriod - 1));
  EXPECT_EQ(summary["mode"], "two-sequence");
  EXPECT_EQ(summary["method"], "dird");
  EXPECT_EQ(summary["score_order"], "higher_is_better");
  // PR block: detections = loops.csv rows, every query has aligned references.
  const nlohmann::json& evaluation = summary["evaluation"];
  ASSERT_TRUE(evaluation["available"].get<bool>());
  EXPECT_EQ(evaluation["truth"]["aligned_tolerance_frames"].get<int>(), 1);
  EXPECT_EQ(evaluation["truth"]["positives"].get<std::size_t>(), kPeriod);
  EXPECT_EQ(evaluation["loop_truth"]["loops"].get<std::size_t>(), result.loops);
  EXPECT_EQ(evaluation["loop_truth"]["loops_true"].get<std::size_t>(), result.loops);
  EXPECT_EQ(evaluation["loop_truth"]["query_frames_with_loops"].get<std::size_t>(), loop_queries.size());
  const nlohmann::json& pr = evaluation["precision_recall"];
  EXPECT_EQ(pr["score_order"], "higher_is_better");
  EXPECT_EQ(pr["queries_with_detection"].get<std::size_t>(), loop_queries.size());
  EXPECT_DOUBLE_EQ(pr["recall_at_100"].get<double>(),
                   static_cast<double>(loop_queries.size()) / static_cast<double>(kPeriod));
  ASSERT_FALSE(pr["curve"].empty());
  EXPECT_DOUBLE_EQ(pr["curve"].back()["precision"].get<double>(), 1.0);
  // The aligned pairs: 2 for the first and last query frame, 3 for the others.
  EXPECT_EQ(read_csv(out / "truth_loops.csv").size(), 3 * kPeriod - 2);
  EXPECT_FALSE(std::filesystem::exists(out / "trace.json"));  // output.trace is off
}

// --trace in two-sequence mode: the process named, the phases on the main track, and the
// describe blocks on the threads that did them, covering every frame of both sequences once.
TEST(PipelineTwoSequence, TraceShowsPhasesAndBlocks) {
  const RevisitDataset reference(kPeriod, 1, 0);
  const RevisitDataset query(kPeriod, 1, 12345);
  for (const char* method : {"dird", "seqslam"}) {
    PipelineConfig config = dird_config();
    if (std::string(method) == "seqslam") config.run.method = Detector::kSeqSlam;
    config.output.trace = true;
    config.run.threads = 2;
    const auto out = testing::make_temp_dir("pipeline-two-seq-trace");
    run_two_sequences(config, reference, query, out);
    const auto trace = nlohmann::json::parse(testing::read_file(out / "trace.json"));
    std::string process_name;
    std::set<std::string> phases;
    std::map<std::string, std::size_t> block_frames;
    for (const auto& event : trace["traceEvents"]) {
      if (event["name"] == "process_name") process_name = event["args"]["name"];
      if (event["ph"] != "X") continue;
      if (event["cat"] == "phase") {
        EXPECT_EQ(event["tid"].get<int>(), 0);
        phases.insert(event["name"].get<std::string>());
      }
      if (event["cat"] == "block") {
        EXPECT_GE(event["tid"].get<int>(), 0);
        EXPECT_LT(event["tid"].get<int>(), 2);
        unsigned begin = 0, end = 0;
        ASSERT_EQ(std::sscanf(event["args"]["detail"].get<std::string>().c_str(), "[%u, %u)", &begin, &end),
                  2);
        block_frames[event["name"].get<std::string>()] += end - begin;
      }
    }
    EXPECT_NE(process_name.find("two sequences"), std::string::npos) << process_name;
    EXPECT_EQ(phases.count("outputs and evaluation"), 1u) << method;
    const std::string step = std::string(method) == "dird" ? "describe" : "preprocess";
    EXPECT_EQ(block_frames[step + " reference"], kPeriod) << method;
    EXPECT_EQ(block_frames[step + " query"], kPeriod) << method;
  }
}

// scale.mode online in two-sequence mode: mu and sigma from the distances of every (reference, query) pair
// by the no-revisit rule (a hand computation: exact quantiles of the sorted distances), and the run equals
// one with those constants configured.
TEST(PipelineTwoSequence, OnlineScaleFollowsTheRuleOnEveryPair) {
  const RevisitDataset reference(kPeriod, 1, 0);
  const RevisitDataset query(kPeriod, 1, 12345);
  PipelineConfig config = dird_config();
  config.eval.aligned_tolerance_frames = 1;
  config.dird.normalization = DirdNormalization::kL2;
  config.scale.mode = ScaleMode::kOnline;
  config.scale.min_distances = 1000;
  const auto out = testing::make_temp_dir("pipeline-two-seq-online");
  run_two_sequences(config, reference, query, out);
  const auto summary = nlohmann::json::parse(read_file(out / "summary.json"));
  const auto& scale = summary.at("scale");
  ASSERT_TRUE(scale.at("estimated").get<bool>());
  EXPECT_EQ(scale.at("distances").get<std::int64_t>(), static_cast<std::int64_t>(kPeriod * kPeriod));

  const DirdExtractor extractor(config.dird);
  const DirdSimilarity similarity(config.dird);
  std::vector<Descriptor> ref_codes, qry_codes;
  for (std::size_t k = 0; k < kPeriod; ++k) {
    ref_codes.push_back(extractor.extract(reference.load_image(k)));
    qry_codes.push_back(extractor.extract(query.load_image(k)));
  }
  std::vector<double> distances;
  for (const Descriptor& q : qry_codes) {
    for (const Descriptor& r : ref_codes) distances.push_back(similarity.distance(q, r));
  }
  std::sort(distances.begin(), distances.end());
  const auto quantile = [&](double p) {
    const double position = p * static_cast<double>(distances.size() - 1);
    const auto below = static_cast<std::size_t>(std::floor(position));
    const double above = distances[std::min(below + 1, distances.size() - 1)];
    return distances[below] + (position - std::floor(position)) * (above - distances[below]);
  };
  const double mu = quantile(config.scale.mu_quantile);
  const double cutoff = quantile(config.scale.cutoff_quantile);
  const double sigma = (cutoff - mu) / std::log(1.0 / config.dird.tau1 - 1.0);
  EXPECT_NEAR(scale.at("mu").get<double>(), mu, mu * 2e-3);
  EXPECT_NEAR(scale.at("cutoff_distance").get<double>(), cutoff, cutoff * 2e-3);
  EXPECT_NEAR(scale.at("sigma").get<double>(), sigma, sigma * 0.05);

  PipelineConfig fixed = config;
  fixed.scale.mode = ScaleMode::kOff;
  fixed.dird.mu = scale.at("mu").get<double>();
  fixed.dird.sigma = scale.at("sigma").get<double>();
  const auto fixed_out = testing::make_temp_dir("pipeline-two-seq-fixed");
  run_two_sequences(fixed, reference, query, fixed_out);
  EXPECT_EQ(read_file(out / "loops.csv"), read_file(fixed_out / "loops.csv"));
  EXPECT_FALSE(read_file(out / "loops.csv").empty());
}

TEST(PipelineTwoSequence, SeqSlamFindsTheAlignedReferences) {
  const RevisitDataset reference(kPeriod, 1, 0);
  RevisitDataset query(kPeriod, 1, 777);
  query.corrupt_frames = {50};
  const auto out = testing::make_temp_dir("pipeline-two-seq-seqslam");
  const TwoSequenceResult result = run_two_sequences(seqslam_config(), reference, query, out);
  EXPECT_EQ(result.reference_frames, kPeriod);
  EXPECT_EQ(result.query_frames, kPeriod);

  std::vector<std::string> header;
  const auto rows = read_csv(out / "frames.csv", &header);
  ASSERT_EQ(rows.size(), kPeriod);
  const std::size_t match = column_index(header, "match_frame");
  const std::size_t score = column_index(header, "match_score");
  const std::size_t detection = column_index(header, "detection");
  const std::size_t half = 5;  // ds / 2 with the default ds = 10
  std::size_t with_match = 0, aligned = 0, ranked = 0, ranked_true = 0, accepted = 0;
  for (std::size_t q = 0; q < kPeriod; ++q) {
    ASSERT_EQ(rows[q].size(), header.size());
    EXPECT_EQ(rows[q][0], std::to_string(q));
    const bool near_end = q < half || q + half >= kPeriod;
    EXPECT_EQ(rows[q][match].empty(), near_end) << q;
    if (near_end) {
      EXPECT_EQ(rows[q][detection], "no match");
      continue;
    }
    ++with_match;
    const bool is_aligned = std::abs(std::stol(rows[q][match]) - static_cast<long>(q)) <= 1;
    aligned += is_aligned ? 1 : 0;
    EXPECT_TRUE(rows[q][detection] == "loop" || rows[q][detection] == "rejected") << rows[q][detection];
    accepted += rows[q][detection] == "loop" ? 1 : 0;
    if (std::isfinite(std::stod(rows[q][score]))) {
      ++ranked;
      ranked_true += is_aligned ? 1 : 0;
    }
  }
  EXPECT_EQ(with_match, kPeriod - 2 * half);
  EXPECT_GE(aligned, with_match * 95 / 100);
  EXPECT_GE(accepted, with_match * 8 / 10);
  EXPECT_EQ(rows[50][column_index(header, "descriptor")], "n");
  EXPECT_EQ(rows[50][column_index(header, "status")], "error");

  const auto loops = read_csv(out / "loops.csv");
  ASSERT_EQ(loops.size(), accepted);
  EXPECT_EQ(result.loops, accepted);
  for (const auto& row : loops) {
    EXPECT_LE(std::abs(std::stol(row[0]) - std::stol(row[1])), 1) << row[0];
    EXPECT_LE(std::stod(row[4]), 0.9);  // ratio <= ratio_threshold
  }

  const nlohmann::json& summary = result.summary;
  EXPECT_EQ(summary["mode"], "two-sequence");
  EXPECT_EQ(summary["method"], "seqslam");
  EXPECT_EQ(summary["score_order"], "lower_is_better");
  EXPECT_EQ(summary["config"]["seqslam"]["exclusion"], "none");  // forced
  EXPECT_EQ(summary["similarities_computed"].get<std::size_t>(), kPeriod * kPeriod);
  EXPECT_EQ(summary["aligned"]["best_match_within_tolerance"].get<std::size_t>(), aligned);
  EXPECT_EQ(summary["aligned"]["loops_within_tolerance"].get<std::size_t>(), loops.size());
  const nlohmann::json& evaluation = summary["evaluation"];
  ASSERT_TRUE(evaluation["available"].get<bool>());
  EXPECT_EQ(evaluation["truth"]["positives"].get<std::size_t>(), kPeriod);
  EXPECT_EQ(evaluation["loop_truth"]["loops"].get<std::size_t>(), accepted);
  const nlohmann::json& pr = evaluation["precision_recall"];
  EXPECT_EQ(pr["score_order"], "lower_is_better");
  // The sweep runs over every query's match, accepted or not.
  EXPECT_EQ(pr["queries_with_detection"].get<std::size_t>(), ranked);
  ASSERT_FALSE(pr["curve"].empty());
  EXPECT_EQ(pr["curve"].back()["detections"].get<std::size_t>(), ranked);
  EXPECT_EQ(pr["curve"].back()["true_positives"].get<std::size_t>(), ranked_true);
  EXPECT_NEAR(pr["curve"].back()["recall"].get<double>(),
              static_cast<double>(ranked_true) / static_cast<double>(kPeriod), 1e-12);
  EXPECT_GE(pr["average_precision"].get<double>(), 0.8);
}

TEST(PipelineTwoSequence, SeqSlamFrameRangeAndThreadCountIndependent) {
  const RevisitDataset reference(kPeriod, 1, 3);
  const RevisitDataset query(kPeriod, 1, 4);
  PipelineConfig config1 = seqslam_config(1);
  PipelineConfig config2 = seqslam_config(2);
  config1.run.frames = config2.run.frames = "20:100";
  const auto out1 = testing::make_temp_dir("pipeline-two-seq-seqslam-t1");
  const auto out2 = testing::make_temp_dir("pipeline-two-seq-seqslam-t2");
  run_two_sequences(config1, reference, query, out1);
  run_two_sequences(config2, reference, query, out2);
  EXPECT_EQ(read_file(out1 / "frames.csv"), read_file(out2 / "frames.csv"));
  EXPECT_EQ(read_file(out1 / "loops.csv"), read_file(out2 / "loops.csv"));
  std::vector<std::string> header;
  const auto rows = read_csv(out1 / "frames.csv", &header);
  ASSERT_EQ(rows.size(), 80u);
  EXPECT_EQ(rows.front()[0], "20");
  EXPECT_EQ(rows.back()[0], "99");
  std::size_t aligned = 0;
  for (const auto& row : rows) {
    const std::string& m = row[column_index(header, "match_frame")];
    if (!m.empty() && std::abs(std::stol(m) - std::stol(row[0])) <= 1) ++aligned;
  }
  EXPECT_GE(aligned, 65u);  // 70 with a match (5 at either end have none)
}

// Every method writes the frames.csv columns they share in the same order, the method's own between them and
// status / reason, and a query image that cannot be read gives an error row (its reason first, then the
// verdict) counted in summary.json's query_frames_with_error, with the queries by outcome adding up.
TEST(PipelineTwoSequence, EveryMethodWritesTheSharedColumnsAndAnUnreadableQueryAsAnError) {
  const RevisitDataset reference(kPeriod, 1, 5);
  RevisitDataset query(kPeriod, 1, 6);
  query.corrupt_frames = {40};
  struct Case {
    Detector method;
    std::vector<std::string> own_columns;
    std::string error_note;
  };
  const std::vector<Case> cases = {
      {Detector::kDird, {"match_score", "best_similarity", "candidates"}, ""},
      {Detector::kDirdSeqSlam, {"match_score", "velocity", "line_end_frame"}, ""},
      {Detector::kSeqSlam,
       {"match_score", "best_score", "second_score"},
       " (took part as an all-zero image)"}};
  for (const Case& c : cases) {
    SCOPED_TRACE(std::string(enum_name(c.method)));
    PipelineConfig config = dird_config();
    config.run.method = c.method;
    config.eval.aligned_tolerance_frames = 1;
    const auto out = testing::make_temp_dir("pipeline-two-seq-columns");
    const TwoSequenceResult result = run_two_sequences(config, reference, query, out);
    std::vector<std::string> header;
    const auto rows = read_csv(out / "frames.csv", &header);
    std::vector<std::string> expected = {"frame", "t_ns", "t_s", "descriptor", "detection", "match_frame"};
    expected.insert(expected.end(), c.own_columns.begin(), c.own_columns.end());
    expected.insert(expected.end(), {"status", "reason"});
    EXPECT_EQ(header, expected);
    ASSERT_EQ(rows.size(), kPeriod);
    const auto& bad = rows[40];
    EXPECT_EQ(bad[column_index(header, "status")], "error");
    const std::string& reason = bad[column_index(header, "reason")];
    EXPECT_EQ(reason.rfind("image: ", 0), 0u) << reason;
    EXPECT_NE(reason.find(c.error_note + "; "), std::string::npos) << reason;
    for (std::size_t q = 0; q < rows.size(); ++q) {
      if (q != 40) {
        EXPECT_EQ(rows[q][column_index(header, "status")], "ok") << q;
      }
    }
    const nlohmann::json& summary = result.summary;
    EXPECT_EQ(summary["query_frames_with_error"].get<std::size_t>(), 1u);
    EXPECT_EQ(summary["method"], std::string(enum_name(c.method)));
    const nlohmann::json& detection = summary["detection"];
    EXPECT_EQ(detection["no_candidate"].get<std::size_t>() + detection["below_threshold"].get<std::size_t>() +
                  detection["suppressed"].get<std::size_t>() + detection["loop"].get<std::size_t>(),
              kPeriod);
    std::size_t loop_rows = 0;
    for (const auto& row : rows) loop_rows += row[column_index(header, "detection")] == "loop" ? 1 : 0;
    EXPECT_EQ(detection["loop"].get<std::size_t>(), loop_rows);
    EXPECT_EQ(read_csv(out / "loops.csv").size(), result.loops);
    EXPECT_EQ(summary["aligned"]["loops_within_tolerance"].get<std::size_t>() +
                  summary["aligned"]["loops_beyond_tolerance"].get<std::size_t>(),
              result.loops);
  }
}

// The two-sequence form a run uses is its registry row's: every full row has one, of its own detector (DIRD's
// raw and standardised rows share DIRD's), and no gated row has one (two sequences have no poses).
TEST(PipelineTwoSequence, EveryFullRowOfTheRegistryBuildsTheFormOfItsDetector) {
  for (const MethodEntry& m : kMethods) {
    SCOPED_TRACE(m.name);
    if (m.mode == RunMode::kGated) {
      EXPECT_EQ(m.two_sequence, nullptr);
      continue;
    }
    ASSERT_NE(m.two_sequence, nullptr);
    PipelineConfig config = dird_config();
    config.run.method = m.detector;
    EXPECT_STREQ(m.two_sequence(config)->name(), enum_name(m.detector).data());
    EXPECT_STREQ(make_two_sequence_method(config)->name(), enum_name(m.detector).data());
  }
}

// The parallel loop hands out blocks of queries to the run's workers, each writing only its own rows: one
// thread and three give the same files, for DIRD's two passes over the pairs (the online scale, then the
// similarities on standardised codes) and for dird-seqslam's distances in query blocks (compact codes).
TEST(PipelineTwoSequence, DirdAndDirdSeqSlamOutputsDoNotDependOnTheThreadCount) {
  const RevisitDataset reference(kPeriod, 1, 7);
  const RevisitDataset query(kPeriod, 1, 8);
  for (const Detector method : {Detector::kDird, Detector::kDirdSeqSlam}) {
    SCOPED_TRACE(std::string(enum_name(method)));
    std::map<int, std::filesystem::path> outs;
    for (const int threads : {1, 3}) {
      PipelineConfig config = dird_config();
      config.run.method = method;
      config.run.threads = threads;
      config.eval.aligned_tolerance_frames = 1;
      config.standardize.mode = StandardizeMode::kCausal;
      config.standardize.warm_up = 20;
      config.scale.mode = ScaleMode::kOnline;
      config.scale.min_distances = 1000;
      config.dird_seqslam.codes.code = DirdCode::kSign;
      outs[threads] = testing::make_temp_dir("pipeline-two-seq-threads");
      const TwoSequenceResult result = run_two_sequences(config, reference, query, outs[threads]);
      EXPECT_GT(result.loops, 0u);
    }
    for (const char* file : {"frames.csv", "loops.csv", "truth_loops.csv"})
      EXPECT_EQ(read_file(outs[1] / file), read_file(outs[3] / file)) << file;
    const auto summary1 = nlohmann::json::parse(read_file(outs[1] / "summary.json"));
    const auto summary3 = nlohmann::json::parse(read_file(outs[3] / "summary.json"));
    EXPECT_EQ(summary1["evaluation"], summary3["evaluation"]);
    EXPECT_EQ(summary1.value("scale", nlohmann::json()), summary3.value("scale", nlohmann::json()));
  }
}

// Hand-checked: 6 query and 6 reference frames from frame 2 on, tolerance 1, so every query is positive
// (16 true pairs). Ranked (lower is better): q0->r0 0.1 true, q1->r3 0.2 false, q2->r2 0.3 true (and
// q2->r5 0.35, not its best), q3->r5 0.4 false.
TEST(PipelineTwoSequence, AlignedEvaluationByHand) {
  const AlignedSequences sequences{2, 6, 2, 6, 1};
  EXPECT_EQ(sequences.pairs().size(), 16u);
  EXPECT_TRUE(sequences.aligned(3, 4));
  EXPECT_FALSE(sequences.aligned(3, 5));
  const std::vector<Detection> ranked = {{0, 0, 0.1}, {1, 3, 0.2}, {2, 5, 0.35}, {2, 2, 0.3}, {3, 5, 0.4}};
  const std::vector<Detection> loops = {{0, 0, 0.1}, {1, 3, 0.2}};
  const nlohmann::json lower = evaluate_aligned(sequences, loops, ranked, ScoreOrder::kLowerIsBetter);
  EXPECT_TRUE(lower["available"].get<bool>());
  EXPECT_EQ(lower["truth"]["aligned_tolerance_frames"].get<int>(), 1);
  EXPECT_EQ(lower["truth"]["positives"].get<std::size_t>(), 6u);
  const nlohmann::json& loop_truth = lower["loop_truth"];
  EXPECT_EQ(loop_truth["loops"].get<std::size_t>(), 2u);
  EXPECT_EQ(loop_truth["loops_true"].get<std::size_t>(), 1u);
  EXPECT_EQ(loop_truth["loops_false"].get<std::size_t>(), 1u);
  EXPECT_EQ(loop_truth["query_frames_with_loops"].get<std::size_t>(), 2u);
  EXPECT_EQ(loop_truth["query_best_loop_true"].get<std::size_t>(), 1u);
  EXPECT_EQ(loop_truth["query_best_loop_false"].get<std::size_t>(), 1u);
  const nlohmann::json& pr = lower["precision_recall"];
  EXPECT_EQ(pr["score_order"], "lower_is_better");
  EXPECT_EQ(pr["positives"].get<std::size_t>(), 6u);
  EXPECT_EQ(pr["queries_with_detection"].get<std::size_t>(), 4u);
  const std::vector<double> thresholds = {0.1, 0.2, 0.3, 0.4};
  const std::vector<double> precision = {1.0, 0.5, 2.0 / 3.0, 0.5};
  const std::vector<double> recall = {1.0 / 6, 1.0 / 6, 2.0 / 6, 2.0 / 6};
  const std::vector<std::size_t> true_positives = {1, 1, 2, 2};
  ASSERT_EQ(pr["curve"].size(), 4u);
  for (std::size_t k = 0; k < 4; ++k) {
    const nlohmann::json& point = pr["curve"][k];
    EXPECT_DOUBLE_EQ(point["threshold"].get<double>(), thresholds[k]);
    EXPECT_DOUBLE_EQ(point["precision"].get<double>(), precision[k]);
    EXPECT_DOUBLE_EQ(point["recall"].get<double>(), recall[k]);
    EXPECT_EQ(point["detections"].get<std::size_t>(), k + 1);
    EXPECT_EQ(point["true_positives"].get<std::size_t>(), true_positives[k]);
  }
  EXPECT_NEAR(pr["average_precision"].get<double>(), 1.0 / 6 + (1.0 / 6) * (2.0 / 3), 1e-12);
  EXPECT_NEAR(pr["recall_at_100"].get<double>(), 1.0 / 6, 1e-12);
  EXPECT_NEAR(pr["recall_at_99"].get<double>(), 1.0 / 6, 1e-12);
  EXPECT_NEAR(pr["recall_at_95"].get<double>(), 1.0 / 6, 1e-12);

  // Higher is better: q2's best is now 0.35 -> r5 (false); order 0.4 false, 0.35 false, 0.2 false,
  // 0.1 true.
  const nlohmann::json higher = evaluate_aligned(sequences, loops, ranked, ScoreOrder::kHigherIsBetter);
  const nlohmann::json& hpr = higher["precision_recall"];
  ASSERT_EQ(hpr["curve"].size(), 4u);
  EXPECT_DOUBLE_EQ(hpr["curve"][0]["precision"].get<double>(), 0.0);
  EXPECT_DOUBLE_EQ(hpr["curve"][3]["precision"].get<double>(), 0.25);
  EXPECT_NEAR(hpr["average_precision"].get<double>(), (1.0 / 6) * 0.25, 1e-12);
  EXPECT_DOUBLE_EQ(hpr["recall_at_100"].get<double>(), 0.0);
}

TEST(PipelineTwoSequence, NoToleranceNoEvaluation) {
  const RevisitDataset reference(40, 1, 0);
  const RevisitDataset query(40, 1, 1);
  PipelineConfig config = seqslam_config();
  config.eval.aligned_tolerance_frames = -1;
  const auto out = testing::make_temp_dir("pipeline-two-seq-no-eval");
  const TwoSequenceResult result = run_two_sequences(config, reference, query, out);
  EXPECT_FALSE(result.summary["evaluation"]["available"].get<bool>());
  EXPECT_FALSE(result.summary.contains("aligned"));
  EXPECT_FALSE(std::filesystem::exists(out / "truth_loops.csv"));
  EXPECT_EQ(read_csv(out / "frames.csv").size(), 40u);
}

TEST(PipelineTwoSequence, ViewpointToleranceIsRefusedNotIgnored) {
  // The viewpoint tolerance lives in the single-sequence dird-seqslam: a two-sequence run refuses it
  // before writing anything rather than running without it.
  const RevisitDataset reference(20, 1, 0);
  const RevisitDataset query(20, 1, 1);
  PipelineConfig config = dird_config();
  config.run.method = Detector::kDirdSeqSlam;
  config.dird_seqslam.viewpoint.lateral_m = 3.5;
  const auto out = testing::make_temp_dir("pipeline-two-seq-viewpoint");
  try {
    (void)run_two_sequences(config, reference, query, out);
    FAIL() << "dird_seqslam.viewpoint_lateral_m=3.5 accepted in a two-sequence run";
  } catch (const ConfigError& e) {
    EXPECT_NE(std::string(e.what()).find("dird_seqslam.viewpoint_lateral_m"), std::string::npos) << e.what();
  }
  EXPECT_FALSE(std::filesystem::exists(out / "summary.json"));
}

TEST(PipelineTwoSequence, BadMethodIsAConfigErrorNamingRunMethod) {
  // run.method is parsed into an enum by the config system: an unknown word never reaches the run.
  RawConfig raw;
  raw.apply_override("run.method=netvlad");
  PipelineConfig loaded;
  try {
    apply_config(raw, loaded);
    FAIL() << "run.method=netvlad accepted";
  } catch (const ConfigError& e) {
    EXPECT_STREQ(e.what(),
                 "run.method: 'netvlad' is not one of dird|seqslam|dird-seqslam (--set run.method=netvlad)");
  }
}

// Nordland summer (reference) vs winter (query), configs/nordland.yaml, both methods, the whole
// ride (3576 x 3576). Measured when written (docs/nordland.md): DIRD AP 0.104, R@P100 0, 1361 query
// frames with a loop, the best one within +-2 frames for 743; SeqSLAM AP 0.483, R@P100 0.355, 1535
// accepted of which 1494 within +-2, every query's match within +-2 for 1782.
// A stop request (SIGINT, SIGTERM, SIGHUP in the app) left an empty output folder. Now the query
// frames described before it (a prefix) are matched and every output is written for them; a stop before
// the reference is complete gives complete, empty outputs.
TEST(PipelineTwoSequence, StopRequestWritesOutputsForTheQueryFramesDescribed) {
  for (const Detector method : {Detector::kDird, Detector::kSeqSlam, Detector::kDirdSeqSlam}) {
    SCOPED_TRACE(std::string(enum_name(method)));
    const RevisitDataset reference(kPeriod, 1, 0);
    RevisitDataset query(kPeriod, 1, 12345);
    std::atomic<bool> stop{false};
    query.on_load = [&](std::size_t frame) {
      if (frame >= 60) stop.store(true);
    };
    PipelineConfig config = method == Detector::kSeqSlam ? seqslam_config() : dird_config();
    config.run.method = method;
    config.eval.aligned_tolerance_frames = 1;
    const auto out = testing::make_temp_dir("two-seq-stop");
    const TwoSequenceResult result = run_two_sequences(config, reference, query, out, &stop);
    EXPECT_TRUE(result.interrupted);
    EXPECT_GT(result.query_frames, 60u);
    EXPECT_LT(result.query_frames, kPeriod);
    const auto rows = read_csv(out / "frames.csv");
    ASSERT_EQ(rows.size(), result.query_frames);
    for (std::size_t q = 0; q < rows.size(); ++q) EXPECT_EQ(rows[q][0], std::to_string(q));
    const auto summary = nlohmann::json::parse(read_file(out / "summary.json"));
    EXPECT_TRUE(summary["interrupted"].get<bool>());
    EXPECT_EQ(summary["query"]["last_frame"].get<std::size_t>(), result.query_frames);
    EXPECT_TRUE(std::filesystem::exists(out / "loops.csv"));

    std::atomic<bool> early{true};  // before anything was described
    const auto empty_out = testing::make_temp_dir("two-seq-stop-early");
    const TwoSequenceResult none = run_two_sequences(config, reference, query, empty_out, &early);
    EXPECT_TRUE(none.interrupted);
    EXPECT_EQ(none.query_frames, 0u);
    EXPECT_TRUE(read_csv(empty_out / "frames.csv").empty());
    EXPECT_TRUE(nlohmann::json::parse(read_file(empty_out / "summary.json"))["interrupted"].get<bool>());
  }
}

// A second stop signal while the query is described: the passes after it (run on pool threads) abort with
// Interrupted, which reaches the caller (the command reports it) instead of ending the process through
// std::terminate from a pool thread.
TEST(PipelineTwoSequence, SecondStopSignalAbortsWithInterruptedOnEveryMethod) {
  for (const Detector method : {Detector::kDird, Detector::kSeqSlam, Detector::kDirdSeqSlam}) {
    SCOPED_TRACE(std::string(enum_name(method)));
    stop_request::reset();
    const RevisitDataset reference(kPeriod, 1, 0);
    RevisitDataset query(kPeriod, 1, 12345);
    query.on_load = [&](std::size_t frame) {
      if (frame == 60) {
        stop_request::record(SIGTERM);
        stop_request::record(SIGTERM);
      }
    };
    PipelineConfig config = method == Detector::kSeqSlam ? seqslam_config() : dird_config();
    config.run.method = method;
    config.eval.aligned_tolerance_frames = 1;
    const auto out = testing::make_temp_dir("two-seq-abort");
    EXPECT_THROW(run_two_sequences(config, reference, query, out, &stop_request::stop_flag()), Interrupted);
  }
  stop_request::reset();
}

TEST(PipelineTwoSequence, NordlandSummerWinterDirdVsSeqSlam) {
  LOOPGATE_REQUIRE_SHARED_DATA("nordland-64x32/winter");
  const auto data = testing::shared_data_dir() / "nordland-64x32";
  const auto summer = open_dataset(data / "summer");
  const auto winter = open_dataset(data / "winter");
  const auto config_file = std::filesystem::path(LOOPGATE_SOURCE_DIR) / "configs/nordland.yaml";
  const auto dird = load_config<PipelineConfig>(config_file, {"output.progress=off", "run.method=dird"});
  const auto seqslam =
      load_config<PipelineConfig>(config_file, {"output.progress=off", "run.method=seqslam"});
  const auto dird_out = testing::make_temp_dir("pipeline-nordland-dird");
  const auto seqslam_out = testing::make_temp_dir("pipeline-nordland-seqslam");
  const nlohmann::json d = run_two_sequences(dird, *summer, *winter, dird_out).summary;
  const nlohmann::json s = run_two_sequences(seqslam, *summer, *winter, seqslam_out).summary;
  ASSERT_TRUE(d["evaluation"]["available"].get<bool>());
  ASSERT_TRUE(s["evaluation"]["available"].get<bool>());
  EXPECT_EQ(d["evaluation"]["truth"]["positives"].get<std::size_t>(), 3576u);
  const auto& d_truth = d["evaluation"]["loop_truth"];
  EXPECT_NEAR(d_truth["query_frames_with_loops"].get<double>(), 1361, 30);
  EXPECT_NEAR(d_truth["query_best_loop_true"].get<double>(), 743, 30);
  EXPECT_NEAR(d["evaluation"]["precision_recall"]["average_precision"].get<double>(), 0.104, 0.02);
  const auto& s_truth = s["evaluation"]["loop_truth"];
  EXPECT_NEAR(s_truth["loops"].get<double>(), 1535, 30);
  EXPECT_GE(s_truth["loops_true"].get<double>(), 0.95 * s_truth["loops"].get<double>());
  EXPECT_NEAR(s["aligned"]["best_match_within_tolerance"].get<double>(), 1782, 30);
  const auto& s_pr = s["evaluation"]["precision_recall"];
  EXPECT_EQ(s_pr["queries_with_detection"].get<std::size_t>(), 3566u);  // all but ds/2 = 5 at each end
  EXPECT_NEAR(s_pr["average_precision"].get<double>(), 0.483, 0.02);
  EXPECT_NEAR(s_pr["recall_at_100"].get<double>(), 0.355, 0.02);
  // Across seasons, SeqSLAM's sequence search beats DIRD's single-image similarity here.
  EXPECT_GT(s_pr["average_precision"].get<double>(),
            2 * d["evaluation"]["precision_recall"]["average_precision"].get<double>());

  // Dird-seqslam (the config's method) beats both, AP and recall at 1 (measured: 0.962, 0.963).
  const auto dird_seqslam = load_config<PipelineConfig>(config_file, {"output.progress=off"});
  ASSERT_EQ(dird_seqslam.run.method, Detector::kDirdSeqSlam);
  const auto dird_seqslam_out = testing::make_temp_dir("pipeline-nordland-dird-seqslam");
  const nlohmann::json ds = run_two_sequences(dird_seqslam, *summer, *winter, dird_seqslam_out).summary;
  const auto& ds_pr = ds["evaluation"]["precision_recall"];
  EXPECT_GE(ds_pr["average_precision"].get<double>(), 0.9);
  EXPECT_GE(ds_pr["recall_at_1"].get<double>(), 0.9);
  EXPECT_GT(ds_pr["average_precision"].get<double>(), s_pr["average_precision"].get<double>() + 0.3);
}

}  // namespace
}  // namespace loopgate
