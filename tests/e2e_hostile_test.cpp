// The hostile-input audit, end to end: the real binary on data the test generates. Nothing hangs
// (bounded parameters, FIFOs refused), nothing is lost (SIGTERM/SIGHUP like SIGINT, two-sequence runs too,
// one run per output folder, no output over an input, whole-or-absent files on a full disk), nothing is
// silently wrong (an outlier row is the row dropped, frames keep their numbers, the majority image size,
// bounded rates, duplicate YAML keys, trajectories that miss the dataset, the lenient problems shown, and
// messages that say what is wrong). Waits are on events (what the child writes), never on timers.
#include <gtest/gtest.h>
#include <signal.h>
#include <sys/stat.h>

#include <cmath>
#include <fstream>
#include <nlohmann/json.hpp>
#include <opencv2/imgcodecs.hpp>
#include <sstream>

#include "test_support.hpp"

namespace loopgate {
namespace {

namespace fs = std::filesystem;

using testing::Child;
using testing::read_csv;
using testing::read_file;

const std::string kBinary = testing::loopgate_binary().string();
const std::string kConfig = std::string(LOOPGATE_SOURCE_DIR) + "/configs/kitti00-thumbs.yaml";

std::string kitti_name(int i) {
  char name[32];
  std::snprintf(name, sizeof(name), "%06d.png", i);
  return name;
}

cv::Mat textured(int i, int width = 64, int height = 32) {
  cv::Mat image(height, width, CV_8UC1);
  for (int r = 0; r < image.rows; ++r) {
    for (int c = 0; c < image.cols; ++c)
      image.at<std::uint8_t>(r, c) = static_cast<std::uint8_t>((r * 9 + c * 5 + i) % 200);
  }
  return image;
}

// A KITTI-layout dataset: image_0/NNNNNN.png (64 x 32), times.txt (10 Hz), poses.txt (a drive along z).
fs::path make_kitti(int frames, const std::string& tag = "hostile-kitti") {
  const fs::path dir = testing::make_temp_dir(tag);
  fs::create_directories(dir / "image_0");
  std::ofstream times(dir / "times.txt");
  std::ofstream poses(dir / "poses.txt");
  for (int i = 0; i < frames; ++i) {
    cv::imwrite((dir / "image_0" / kitti_name(i)).string(), textured(i));
    times << 0.1 * i << "\n";
    poses << "1 0 0 " << 0.05 * std::sin(0.1 * i) << " 0 1 0 0 0 0 1 " << 1.0 * i << "\n";
  }
  return dir;
}

void rewrite_line(const fs::path& file, int index, const std::string& text) {
  std::istringstream in(read_file(file));
  std::string line, out;
  for (int i = 0; std::getline(in, line); ++i) out += (i == index ? text : line) + "\n";
  std::ofstream(file, std::ios::trunc) << out;
}

// Runs loopgate with `args` (under `timeout`, so that a regression that hangs fails instead).
std::string run(const std::string& args, int* status) {
  std::string output;
  *status = testing::run_command("timeout 120 " + kBinary + " " + args, &output);
  return output;
}

// The generated sequences are short: a margin they exceed (a run that cannot compare any pair fails, issue
// 14).
std::string run_args(const fs::path& dataset, const fs::path& out) {
  return "run --config " + kConfig + " --dataset " + dataset.string() + " --out " + out.string() +
         " --set match.margin=4";
}

// A CSV output is whole: every line ends with a newline and has as many cells as the header.
void expect_whole_csv(const fs::path& file) {
  const std::string text = read_file(file);
  ASSERT_FALSE(text.empty()) << file;
  EXPECT_EQ(text.back(), '\n') << file << " cut mid-line";
  std::vector<std::string> header;
  const auto rows = read_csv(file, &header);
  for (std::size_t i = 0; i < rows.size(); ++i)
    ASSERT_EQ(rows[i].size(), header.size()) << file << " row " << i << " is ragged";
}

std::vector<fs::path> partial_files(const fs::path& dir) {
  std::vector<fs::path> out;
  for (const auto& entry : fs::recursive_directory_iterator(dir))
    if (entry.path().extension() == ".partial") out.push_back(entry.path());
  return out;
}

// ---------------------------------------------------------------------------------------------- hangs

TEST(E2eHostile, HugeParametersAreRefusedWithTheirBound) {
  const fs::path dataset = make_kitti(5);
  int status = -1;
  std::string output = run(run_args(dataset, testing::make_temp_dir("hostile-nms")) +
                               " --mode full --set match.nms_half_window=2000000000",
                           &status);
  EXPECT_EQ(status, 1) << output;
  EXPECT_NE(output.find("match.nms_half_window: must be in [0, 1000] frames (got 2000000000)"),
            std::string::npos)
      << output;
}

TEST(E2eHostile, FifoInputsAreRefusedNotWaitedOn) {
  const fs::path dir = testing::make_temp_dir("hostile-fifo");
  ASSERT_EQ(::mkfifo((dir / "config.yaml").c_str(), 0600), 0);
  int status = -1;
  std::string output = run("run --config " + (dir / "config.yaml").string() + " --dataset " +
                               make_kitti(5).string() + " --out " + (dir / "out").string(),
                           &status);
  EXPECT_EQ(status, 1) << output;
  EXPECT_NE(
      output.find("config.yaml: the configuration file is a FIFO (named pipe), expected a regular file"),
      std::string::npos)
      << output;

  // EuRoC: cam0/data.csv, then imu0/data.csv as FIFOs.
  const fs::path euroc = dir / "euroc";
  fs::create_directories(euroc / "mav0/cam0/data");
  fs::create_directories(euroc / "mav0/imu0");
  {
    std::ofstream cam(euroc / "mav0/cam0/data.csv");
    cam << "#timestamp [ns],filename\n";
    for (int i = 0; i < 5; ++i) {
      const std::string name = std::to_string(1000000000 + i * 100000000) + ".png";
      cam << 1000000000 + i * 100000000 << "," << name << "\n";
      cv::imwrite((euroc / "mav0/cam0/data" / name).string(), textured(i));
    }
  }
  ASSERT_EQ(::mkfifo((euroc / "mav0/imu0/data.csv").c_str(), 0600), 0);
  output = run("run --dataset " + euroc.string() + " --mode odometry --set odometry.source=drift --out " +
                   (dir / "out2").string(),
               &status);
  EXPECT_EQ(status, 1) << output;
  EXPECT_NE(output.find("imu0/data.csv: input is a FIFO (named pipe), expected a regular file"),
            std::string::npos)
      << output;
  fs::rename(euroc / "mav0/cam0/data.csv", dir / "cam.csv");
  ASSERT_EQ(::mkfifo((euroc / "mav0/cam0/data.csv").c_str(), 0600), 0);
  output = run("run --dataset " + euroc.string() + " --out " + (dir / "out3").string(), &status);
  EXPECT_EQ(status, 1) << output;
  EXPECT_NE(output.find("cam0/data.csv: input is a FIFO (named pipe), expected a regular file"),
            std::string::npos)
      << output;

  // KITTI times.txt.
  const fs::path kitti = make_kitti(5);
  fs::remove(kitti / "times.txt");
  ASSERT_EQ(::mkfifo((kitti / "times.txt").c_str(), 0600), 0);
  output = run(run_args(kitti, dir / "out4"), &status);
  EXPECT_EQ(status, 1) << output;
  EXPECT_NE(output.find("times.txt: input is a FIFO"), std::string::npos) << output;
}

// ------------------------------------------------------------------------------------------ data lost

// SIGINT, SIGTERM and SIGHUP: the run drains, writes every output whole, and exits 128 + signal.
TEST(E2eHostile, StopSignalsDrainAndWriteEverything) {
  const fs::path dataset = make_kitti(100);  // 10 s of data, replayed in real time
  for (const auto& [signal_number, code] :
       {std::pair{SIGTERM, 143}, std::pair{SIGHUP, 129}, std::pair{SIGINT, 130}}) {
    SCOPED_TRACE(code);
    const fs::path out = testing::make_temp_dir("hostile-signal");
    Child child({kBinary, "run", "--config", kConfig, "--dataset", dataset.string(), "--out", out.string(),
                 "--rate", "1.0", "--set", "output.progress=on"});
    ASSERT_TRUE(child.wait_for_output("[run] ")) << child.output();  // a frame is through the sink
    child.send(signal_number);
    EXPECT_EQ(child.wait(), code) << child.output();
    const auto summary = nlohmann::json::parse(read_file(out / "summary.json"));
    EXPECT_TRUE(summary["interrupted"].get<bool>());
    const auto processed = summary["frames_processed"].get<std::size_t>();
    EXPECT_GT(processed, 0u);
    EXPECT_LT(processed, 100u);
    for (const char* name : {"frames.csv", "timing.csv", "loops.csv"}) expect_whole_csv(out / name);
    EXPECT_EQ(read_csv(out / "frames.csv").size(), processed);
    EXPECT_TRUE(partial_files(out).empty());
  }
}

TEST(E2eHostile, TwoSequenceRunsHandleStopSignals) {
  const fs::path root = testing::make_temp_dir("hostile-two-seq");
  for (const char* name : {"reference", "query"}) {
    fs::create_directories(root / name);
    for (int i = 0; i < 1500; ++i) cv::imwrite((root / name / kitti_name(i)).string(), textured(i));
  }
  const fs::path out = root / "out";
  Child child({kBinary, "run", "--reference", (root / "reference").string(), "--query",
               (root / "query").string(), "--out", out.string(), "--set", "eval.aligned_tolerance_frames=2"});
  // The reference is open (the stop handlers are installed before): the query is being opened or described.
  ASSERT_TRUE(child.wait_for_output("folder dataset " + (root / "reference").string())) << child.output();
  child.send(SIGTERM);
  EXPECT_EQ(child.wait(), 143) << child.output();
  const auto summary = nlohmann::json::parse(read_file(out / "summary.json"));
  EXPECT_TRUE(summary["interrupted"].get<bool>());
  expect_whole_csv(out / "loops.csv");
  if (summary["query_frames"].get<std::size_t>() > 0) expect_whole_csv(out / "frames.csv");
  EXPECT_EQ(read_csv(out / "frames.csv").size(), summary["query_frames"].get<std::size_t>());

  // A compare stopped the same way says so under its console table, and names the methods it did not run.
  Child compare({kBinary, "compare", "--no-plots", "--reference", (root / "reference").string(), "--query",
                 (root / "query").string(), "--out", (root / "cmp").string()});
  ASSERT_TRUE(compare.wait_for_output("compare: running full into")) << compare.output();
  compare.send(SIGTERM);
  EXPECT_EQ(compare.wait(), 143) << compare.output();
  EXPECT_NE(
      compare.output().find("interrupted by SIGTERM: full stopped early (its column covers the frames it "
                            "reached); not run: seqslam, std-full, dird-seqslam"),
      std::string::npos)
      << compare.output();
}

TEST(E2eHostile, ASecondRunIntoTheSameFolderFailsAtOnce) {
  const fs::path dataset = make_kitti(100);
  const fs::path out = testing::make_temp_dir("hostile-lock");
  Child first({kBinary, "run", "--config", kConfig, "--dataset", dataset.string(), "--out", out.string(),
               "--rate", "1.0", "--set", "output.progress=on"});
  ASSERT_TRUE(first.wait_for_output("[run] ")) << first.output();
  int status = -1;
  const std::string output = run(run_args(dataset, out), &status);
  EXPECT_EQ(status, 1) << output;
  EXPECT_NE(output.find("the output folder is in use by another loopgate command (pid " +
                        std::to_string(first.pid()) + ": loopgate run)"),
            std::string::npos)
      << output;
  first.send(SIGINT);
  EXPECT_EQ(first.wait(), 130) << first.output();
  const auto summary = nlohmann::json::parse(read_file(out / "summary.json"));
  expect_whole_csv(out / "frames.csv");
  EXPECT_EQ(read_csv(out / "frames.csv").size(), summary["frames_processed"].get<std::size_t>());
  EXPECT_FALSE(fs::exists(out / ".loopgate.lock"));  // released: the next run may go
  EXPECT_EQ(run(run_args(dataset, out) + " --frames 0:5 --force", &status).find("in use"), std::string::npos);
  EXPECT_EQ(status, 0);
}

// One writer per folder, nested folders too: `run --out O/full` while `compare --out O` runs is refused (it
// mixed a 300-row frames.csv with an 800-frame summary, both exiting 0).
TEST(E2eHostile, ARunInsideARunningComparesFolderIsRefused) {
  const fs::path dataset = make_kitti(100);
  const fs::path out = testing::make_temp_dir("hostile-nested");
  Child compare({kBinary, "compare", "--config", kConfig, "--dataset", dataset.string(), "--out",
                 out.string(), "--methods", "full", "--set", "run.rate=1.0", "--set", "match.margin=4",
                 "--set", "output.progress=on"});
  ASSERT_TRUE(compare.wait_for_output("[run] ")) << compare.output();
  int status = -1;
  const std::string output = run(run_args(dataset, out / "full") + " --frames 0:20", &status);
  EXPECT_EQ(status, 1) << output;
  EXPECT_NE(output.find("which another loopgate command is writing (pid " + std::to_string(compare.pid())),
            std::string::npos)
      << output;
  compare.send(SIGINT);
  compare.wait();
}

// A compare into a run's folder is refused without --force, like a run into a run's; a run --force into a
// compare's folder removes its compare.json (aggregate reported the old compare).
TEST(E2eHostile, RunAndCompareOutputsDoNotMix) {
  const fs::path dataset = make_kitti(40);
  const fs::path out = testing::make_temp_dir("hostile-mix");
  int status = -1;
  std::string output = run(run_args(dataset, out), &status);
  ASSERT_EQ(status, 0) << output;
  output = run("compare --config " + kConfig + " --dataset " + dataset.string() + " --out " + out.string() +
                   " --methods full --set match.margin=4",
               &status);
  EXPECT_EQ(status, 1) << output;
  EXPECT_NE(output.find("already holds another run's outputs (frames.csv"), std::string::npos) << output;
  output = run("compare --config " + kConfig + " --dataset " + dataset.string() + " --out " + out.string() +
                   " --methods full --set match.margin=4 --force",
               &status);
  ASSERT_EQ(status, 0) << output;
  EXPECT_TRUE(fs::exists(out / "compare.json"));
  EXPECT_FALSE(fs::exists(out / "frames.csv"));  // the run's outputs went with --force
  output = run(run_args(dataset, out), &status);
  EXPECT_EQ(status, 1) << output;
  EXPECT_NE(output.find("compare.json"), std::string::npos) << output;
  output = run(run_args(dataset, out) + " --force", &status);
  ASSERT_EQ(status, 0) << output;
  EXPECT_FALSE(fs::exists(out / "compare.json"));
  EXPECT_TRUE(fs::exists(out / "summary.json"));
}

TEST(E2eHostile, OutputsNeverOverwriteInputs) {
  const fs::path dataset = make_kitti(30);
  const fs::path out = testing::make_temp_dir("hostile-overlap");
  int status = -1;
  std::string output = run(run_args(dataset, out), &status);
  ASSERT_EQ(status, 0) << output;
  // The previous run's trajectory as this run's odometry file: refused, left as it was.
  const std::string trajectory = read_file(out / "trajectory.tum");
  output = run(run_args(dataset, out) +
                   " --set odometry.source=file --set odometry.file=" + (out / "trajectory.tum").string(),
               &status);
  EXPECT_EQ(status, 1) << output;
  EXPECT_NE(output.find("trajectory.tum is also odometry.file"), std::string::npos) << output;
  EXPECT_EQ(read_file(out / "trajectory.tum"), trajectory);

  // describe --out IMAGE and --picture IMAGES_DIR: refused before anything is written.
  const fs::path image = dataset / "image_0" / kitti_name(3);
  const std::string image_bytes = read_file(image);
  output = run("describe " + image.string() + " --out " + image.string(), &status);
  EXPECT_EQ(status, 1) << output;
  EXPECT_NE(output.find("is also an input image"), std::string::npos) << output;
  EXPECT_EQ(read_file(image), image_bytes);
  output = run("describe " + image.string() + " " + (dataset / "image_0" / kitti_name(4)).string() +
                   " --picture " + (dataset / "image_0").string(),
               &status);
  EXPECT_EQ(status, 1) << output;
  EXPECT_NE(output.find("is also an input image"), std::string::npos) << output;
  EXPECT_EQ(read_file(image), image_bytes);

  // describe DIR: says what it is.
  output = run("describe " + dataset.string(), &status);
  EXPECT_EQ(status, 1) << output;
  EXPECT_NE(output.find("the image is a directory, expected a regular file"), std::string::npos) << output;
}

// 16-bit PNGs (TUM-VI's images): describe and run read them the same way, scaled to 8 bits (v / 257).
TEST(E2eHostile, DescribeAndRunAgreeOnSixteenBitImages) {
  const fs::path dataset = make_kitti(12);
  const fs::path eight = dataset / "image_0" / kitti_name(4);
  const fs::path deep = dataset / "image_0" / kitti_name(5);
  cv::Mat image16;
  cv::imread(eight.string(), cv::IMREAD_GRAYSCALE).convertTo(image16, CV_16U, 257.0);
  ASSERT_TRUE(cv::imwrite(deep.string(), image16));
  const fs::path dir = testing::make_temp_dir("hostile-16bit-describe");
  int status = -1;
  std::string output = run("describe " + deep.string() + " --out " + (dir / "deep.csv").string(), &status);
  ASSERT_EQ(status, 0) << output;
  output = run("describe " + eight.string() + " --out " + (dir / "eight.csv").string(), &status);
  ASSERT_EQ(status, 0) << output;
  const auto descriptor = [](const std::string& csv) { return csv.substr(csv.find(',')); };
  EXPECT_EQ(descriptor(read_file(dir / "deep.csv")), descriptor(read_file(dir / "eight.csv")))
      << "the 16-bit copy of frame 4 describes like frame 4";
  const fs::path out = testing::make_temp_dir("hostile-16bit");
  output = run(run_args(dataset, out) + " --mode full --set run.decode=all", &status);
  ASSERT_EQ(status, 0) << output;
  std::vector<std::string> header;
  const auto rows = read_csv(out / "frames.csv", &header);
  EXPECT_EQ(rows.at(5).at(testing::column_index(header, "status")), "ok");
  EXPECT_EQ(rows.at(5).at(testing::column_index(header, "descriptor")), "y");
}

// A full disk (here: a file-size limit, which the program turns into a write error): every output is whole
// or absent, no temporary file is left, and the console names the missing ones.
TEST(E2eHostile, FullDiskLeavesWholeFilesAndNamesTheMissingOnes) {
  const fs::path dataset = make_kitti(80);
  const fs::path out = testing::make_temp_dir("hostile-full");
  Child child({kBinary, "run", "--config", kConfig, "--dataset", dataset.string(), "--out", out.string(),
               "--mode", "full"},
              8 * 1024);
  EXPECT_EQ(child.wait(), 1) << child.output();
  const std::string& output = child.output();
  EXPECT_NE(output.find("outputs missing from " + out.string() + ": frames.csv"), std::string::npos)
      << output;
  EXPECT_FALSE(fs::exists(out / "frames.csv"));
  for (const char* name : {"timing.csv", "loops.csv", "trajectory.tum", "summary.json"}) {
    SCOPED_TRACE(name);
    if (!fs::exists(out / name)) {
      EXPECT_NE(output.find(name), std::string::npos) << name << " missing but not named:\n" << output;
    } else if (std::string(name) == "summary.json") {
      const auto summary = nlohmann::json::parse(read_file(out / name));
      EXPECT_NE(summary["outputs_missing"].dump().find("frames.csv"), std::string::npos);
    } else if (std::string(name) != "trajectory.tum") {
      expect_whole_csv(out / name);
    } else {
      EXPECT_EQ(read_file(out / name).back(), '\n');
    }
  }
  EXPECT_TRUE(partial_files(out).empty());
}

// ------------------------------------------------------------------------------------- silently wrong

TEST(E2eHostile, OneOutlierTimestampDropsOneFrameAndFramesKeepTheirNumbers) {
  const fs::path dataset = make_kitti(60);
  rewrite_line(dataset / "times.txt", 10, "100000.0");  // a typo of 10^5 s at row 10
  const fs::path out = testing::make_temp_dir("hostile-outlier");
  int status = -1;
  const std::string output = run(run_args(dataset, out), &status);
  ASSERT_EQ(status, 0) << output;
  EXPECT_NE(output.find("frame(s) 10 are skipped"), std::string::npos) << output;
  const auto summary = nlohmann::json::parse(read_file(out / "summary.json"));
  EXPECT_EQ(summary["frames_processed"].get<int>(), 59);
  EXPECT_NE(summary["data_issues"]["dataset_issues"].dump().find("times.txt:11: time 100000.000000000 s"),
            std::string::npos);
  const auto rows = read_csv(out / "frames.csv");
  ASSERT_EQ(rows.size(), 59u);
  EXPECT_EQ(rows[9][1], "9");
  EXPECT_EQ(rows[10][1], "11");  // image 000011.png is frame 11, not frame 10
  EXPECT_EQ(rows[58][1], "59");

  // Most rows bad: a loud failure, not a run on what is left.
  for (int i = 5; i < 60; ++i) rewrite_line(dataset / "times.txt", i, "nan?");
  const std::string bad = run(run_args(dataset, testing::make_temp_dir("hostile-mostly")), &status);
  EXPECT_EQ(status, 1) << bad;
  EXPECT_NE(bad.find("55 of its 60 rows are bad"), std::string::npos) << bad;
}

TEST(E2eHostile, AnOddFirstFrameFailsAloneNotEveryOtherFrame) {
  const fs::path dataset = make_kitti(40);
  cv::imwrite((dataset / "image_0" / kitti_name(0)).string(), textured(0, 32, 16));
  const fs::path out = testing::make_temp_dir("hostile-size");
  int status = -1;
  const std::string output = run(run_args(dataset, out) + " --mode full", &status);
  ASSERT_EQ(status, 0) << output;
  const auto summary = nlohmann::json::parse(read_file(out / "summary.json"));
  EXPECT_EQ(summary["counts"]["frames_error"].get<int>(), 1);
  EXPECT_EQ(summary["descriptors_computed"].get<int>(), 39);
}

TEST(E2eHostile, MisleadingInputsGetMessagesThatSayWhatIsWrong) {
  const fs::path dataset = make_kitti(20);
  const fs::path out = testing::make_temp_dir("hostile-messages");
  int status = -1;
  std::string output = run(run_args(dataset, out) + " --frames 500:100", &status);
  EXPECT_EQ(status, 1);
  EXPECT_NE(output.find("run.frames: '500:100' is empty: A (500) must be below B (100)"), std::string::npos)
      << output;
  output = run(run_args(dataset, out) + " --frames 500:", &status);
  EXPECT_EQ(status, 1);
  EXPECT_NE(output.find("starts at frame 500, and the dataset has 20 frames (0..19)"), std::string::npos)
      << output;
  output = run(run_args(dataset, out) + " --rate 1e-300", &status);
  EXPECT_EQ(status, 1);
  EXPECT_NE(output.find("run.rate: '1e-300' is out of range"), std::string::npos) << output;
  output = run("simulate --frames -5 --out " + (out / "sim").string(), &status);
  EXPECT_NE(status, 0);
  EXPECT_NE(output.find("-5"), std::string::npos) << output;
  EXPECT_LT(output.size(), 400u) << output;  // no 300-digit bound

  // A duplicated YAML key names both lines.
  std::ofstream(out / "twice.yaml") << "match:\n  margin: 10\n  tau3: 0.1\n  margin: 20\n";
  output = run("run --config " + (out / "twice.yaml").string() + " --dataset " + dataset.string() +
                   " --out " + (out / "o").string(),
               &status);
  EXPECT_EQ(status, 1);
  EXPECT_NE(output.find("match.margin: key given twice, at " + (out / "twice.yaml").string() + ":2 and " +
                        (out / "twice.yaml").string() + ":4"),
            std::string::npos)
      << output;

  // A trajectory that misses the dataset entirely.
  std::ofstream(out / "elsewhere.tum") << "900 0 0 0 0 0 0 1\n901 0 0 1 0 0 0 1\n";
  output = run(run_args(dataset, out / "o2") +
                   " --set odometry.source=file --set odometry.file=" + (out / "elsewhere.tum").string(),
               &status);
  EXPECT_EQ(status, 1);
  EXPECT_NE(output.find("no frame within odometry.file_max_gap_s of the trajectory"), std::string::npos)
      << output;

  // Lenient problems behind a stop before summary.json: shown on the console.
  std::ofstream(dataset / "poses.txt", std::ios::trunc) << "";
  output = run(run_args(dataset, out / "o3"), &status);
  EXPECT_EQ(status, 1);
  EXPECT_NE(output.find("problem(s) found while opening"), std::string::npos) << output;
  EXPECT_NE(output.find("poses.txt: 0 poses, expected 20"), std::string::npos) << output;
}

// A 20 MB field is quoted capped into summary.json.
TEST(E2eHostile, HugeFieldsAreQuotedCapped) {
  const fs::path dataset = make_kitti(30);
  rewrite_line(dataset / "times.txt", 7, std::string(20'000'000, '9') + "x");
  const fs::path out = testing::make_temp_dir("hostile-huge");
  int status = -1;
  const std::string output = run(run_args(dataset, out), &status);
  ASSERT_EQ(status, 0) << output.substr(0, 2000);
  EXPECT_LT(output.size(), 200'000u);
  EXPECT_LT(fs::file_size(out / "summary.json"), 1'000'000u);
  EXPECT_NE(read_file(out / "summary.json").find("(20000001 bytes)"), std::string::npos);
}

// A two-sequence compare of one image against one image exited 0 with a score for every method, where a
// single-sequence run says no detection is possible. It fails before writing a method's outputs.
TEST(E2eHostile, ATwoSequenceRunOfOneFramePerSideSaysNoDetectionIsPossible) {
  const fs::path reference = make_kitti(1, "hostile-one-ref");
  const fs::path query = make_kitti(1, "hostile-one-query");
  const fs::path out = testing::make_temp_dir("hostile-one-out") / "cmp";
  int status = 0;
  std::string output = run("compare --no-plots --reference " + reference.string() + " --query " +
                               query.string() + " --out " + out.string(),
                           &status);
  EXPECT_EQ(status, 1) << output;
  EXPECT_NE(
      output.find("no detection possible: the reference has 1 frame(s) and the query 1 in the range run; "
                  "a two-sequence run needs at least 2 frames on each side"),
      std::string::npos)
      << output;
  EXPECT_FALSE(fs::exists(out / "full" / "summary.json"));
  for (const char* method : {"dird", "seqslam", "dird-seqslam"}) {
    output = run("run --method " + std::string(method) + " --reference " + reference.string() + " --query " +
                     query.string() + " --out " + (out.parent_path() / method).string(),
                 &status);
    EXPECT_EQ(status, 1) << method << "\n" << output;
    EXPECT_NE(output.find("no detection possible"), std::string::npos) << method << "\n" << output;
  }
  // Two frames a side pass the check (the boundary).
  const fs::path reference2 = make_kitti(2, "hostile-two-ref");
  output = run("run --method dird --reference " + reference2.string() + " --query " + reference2.string() +
                   " --out " + (out.parent_path() / "two").string(),
               &status);
  EXPECT_EQ(status, 0) << output;
}

// Truth pairs closer than the method's margin counted as positives that the run, which never compares such
// a pair, could never find, and nothing was said. They are left out of the evaluation with a warning.
TEST(E2eHostile, TruthPairsCloserThanTheMarginAreNamedAndLeftOut) {
  const fs::path data = make_kitti(60, "hostile-close-pairs");
  {
    std::ofstream pairs(data / "pairs.csv");
    for (int q = 40; q < 50; ++q) pairs << q << "," << q - 30 << "\n";  // findable: 30 frames apart
    for (int q = 50; q < 55; ++q) pairs << q << "," << q - 2 << "\n";   // 2 < match.margin = 4
  }
  const fs::path out = testing::make_temp_dir("hostile-close-pairs-out") / "out";
  int status = 0;
  const std::string output =
      run(run_args(data, out) + " --set eval.truth_pairs_file=" + (data / "pairs.csv").string(), &status);
  ASSERT_EQ(status, 0) << output;
  EXPECT_NE(
      output.find("eval: 5 of the 15 pairs of " + (data / "pairs.csv").string() +
                  " in the run are closer than match.margin = 4 frames (first: query 50, reference 48)"),
      std::string::npos)
      << output;
  const auto summary = nlohmann::json::parse(read_file(out / "summary.json"));
  const auto& truth = summary["evaluation"]["truth"];
  EXPECT_EQ(truth["pairs_in_run"], 15) << truth.dump();
  EXPECT_EQ(truth["pairs_closer_than_margin"], 5) << truth.dump();
  EXPECT_EQ(truth["positives"], 10) << truth.dump();
}

}  // namespace
}  // namespace loopgate
