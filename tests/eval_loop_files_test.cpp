// Readers of pairs files and of the paper's authors' outputs (1-based, nan).
#include <gtest/gtest.h>

#include <cmath>
#include <fstream>
#include <optional>

#include "core/error.hpp"
#include "eval/loop_files.hpp"
#include "test_support.hpp"

namespace loopgate {
namespace {

std::filesystem::path write_file(const std::string& name, const std::string& text) {
  const auto path = testing::make_temp_dir("eval-files") / name;
  std::ofstream(path) << text;
  return path;
}

TEST(EvalLoopFiles, PairsAndOneBasedFiles) {
  const auto pairs = read_loop_pairs(write_file("p.csv", "# header\n589,18\n\n590, 19\r\n"));
  const std::vector<std::pair<std::size_t, std::size_t>> expected{{589, 18}, {590, 19}};
  EXPECT_EQ(pairs, expected);
  const auto loops = read_vio_dird_true_loops(write_file("t.csv", "# trueloop\n123,1570\n"));
  ASSERT_EQ(loops.size(), 1u);
  EXPECT_EQ(loops[0], (std::pair<std::size_t, std::size_t>{1569, 122}));
  const auto matches = read_vio_dird_seqslam_matches(write_file("m.csv", "nan,nan\n713,0.98894\n"));
  ASSERT_EQ(matches.size(), 2u);
  EXPECT_FALSE(matches[0].has_match);
  EXPECT_TRUE(matches[1].has_match);
  EXPECT_EQ(matches[1].reference, 712u);
  EXPECT_DOUBLE_EQ(matches[1].ratio, 0.98894);
  const auto det = read_vio_dird_detections(write_file("d.csv", "1,21,0.99979\n"));
  ASSERT_EQ(det.size(), 1u);
  EXPECT_EQ(det[0].query, 20u);
  EXPECT_EQ(det[0].reference, 0u);
  const auto shifted = read_vio_dird_true_loops(write_file("o.csv", "3,23\n"), 400);
  EXPECT_EQ(shifted[0], (std::pair<std::size_t, std::size_t>{422, 402}));
  const auto pos = read_vio_dird_positions(write_file("x.csv", "0,0,0\n1.5,-2,3\n"));
  ASSERT_EQ(pos.size(), 2u);
  EXPECT_EQ(pos[1], Eigen::Vector3d(1.5, -2, 3));
}

TEST(EvalLoopFiles, MalformedRowsNameFileAndLine) {
  const auto bad = write_file("bad.csv", "# c\n1,2\n3;4\n");
  try {
    read_loop_pairs(bad);
    FAIL() << "expected DataError";
  } catch (const DataError& e) {
    EXPECT_EQ(e.line(), 3u);
    EXPECT_EQ(e.file(), bad);
  }
  EXPECT_THROW(read_loop_pairs(write_file("c.csv", "1,2,3\n")), DataError);         // 3 columns
  EXPECT_THROW(read_vio_dird_true_loops(write_file("z.csv", "0,5\n")), DataError);  // 0 in a 1-based file
  EXPECT_THROW(read_loop_pairs(write_file("f.csv", "1.5,2\n")), DataError);         // not an index
  EXPECT_THROW(read_vio_dird_seqslam_matches(write_file("r.csv", "5,nan\n")), DataError);
  EXPECT_THROW(read_loop_pairs("/nonexistent/pairs.csv"), DataError);
}

// eval.truth_pairs_file: the published forms (a header, file-name columns, blanks or commas, both halves of a
// symmetric matrix), and errors naming the file and line.
TEST(EvalLoopFiles, TruthPairsInThePublishedForms) {
  const auto rtabmap = read_truth_pairs(write_file("gt.csv",
                                                   "query_index0,match_index0,query_file,match_file\n40,0,"
                                                   "images/41.jpg,images/1.jpg\n40,1,a.jpg,b.jpg\n"));
  const std::vector<std::pair<std::size_t, std::size_t>> expected{{40, 0}, {40, 1}};
  EXPECT_EQ(rtabmap.pairs, expected);
  EXPECT_EQ(rtabmap.rows, 2u);
  // Blanks, a comment, (reference, query) order and a duplicate from the other half of a symmetric matrix.
  const auto symmetric = read_truth_pairs(write_file("sym.txt", "# i j\n0 40\n40\t0\n  41 1  \n"), 84);
  const std::vector<std::pair<std::size_t, std::size_t>> once{{40, 0}, {41, 1}};
  EXPECT_EQ(symmetric.pairs, once);
  EXPECT_EQ(symmetric.rows, 3u);
}

// A UTF-8 byte-order mark before a header-less file: its first pair is a pair, not a header.
TEST(EvalLoopFiles, ByteOrderMarkBeforeTheFirstPairIsNotAHeader) {
  const auto pairs = read_truth_pairs(write_file("bom.csv",
                                                 "\xEF\xBB\xBF"
                                                 "40,0\n41,1\n"));
  const std::vector<std::pair<std::size_t, std::size_t>> expected{{40, 0}, {41, 1}};
  EXPECT_EQ(pairs.pairs, expected);
  EXPECT_EQ(pairs.rows, 2u);
  const auto with_header = read_truth_pairs(write_file("bomh.csv",
                                                       "\xEF\xBB\xBF"
                                                       "query,match\n40,0\n"));
  EXPECT_EQ(with_header.rows, 1u);
  const auto loops = read_loop_pairs(write_file("bomp.csv",
                                                "\xEF\xBB\xBF"
                                                "589,18\n"));
  ASSERT_EQ(loops.size(), 1u);
  EXPECT_EQ(loops[0], std::make_pair(std::size_t{589}, std::size_t{18}));
}

TEST(EvalLoopFiles, BadTruthPairsNameFileAndLine) {
  const auto expect_error = [](const std::string& text, std::size_t line, const std::string& message,
                               std::optional<std::size_t> frames = std::nullopt) {
    const auto file = write_file("bad.csv", text);
    try {
      read_truth_pairs(file, frames);
      FAIL() << "expected DataError for " << text;
    } catch (const DataError& e) {
      EXPECT_EQ(e.file(), file);
      EXPECT_EQ(e.line(), line) << e.what();
      EXPECT_NE(std::string(e.what()).find(message), std::string::npos) << e.what();
    }
  };
  expect_error("q,r\n1,2\n3;4\n", 3, "expected two 0-based frame numbers (query, reference)");
  expect_error("1.5,2\n", 1, "expected two 0-based frame numbers");  // not a header: a number
  expect_error("5,-1\n", 1, "expected two 0-based frame numbers");
  expect_error("7,7\n", 1, "frame 7 is paired with itself");
  expect_error("40,0\n90,3\n", 2, "frame 90 is not a frame of the dataset (its frames are numbered 0..83)",
               84);
  EXPECT_THROW(read_truth_pairs("/nonexistent/pairs.csv"), DataError);
}

TEST(EvalLoopFiles, RealFiles) {
  LOOPGATE_REQUIRE_SHARED_DATA("reference/vio-dird/seqslam_kitti00_matches.csv");
  LOOPGATE_REQUIRE_SHARED_DATA("kitti/00/loops-gt/botw_pairs.csv");
  const auto data = testing::shared_data_dir();
  const auto matches = read_vio_dird_seqslam_matches(data / "reference/vio-dird/seqslam_kitti00_matches.csv");
  ASSERT_EQ(matches.size(), 4540u);
  EXPECT_FALSE(matches[4].has_match);
  EXPECT_TRUE(matches[5].has_match);
  EXPECT_EQ(matches[5].reference, 712u);
  EXPECT_FALSE(matches[4535].has_match);
  const auto pairs = read_loop_pairs(data / "kitti/00/loops-gt/botw_pairs.csv");
  EXPECT_EQ(pairs.size(), 34648u);
  for (const auto& [q, r] : pairs) EXPECT_GT(q, r);
  EXPECT_EQ(read_truth_pairs(data / "kitti/00/loops-gt/botw_pairs.csv", 4541).pairs, pairs);
  const auto det = read_vio_dird_detections(data / "reference/vio-dird/dird_mh05_loops_margin20.csv");
  EXPECT_EQ(det.size(), 996u);
  const auto pos = read_vio_dird_positions(data / "reference/vio-dird/msckf_mh05_positions.csv");
  EXPECT_EQ(pos.size(), 2252u);
}

}  // namespace
}  // namespace loopgate
