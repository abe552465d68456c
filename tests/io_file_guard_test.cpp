// Guards on a command's files: inputs are regular files (a FIFO would block open() forever), no
// output is an input, and one command at a time writes into an output folder.
#include <gtest/gtest.h>
#include <sys/stat.h>
#include <sys/wait.h>
#include <unistd.h>

#include <fstream>

#include "core/error.hpp"
#include "io/file_guard.hpp"
#include "test_support.hpp"

namespace loopgate {
namespace {

namespace fs = std::filesystem;

template <class F>
std::string error_of(F&& f) {
  try {
    f();
  } catch (const std::exception& e) {
    return e.what();
  }
  return "";
}

TEST(IoFileGuard, InputsMustBeRegularFiles) {
  const fs::path dir = testing::make_temp_dir("guard-regular");
  std::ofstream(dir / "ok.csv") << "1,2\n";
  EXPECT_NO_THROW(require_regular_file(dir / "ok.csv"));
  ASSERT_EQ(::mkfifo((dir / "fifo.csv").c_str(), 0600), 0);
  const std::string fifo = error_of([&] { require_regular_file(dir / "fifo.csv", "imu0/data.csv"); });
  EXPECT_NE(fifo.find("fifo.csv: imu0/data.csv is a FIFO (named pipe), expected a regular file"),
            std::string::npos)
      << fifo;
  EXPECT_NE(error_of([&] { require_regular_file(dir); }).find("is a directory"), std::string::npos);
  EXPECT_NE(error_of([&] { require_regular_file(dir / "absent.csv"); }).find("not found"), std::string::npos);
  fs::create_symlink(dir / "ok.csv", dir / "link.csv");  // a link to a regular file is one
  EXPECT_NO_THROW(require_regular_file(dir / "link.csv"));
}

TEST(IoFileGuard, AnOutputThatIsAnInputIsRefused) {
  const fs::path dir = testing::make_temp_dir("guard-overlap");
  fs::create_directories(dir / "out");
  std::ofstream(dir / "out" / "trajectory.tum") << "0 0 0 0 0 0 0 1\n";
  fs::create_symlink(dir / "out" / "trajectory.tum", dir / "previous.tum");
  EXPECT_TRUE(same_file(dir / "out" / "trajectory.tum", dir / "out" / ".." / "out" / "trajectory.tum"));
  EXPECT_TRUE(same_file(dir / "previous.tum", dir / "out" / "trajectory.tum"));  // through the link
  EXPECT_FALSE(same_file(dir / "out" / "frames.csv", dir / "out" / "trajectory.tum"));
  const std::string error = error_of([&] {
    refuse_outputs_over_inputs({{"the output", dir / "out" / "trajectory.tum"}},
                               {{"odometry.file", dir / "previous.tum"}});
  });
  EXPECT_NE(error.find("trajectory.tum is also odometry.file"), std::string::npos) << error;
  EXPECT_NE(error.find("overwritten while it is read"), std::string::npos) << error;
  EXPECT_NO_THROW(refuse_outputs_over_inputs({{"the output", dir / "out" / "frames.csv"}},
                                             {{"odometry.file", dir / "previous.tum"}, {"--config", ""}}));
  EXPECT_TRUE(path_inside(dir / "out" / "a" / "b.csv", dir / "out"));
  EXPECT_TRUE(path_inside(dir / "out", dir / "out"));
  EXPECT_FALSE(path_inside(dir / "outer" / "b.csv", dir / "out"));
  EXPECT_FALSE(path_inside(dir, dir / "out"));
}

// One writer per folder, nested folders too: while another process holds OUT (a compare), OUT/full (its
// method folder) is refused to a second command; the process holding OUT may lock OUT/full itself.
TEST(IoFileGuard, AFolderInsideAnotherCommandsFolderIsRefused) {
  const fs::path out = testing::make_temp_dir("guard-nested") / "out";
  int ready[2], release[2];
  ASSERT_EQ(::pipe(ready), 0);
  ASSERT_EQ(::pipe(release), 0);
  const pid_t child = ::fork();
  ASSERT_GE(child, 0);
  if (child == 0) {
    int code = 0;
    try {
      const OutputLock lock(out, "loopgate compare");
      const OutputLock method(out / "full", "loopgate compare, method full");  // its own: allowed
      char c = 1;
      code = ::write(ready[1], &c, 1) == 1 ? 0 : 2;
      (void)::read(release[0], &c, 1);
    } catch (...) {
      code = 1;
    }
    ::_exit(code);
  }
  char c = 0;
  ASSERT_EQ(::read(ready[0], &c, 1), 1);
  for (const fs::path& inner : {out / "full", out / "gated" / "deeper"}) {
    const std::string error = error_of([&] { OutputLock nested(inner, "loopgate run"); });
    EXPECT_NE(error.find("which another loopgate command is writing (pid " + std::to_string(child) +
                         ": loopgate compare)"),
              std::string::npos)
        << error;
  }
  c = 1;
  ASSERT_EQ(::write(release[1], &c, 1), 1);
  int status = 0;
  ::waitpid(child, &status, 0);
  EXPECT_TRUE(WIFEXITED(status) && WEXITSTATUS(status) == 0);
  EXPECT_NO_THROW(OutputLock after(out / "full", "loopgate run"));  // released with the process
}

// The other way round: `compare --out O` while `run --out O/full` runs. The folder that holds another
// command's folder is refused, naming the inner folder and its holder, and no lock is left behind.
TEST(IoFileGuard, AFolderHoldingAnotherCommandsFolderIsRefused) {
  const fs::path out = testing::make_temp_dir("guard-outer") / "out";
  int ready[2], release[2];
  ASSERT_EQ(::pipe(ready), 0);
  ASSERT_EQ(::pipe(release), 0);
  const pid_t child = ::fork();
  ASSERT_GE(child, 0);
  if (child == 0) {
    int code = 0;
    try {
      const OutputLock run(out / "full", "loopgate run");
      char c = 1;
      code = ::write(ready[1], &c, 1) == 1 ? 0 : 2;
      (void)::read(release[0], &c, 1);
    } catch (...) {
      code = 1;
    }
    ::_exit(code);
  }
  char c = 0;
  ASSERT_EQ(::read(ready[0], &c, 1), 1);
  for (const fs::path& outer : {out, out.parent_path()}) {
    const std::string error = error_of([&] { OutputLock compare(outer, "loopgate compare"); });
    EXPECT_NE(error.find("the output folder holds " + (out / "full").string() +
                         ", which another loopgate command is writing (pid " + std::to_string(child) +
                         ": loopgate run)"),
              std::string::npos)
        << error;
    EXPECT_FALSE(fs::exists(outer / OutputLock::kFileName)) << outer;
  }
  c = 1;
  ASSERT_EQ(::write(release[1], &c, 1), 1);
  int status = 0;
  ::waitpid(child, &status, 0);
  EXPECT_TRUE(WIFEXITED(status) && WEXITSTATUS(status) == 0);
  EXPECT_NO_THROW(OutputLock after(out, "loopgate compare"));  // released with the process
}

TEST(IoFileGuard, OneCommandAtATimeInAnOutputFolder) {
  const fs::path out = testing::make_temp_dir("guard-lock") / "out";  // created by the lock
  {
    const OutputLock first(out, "loopgate run");
    EXPECT_TRUE(fs::is_regular_file(out / OutputLock::kFileName));
    // A second lock is a second open file description: refused at once, naming the holder.
    const std::string error = error_of([&] { OutputLock second(out, "loopgate compare"); });
    EXPECT_NE(error.find("in use by another loopgate command (pid "), std::string::npos) << error;
    EXPECT_NE(error.find(": loopgate run)"), std::string::npos) << error;
  }
  EXPECT_FALSE(fs::exists(out / OutputLock::kFileName));  // released and removed
  EXPECT_NO_THROW(OutputLock again(out, "loopgate run"));
  // A stale lock file (its process killed) does not block: the kernel released its lock.
  std::ofstream(out / OutputLock::kFileName) << "pid 1: loopgate run\n";
  EXPECT_NO_THROW(OutputLock after_crash(out, "loopgate run"));
}

}  // namespace
}  // namespace loopgate
