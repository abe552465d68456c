// scripts/batch.sh (GNU parallel) and scripts/slurm/loopgate-array.sbatch end to end on a tiny manifest the
// test writes: a rendered aliasing excerpt, a run and a compare on it. A second batch.sh redoes nothing; a
// job whose outputs were removed is redone alone; a failing line makes batch.sh exit non-zero naming it, and
// the next batch.sh retries only that line; a bad manifest line is an error naming file and line; the Slurm
// template run by hand for one index does that job (or skips it when done). Skipped without GNU parallel.
#include <gtest/gtest.h>

#include <algorithm>
#include <filesystem>
#include <fstream>
#include <string>

#include "test_support.hpp"

namespace loopgate {
namespace {

namespace fs = std::filesystem;

const fs::path kSource = LOOPGATE_SOURCE_DIR;

bool have_gnu_parallel() {
  std::string output;
  return testing::run_command("parallel --version", &output) == 0 &&
         output.find("GNU parallel") != std::string::npos;
}

struct Result {
  int status = -1;
  std::string output;
};

Result batch(const fs::path& manifest, const fs::path& root, const std::string& extra = "") {
  Result r;
  r.status = testing::run_command((kSource / "scripts" / "batch.sh").string() + " " + manifest.string() +
                                      " -j 2 --out " + root.string() + " --loopgate " +
                                      testing::loopgate_binary().string() + extra,
                                  &r.output);
  return r;
}

Result slurm_task(int index, const fs::path& manifest, const fs::path& root) {
  Result r;
  r.status = testing::run_command("env -u SLURM_JOB_ID SLURM_ARRAY_TASK_ID=" + std::to_string(index) +
                                      " LOOPGATE=" + testing::loopgate_binary().string() + " bash " +
                                      (kSource / "scripts" / "slurm" / "loopgate-array.sbatch").string() +
                                      " " + manifest.string() + " --out " + root.string(),
                                  &r.output);
  return r;
}

// How many times batch started the job: one "===" header per attempt in its console log.
int attempts(const fs::path& root, const std::string& name) {
  const std::string log = testing::read_file(root / "_batch" / "logs" / (name + ".log"));
  int count = 0;
  for (std::size_t at = log.find("=== "); at != std::string::npos; at = log.find("\n=== ", at + 1)) ++count;
  return count;
}

std::size_t lines(const fs::path& file) {
  const std::string text = testing::read_file(file);
  return static_cast<std::size_t>(std::count(text.begin(), text.end(), '\n'));
}

fs::path write_manifest(const fs::path& dir, const std::string& name, const std::string& jobs) {
  const fs::path file = dir / name;
  std::ofstream(file) << "# a test manifest\nname\tcommand\tdataset\tconfig\tset\toptions\n" << jobs;
  return file;
}

const std::string kConfig = (kSource / "configs" / "aliasing.yaml").string();

std::string tiny_jobs() {
  const std::string set = "output.progress=off match.margin=50 seqslam.exclusion_margin_frames=50";
  return "sim\tsimulate\taliasing\t-\t-\t--frames 120\n"
         "\n"
         "gated\trun\t@sim\t" +
         kConfig + "\t" + set + "\t--mode gated\n" + "cmp\tcompare\t@sim\t" + kConfig + "\t" + set +
         "\t--methods gated,seqslam --no-plots\n";
}

TEST(E2eBatch, ResumesWithoutRedoingFinishedRuns) {
  if (!have_gnu_parallel()) GTEST_SKIP() << "GNU parallel not installed (Debian package parallel)";
  const fs::path dir = testing::make_temp_dir("e2e-batch");
  const fs::path manifest = write_manifest(dir, "tiny.tsv", tiny_jobs());
  const fs::path root = dir / "out";

  Result r = batch(manifest, root);
  ASSERT_EQ(r.status, 0) << r.output;
  EXPECT_TRUE(fs::is_regular_file(root / "sim" / "simulation.json"));
  EXPECT_TRUE(fs::is_regular_file(root / "gated" / "summary.json"));
  EXPECT_TRUE(fs::is_regular_file(root / "cmp" / "compare.json"));
  EXPECT_TRUE(fs::is_regular_file(root / "_batch" / "joblog-simulate.tsv"));
  EXPECT_EQ(lines(root / "_batch" / "joblog-runs.tsv"), 3u) << "header + 2 jobs";
  for (const char* name : {"sim", "gated", "cmp"}) EXPECT_EQ(attempts(root, name), 1) << name;

  // Again: the job logs say everything succeeded, nothing starts.
  r = batch(manifest, root);
  ASSERT_EQ(r.status, 0) << r.output;
  for (const char* name : {"sim", "gated", "cmp"}) EXPECT_EQ(attempts(root, name), 1) << name;
  EXPECT_EQ(lines(root / "_batch" / "joblog-runs.tsv"), 3u);

  // The Slurm template by hand on a finished job: skipped.
  r = slurm_task(2, manifest, root);
  ASSERT_EQ(r.status, 0) << r.output;
  EXPECT_NE(r.output.find("job 2 'gated'"), std::string::npos) << r.output;
  EXPECT_NE(r.output.find("done already"), std::string::npos) << r.output;
  EXPECT_EQ(attempts(root, "gated"), 1);

  // Outputs removed: that job alone is redone (the job log no longer agrees with the outputs).
  fs::remove_all(root / "cmp");
  r = batch(manifest, root);
  ASSERT_EQ(r.status, 0) << r.output;
  EXPECT_TRUE(fs::is_regular_file(root / "cmp" / "compare.json"));
  EXPECT_EQ(attempts(root, "cmp"), 2);
  EXPECT_EQ(attempts(root, "gated"), 1);
  EXPECT_EQ(attempts(root, "sim"), 1);
  EXPECT_NE(r.output.find("its outputs are gone"), std::string::npos) << r.output;
}

TEST(E2eBatch, SlurmTemplateRunsOneIndexByHand) {
  const fs::path dir = testing::make_temp_dir("e2e-batch-slurm");
  const fs::path manifest = write_manifest(dir, "tiny.tsv", tiny_jobs());
  const fs::path root = dir / "out";
  Result r = slurm_task(2, manifest, root);  // the run before its dataset: a clear error
  EXPECT_NE(r.status, 0);
  EXPECT_NE(r.output.find(manifest.string() + ":5: 'gated' reads @sim, which is not rendered yet"),
            std::string::npos)
      << r.output;
  r = slurm_task(1, manifest, root);
  ASSERT_EQ(r.status, 0) << r.output;
  EXPECT_TRUE(fs::is_regular_file(root / "sim" / "simulation.json"));
  r = slurm_task(2, manifest, root);
  ASSERT_EQ(r.status, 0) << r.output;
  EXPECT_TRUE(fs::is_regular_file(root / "gated" / "summary.json"));
  r = slurm_task(4, manifest, root);
  EXPECT_EQ(r.status, 2);
  EXPECT_NE(r.output.find("job number '4': expected 1..3"), std::string::npos) << r.output;
}

TEST(E2eBatch, FailedLineIsNamedAndRetriedAlone) {
  if (!have_gnu_parallel()) GTEST_SKIP() << "GNU parallel not installed (Debian package parallel)";
  const fs::path dir = testing::make_temp_dir("e2e-batch-fail");
  const fs::path data = dir / "data";
  ASSERT_EQ(testing::run_command(testing::loopgate_binary().string() +
                                 " --log-level warn simulate --preset aliasing --frames 100 --out " +
                                 data.string()),
            0);
  const std::string set = "output.progress=off";
  const fs::path manifest = write_manifest(
      dir, "fail.tsv",
      "good\trun\t" + data.string() + "\t" + kConfig + "\t" + set + "\t--mode odometry\n" + "bad\trun\t" +
          (dir / "no-such-dataset").string() + "\t" + kConfig + "\t" + set + "\t--mode odometry\n");
  const fs::path root = dir / "out";
  Result r = batch(manifest, root);
  EXPECT_EQ(r.status, 1) << r.output;
  EXPECT_NE(r.output.find("batch: FAILED " + manifest.string() + ":4: job 2 'bad' (run): exit status 1"),
            std::string::npos)
      << r.output;
  EXPECT_NE(r.output.find("no-such-dataset"), std::string::npos) << r.output;  // the log's tail
  EXPECT_EQ(r.output.find("'good' (run): exit"), std::string::npos) << r.output;
  EXPECT_TRUE(fs::is_regular_file(root / "good" / "summary.json"));

  r = batch(manifest, root);  // retries the failed line only
  EXPECT_EQ(r.status, 1) << r.output;
  EXPECT_EQ(attempts(root, "good"), 1);
  EXPECT_EQ(attempts(root, "bad"), 2);
}

fs::path simulate_tiny(const fs::path& dir) {
  const fs::path data = dir / "data";
  EXPECT_EQ(
      testing::run_command(testing::loopgate_binary().string() +
                           " --log-level warn simulate --preset aliasing --frames 60 --out " + data.string()),
      0);
  return data;
}

// A job folder that already holds another run's outputs is refused on the first call; the second call must
// not take the first attempt's "started" marker as leave to replace them with --force.
TEST(E2eBatch, ASecondCallDoesNotForceOverAnotherRunsOutputs) {
  if (!have_gnu_parallel()) GTEST_SKIP() << "GNU parallel not installed (Debian package parallel)";
  const fs::path dir = testing::make_temp_dir("e2e-batch-foreign");
  const fs::path data = simulate_tiny(dir);
  const fs::path root = dir / "out";
  ASSERT_EQ(testing::run_command(testing::loopgate_binary().string() + " --log-level warn run --dataset " +
                                 data.string() + " --config " + kConfig +
                                 " --mode odometry --set output.progress=off --out " + (root / "r").string()),
            0);
  const std::string before = testing::read_file(root / "r" / "summary.json");
  ASSERT_FALSE(before.empty());
  const fs::path manifest = write_manifest(dir, "foreign.tsv",
                                           "r\trun\t" + data.string() + "\t" + kConfig +
                                               "\toutput.progress=off match.margin=20\t--mode odometry\n");
  for (int call = 1; call <= 2; ++call) {
    const Result r = batch(manifest, root);
    EXPECT_EQ(r.status, 1) << "call " << call << "\n" << r.output;
    EXPECT_NE(r.output.find("held files before batch first started this job"), std::string::npos)
        << "call " << call << "\n"
        << r.output;
    EXPECT_NE(r.output.find("already holds"), std::string::npos) << "call " << call << "\n" << r.output;
    EXPECT_NE(r.output.find(" --out " + (root / "r").string() + "\n"), std::string::npos)
        << "call " << call << ": the job ran without --force\n"
        << r.output;
    EXPECT_EQ(testing::read_file(root / "r" / "summary.json"), before) << "call " << call;
  }
}

// The manifest check looked at neighbours in sorted order only: 'c.x' sorts between 'c' and 'c/full'.
TEST(E2eBatch, NamesInsideAnotherJobsFolderAreRefusedWhateverTheirOrder) {
  const fs::path dir = testing::make_temp_dir("e2e-batch-nested");
  const fs::path manifest = write_manifest(dir, "nested.tsv",
                                           "c\tcompare\t/data\t-\t-\t-\n"
                                           "c.x\trun\t/data\t-\t-\t-\n"
                                           "c/full\trun\t/data\t-\t-\t-\n"
                                           "d/e/f\trun\t/data\t-\t-\t-\n"
                                           "d\trun\t/data\t-\t-\t-\n");
  Result r;
  r.status = testing::run_command(
      "/usr/bin/python3 " + (kSource / "scripts" / "batch.py").string() + " check " + manifest.string(),
      &r.output);
  EXPECT_EQ(r.status, 2) << r.output;
  const std::string m = manifest.string();
  EXPECT_NE(
      r.output.find(m + ":5: name 'c/full' lies inside the output folder of 'c' (line 3, a compare line)"),
      std::string::npos)
      << r.output;
  EXPECT_NE(r.output.find(m + ":6: name 'd/e/f' lies inside the output folder of 'd' (line 7"),
            std::string::npos)
      << r.output;
  EXPECT_EQ(r.output.find("'c.x' lies"), std::string::npos) << r.output;
}

// 'x/y' and 'x__y' shared one done marker and one log: each finished job made the other look undone.
TEST(E2eBatch, SlashAndDoubleUnderscoreNamesKeepTheirOwnMarkers) {
  if (!have_gnu_parallel()) GTEST_SKIP() << "GNU parallel not installed (Debian package parallel)";
  const fs::path dir = testing::make_temp_dir("e2e-batch-markers");
  const fs::path data = simulate_tiny(dir);
  const std::string line =
      "\trun\t" + data.string() + "\t" + kConfig + "\toutput.progress=off\t--mode odometry\n";
  const fs::path manifest = write_manifest(dir, "markers.tsv", "x/y" + line + "x__y" + line);
  const fs::path root = dir / "out";
  Result r = batch(manifest, root);
  ASSERT_EQ(r.status, 0) << r.output;
  r = batch(manifest, root);
  EXPECT_EQ(r.status, 0) << r.output;
  EXPECT_EQ(attempts(root, "x%2Fy"), 1);
  EXPECT_EQ(attempts(root, "x__y"), 1);
  EXPECT_TRUE(fs::is_regular_file(root / "_batch" / "done" / "x%2Fy.json"));
  EXPECT_TRUE(fs::is_regular_file(root / "_batch" / "done" / "x__y.json"));
}

// Two batch.sh at once on one root ran the same jobs into the same folders and wrote one job log, which
// then said "FAILED" for a job that had finished. The second is refused at once.
TEST(E2eBatch, ASecondBatchOnARootInUseIsRefused) {
  if (!have_gnu_parallel()) GTEST_SKIP() << "GNU parallel not installed (Debian package parallel)";
  const fs::path dir = testing::make_temp_dir("e2e-batch-lock");
  const fs::path manifest = write_manifest(dir, "lock.tsv", "a\trun\t/data\t-\t-\t-\n");
  const fs::path root = dir / "out";
  fs::create_directories(root / "_batch");
  std::ofstream(root / "_batch" / "lock.pid") << "4242\n";
  Result r;
  // flock(1) holds the root's lock, as a running batch.sh does, while the second batch.sh starts.
  r.status = testing::run_command("flock " + (root / "_batch" / "lock").string() + " " +
                                      (kSource / "scripts" / "batch.sh").string() + " " + manifest.string() +
                                      " --out " + root.string(),
                                  &r.output);
  EXPECT_EQ(r.status, 2) << r.output;
  EXPECT_NE(r.output.find("is in use by another batch.sh (pid 4242)"), std::string::npos) << r.output;
  EXPECT_FALSE(fs::exists(root / "_batch" / "manifest.tsv")) << "nothing prepared";
}

TEST(E2eBatch, BadManifestLinesAreNamed) {
  if (!have_gnu_parallel()) GTEST_SKIP() << "GNU parallel not installed (Debian package parallel)";
  const fs::path dir = testing::make_temp_dir("e2e-batch-manifest");
  const fs::path manifest = write_manifest(dir, "bad.tsv",
                                           "a\trun\t/data\t-\t-\n"
                                           "b\tcompute\t/data\t-\t-\t-\n"
                                           "c\trun\t@nothing\t-\t-\t--out /tmp/x\n"
                                           "d\trun\t/data\t-\tnot-a-key\t-\n"
                                           "b\trun\t/data\t-\t-\t-\n");
  const Result r = batch(manifest, dir / "out");
  EXPECT_EQ(r.status, 2) << r.output;
  const std::string m = manifest.string();
  for (const std::string& expected :
       {m + ":3: expected 6 tab-separated fields", m + ":4: command 'compute': expected one of",
        m + ":5: options: --out is not allowed here", m + ":6: set: 'not-a-key' is not section.key=value",
        m + ":7: name 'b' already used on line 4"})
    EXPECT_NE(r.output.find(expected), std::string::npos) << expected << "\n" << r.output;
  EXPECT_FALSE(fs::exists(dir / "out" / "_batch")) << "nothing run or prepared";
}

}  // namespace
}  // namespace loopgate
