// Behaviour is pinned: the deterministic outputs of full DIRD, gated DIRD, full SeqSLAM, gated SeqSLAM and
// the two-sequence runs of dird, seqslam and dird-seqslam (loops.csv, frames.csv, trajectory.tum,
// candidate_cells.csv and the evaluation block of summary.json) have the digests in
// tests/golden/run_digests.txt, recorded before the pipeline was reorganised (gated SeqSLAM's when it was
// added). A refactor must leave them unchanged; a change of behaviour updates the file on purpose, in the
// same commit, saying why:
//   /usr/bin/python3 scripts/run_digest.py OUT/aliasing OUT/aliasing-seqslam-gated OUT/thumbs
//     OUT/thumbs-seqslam-gated OUT/nordland-dird OUT/nordland-seqslam OUT/nordland-dird-seqslam
//     (one command line)
// The SeqSLAM of `compare` is the full one (compare sets run.mode full for it); gated SeqSLAM is a `run
// --method seqslam --mode gated`. The two-sequence (Nordland) runs have no pose gate: run.mode does not
// apply. The rendered aliasing preset always runs; the KITTI 00 thumbnails and Nordland need ../shared/data.
#include <gtest/gtest.h>

#include <filesystem>
#include <fstream>
#include <map>
#include <sstream>
#include <string>

#include "test_support.hpp"

namespace loopgate {
namespace {

namespace fs = std::filesystem;

const fs::path kSource = LOOPGATE_SOURCE_DIR;

std::map<std::string, std::string> read_digests(const std::string& text) {
  std::map<std::string, std::string> out;
  std::istringstream in(text);
  std::string key, value;
  while (in >> key >> value) out[key] = value;
  return out;
}

std::map<std::string, std::string> golden(const std::string& prefix) {
  std::ifstream in(kSource / "tests" / "golden" / "run_digests.txt");
  std::stringstream text;
  text << in.rdbuf();
  std::map<std::string, std::string> out;
  for (const auto& [key, value] : read_digests(text.str()))
    if (key.rfind(prefix + "/", 0) == 0) out[key] = value;
  return out;
}

// Runs `args` (a loopgate command writing into OUT/label), then the digest of OUT/label.
void expect_digests(const std::string& label, const std::string& args) {
  const fs::path out = testing::make_temp_dir("e2e-golden") / label;
  std::string log;
  ASSERT_EQ(testing::run_command(testing::loopgate_binary().string() + " --log-level warn " + args +
                                     " --out " + out.string() + " --set output.progress=off",
                                 &log),
            0)
      << log;
  std::string digest;
  ASSERT_EQ(testing::run_command(
                "/usr/bin/python3 " + (kSource / "scripts" / "run_digest.py").string() + " " + out.string(),
                &digest),
            0)
      << digest;
  const auto expected = golden(label);
  ASSERT_FALSE(expected.empty()) << "no golden digests for " << label;
  const auto actual = read_digests(digest);
  for (const auto& [key, value] : expected) {
    const auto it = actual.find(key);
    ASSERT_NE(it, actual.end()) << key << " missing from the run's outputs";
    EXPECT_EQ(it->second, value) << key << " changed (tests/golden/run_digests.txt; outputs in " << out
                                 << ")";
  }
}

TEST(E2eGolden, AliasingPresetDirdAndSeqSlamFullAndGated) {
  const fs::path data = testing::make_temp_dir("e2e-golden-data") / "aliasing";
  std::string log;
  ASSERT_EQ(testing::run_command(testing::loopgate_binary().string() +
                                     " --log-level warn simulate --preset aliasing --out " + data.string(),
                                 &log),
            0)
      << log;
  expect_digests("aliasing", "compare --no-plots --methods full,gated,seqslam --config " +
                                 (kSource / "configs" / "aliasing.yaml").string() + " --dataset " +
                                 data.string());
  expect_digests("aliasing-seqslam-gated", "run --method seqslam --mode gated --config " +
                                               (kSource / "configs" / "aliasing.yaml").string() +
                                               " --dataset " + data.string());
}

TEST(E2eGolden, KittiThumbsDirdAndSeqSlamFullAndGated) {
  LOOPGATE_REQUIRE_SHARED_DATA("kitti/00/thumbs");
  expect_digests("thumbs", "compare --no-plots --methods full,gated,seqslam --config " +
                               (kSource / "configs" / "kitti00-thumbs.yaml").string() + " --dataset " +
                               (testing::shared_data_dir() / "kitti/00/thumbs").string());
  expect_digests("thumbs-seqslam-gated", "run --method seqslam --mode gated --config " +
                                             (kSource / "configs" / "kitti00-thumbs.yaml").string() +
                                             " --dataset " +
                                             (testing::shared_data_dir() / "kitti/00/thumbs").string());
}

TEST(E2eGolden, NordlandTwoSequences) {
  LOOPGATE_REQUIRE_SHARED_DATA("nordland-64x32/summer");
  const fs::path nordland = testing::shared_data_dir() / "nordland-64x32";
  for (const std::string method : {"dird", "seqslam", "dird-seqslam"}) {
    expect_digests("nordland-" + method, "run --config " + (kSource / "configs" / "nordland.yaml").string() +
                                             " --method " + method + " --reference " +
                                             (nordland / "summer").string() + " --query " +
                                             (nordland / "winter").string());
  }
}

}  // namespace
}  // namespace loopgate
