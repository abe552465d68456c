// Which descriptor standardisation to wire in (not a Google Benchmark: a measurement program with a main).
//
// Nordland 64x32 (reference summer, query winter, frame k = frame k +- 2) and KITTI 00 thumbnails (single
// sequence, revisits within 2 m in x-z at least `margin` frames back), DIRD in l2 normalisation mode. For the
// raw descriptors and for standardised ones (batch per sequence, causal; int8 codes with L1 or cosine, float
// z-scores with L1 or cosine) it reports:
//   - single image: recall@1 (each query's best reference is a true match) and the AP of each query's best
//     match ranked by distance (evaluation.md: one PR point per distinct score, AP = sum dR * P);
//   - distance quantiles in dataset-independent units (raw L1: mean |byte difference|; code / float L1: mean
//     |z-score difference| per dimension; cosine: 1 - cos): all compared pairs (the calibration rule's
//     input), different places and same places;
//   - sequence matching (DP + NMS, match defaults, two-sequence mode for Nordland, margin for KITTI): AP of
//     each query's best loop closure by DP score, with the logistic scale from the offline rule on all pairs
//     (oracle), the fixed default (standard_default_scale(), or the dataset config's constants for raw), and
//     OnlineScale (causal, prior = the fixed one).
//
// A rendered sequence (`loopgate simulate --preset demo --out DIR`: a dusk revisit of day frames) is measured
// like KITTI with --rendered DIR (--dataset none to run it alone).
//
// Usage: build/release/bench_match_standardize_experiment [--data DIR] [--dataset nordland|kitti|both|none]
//          [--rendered DIR]
//          [--clamp 4] [--min-stddev 1] [--warm-up 50] [--window 0] [--refresh 1] [--threads 2] [--quick]
//          [--sweep] [--only NAME-PART]   (env LG_GRID=1: DP AP over a grid of fixed scales; LG_TOP=1,
//          LG_SEGMENTS=1)
#include <algorithm>
#include <array>
#include <chrono>
#include <cmath>
#include <cstdio>
#include <cstdlib>
#include <deque>
#include <filesystem>
#include <fstream>
#include <functional>
#include <iterator>
#include <map>
#include <opencv2/imgcodecs.hpp>
#include <sstream>
#include <string>
#include <thread>
#include <vector>

#include "stages/dird/dird_calibration.hpp"
#include "stages/dird/dird_extractor.hpp"
#include "stages/dird/dird_online_scale.hpp"
#include "stages/dird/dird_similarity.hpp"
#include "stages/dird/dird_standardize.hpp"
#include "stages/match/sequence_matcher.hpp"

namespace lg = loopgate;
namespace fs = std::filesystem;

namespace {

struct Options {
  fs::path data = LOOPGATE_SHARED_DATA_DIR;
  fs::path rendered;  // --rendered DIR: a `loopgate simulate` output (EuRoC layout)
  std::string dataset = "both";
  lg::StandardizeConfig standardize;
  int threads = 2;
  bool quick = false;  // only the code variants (int8 L1, cosine), no float
  bool sweep = false;  // causal statistics variants (window, warm-up, refresh)
  std::string only;    // run only the variants whose name contains this
};

// ---------------------------------------------------------------------------------------------------------
// Data

// Images of a folder in name order (numeric_names: by the number the name is, e.g. EuRoC timestamps).
std::vector<lg::Descriptor> describe_folder(const fs::path& dir, const lg::DirdExtractor& extractor,
                                            bool numeric_names = false) {
  std::vector<fs::path> files;
  for (const auto& entry : fs::directory_iterator(dir)) {
    if (entry.path().extension() == ".png") files.push_back(entry.path());
  }
  std::sort(files.begin(), files.end());
  if (numeric_names) {
    std::sort(files.begin(), files.end(), [](const fs::path& a, const fs::path& b) {
      return std::stoll(a.stem().string()) < std::stoll(b.stem().string());
    });
  }
  std::vector<lg::Descriptor> out(files.size());
  for (std::size_t k = 0; k < files.size(); ++k) {
    const cv::Mat image = cv::imread(files[k].string(), cv::IMREAD_UNCHANGED);
    if (image.empty()) {
      std::fprintf(stderr, "cannot read %s\n", files[k].c_str());
      std::exit(2);
    }
    extractor.extract(image, out[k]);
  }
  return out;
}

// x-z positions of a KITTI poses file (row-major 3 x 4: t_x = column 3, t_z = column 11).
std::vector<std::array<double, 2>> read_xz(const fs::path& file) {
  std::ifstream in(file);
  std::vector<std::array<double, 2>> out;
  std::string line;
  while (std::getline(in, line)) {
    std::istringstream s(line);
    double v[12];
    for (double& x : v) s >> x;
    if (s) out.push_back({v[3], v[11]});
  }
  return out;
}

// ---------------------------------------------------------------------------------------------------------
// Encodings of one sequence and pair distances

enum class Rep { kRaw, kCodes, kFloat };
enum class Metric { kL1, kCosine };

struct Encoded {
  Rep rep = Rep::kRaw;
  std::vector<lg::Descriptor> bytes;  // raw bytes or codes
  std::vector<lg::StandardizedFloat> floats;
  std::vector<double> norms;  // cosine
};

struct Variant {
  std::string name;
  Metric metric = Metric::kL1;
  double unit = 1.0;  // distance * unit = the normalised distance reported
  const Encoded* reference = nullptr;
  const Encoded* query = nullptr;
  bool is_raw = false;
};

void add_norms(Encoded& e) {
  e.norms.clear();
  if (e.rep == Rep::kFloat) {
    for (const auto& z : e.floats) e.norms.push_back(std::sqrt(static_cast<double>(lg::float_dot(z, z))));
  } else {
    for (const auto& c : e.bytes) e.norms.push_back(lg::standard_norm(c));
  }
}

Encoded encode_raw(const std::vector<lg::Descriptor>& raw) {
  Encoded e;
  e.rep = Rep::kRaw;
  e.bytes = raw;
  return e;
}

// Codes and floats with one Standardization per frame (statistics(k)).
template <class StatisticsOf>
Encoded encode_std(const std::vector<lg::Descriptor>& raw, Rep rep, StatisticsOf statistics) {
  Encoded e;
  e.rep = rep;
  if (rep == Rep::kCodes) {
    e.bytes.resize(raw.size());
    for (std::size_t k = 0; k < raw.size(); ++k) statistics(k).apply(raw[k], e.bytes[k]);
  } else {
    e.floats.reserve(raw.size());
    lg::StandardizedFloat z;
    for (std::size_t k = 0; k < raw.size(); ++k) {
      statistics(k).apply_float(raw[k], z);
      e.floats.push_back(z);
    }
  }
  add_norms(e);
  return e;
}

Encoded encode_batch(const std::vector<lg::Descriptor>& raw, Rep rep, const lg::StandardizeConfig& config) {
  const lg::Standardization s = lg::standardization_of(raw, config);
  return encode_std(raw, rep, [&](std::size_t) -> const lg::Standardization& { return s; });
}

// Controls for cosine without standardisation, as codes: (a) raw bytes - 100 (DIRD's zero response), (b)
// bytes minus the sequence's per-dimension mean, one common scale (centring without per-dimension scaling).
Encoded encode_offset(const std::vector<lg::Descriptor>& raw, bool centre) {
  lg::DescriptorMoments moments;
  for (const auto& d : raw) moments.add(d);
  double rms = 0.0;
  for (std::size_t k = 0; k < lg::kDirdBytes; ++k) rms += moments.variance(k);
  rms = std::sqrt(rms / static_cast<double>(lg::kDirdBytes));
  Encoded e;
  e.rep = Rep::kCodes;
  e.bytes.resize(raw.size());
  for (std::size_t i = 0; i < raw.size(); ++i) {
    for (std::size_t k = 0; k < lg::kDirdBytes; ++k) {
      const double v = centre ? (raw[i][k] - moments.mean(k)) * 127.0 / (4.0 * rms) : raw[i][k] - 100.0;
      e.bytes[i][k] = static_cast<std::uint8_t>(std::lround(std::clamp(v, -127.0, 127.0)) + 128);
    }
  }
  add_norms(e);
  return e;
}

// The stream: observe frame k, then standardise every frame that can be (warm-up frames once ready).
Encoded encode_causal(const std::vector<lg::Descriptor>& raw, Rep rep, const lg::StandardizeConfig& config) {
  lg::CausalStandardizer causal(config);
  for (std::size_t k = 0; k < raw.size(); ++k) causal.observe(static_cast<std::int64_t>(k), raw[k]);
  return encode_std(raw, rep, [&](std::size_t k) -> const lg::Standardization& {
    return causal.statistics_for(static_cast<std::int64_t>(k));
  });
}

inline float pair_distance(const Variant& v, std::size_t i, std::size_t j) {
  const Encoded& q = *v.query;
  const Encoded& r = *v.reference;
  if (q.rep == Rep::kFloat) {
    if (v.metric == Metric::kL1) return lg::float_l1_distance(q.floats[i], r.floats[j]);
    const double n = q.norms[i] * r.norms[j];
    return n == 0.0
               ? 1.0f
               : static_cast<float>(1.0 - static_cast<double>(lg::float_dot(q.floats[i], r.floats[j])) / n);
  }
  if (v.metric == Metric::kL1) return static_cast<float>(lg::l1_distance(q.bytes[i], r.bytes[j]));
  return static_cast<float>(lg::standard_cosine_distance(q.bytes[i], q.norms[i], r.bytes[j], r.norms[j]));
}

// Distance matrix rows = queries, columns = references j < columns(i) (all, or j <= i - margin).
struct Matrix {
  std::size_t rows = 0;
  std::vector<std::size_t> row_start;
  std::vector<std::size_t> columns;
  std::vector<float> d;
  const float* row(std::size_t i) const { return d.data() + row_start[i]; }
};

Matrix distance_matrix(const Variant& v, const std::function<std::size_t(std::size_t)>& columns,
                       int threads) {
  Matrix m;
  m.rows = v.query->rep == Rep::kFloat ? v.query->floats.size() : v.query->bytes.size();
  std::size_t total = 0;
  for (std::size_t i = 0; i < m.rows; ++i) {
    m.row_start.push_back(total);
    m.columns.push_back(columns(i));
    total += m.columns.back();
  }
  m.d.resize(total);
  auto work = [&](std::size_t t) {
    for (std::size_t i = t; i < m.rows; i += static_cast<std::size_t>(threads)) {
      float* out = m.d.data() + m.row_start[i];
      for (std::size_t j = 0; j < m.columns[i]; ++j) out[j] = pair_distance(v, i, j);
    }
  };
  std::vector<std::thread> pool;
  for (int t = 1; t < threads; ++t) pool.emplace_back(work, static_cast<std::size_t>(t));
  work(0);
  for (auto& th : pool) th.join();
  return m;
}

// ---------------------------------------------------------------------------------------------------------
// Scoring

struct Scored {
  double score = 0.0;  // higher is better
  bool correct = false;
};

// AP and R@P100 over each query's best detection (evaluation.md): one PR point per distinct score.
struct Pr {
  double ap = 0.0;
  double r100 = 0.0;
};

Pr precision_recall(std::vector<Scored> best, std::size_t positives) {
  std::stable_sort(best.begin(), best.end(),
                   [](const Scored& a, const Scored& b) { return a.score > b.score; });
  Pr pr;
  std::size_t accepted = 0, tp = 0;
  double previous_recall = 0.0;
  for (std::size_t k = 0; k < best.size();) {
    std::size_t end = k;
    while (end < best.size() && best[end].score == best[k].score) {
      ++accepted;
      tp += best[end].correct;
      ++end;
    }
    const double precision = static_cast<double>(tp) / static_cast<double>(accepted);
    const double recall = static_cast<double>(tp) / static_cast<double>(positives);
    pr.ap += (recall - previous_recall) * precision;
    previous_recall = recall;
    if (precision >= 1.0) pr.r100 = std::max(pr.r100, recall);
    k = end;
  }
  return pr;
}

struct Truth {
  // correct(i, j): j is a true match of query i (single image) / an accepted loop.
  std::function<bool(std::size_t, std::size_t)> correct;
  std::function<bool(std::size_t, std::size_t)> correct_loose;  // loops only (KITTI 10 m), may be empty
  std::function<bool(std::size_t, std::size_t)> different;      // a pair of different places (quantiles)
  std::function<bool(std::size_t, std::size_t)> same;           // a same-place pair (quantiles)
  std::vector<bool> positive;                                   // query has a true match
  std::size_t positives = 0;
};

double exact_quantile(std::vector<float>& values, double q) {
  if (values.empty()) return std::nan("");
  const double position = q * static_cast<double>(values.size() - 1);
  const std::size_t below = static_cast<std::size_t>(std::floor(position));
  std::nth_element(values.begin(), values.begin() + static_cast<std::ptrdiff_t>(below), values.end());
  const double lo = values[below];
  double hi = lo;
  if (below + 1 < values.size()) {
    hi = *std::min_element(values.begin() + static_cast<std::ptrdiff_t>(below) + 1, values.end());
  }
  return lo + (position - static_cast<double>(below)) * (hi - lo);
}

struct ScaleRow {
  std::string name;
  lg::LogisticScale scale;
};

struct Result {
  double recall1 = 0.0;
  Pr single;
  double q_all_mu = 0.0, q_all_cut = 0.0, q_all_median = 0.0;  // normalised
  double q_diff_mu = 0.0, q_diff_cut = 0.0, q_diff_median = 0.0, q_same_median = 0.0;
  double online_mu_err = 0.0, online_cut_err = 0.0;  // relative, histogram vs exact
  std::vector<std::pair<std::string, Pr>> dp;
  std::vector<std::pair<std::string, Pr>> dp_loose;
  std::vector<std::pair<std::string, std::size_t>> dp_loops;
};

// DP + NMS on the sparse S built from the distance matrix with a per-frame scale.
std::vector<lg::LoopClosure> run_dp(const Matrix& m, bool two_sequence, const lg::MatchConfig& match,
                                    double tau1,
                                    const std::function<lg::LogisticScale(std::size_t)>& scale_of,
                                    const std::function<void(std::size_t)>& after_row) {
  lg::SequenceMatcher matcher(match, two_sequence ? lg::SequenceMatcher::Mode::kTwoSequence
                                                  : lg::SequenceMatcher::Mode::kSingleSequence);
  lg::MatchOutput out;
  std::vector<lg::SimilarityEntry> entries;
  for (std::size_t i = 0; i < m.rows; ++i) {
    const lg::LogisticScale s = scale_of(i);
    entries.clear();
    const float* row = m.row(i);
    for (std::size_t j = 0; j < m.columns[i]; ++j) {
      const double sim = lg::logistic_similarity(static_cast<double>(row[j]), s.mu, s.sigma);
      if (sim > tau1) entries.push_back({static_cast<std::int64_t>(j), sim});
    }
    matcher.push(static_cast<std::int64_t>(i), entries, out);
    if (after_row) after_row(i);
  }
  matcher.flush(out);
  return out.loops;
}

Pr loops_pr(const std::vector<lg::LoopClosure>& loops, std::size_t rows,
            const std::function<bool(std::size_t, std::size_t)>& correct, std::size_t positives) {
  std::vector<const lg::LoopClosure*> best(rows, nullptr);
  for (const auto& l : loops) {
    auto& b = best[static_cast<std::size_t>(l.i)];
    if (b == nullptr || l.score > b->score) b = &l;
  }
  std::vector<Scored> scored;
  for (const auto* b : best) {
    if (b != nullptr) {
      scored.push_back({b->score, correct(static_cast<std::size_t>(b->i), static_cast<std::size_t>(b->j))});
    }
  }
  return precision_recall(scored, positives);
}

Result evaluate(const Variant& v, const Matrix& m, const Truth& truth, bool two_sequence,
                const lg::MatchConfig& match, const lg::LogisticScale& fixed, const std::string& fixed_name) {
  Result r;
  constexpr double kTau1 = 0.05;
  // Single image.
  std::vector<Scored> best;
  std::size_t recalled = 0;
  for (std::size_t i = 0; i < m.rows; ++i) {
    if (m.columns[i] == 0) continue;
    const float* row = m.row(i);
    const std::size_t j = static_cast<std::size_t>(std::min_element(row, row + m.columns[i]) - row);
    const bool ok = truth.correct(i, j);
    best.push_back({-static_cast<double>(row[j]), ok});
    recalled += ok && truth.positive[i];
  }
  r.recall1 = static_cast<double>(recalled) / static_cast<double>(truth.positives);
  if (std::getenv("LG_SEGMENTS") != nullptr) {
    // Per block of 500 query frames: recall@1 and the median best distance (normalised).
    for (std::size_t begin = 0; begin < m.rows; begin += 500) {
      std::size_t ok = 0, pos = 0;
      std::vector<float> best_d;
      for (std::size_t i = begin; i < std::min(m.rows, begin + 500); ++i) {
        if (m.columns[i] == 0 || !truth.positive[i]) continue;
        const float* row = m.row(i);
        const std::size_t j = static_cast<std::size_t>(std::min_element(row, row + m.columns[i]) - row);
        ok += truth.correct(i, j);
        ++pos;
        best_d.push_back(row[j]);
      }
      std::printf("  [%zu, %zu): R@1 %zu/%zu, median best %.4g\n", begin, std::min(m.rows, begin + 500), ok,
                  pos, best_d.empty() ? 0.0 : exact_quantile(best_d, 0.5) * v.unit);
    }
  }
  r.single = precision_recall(best, truth.positives);
  // Quantiles.
  std::vector<float> diff, same;
  lg::OnlineScaleConfig online_config;
  online_config.mode = lg::ScaleMode::kOnline;
  lg::OnlineScale all(online_config, kTau1, fixed);
  for (std::size_t i = 0; i < m.rows; ++i) {
    const float* row = m.row(i);
    for (std::size_t j = 0; j < m.columns[i]; ++j) {
      all.add(static_cast<double>(row[j]));
      if (truth.different(i, j)) diff.push_back(row[j]);
      if (truth.same(i, j)) same.push_back(row[j]);
    }
  }
  std::vector<float> every = m.d;
  const double mu_exact = exact_quantile(every, online_config.mu_quantile);
  const double cut_exact = exact_quantile(every, online_config.cutoff_quantile);
  r.q_all_mu = mu_exact * v.unit;
  r.q_all_cut = cut_exact * v.unit;
  r.q_all_median = exact_quantile(every, 0.5) * v.unit;
  r.online_mu_err = all.quantile(online_config.mu_quantile) / mu_exact - 1.0;
  r.online_cut_err = all.quantile(online_config.cutoff_quantile) / cut_exact - 1.0;
  r.q_diff_mu = exact_quantile(diff, online_config.mu_quantile) * v.unit;
  r.q_diff_cut = exact_quantile(diff, online_config.cutoff_quantile) * v.unit;
  r.q_diff_median = exact_quantile(diff, 0.5) * v.unit;
  r.q_same_median = exact_quantile(same, 0.5) * v.unit;
  // Sequence matching with three scales.
  lg::LogisticScale oracle;
  oracle.mu = mu_exact;
  oracle.cutoff_distance = cut_exact;
  oracle.sigma = (cut_exact - mu_exact) / std::log(1.0 / kTau1 - 1.0);
  auto record = [&](const std::string& name, const std::vector<lg::LoopClosure>& loops) {
    r.dp.emplace_back(name, loops_pr(loops, m.rows, truth.correct, truth.positives));
    if (truth.correct_loose)
      r.dp_loose.emplace_back(name, loops_pr(loops, m.rows, truth.correct_loose, truth.positives));
    r.dp_loops.emplace_back(name, loops.size());
  };
  if (oracle.sigma > 0.0) {
    const auto loops = run_dp(m, two_sequence, match, kTau1, [&](std::size_t) { return oracle; }, {});
    record("offline", loops);
    if (std::getenv("LG_TOP") != nullptr) {
      std::vector<lg::LoopClosure> top(m.rows);
      for (const auto& l : loops) {
        auto& b = top[static_cast<std::size_t>(l.i)];
        if (l.score > b.score) b = l;
      }
      std::sort(top.begin(), top.end(), [](const auto& a, const auto& b) { return a.score > b.score; });
      for (std::size_t k = 0; k < 30 && k < top.size(); ++k) {
        const auto i = static_cast<std::size_t>(top[k].i), j = static_cast<std::size_t>(top[k].j);
        std::printf("  top %zu: i %zu j %zu score %.2f %s\n", k, i, j, top[k].score,
                    truth.correct(i, j) ? "ok" : "wrong");
      }
    }
  }
  record(fixed_name, run_dp(m, two_sequence, match, kTau1, [&](std::size_t) { return fixed; }, {}));
  if (std::getenv("LG_GRID") != nullptr && !v.is_raw) {
    // Fixed scales in normalised units: DP AP for each (mu, cut-off).
    for (double cut : {0.85, 0.88, 0.9, 0.92, 0.95, 1.0}) {
      for (double mu : {0.5, 0.6, 0.7, 0.75, 0.8, 0.85, 0.9}) {
        if (mu >= cut) continue;
        lg::LogisticScale g;
        g.mu = mu / v.unit;
        g.cutoff_distance = cut / v.unit;
        g.sigma = (g.cutoff_distance - g.mu) / std::log(1.0 / kTau1 - 1.0);
        const auto loops = run_dp(m, two_sequence, match, kTau1, [&](std::size_t) { return g; }, {});
        const Pr pr = loops_pr(loops, m.rows, truth.correct, truth.positives);
        std::printf("  grid mu %.2f cut %.2f: DP AP %.3f (%zu loops)\n", mu, cut, pr.ap, loops.size());
      }
    }
  }
  if (std::getenv("LG_QGRID") != nullptr) {
    // Scales from quantiles of all compared pairs (the offline rule with other quantiles): DP AP.
    for (double cut_q : {0.01, 0.03, 0.1, 0.2, 0.3, 0.5}) {
      for (double mu_q : {0.0005, 0.003, 0.01, 0.03, 0.1, 0.2}) {
        if (mu_q >= cut_q) continue;
        lg::LogisticScale g;
        g.mu = all.quantile(mu_q);
        g.cutoff_distance = all.quantile(cut_q);
        g.sigma = (g.cutoff_distance - g.mu) / std::log(1.0 / kTau1 - 1.0);
        const auto loops = run_dp(m, two_sequence, match, kTau1, [&](std::size_t) { return g; }, {});
        const Pr pr = loops_pr(loops, m.rows, truth.correct, truth.positives);
        std::printf("  qgrid mu_q %.4f cut_q %.2f (mu %.4g cut %.4g): DP AP %.3f R@P100 %.3f (%zu loops)\n",
                    mu_q, cut_q, g.mu * v.unit, g.cutoff_distance * v.unit, pr.ap, pr.r100, loops.size());
      }
    }
  }
  lg::OnlineScale online(online_config, kTau1, fixed);
  record("online", run_dp(
                       m, two_sequence, match, kTau1, [&](std::size_t) { return online.scale(); },
                       [&](std::size_t i) {
                         const float* row = m.row(i);
                         for (std::size_t j = 0; j < m.columns[i]; ++j)
                           online.add(static_cast<double>(row[j]));
                       }));
  return r;
}

void print_header(bool loose) {
  std::printf(
      "| variant | R@1 | AP single | all q0.0005 | all q0.01 | all median | diff q0.01 | diff median | same "
      "median | hist err mu/cut | DP AP (R@P100) offline | DP fixed | DP online |%s\n",
      loose ? " DP 10 m offline / fixed / online |" : "");
  std::printf("|---|---|---|---|---|---|---|---|---|---|---|---|---|%s\n", loose ? "---|" : "");
}

void print_row(const std::string& name, const Result& r) {
  std::printf("| %s | %.3f | %.3f | %.4g | %.4g | %.4g | %.4g | %.4g | %.4g | %.1e / %.1e |", name.c_str(),
              r.recall1, r.single.ap, r.q_all_mu, r.q_all_cut, r.q_all_median, r.q_diff_cut, r.q_diff_median,
              r.q_same_median, r.online_mu_err, r.online_cut_err);
  auto find = [&](const std::vector<std::pair<std::string, Pr>>& list,
                  const std::string& key) -> std::string {
    for (const auto& [k, pr] : list) {
      if (k == key || (key == "fixed" && k != "offline" && k != "online")) {
        char text[64];
        std::snprintf(text, sizeof text, "%.3f (%.2f)", pr.ap, pr.r100);
        return text;
      }
    }
    return "-";
  };
  std::printf(" %s | %s | %s |", find(r.dp, "offline").c_str(), find(r.dp, "fixed").c_str(),
              find(r.dp, "online").c_str());
  if (!r.dp_loose.empty()) {
    std::printf(" %s / %s / %s |", find(r.dp_loose, "offline").c_str(), find(r.dp_loose, "fixed").c_str(),
                find(r.dp_loose, "online").c_str());
  }
  std::printf("\n");
  std::fflush(stdout);
}

struct Job {
  std::string name;
  Metric metric;
  const Encoded* reference;
  const Encoded* query;
  bool raw;
};

double unit_of(const Job& job, const lg::StandardizeConfig& config) {
  if (job.metric == Metric::kCosine) return 1.0;
  if (job.raw) return 1.0 / static_cast<double>(lg::kDirdBytes);
  if (job.query->rep == Rep::kFloat) return 1.0 / static_cast<double>(lg::kDirdBytes);
  return lg::standard_l1_unit(config.clamp_sigma);
}

void run_jobs(const std::vector<Job>& jobs, const Options& options, const Truth& truth, bool two_sequence,
              const lg::MatchConfig& match, const lg::LogisticScale& raw_fixed,
              const std::function<std::size_t(std::size_t)>& columns) {
  print_header(static_cast<bool>(truth.correct_loose));
  for (const Job& job : jobs) {
    if (!options.only.empty() && job.name.find(options.only) == std::string::npos) continue;
    const auto t0 = std::chrono::steady_clock::now();
    Variant v{job.name, job.metric, unit_of(job, options.standardize), job.reference, job.query, job.raw};
    const Matrix m = distance_matrix(v, columns, options.threads);
    const double seconds = std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count();
    lg::LogisticScale fixed = raw_fixed;
    std::string fixed_name = "config";
    if (!job.raw) {
      lg::StandardizeConfig c = options.standardize;
      c.distance =
          job.metric == Metric::kCosine ? lg::StandardizeDistance::kCosine : lg::StandardizeDistance::kL1;
      fixed = lg::standard_default_scale(c);
      if (job.query->rep == Rep::kFloat && job.metric == Metric::kL1) {
        // Floats: the scale in mean |z| per dimension times 3456.
        const double to_float = lg::standard_l1_unit(c.clamp_sigma) * static_cast<double>(lg::kDirdBytes);
        fixed.mu *= to_float;
        fixed.sigma *= to_float;
        fixed.cutoff_distance *= to_float;
      }
      fixed_name = "default";
    }
    const Result r = evaluate(v, m, truth, two_sequence, match, fixed, fixed_name);
    print_row(job.name + " (" + std::to_string(static_cast<int>(seconds * 1000)) + " ms)", r);
  }
}

// ---------------------------------------------------------------------------------------------------------

std::vector<std::pair<std::string, lg::StandardizeConfig>> causal_variants(const Options& options) {
  std::vector<std::pair<std::string, lg::StandardizeConfig>> out;
  const lg::StandardizeConfig& base = options.standardize;
  auto name_of = [](const lg::StandardizeConfig& c) {
    std::string name = "causal";
    if (c.window > 0) name += " window " + std::to_string(c.window);
    return name;
  };
  out.emplace_back(name_of(base), base);
  if (!options.sweep) return out;
  for (std::int64_t window : {50, 100, 200, 300, 1000}) {
    lg::StandardizeConfig c = base;
    c.window = window;
    c.warm_up = std::min(c.warm_up, window);
    if (c.window != base.window) out.emplace_back(name_of(c), c);
  }
  for (std::int64_t warm_up : {10, 200}) {
    lg::StandardizeConfig c = base;
    c.warm_up = warm_up;
    if (c.window > 0 && c.window < warm_up) continue;
    out.emplace_back(name_of(c) + " warm-up " + std::to_string(warm_up), c);
  }
  for (std::int64_t refresh : {10, 25}) {
    lg::StandardizeConfig c = base;
    c.refresh_every = refresh;
    out.emplace_back(name_of(c) + " refresh " + std::to_string(refresh), c);
  }
  return out;
}

void nordland(const Options& options, const lg::DirdExtractor& extractor) {
  const fs::path root = options.data / "nordland-64x32";
  const auto t0 = std::chrono::steady_clock::now();
  const std::vector<lg::Descriptor> summer = describe_folder(root / "summer", extractor);
  const std::vector<lg::Descriptor> winter = describe_folder(root / "winter", extractor);
  std::printf("\n## Nordland 64x32: reference summer (%zu), query winter (%zu); described in %.1f s\n\n",
              summer.size(), winter.size(),
              std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count());
  const std::size_t n = summer.size();
  Truth truth;
  truth.correct = [](std::size_t i, std::size_t j) {
    return std::abs(static_cast<long>(i) - static_cast<long>(j)) <= 2;
  };
  truth.different = [](std::size_t i, std::size_t j) {
    return std::abs(static_cast<long>(i) - static_cast<long>(j)) > 20;
  };
  truth.same = [](std::size_t i, std::size_t j) { return i == j; };
  truth.positive.assign(winter.size(), true);
  truth.positives = winter.size();
  lg::MatchConfig match;
  match.margin = 0;
  lg::LogisticScale config_scale;  // configs/nordland.yaml
  config_scale.mu = 36668.5;
  config_scale.sigma = 5197.4;

  const lg::StandardizeConfig& c = options.standardize;
  std::deque<Encoded> store;  // stable addresses
  auto keep = [&](Encoded e) -> const Encoded* {
    store.push_back(std::move(e));
    return &store.back();
  };
  const Encoded* raw_s = keep(encode_raw(summer));
  const Encoded* raw_w = keep(encode_raw(winter));
  std::vector<Job> jobs;
  jobs.push_back({"raw L1", Metric::kL1, raw_s, raw_w, true});
  {
    const Encoded* os = keep(encode_offset(summer, false));
    const Encoded* ow = keep(encode_offset(winter, false));
    jobs.push_back({"control: raw - 100, cosine", Metric::kCosine, os, ow, false});
    const Encoded* cs = keep(encode_offset(summer, true));
    const Encoded* cw = keep(encode_offset(winter, true));
    jobs.push_back({"control: centred per sequence, not scaled, cosine", Metric::kCosine, cs, cw, false});
  }
  for (Rep rep : options.quick ? std::vector<Rep>{Rep::kCodes} : std::vector<Rep>{Rep::kCodes, Rep::kFloat}) {
    const char* rep_name = rep == Rep::kCodes ? "int8" : "float";
    const Encoded* bs = keep(encode_batch(summer, rep, c));
    const Encoded* bw = keep(encode_batch(winter, rep, c));
    for (Metric metric : {Metric::kL1, Metric::kCosine}) {
      const std::string m = metric == Metric::kL1 ? "L1" : "cosine";
      jobs.push_back({std::string("batch/batch ") + rep_name + " " + m, metric, bs, bw, false});
    }
    if (rep == Rep::kCodes) {
      // One set of statistics for both conditions: what per-condition statistics add.
      std::vector<lg::Descriptor> both = summer;
      both.insert(both.end(), winter.begin(), winter.end());
      const lg::Standardization pooled = lg::standardization_of(both, c);
      auto by_pooled = [&](std::size_t) -> const lg::Standardization& { return pooled; };
      const Encoded* ps = keep(encode_std(summer, rep, by_pooled));
      const Encoded* pw = keep(encode_std(winter, rep, by_pooled));
      jobs.push_back({"pooled stats int8 L1", Metric::kL1, ps, pw, false});
    }
    const auto variants = causal_variants(options);
    for (const auto& [name, config] : variants) {
      const Encoded* cs = keep(encode_causal(summer, rep, config));
      const Encoded* cw = keep(encode_causal(winter, rep, config));
      for (Metric metric : {Metric::kL1, Metric::kCosine}) {
        const std::string m = metric == Metric::kL1 ? "L1" : "cosine";
        jobs.push_back({name + "/" + name + " " + rep_name + " " + m, metric, cs, cw, false});
        if (name == variants.front().first)  // the streaming query against a batch reference
          jobs.push_back({"batch/" + name + " " + rep_name + " " + m, metric, bs, cw, false});
      }
    }
  }
  run_jobs(jobs, options, truth, true, match, config_scale, [n](std::size_t) { return n; });
}

// Single sequence: frames with positions (metres), revisits within `truth_m` at least `margin` frames back.
struct SingleSequence {
  std::string title;
  std::vector<lg::Descriptor> frames;
  std::vector<std::array<double, 3>> positions;
  double truth_m = 2.0;
  double accept_m = 10.0;          // loops: the dataset config's eval.accept_radius_m
  lg::LogisticScale config_scale;  // the dataset config's dird.mu / dird.sigma (raw L1)
};

void single_sequence(const Options& options, const SingleSequence& data) {
  lg::MatchConfig match;  // margin 200
  const std::size_t margin = static_cast<std::size_t>(match.margin);
  const auto& p = data.positions;
  auto distance_m = [&p](std::size_t i, std::size_t j) {
    const double dx = p[i][0] - p[j][0], dy = p[i][1] - p[j][1], dz = p[i][2] - p[j][2];
    return std::sqrt(dx * dx + dy * dy + dz * dz);
  };
  const double truth_m = data.truth_m, accept_m = data.accept_m;
  Truth truth;
  truth.correct = [=](std::size_t i, std::size_t j) { return distance_m(i, j) <= truth_m; };
  truth.correct_loose = [=](std::size_t i, std::size_t j) { return distance_m(i, j) <= accept_m; };
  truth.different = [=](std::size_t i, std::size_t j) { return distance_m(i, j) > 10.0; };
  truth.same = [=](std::size_t i, std::size_t j) { return distance_m(i, j) <= truth_m; };
  truth.positive.assign(data.frames.size(), false);
  for (std::size_t i = margin; i < data.frames.size(); ++i) {
    for (std::size_t j = 0; j + margin <= i; ++j) {
      if (distance_m(i, j) <= truth_m) {
        truth.positive[i] = true;
        break;
      }
    }
    truth.positives += truth.positive[i];
  }
  std::printf(
      "\n## %s: %zu frames, margin %zu, %zu positive queries (a frame <= i - %zu within %g m); loops also "
      "scored within %g m\n\n",
      data.title.c_str(), data.frames.size(), margin, truth.positives, margin, truth_m, accept_m);

  const lg::StandardizeConfig& c = options.standardize;
  std::deque<Encoded> store;  // stable addresses
  auto keep = [&](Encoded e) -> const Encoded* {
    store.push_back(std::move(e));
    return &store.back();
  };
  const auto& frames = data.frames;
  const Encoded* raw = keep(encode_raw(frames));
  std::vector<Job> jobs;
  jobs.push_back({"raw L1", Metric::kL1, raw, raw, true});
  for (Rep rep : options.quick ? std::vector<Rep>{Rep::kCodes} : std::vector<Rep>{Rep::kCodes, Rep::kFloat}) {
    const char* rep_name = rep == Rep::kCodes ? "int8" : "float";
    for (const auto& [name, config] : causal_variants(options)) {
      const Encoded* e = keep(encode_causal(frames, rep, config));
      for (Metric metric : {Metric::kL1, Metric::kCosine}) {
        jobs.push_back(
            {name + " " + rep_name + (metric == Metric::kL1 ? " L1" : " cosine"), metric, e, e, false});
      }
    }
    const Encoded* b = keep(encode_batch(frames, rep, c));
    for (Metric metric : {Metric::kL1, Metric::kCosine}) {
      jobs.push_back(
          {std::string("batch (not causal) ") + rep_name + (metric == Metric::kL1 ? " L1" : " cosine"),
           metric, b, b, false});
    }
  }
  run_jobs(jobs, options, truth, false, match, data.config_scale,
           [margin](std::size_t i) { return i >= margin ? i - margin + 1 : 0; });
}

void kitti(const Options& options, const lg::DirdExtractor& extractor) {
  const fs::path root = options.data / "kitti/00/thumbs";
  SingleSequence data;
  data.title = "KITTI 00 thumbnails (image_0, x-z distances)";
  data.frames = describe_folder(root / "image_0", extractor);
  for (const auto& xz : read_xz(root / "poses.txt")) data.positions.push_back({xz[0], 0.0, xz[1]});
  if (data.positions.size() < data.frames.size()) {
    std::fprintf(stderr, "poses.txt: %zu rows for %zu frames\n", data.positions.size(), data.frames.size());
    std::exit(2);
  }
  data.truth_m = 2.0;
  data.accept_m = 10.0;
  data.config_scale.mu = 48477.5;  // configs/kitti00-thumbs.yaml
  data.config_scale.sigma = 1796.7769;
  single_sequence(options, data);
}

// A rendered EuRoC-layout sequence (`loopgate simulate --preset demo`): mav0/cam0/data/*.png and the ground
// truth position nearest in time to each image.
void rendered(const Options& options, const lg::DirdExtractor& extractor) {
  const fs::path mav0 = options.rendered / "mav0";
  SingleSequence data;
  data.title = "rendered " + options.rendered.filename().string() + " (3-D distances)";
  data.frames = describe_folder(mav0 / "cam0/data", extractor, true);
  std::vector<std::int64_t> image_t;
  for (const auto& entry : fs::directory_iterator(mav0 / "cam0/data")) {
    if (entry.path().extension() == ".png") image_t.push_back(std::stoll(entry.path().stem().string()));
  }
  std::sort(image_t.begin(), image_t.end());
  std::vector<std::pair<std::int64_t, std::array<double, 3>>> truth_rows;
  std::ifstream in(mav0 / "state_groundtruth_estimate0/data.csv");
  std::string line;
  while (std::getline(in, line)) {
    if (line.empty() || line[0] == '#') continue;
    std::replace(line.begin(), line.end(), ',', ' ');
    std::istringstream row(line);
    std::int64_t t = 0;
    std::array<double, 3> pos{};
    row >> t >> pos[0] >> pos[1] >> pos[2];
    if (row) truth_rows.emplace_back(t, pos);
  }
  if (truth_rows.empty() || image_t.size() != data.frames.size()) {
    std::fprintf(stderr, "%s: no ground truth or image names are not timestamps\n", mav0.c_str());
    std::exit(2);
  }
  for (std::int64_t t : image_t) {
    const auto after = std::lower_bound(truth_rows.begin(), truth_rows.end(), t,
                                        [](const auto& r, std::int64_t value) { return r.first < value; });
    auto nearest = after == truth_rows.end() ? std::prev(after) : after;
    if (after != truth_rows.begin() && after != truth_rows.end() &&
        t - std::prev(after)->first < after->first - t) {
      nearest = std::prev(after);
    }
    data.positions.push_back(nearest->second);
  }
  data.truth_m = 2.0;
  data.accept_m = 3.0;
  data.config_scale.mu = 34177.402;  // configs/demo.yaml
  data.config_scale.sigma = 3434.4565;
  single_sequence(options, data);
}

}  // namespace

int main(int argc, char** argv) {
  Options options;
  for (int k = 1; k < argc; ++k) {
    const std::string key = argv[k];
    auto value = [&]() -> std::string {
      if (k + 1 >= argc) {
        std::fprintf(stderr, "%s needs a value\n", key.c_str());
        std::exit(2);
      }
      return argv[++k];
    };
    if (key == "--data") {
      options.data = value();
    } else if (key == "--dataset") {
      options.dataset = value();
    } else if (key == "--rendered") {
      options.rendered = value();
    } else if (key == "--clamp") {
      options.standardize.clamp_sigma = std::stod(value());
    } else if (key == "--min-stddev") {
      options.standardize.min_stddev = std::stod(value());
    } else if (key == "--warm-up") {
      options.standardize.warm_up = std::stoll(value());
    } else if (key == "--window") {
      options.standardize.window = std::stoll(value());
    } else if (key == "--refresh") {
      options.standardize.refresh_every = std::stoll(value());
    } else if (key == "--threads") {
      options.threads = std::stoi(value());
    } else if (key == "--only") {
      options.only = value();
    } else if (key == "--quick") {
      options.quick = true;
    } else if (key == "--sweep") {
      options.sweep = true;
    } else {
      std::fprintf(stderr, "unknown option %s (see the comment at the top of the source)\n", key.c_str());
      return 2;
    }
  }
  options.standardize.mode = lg::StandardizeMode::kCausal;
  options.standardize.validate();
  lg::DirdConfig dird;
  dird.normalization = lg::DirdNormalization::kL2;
  const lg::DirdExtractor extractor(dird);
  std::printf("standardize: clamp_sigma %g, min_stddev %g, warm_up %lld, window %lld, refresh_every %lld\n",
              options.standardize.clamp_sigma, options.standardize.min_stddev,
              static_cast<long long>(options.standardize.warm_up),
              static_cast<long long>(options.standardize.window),
              static_cast<long long>(options.standardize.refresh_every));
  if (options.dataset == "nordland" || options.dataset == "both") nordland(options, extractor);
  if (options.dataset == "kitti" || options.dataset == "both") kitti(options, extractor);
  if (!options.rendered.empty()) rendered(options, extractor);
  return 0;
}
