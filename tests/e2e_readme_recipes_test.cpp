// The README's "Your own data" recipes, run as a user would copy them. Each recipe is the shell block after a
// `<!-- recipe NAME -->` line of README.md: one `loopgate run` command. The test renders a short drive with
// `loopgate simulate`, writes it in the recipe's layout (an EuRoC ASL folder, a KITTI sequence, a TUM-VI
// tree, a ROS1 bag with its ASL folder beside it, an image folder) at the path the recipe names (its last
// components, under a temporary folder), and runs the README's command from the repository folder with only
// the program, the dataset path and the output folder replaced. So a recipe that stops working, or a README
// that changes its command into one that does not run, fails here.
#include <gtest/gtest.h>

#include <filesystem>
#include <map>
#include <nlohmann/json.hpp>
#include <opencv2/imgcodecs.hpp>
#include <set>
#include <sstream>
#include <string>
#include <vector>

#include "bag_test_writer.hpp"
#include "dataset_layouts.hpp"
#include "io/dataset.hpp"
#include "io/trajectory_io.hpp"
#include "test_support.hpp"

namespace loopgate {
namespace {

namespace fs = std::filesystem;

// More frames than the largest margin of the configs the recipes use (configs/kitti00.yaml: 200), so that
// every recipe's run can detect.
constexpr int kFrames = 260;

struct Recipe {
  std::string name;
  std::string command;  // the block's command, its lines joined
  int line = 0;         // of the marker in README.md
};

// Every `<!-- recipe NAME -->` of README.md and the command of the ```sh block that follows it.
std::vector<Recipe> readme_recipes() {
  std::istringstream readme(testing::read_file(fs::path(LOOPGATE_SOURCE_DIR) / "README.md"));
  std::vector<Recipe> recipes;
  std::string text;
  int number = 0;
  const std::string marker = "<!-- recipe ";
  while (std::getline(readme, text)) {
    ++number;
    if (text.rfind(marker, 0) != 0) continue;
    Recipe recipe;
    recipe.line = number;
    recipe.name = text.substr(marker.size(), text.find(" -->") - marker.size());
    bool in_block = false;
    while (std::getline(readme, text)) {
      ++number;
      if (!in_block) {
        if (text.rfind("```", 0) == 0) in_block = true;
        continue;
      }
      if (text.rfind("```", 0) == 0) break;
      if (!text.empty() && text.back() == '\\') text.pop_back();  // a continued line
      recipe.command += (recipe.command.empty() ? "" : " ") + text;
    }
    recipes.push_back(recipe);
  }
  return recipes;
}

std::vector<std::string> words(const std::string& command) {
  std::istringstream in(command);
  std::vector<std::string> result;
  for (std::string word; in >> word;) result.push_back(word);
  return result;
}

// The value after `flag` in `args` (exactly one occurrence), or a test failure and "".
std::string option_value(const std::vector<std::string>& args, const std::string& flag) {
  std::string value;
  int count = 0;
  for (std::size_t k = 0; k + 1 < args.size(); ++k) {
    if (args[k] == flag) {
      value = args[k + 1];
      ++count;
    }
  }
  EXPECT_EQ(count, 1) << "expected exactly one " << flag;
  return value;
}

const Recipe& recipe(const std::string& name) {
  static const std::vector<Recipe> recipes = readme_recipes();
  for (const Recipe& r : recipes) {
    if (r.name == name) return r;
  }
  static const Recipe none;
  ADD_FAILURE() << "README.md has no '<!-- recipe " << name << " -->' followed by a ```sh block";
  return none;
}

int run_command(const std::string& command, std::string* output) {
  return testing::run_command(command, output);
}

// The short drive every recipe's dataset is written from (EuRoC ASL layout), rendered once.
const fs::path& simulated() {
  static const fs::path sim = [] {
    const fs::path dir = testing::make_temp_dir("e2e-recipes-sim") / "sim";
    std::string output;
    const int status =
        run_command(testing::loopgate_binary().string() + " --log-level warn simulate --preset demo" +
                        " --frames " + std::to_string(kFrames) + " --out " + dir.string(),
                    &output);
    EXPECT_EQ(status, 0) << output;
    return dir;
  }();
  return sim;
}

// Where the recipe's dataset goes: the README's path below `root` (a leading "~/" or "/" dropped), so that a
// bag's folder beside it and KITTI's poses folder keep the README's names.
fs::path dataset_path(const fs::path& root, const std::string& readme_path) {
  std::string relative = readme_path;
  if (relative.rfind("~/", 0) == 0) relative = relative.substr(2);
  while (!relative.empty() && relative.front() == '/') relative = relative.substr(1);
  return root / relative;
}

// Runs recipe `name` on the dataset `make` writes at the recipe's path; returns the output folder.
template <class Make>
fs::path run_recipe(const std::string& name, Make&& make) {
  const Recipe& r = recipe(name);
  if (r.command.empty()) return {};
  const std::vector<std::string> args = words(r.command);
  EXPECT_GE(args.size(), 2u);
  if (args.size() < 2) return {};
  EXPECT_EQ(args[0], "loopgate") << "README.md:" << r.line << ": " << r.command;
  EXPECT_EQ(args[1], "run") << "README.md:" << r.line << ": " << r.command;
  EXPECT_EQ(r.command.find_first_of("\"'$`|;&<>"), std::string::npos)
      << "README.md:" << r.line << ": a recipe is one plain command: " << r.command;
  const std::string readme_dataset = option_value(args, "--dataset");
  const std::string readme_out = option_value(args, "--out");
  if (readme_dataset.empty() || readme_out.empty()) return {};

  const fs::path root = testing::make_temp_dir("e2e-recipe-" + name);
  const fs::path dataset = dataset_path(root, readme_dataset);
  fs::create_directories(dataset.parent_path());
  make(dataset);
  if (::testing::Test::HasFatalFailure()) return {};
  const fs::path out = root / "out";

  // The README's words, with the program, the dataset and the output folder replaced.
  std::string command =
      "cd " + std::string(LOOPGATE_SOURCE_DIR) + " && " + testing::loopgate_binary().string();
  for (std::size_t k = 1; k < args.size(); ++k) {
    std::string word = args[k];
    if (args[k - 1] == "--dataset") word = dataset.string();
    if (args[k - 1] == "--out") word = out.string();
    command += " " + word;
  }
  std::string output;
  const int status = run_command(command, &output);
  EXPECT_EQ(status, 0) << "README.md:" << r.line << ": " << r.command << "\nran: " << command << "\n"
                       << output;
  EXPECT_TRUE(fs::exists(out / "summary.json")) << output;
  return out;
}

nlohmann::json summary(const fs::path& out) {
  return nlohmann::json::parse(testing::read_file(out / "summary.json"), nullptr, false);
}

TEST(E2eReadmeRecipes, TheReadmeHasOneRecipePerLayoutEachOneCommand) {
  const std::vector<Recipe> recipes = readme_recipes();
  std::set<std::string> names;
  for (const Recipe& r : recipes) {
    EXPECT_TRUE(names.insert(r.name).second) << "README.md:" << r.line << ": recipe '" << r.name << "' twice";
    EXPECT_FALSE(r.command.empty()) << "README.md:" << r.line << ": recipe '" << r.name << "' has no command";
  }
  EXPECT_EQ(names, (std::set<std::string>{"euroc", "kitti", "tumvi", "bag", "folder"}));
}

TEST(E2eReadmeRecipes, EurocAslFolder) {
  const fs::path out = run_recipe(
      "euroc", [](const fs::path& dataset) { fs::copy(simulated(), dataset, fs::copy_options::recursive); });
  if (out.empty()) return;
  const auto s = summary(out);
  ASSERT_TRUE(s.is_object());
  EXPECT_TRUE(s.at("dataset").at("has_ground_truth").get<bool>());
  EXPECT_TRUE(s.contains("evaluation")) << s.dump(1);
}

TEST(E2eReadmeRecipes, KittiSequence) {
  const fs::path out = run_recipe("kitti", [](const fs::path& dataset) {
    testing::make_kitti_layout(simulated(), dataset);
    // The official tree keeps the ground truth apart: dataset/sequences/NN and dataset/poses/NN.txt.
    const fs::path poses =
        dataset.parent_path().parent_path() / "poses" / (dataset.filename().string() + ".txt");
    fs::create_directories(poses.parent_path());
    fs::rename(dataset / "poses.txt", poses);
  });
  if (out.empty()) return;
  const auto s = summary(out);
  ASSERT_TRUE(s.is_object());
  EXPECT_EQ(s.at("dataset").at("layout").get<std::string>(), "kitti");
  EXPECT_TRUE(s.at("dataset").at("has_ground_truth").get<bool>());
}

TEST(E2eReadmeRecipes, TumViTree) {
  const fs::path out = run_recipe("tumvi", [](const fs::path& dataset) {
    const fs::path scratch = testing::make_temp_dir("e2e-recipe-tumvi-euroc") / "euroc";
    testing::make_tumvi_layouts(simulated(), scratch, dataset);
  });
  if (out.empty()) return;
  const auto s = summary(out);
  ASSERT_TRUE(s.is_object());
  EXPECT_TRUE(s.at("dataset").at("has_ground_truth").get<bool>());
  EXPECT_TRUE(s.at("dataset").at("has_imu").get<bool>());
}

TEST(E2eReadmeRecipes, RosBagWithItsAslFolderBeside) {
  LOOPGATE_REQUIRE_ROSBAG();
  const fs::path out = run_recipe("bag", [](const fs::path& bag_file) {
    const fs::path mav = simulated() / "mav0";
    // What a bag does not carry: the sequence's ASL folder beside it, named like it.
    const fs::path asl = bag_file.parent_path() / bag_file.stem();
    for (const char* file :
         {"cam0/sensor.yaml", "imu0/sensor.yaml", "state_groundtruth_estimate0/data.csv"}) {
      fs::create_directories((asl / "mav0" / file).parent_path());
      fs::copy_file(mav / file, asl / "mav0" / file);
    }
    // EuRoC's topics: /cam0/image_raw (mono8) and /imu0, in time order like a recording.
    const std::vector<EurocImageEntry> frames = read_euroc_camera_csv(mav / "cam0/data.csv");
    const std::vector<ImuSample> imu = read_euroc_imu(mav / "imu0/data.csv");
    testing::BagTestWriter bag(bag_file.string());
    std::size_t next_imu = 0;
    const auto write_imu_until = [&](Timestamp t_ns) {
      for (; next_imu < imu.size() && imu[next_imu].t_ns <= t_ns; ++next_imu) {
        const ImuSample& s = imu[next_imu];
        bag.imu("/imu0", s.t_ns, {s.gyro_radps.x(), s.gyro_radps.y(), s.gyro_radps.z()},
                {s.accel_mps2.x(), s.accel_mps2.y(), s.accel_mps2.z()});
      }
    };
    for (const EurocImageEntry& frame : frames) {
      write_imu_until(frame.t_ns);
      const cv::Mat image = cv::imread((mav / "cam0/data" / frame.filename).string(), cv::IMREAD_UNCHANGED);
      ASSERT_EQ(image.type(), CV_8UC1);
      ASSERT_TRUE(image.isContinuous());
      const auto width = static_cast<std::uint32_t>(image.cols);
      bag.image("/cam0/image_raw", frame.t_ns, width, static_cast<std::uint32_t>(image.rows), "mono8", width,
                std::vector<std::uint8_t>(image.data, image.data + image.total()));
    }
    write_imu_until(imu.empty() ? 0 : imu.back().t_ns);
    bag.close();
  });
  if (out.empty()) return;
  const auto s = summary(out);
  ASSERT_TRUE(s.is_object());
  EXPECT_EQ(s.at("dataset").at("layout").get<std::string>(), "rosbag");
  EXPECT_TRUE(s.at("dataset").at("has_ground_truth").get<bool>());
}

TEST(E2eReadmeRecipes, ImageFolder) {
  const fs::path out =
      run_recipe("folder", [](const fs::path& dataset) { testing::make_image_folder(simulated(), dataset); });
  if (out.empty()) return;
  const auto s = summary(out);
  ASSERT_TRUE(s.is_object());
  EXPECT_EQ(s.at("dataset").at("layout").get<std::string>(), "folder");
  EXPECT_TRUE(fs::exists(out / "loops.csv"));
}

}  // namespace
}  // namespace loopgate
