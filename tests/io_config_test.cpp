#include <gtest/gtest.h>
#include <sys/stat.h>
#include <sys/wait.h>
#include <unistd.h>

#include <fstream>
#include <sstream>

#include "io/config.hpp"
#include "io/writers.hpp"
#include "test_support.hpp"

namespace loopgate {
namespace {

struct AlphaSection {
  bool enabled = false;
  int count = 3;
  std::int64_t seed = 7;
  double gain = 1.5;
  std::string mode = "fast";

  // The keys, in order, for loading, printing and the JSON echo (Self is AlphaSection or const AlphaSection).
  template <class Self, class V>
  static void fields(Self& self, V&& v) {
    v("enabled", self.enabled);
    v("count", self.count);
    v("seed", self.seed);
    v("gain", self.gain);
    v("mode", self.mode);
  }
  void validate() const {
    require_one_of("alpha.mode", mode, {"fast", "slow"});
    require(count >= 0, "alpha.count", ">= 0", std::to_string(count));
  }
};

struct BetaSection {
  double sigma_m = 0.25;
  // The keys, in order, for loading, printing and the JSON echo (Self is BetaSection or const BetaSection).
  template <class Self, class V>
  static void fields(Self& self, V&& v) {
    v("sigma_m", self.sigma_m);
  }
  void validate() const {}
};

struct TestConfig {
  AlphaSection alpha;
  BetaSection beta;
  // The sections, in order, for loading, printing and the JSON echo (Self is TestConfig or const TestConfig).
  template <class Self, class V>
  static void sections(Self& self, V&& v) {
    v("alpha", self.alpha);
    v("beta", self.beta);
  }
};

TestConfig from_yaml(const std::string& text, const std::vector<std::string>& overrides = {}) {
  RawConfig raw = RawConfig::from_yaml_string(text, "test.yaml");
  for (const auto& o : overrides) raw.apply_override(o);
  TestConfig config;
  apply_config(raw, config);
  return config;
}

std::string error_of(const std::string& text, const std::vector<std::string>& overrides = {}) {
  try {
    from_yaml(text, overrides);
  } catch (const ConfigError& e) {
    return e.what();
  }
  return "";
}

TEST(IoConfig, DefaultsWhenEmpty) {
  const TestConfig config = from_yaml("");
  EXPECT_FALSE(config.alpha.enabled);
  EXPECT_EQ(config.alpha.count, 3);
  EXPECT_DOUBLE_EQ(config.beta.sigma_m, 0.25);
}

TEST(IoConfig, LoadsEveryType) {
  const TestConfig config = from_yaml(
      "alpha:\n  enabled: true\n  count: 12\n  seed: 12345678901\n  gain: -2.5e-3\n  mode: slow\n"
      "beta:\n  sigma_m: 4\n");
  EXPECT_TRUE(config.alpha.enabled);
  EXPECT_EQ(config.alpha.count, 12);
  EXPECT_EQ(config.alpha.seed, 12345678901LL);
  EXPECT_DOUBLE_EQ(config.alpha.gain, -2.5e-3);
  EXPECT_EQ(config.alpha.mode, "slow");
  EXPECT_DOUBLE_EQ(config.beta.sigma_m, 4.0);
}

TEST(IoConfig, UnknownKeyIsNamedWithLine) {
  const std::string error = error_of("alpha:\n  count: 2\n  cuont: 3\n");
  EXPECT_NE(error.find("unknown key 'alpha.cuont'"), std::string::npos) << error;
  EXPECT_NE(error.find("test.yaml:3"), std::string::npos) << error;
  EXPECT_NE(error.find("count"), std::string::npos) << error;
}

TEST(IoConfig, UnknownSectionIsNamed) {
  const std::string error = error_of("gamma:\n  x: 1\n");
  EXPECT_NE(error.find("unknown section 'gamma'"), std::string::npos) << error;
  EXPECT_NE(error.find("alpha, beta"), std::string::npos) << error;
}

TEST(IoConfig, WrongTypeNamesKeyAndType) {
  std::string error = error_of("alpha:\n  count: 2.5\n");
  EXPECT_NE(error.find("alpha.count: expected an integer (int), got '2.5'"), std::string::npos) << error;
  error = error_of("beta:\n  sigma_m: abc\n");
  EXPECT_NE(error.find("beta.sigma_m: expected a finite number (double)"), std::string::npos) << error;
  error = error_of("alpha:\n  enabled: maybe\n");
  EXPECT_NE(error.find("alpha.enabled: expected a bool"), std::string::npos) << error;
  error = error_of("alpha:\n  count: [1, 2]\n");
  EXPECT_NE(error.find("alpha.count: expected a scalar"), std::string::npos) << error;
  error = error_of("alpha:\n  count: 99999999999\n");
  EXPECT_NE(error.find("alpha.count"), std::string::npos) << error;
}

TEST(IoConfig, ValidateNamesKeyAndAllowedValues) {
  const std::string error = error_of("alpha:\n  mode: medium\n");
  EXPECT_NE(error.find("alpha.mode: 'medium' is not one of fast|slow"), std::string::npos) << error;
  EXPECT_NE(error_of("alpha:\n  count: -1\n").find("alpha.count: must be >= 0"), std::string::npos);
}

TEST(IoConfig, SetOverridesYamlInOrder) {
  const TestConfig config = from_yaml(
      "alpha:\n  count: 2\n", {"alpha.count=5", "beta.sigma_m = 0.5", "alpha.count=6", "alpha.mode=slow"});
  EXPECT_EQ(config.alpha.count, 6);
  EXPECT_DOUBLE_EQ(config.beta.sigma_m, 0.5);
  EXPECT_EQ(config.alpha.mode, "slow");
}

TEST(IoConfig, SetErrors) {
  EXPECT_NE(error_of("", {"alpha.nope=1"}).find("unknown key 'alpha.nope' (--set alpha.nope=1)"),
            std::string::npos);
  EXPECT_NE(error_of("", {"alphacount=1"}).find("expected section.key=value"), std::string::npos);
  EXPECT_NE(error_of("", {"alpha.count"}).find("expected section.key=value"), std::string::npos);
  EXPECT_NE(error_of("", {"alpha.count=x"}).find("alpha.count: expected an integer"), std::string::npos);
}

TEST(IoConfig, JsonEchoAndLinesKeepTypes) {
  TestConfig config = from_yaml("alpha:\n  gain: 0.1\n");
  const nlohmann::json json = config_to_json(config);
  EXPECT_EQ(json["alpha"]["count"].get<int>(), 3);
  EXPECT_TRUE(json["alpha"]["gain"].is_number_float());
  EXPECT_DOUBLE_EQ(json["alpha"]["gain"].get<double>(), 0.1);
  EXPECT_EQ(json["alpha"]["mode"].get<std::string>(), "fast");
  EXPECT_FALSE(json["alpha"]["enabled"].get<bool>());
  const auto lines = config_to_lines(config);
  ASSERT_EQ(lines.size(), 6u);
  EXPECT_EQ(lines[3], "alpha.gain = 0.1");
  EXPECT_EQ(lines[4], "alpha.mode = 'fast'");
}

TEST(IoConfig, FileErrorsNameTheFile) {
  const auto dir = testing::make_temp_dir("config");
  EXPECT_THROW(load_config<TestConfig>(dir / "absent.yaml"), ConfigError);
  { std::ofstream(dir / "bad.yaml") << "alpha:\n  count: [1,\n"; }
  try {
    load_config<TestConfig>(dir / "bad.yaml");
    FAIL() << "expected ConfigError";
  } catch (const ConfigError& e) {
    EXPECT_NE(std::string(e.what()).find("bad.yaml"), std::string::npos) << e.what();
  }
  { std::ofstream(dir / "good.yaml") << "# comment\nbeta:\n  sigma_m: 2\n"; }
  const TestConfig config = load_config<TestConfig>(dir / "good.yaml", {"alpha.seed=9"});
  EXPECT_DOUBLE_EQ(config.beta.sigma_m, 2.0);
  EXPECT_EQ(config.alpha.seed, 9);
}

// A YAML key (or section) given twice is an error naming both lines; the last value no longer
// wins silently.
TEST(IoConfig, DuplicateKeysAreErrorsNamingBothLines) {
  const auto error = [](const std::string& text) {
    try {
      RawConfig::from_yaml_string(text, "cfg.yaml");
    } catch (const ConfigError& e) {
      return std::string(e.what());
    }
    return std::string();
  };
  EXPECT_EQ(error("alpha:\n  count: 4\n  gain: 2\n  count: 5\n"),
            "alpha.count: key given twice, at cfg.yaml:2 and cfg.yaml:4 (each key once; the last value would "
            "silently win)");
  EXPECT_NE(error("alpha:\n  count: 4\nbeta:\n  sigma_m: 1\nalpha:\n  gain: 2\n")
                .find("alpha: section given twice, at cfg.yaml:1 and cfg.yaml:5"),
            std::string::npos);
  EXPECT_EQ(error("alpha:\n  count: 4\nbeta:\n  count: 4\n"), "");  // same key, different sections
}

// A FIFO given as --config blocked open() forever.
TEST(IoConfig, ConfigFileMustBeARegularFile) {
  const auto dir = testing::make_temp_dir("config-fifo");
  ASSERT_EQ(::mkfifo((dir / "config.yaml").c_str(), 0600), 0);
  try {
    RawConfig::from_yaml_file(dir / "config.yaml");
    FAIL() << "no ConfigError";
  } catch (const ConfigError& e) {
    EXPECT_NE(
        std::string(e.what()).find("the configuration file is a FIFO (named pipe), expected a regular file"),
        std::string::npos)
        << e.what();
  }
}

// A huge value is quoted capped in the error.
TEST(IoConfig, HugeValuesAreQuotedCapped) {
  try {
    from_yaml("", {"alpha.count=" + std::string(1'000'000, '9') + "x"});
    FAIL() << "no ConfigError";
  } catch (const ConfigError& e) {
    EXPECT_LT(std::string(e.what()).size(), 400u);
    EXPECT_NE(std::string(e.what()).find("(1000001 bytes)"), std::string::npos) << e.what();
  }
}

TEST(IoWriters, CsvQuotesAndChecksWidth) {
  const auto dir = testing::make_temp_dir("writers");
  {
    CsvWriter csv(dir / "a.csv", {"x", "y"});
    csv.write_row({"1", "a,b"});
    csv.write_row({"2", "say \"hi\""});
    EXPECT_THROW(csv.write_row({"3"}), DataError);
    csv.close();
  }
  std::ifstream in(dir / "a.csv");
  std::stringstream buffer;
  buffer << in.rdbuf();
  const std::string content = buffer.str();
  EXPECT_EQ(content, "x,y\n1,\"a,b\"\n2,\"say \"\"hi\"\"\"\n");
  EXPECT_EQ(format_fixed(1.0 / 3.0, 3), "0.333");
}

// Every output is whole or absent. While written it is FILE.PID.partial; close() renames it; a writer
// destroyed without close() (an exception on the way) leaves nothing; a failed write names the file and the
// system's reason, and leaves nothing either.
TEST(IoWriters, OutputsAreWholeOrAbsent) {
  const auto dir = testing::make_temp_dir("writers-atomic");
  {
    CsvWriter csv(dir / "frames.csv", {"a", "b"});
    csv.write_row({"1", "2"});
    csv.flush();
    EXPECT_FALSE(std::filesystem::exists(dir / "frames.csv"));
    EXPECT_TRUE(std::filesystem::exists(partial_path(dir / "frames.csv")));
    csv.close();
  }
  EXPECT_TRUE(std::filesystem::exists(dir / "frames.csv"));
  EXPECT_FALSE(std::filesystem::exists(partial_path(dir / "frames.csv")));
  {
    TumWriter tum(dir / "trajectory.tum");
    tum.write(0, Eigen::Isometry3d::Identity());
  }  // destroyed without close(): abandoned
  EXPECT_FALSE(std::filesystem::exists(dir / "trajectory.tum"));
  EXPECT_FALSE(std::filesystem::exists(partial_path(dir / "trajectory.tum")));

  // A full disk: the temporary file is /dev/full, where every write fails with ENOSPC.
  std::filesystem::create_symlink("/dev/full", partial_path(dir / "loops.csv"));
  CsvWriter full;
  full.open(dir / "loops.csv", {"i", "j"});
  std::string error;
  try {
    for (int k = 0; k < 100000; ++k) full.write_row({"1", "2"});  // beyond the stream's buffer
    full.close();
  } catch (const DataError& e) {
    error = e.what();
  }
  EXPECT_NE(error.find("loops.csv: write failed: No space left on device"), std::string::npos) << error;
  full.abandon();
  EXPECT_FALSE(std::filesystem::exists(dir / "loops.csv"));
  EXPECT_FALSE(std::filesystem::is_symlink(partial_path(dir / "loops.csv")));

  write_json_file(dir / "summary.json", {{"a", "\xff\xfe not utf-8"}});  // replaced, not a lost file
  EXPECT_TRUE(std::filesystem::exists(dir / "summary.json"));
  EXPECT_FALSE(std::filesystem::exists(partial_path(dir / "summary.json")));
}

// Two processes writing one output name never share a temporary file: the name carries the process id.
TEST(IoWriters, PartialNamesAreUniquePerProcess) {
  const std::filesystem::path file = "out/frames.csv";
  EXPECT_EQ(partial_path(file), "out/frames.csv." + std::to_string(::getpid()) + ".partial");
  int fds[2];
  ASSERT_EQ(::pipe(fds), 0);
  const pid_t child = ::fork();
  ASSERT_GE(child, 0);
  if (child == 0) {
    const std::string name = partial_path(file).string();
    ::_exit(::write(fds[1], name.data(), name.size()) == static_cast<ssize_t>(name.size()) ? 0 : 1);
  }
  ::close(fds[1]);
  char buffer[256] = {};
  const ssize_t n = ::read(fds[0], buffer, sizeof(buffer) - 1);
  ::close(fds[0]);
  int status = 0;
  ::waitpid(child, &status, 0);
  ASSERT_GT(n, 0);
  EXPECT_EQ(std::string(buffer, static_cast<std::size_t>(n)),
            "out/frames.csv." + std::to_string(child) + ".partial");
  EXPECT_NE(std::string(buffer, static_cast<std::size_t>(n)), partial_path(file).string());
}

}  // namespace
}  // namespace loopgate
