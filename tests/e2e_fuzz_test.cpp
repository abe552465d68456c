// A mutation fuzzer over the readers of every input format (GCC has no libFuzzer, so this is a small driver):
// seed inputs written here (a ROS1 bag, EuRoC / TUM-VI camera, IMU and ground-truth CSVs, KITTI poses and
// times, a Kalibr camchain, the shipped config YAMLs, a truth-pairs file, a batch manifest, a
// summary.json for `loopgate aggregate`) are mutated with a fixed seed (bit
// flips, bytes set to edge values, tokens such as "nan", "1e308", a BOM or a 20-digit number inserted, ranges
// deleted or duplicated, the file cut short) and each mutant is read by the real reader function in a forked
// child (the manifest and the summary by the programs that read them, scripts/batch.py and loopgate
// aggregate, run from the child). The property: the child exits normally (the input read, or refused with an
// exception), never by a signal, never after the time limit, and it writes nowhere but its --out: the child
// runs with its working directory, TMPDIR and HOME set to empty folders that must stay empty, and the whole
// scratch tree (the input folders included) must be as it was, except the aggregate's --out folder.
//
// In the suite it runs for LOOPGATE_FUZZ_SECONDS (default 40) split over the targets; by hand, e.g.
//   LOOPGATE_FUZZ_SECONDS=1200 LOOPGATE_FUZZ_SEED=7 build/release/e2e_fuzz_test
// Inputs that crash or hang are kept under LOOPGATE_FUZZ_FINDINGS (default: a temporary folder) and named in
// the failure.
#include <gtest/gtest.h>
#include <spdlog/spdlog.h>
#include <sys/types.h>
#include <sys/wait.h>
#include <unistd.h>

#include <chrono>
#include <csignal>
#include <cstdlib>
#include <fstream>
#include <functional>
#include <map>
#include <random>
#include <stdexcept>
#include <string>
#include <thread>
#include <vector>

#include "bag_test_writer.hpp"
#include "eval/loop_files.hpp"
#include "io/config.hpp"
#include "io/dataset.hpp"
#include "io/kalibr_calibration.hpp"
#include "io/trajectory_io.hpp"
#include "pipeline/pipeline_config.hpp"
#include "test_support.hpp"

namespace loopgate {
namespace {

namespace fs = std::filesystem;

struct Target {
  std::string name;
  std::string file;                           // the input mutated, relative to the target's folder
  std::string seed;                           // its seed bytes
  std::map<std::string, std::string> others;  // files beside it, not mutated
  std::function<void(const fs::path& dir)> read;
};

std::string read_bytes(const fs::path& file) {
  return testing::read_file(file);
}

void write_bytes(const fs::path& file, const std::string& bytes) {
  fs::create_directories(file.parent_path());
  std::ofstream(file, std::ios::binary | std::ios::trunc) << bytes;
}

// Every file under dir with its size: what a reader must leave as it is.
std::map<std::string, std::uintmax_t> listing(const fs::path& dir) {
  std::map<std::string, std::uintmax_t> out;
  for (const auto& entry : fs::recursive_directory_iterator(dir))
    out[entry.path().string()] = entry.is_regular_file() ? entry.file_size() : 0;
  return out;
}

class Mutator {
 public:
  explicit Mutator(std::uint64_t seed) : rng_(seed) {}

  std::string mutate(std::string bytes) {
    const int ops = 1 + static_cast<int>(below(4));
    for (int k = 0; k < ops; ++k) apply(bytes);
    return bytes;
  }

 private:
  std::size_t below(std::size_t n) {
    return n == 0 ? 0 : std::uniform_int_distribution<std::size_t>(0, n - 1)(rng_);
  }

  void apply(std::string& b) {
    static const std::vector<std::string> tokens = {"0",
                                                    "-1",
                                                    "nan",
                                                    "inf",
                                                    "-inf",
                                                    "1e308",
                                                    "-1e308",
                                                    "1e-320",
                                                    "99999999999999999999",
                                                    "0000000000000000001",
                                                    "4294967295",
                                                    "2147483648",
                                                    "18446744073709551616",
                                                    ",",
                                                    ",,",
                                                    "\n",
                                                    "\r\n",
                                                    "\xEF\xBB\xBF",
                                                    " ",
                                                    "\t",
                                                    ":",
                                                    "[",
                                                    "]",
                                                    "{",
                                                    "}",
                                                    "- ",
                                                    "#",
                                                    "\"",
                                                    "'",
                                                    "~",
                                                    "*a",
                                                    "&a",
                                                    "!!binary",
                                                    "1e12",
                                                    "0x80000000",
                                                    std::string(1, '\0'),
                                                    "\xFF\xFF\xFF\x7F",
                                                    "\x00\x00\x00\x80"};
    const std::size_t pos = below(b.size() + 1);
    switch (below(8)) {
      case 0:  // flip a bit
        if (!b.empty()) b[below(b.size())] ^= static_cast<char>(1 << below(8));
        break;
      case 1: {  // a byte set to an edge value
        static const unsigned char values[] = {0x00, 0x01, 0x7F, 0x80, 0xFF, '0', '9', '-', '.', 'e'};
        if (!b.empty()) b[below(b.size())] = static_cast<char>(values[below(sizeof(values))]);
        break;
      }
      case 2:
      case 3:  // a token inserted
        b.insert(pos, tokens[below(tokens.size())]);
        break;
      case 4:  // a token over the bytes there
      {
        const std::string& t = tokens[below(tokens.size())];
        b.replace(pos, std::min(t.size(), b.size() - pos), t);
        break;
      }
      case 5:  // a range deleted
        b.erase(pos, below(std::min<std::size_t>(64, b.size() - pos) + 1));
        break;
      case 6: {  // a range duplicated
        const std::size_t n = below(std::min<std::size_t>(128, b.size() - pos) + 1);
        b.insert(pos, b.substr(pos, n));
        break;
      }
      default:  // cut short
        b.resize(pos);
        break;
    }
  }

  std::mt19937_64 rng_;
};

enum class Outcome { kRead, kRefused, kCrash, kHang };

// Where a child may not write: its working directory, TMPDIR and HOME, all empty folders under sandbox.
struct Sandbox {
  fs::path cwd, tmp, home;
  explicit Sandbox(const fs::path& root) : cwd(root / "cwd"), tmp(root / "tmp"), home(root / "home") {
    for (const fs::path& p : {cwd, tmp, home}) fs::create_directories(p);
  }
  // The files found in the three folders (empty when nothing was written there).
  std::vector<std::string> written() const {
    std::vector<std::string> out;
    for (const fs::path& p : {cwd, tmp, home})
      for (const auto& entry : fs::recursive_directory_iterator(p)) out.push_back(entry.path().string());
    return out;
  }
};

// Runs read(dir) in a forked child inside the sandbox; kHang after timeout (the child is killed).
Outcome run_child(const Target& target, const fs::path& dir, const Sandbox& sandbox,
                  std::chrono::milliseconds timeout) {
  const pid_t pid = ::fork();
  if (pid == 0) {
    int code = 0;
    try {
      if (::chdir(sandbox.cwd.c_str()) != 0) ::_exit(4);
      ::setenv("TMPDIR", sandbox.tmp.c_str(), 1);
      ::setenv("HOME", sandbox.home.c_str(), 1);
      target.read(dir);
    } catch (const std::exception&) {
      code = 3;
    }
    ::_exit(code);
  }
  if (pid < 0) return Outcome::kCrash;
  const auto start = std::chrono::steady_clock::now();
  int status = 0;
  for (;;) {
    const pid_t r = ::waitpid(pid, &status, WNOHANG);
    if (r == pid) break;
    if (std::chrono::steady_clock::now() - start > timeout) {
      ::kill(pid, SIGKILL);
      ::waitpid(pid, &status, 0);
      return Outcome::kHang;
    }
    std::this_thread::sleep_for(std::chrono::microseconds(200));
  }
  if (WIFSIGNALED(status)) return Outcome::kCrash;
  if (WIFEXITED(status) && WEXITSTATUS(status) == 0) return Outcome::kRead;
  if (WIFEXITED(status) && WEXITSTATUS(status) == 3) return Outcome::kRefused;
  return Outcome::kCrash;  // any other exit: an exception that is not std::exception, or an abort path
}

const char* kCamchain = R"(cam0:
  T_cam_imu:
  - [-0.9995, 0.0296, -0.0085, 0.0475]
  - [0.0075, -0.0344, -0.9994, -0.0474]
  - [-0.0299, -0.9990, 0.0342, -0.0681]
  - [0.0, 0.0, 0.0, 1.0]
  camera_model: pinhole
  distortion_coeffs: [0.0034, 0.0007, -0.0021, 0.0002]
  distortion_model: equidistant
  intrinsics: [190.98, 190.97, 254.93, 256.90]
  resolution: [512, 512]
  rostopic: /cam0/image_raw
)";

std::string euroc_camera_csv() {
  std::string s = "#timestamp [ns],filename\n";
  for (int i = 0; i < 12; ++i) {
    const std::string t = std::to_string(1403636579763555584LL + 50000000LL * i);
    s += t + "," + t + ".png\n";
  }
  return s;
}

std::string euroc_imu_csv() {
  std::string s =
      "#timestamp [ns],w_RS_S_x [rad s^-1],w_RS_S_y [rad s^-1],w_RS_S_z [rad s^-1],a_RS_S_x [m s^-2],"
      "a_RS_S_y [m s^-2],a_RS_S_z [m s^-2]\n";
  for (int i = 0; i < 20; ++i)
    s += std::to_string(1403636579758555392LL + 5000000LL * i) + ",-0.0991,0.1418,0.0279,8.14,-0.37,-2.43\n";
  return s;
}

std::string euroc_groundtruth_csv() {
  std::string s =
      "#timestamp, p_RS_R_x [m], p_RS_R_y [m], p_RS_R_z [m], q_RS_w [], q_RS_x [], q_RS_y [], q_RS_z [], "
      "v_RS_R_x [m s^-1], v_RS_R_y [m s^-1], v_RS_R_z [m s^-1], b_w_RS_S_x [rad s^-1], b_w_RS_S_y [rad "
      "s^-1], "
      "b_w_RS_S_z [rad s^-1], b_a_RS_S_x [m s^-2], b_a_RS_S_y [m s^-2], b_a_RS_S_z [m s^-2]\n";
  for (int i = 0; i < 10; ++i) {
    s += std::to_string(1403636580838555648LL + 5000000LL * i) + "," + std::to_string(4.68 + 0.01 * i) +
         ",-1.78,0.80,0.53,-0.15,-0.82,-0.12,-0.02,0.02,0.08,-0.002,0.02,0.07,-0.01,0.11,0.09\n";
  }
  return s;
}

std::string kitti_poses() {
  std::string s;
  for (int i = 0; i < 10; ++i)
    s += "1.000000e+00 0.000000e+00 0.000000e+00 " + std::to_string(0.1 * i) +
         " 0.000000e+00 1.000000e+00 0.000000e+00 0.000000e+00 0.000000e+00 0.000000e+00 1.000000e+00 " +
         std::to_string(0.8 * i) + "\n";
  return s;
}

std::string kitti_times() {
  std::string s;
  for (int i = 0; i < 10; ++i) s += std::to_string(0.1036 * i) + "\n";
  return s;
}

// A small bag: 4 mono8 images on /cam0/image_raw and 40 IMU samples on /imu0, uncompressed chunks.
std::string seed_bag(const fs::path& dir) {
  const fs::path file = dir / "seed.bag";
  testing::BagTestWriter bag(file.string());
  for (int k = 0; k < 40; ++k) {
    bag.imu("/imu0", 1403636579763555584LL + 5000000LL * k, {0.1, -0.2, 0.3}, {9.81, 0.01 * k, -0.5});
    if (k % 10 == 0) {
      std::vector<std::uint8_t> pixels(16 * 8);
      for (std::size_t p = 0; p < pixels.size(); ++p) pixels[p] = static_cast<std::uint8_t>(p * 7 + k);
      bag.image("/cam0/image_raw", 1403636579763555584LL + 5000000LL * k, 16, 8, "mono8", 16, pixels);
    }
  }
  bag.close();
  return read_bytes(file);
}

// Runs a program (a reader that is not a function of ours: the batch manifest's Python, `loopgate aggregate`)
// on the mutant in the child: its exit statuses that mean "read" and "refused" map to those outcomes; any
// other status (a Python traceback exits 1, a signal) is a crash.
void run_program(const std::string& command, int read_status, int refused_status) {
  const int status = std::system((command + " >/dev/null 2>&1").c_str());
  if (status != -1 && WIFEXITED(status)) {
    if (WEXITSTATUS(status) == read_status) return;
    if (WEXITSTATUS(status) == refused_status) throw std::runtime_error("refused");
  }
  std::abort();
}

const char* kManifest =
    "# seed\nname\tcommand\tdataset\tconfig\tset\toptions\nsim\tsimulate\taliasing\t-\t-\t--frames 120\n"
    "gated\trun\t@sim\t-\toutput.progress=off match.margin=50\t--mode gated\n"
    "cmp/x\tcompare\t@sim\t-\t-\t--methods gated,seqslam --no-plots\n";

const char* kSummary = R"({"mode": "gated", "method": "dird", "wall_s": 2.5, "realtime_factor": 12.5,
 "frames_processed": 300, "loops": 12, "end_of_stream_ms": 5.0,
 "stages": {"describe": {"total_ms": 100.0}, "match": {"total_ms": 20.25}},
 "config": {"run": {"dataset": "/data/demo"}, "standardize": {"mode": "off"}},
 "evaluation": {"loop_truth": {"loops_true": 10, "loops_false": 2},
  "precision_recall": {"average_precision": 0.9, "recall_at_100": 0.5, "recall_at_99": 0.6, "recall_at_95": 0.7}},
 "trajectory_accuracy": {"available": true, "rmse_m": 0.72},
 "provenance": {"version": "0.1.0", "command_line": "loopgate run --out x", "config_hash": "00112233aabbccdd"}}
)";

std::vector<Target> targets(const fs::path& scratch) {
  std::vector<Target> out;
  const std::string source = LOOPGATE_SOURCE_DIR;
  const auto open_all = [](const fs::path& path) {
    OpenOptions options;
    options.strict = false;
    const auto d = open_dataset(path, options);
    for (std::size_t f = 0; f < d->frame_count(); ++f) {
      try {
        (void)d->load_image(f);
      } catch (const std::exception&) {
      }
    }
  };
  if (rosbag_support_built()) {
    out.push_back(
        {"bag", "x.bag", seed_bag(scratch), {}, [open_all](const fs::path& d) { open_all(d / "x.bag"); }});
  }
  out.push_back({"euroc-camera-csv",
                 "mav0/cam0/data.csv",
                 euroc_camera_csv(),
                 {{"mav0/imu0/data.csv", euroc_imu_csv()}},
                 [open_all](const fs::path& d) { open_all(d); }});
  out.push_back({"euroc-imu-csv", "data.csv", euroc_imu_csv(), {}, [](const fs::path& d) {
                   (void)read_euroc_imu(d / "data.csv");
                 }});
  out.push_back({"euroc-groundtruth-csv", "data.csv", euroc_groundtruth_csv(), {}, [](const fs::path& d) {
                   (void)read_euroc_groundtruth(d / "data.csv");
                 }});
  out.push_back({"tumvi-camera-csv", "data.csv", euroc_camera_csv(), {}, [](const fs::path& d) {
                   (void)read_euroc_camera_csv(d / "data.csv");
                 }});
  out.push_back(
      {"kitti-poses", "poses.txt", kitti_poses(), {{"times.txt", kitti_times()}}, [](const fs::path& d) {
         (void)read_kitti_poses(d / "poses.txt", d / "times.txt");
       }});
  out.push_back({"kitti-times", "times.txt", kitti_times(), {}, [](const fs::path& d) {
                   (void)read_kitti_times(d / "times.txt");
                 }});
  out.push_back({"kalibr-camchain", "camchain.yaml", kCamchain, {}, [](const fs::path& d) {
                   (void)read_kalibr_camchain(d / "camchain.yaml", 0);
                 }});
  for (const char* config : {"demo.yaml", "euroc-mh05.yaml"}) {
    out.push_back({std::string("config-") + config,
                   "config.yaml",
                   read_bytes(source + "/configs/" + config),
                   {},
                   [](const fs::path& d) { (void)load_config<PipelineConfig>(d / "config.yaml"); }});
  }
  out.push_back({"truth-pairs",
                 "pairs.csv",
                 "query_index0,match_index0\n40,0\n41,1\n52 3\n",
                 {},
                 [](const fs::path& d) { (void)read_truth_pairs(d / "pairs.csv", 100); }});
  // The batch manifest (scripts/batch.py check: exit 0 read, 2 a bad manifest).
  out.push_back({"batch-manifest", "manifest.tsv", kManifest, {}, [source](const fs::path& d) {
                   run_program("/usr/bin/python3 " + source + "/scripts/batch.py check " +
                                   (d / "manifest.tsv").string(),
                               0, 2);
                 }});
  // A run's summary.json read by `loopgate aggregate` (exit 0 read, 1 an error naming the file); its table
  // goes to a folder outside the input folder, which must stay as it was.
  const std::string loopgate = testing::loopgate_binary().string();
  out.push_back({"aggregate-summary", "runs/r/summary.json", kSummary, {}, [loopgate](const fs::path& d) {
                   run_program(loopgate + " --log-level off aggregate " + (d / "runs").string() + " --out " +
                                   (d.parent_path() / "aggregate-out").string() + " --no-plots",
                               0, 1);
                 }});
  return out;
}

std::uint64_t env_number(const char* name, std::uint64_t fallback) {
  const char* text = std::getenv(name);
  return text && *text ? std::strtoull(text, nullptr, 10) : fallback;
}

TEST(E2eFuzz, MutatedInputsAreReadOrRefusedNeverCrashOrHang) {
  const double seconds = static_cast<double>(env_number("LOOPGATE_FUZZ_SECONDS", 40));
  const std::uint64_t seed = env_number("LOOPGATE_FUZZ_SEED", 1);
  const char* findings_env = std::getenv("LOOPGATE_FUZZ_FINDINGS");
  const fs::path scratch = testing::make_temp_dir("fuzz");
  const fs::path findings = findings_env && *findings_env ? fs::path(findings_env) : scratch / "findings";
  spdlog::set_level(spdlog::level::off);  // the children's warnings would flood the log
  const std::vector<Target> all = targets(scratch);
  const Sandbox sandbox(scratch / "sandbox");
  const auto per_target = std::chrono::duration<double>(seconds / static_cast<double>(all.size()));
  std::size_t tried = 0, read = 0, refused = 0, crashes = 0, hangs = 0;
  std::vector<std::string> found;
  Mutator mutator(seed);
  for (const Target& target : all) {
    const fs::path dir = scratch / target.name;
    for (const auto& [name, bytes] : target.others) write_bytes(dir / name, bytes);
    write_bytes(dir / target.file, target.seed);
    // Everything in the scratch tree but the folders a run may write: findings and the aggregate's --out.
    const auto scratch_listing = [&] {
      auto all_files = listing(scratch);
      std::erase_if(all_files, [&](const auto& entry) {
        return entry.first.starts_with((scratch / "aggregate-out").string()) ||
               entry.first.starts_with(findings.string());
      });
      return all_files;
    };
    const auto before = scratch_listing();
    std::size_t n = 0;
    const auto start = std::chrono::steady_clock::now();
    while (std::chrono::steady_clock::now() - start < per_target) {
      // The seed itself first, then mutants of the seed.
      const std::string input = n == 0 ? target.seed : mutator.mutate(target.seed);
      write_bytes(dir / target.file, input);
      const Outcome outcome = run_child(target, dir, sandbox, std::chrono::milliseconds(10000));
      for (const std::string& file : sandbox.written()) {
        ADD_FAILURE() << target.name << ": input " << n << " wrote " << file << " outside its --out";
        fs::remove_all(file);
      }
      ++n;
      if (outcome == Outcome::kRead) ++read;
      if (outcome == Outcome::kRefused) ++refused;
      if (outcome == Outcome::kCrash || outcome == Outcome::kHang) {
        (outcome == Outcome::kCrash ? crashes : hangs)++;
        const fs::path kept = findings / (target.name + "-" + std::to_string(n) +
                                          (outcome == Outcome::kCrash ? ".crash" : ".hang"));
        write_bytes(kept, input);
        found.push_back(kept.string());
      }
      if (n == 1) {
        EXPECT_NE(outcome, Outcome::kCrash) << target.name << ": the seed itself";
      }
    }
    tried += n;
    write_bytes(dir / target.file, target.seed);
    EXPECT_EQ(scratch_listing(), before) << target.name << ": a reader wrote outside its --out";
    std::printf("fuzz %-24s %6zu inputs\n", target.name.c_str(), n);
  }
  std::printf(
      "fuzz: seed %llu, %zu inputs tried (%zu read, %zu refused with an error), %zu crashes, %zu hangs\n",
      static_cast<unsigned long long>(seed), tried, read, refused, crashes, hangs);
  RecordProperty("inputs", static_cast<int>(tried));
  RecordProperty("crashes", static_cast<int>(crashes));
  RecordProperty("hangs", static_cast<int>(hangs));
  EXPECT_GT(tried, all.size());
  EXPECT_EQ(crashes, 0u);
  EXPECT_EQ(hangs, 0u);
  for (const std::string& f : found) ADD_FAILURE() << "kept: " << f;
}

}  // namespace
}  // namespace loopgate
