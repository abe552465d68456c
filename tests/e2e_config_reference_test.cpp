// docs/configuration.md against the code: `loopgate config-reference` walks the config structs' fields() and
// prints every key with its default; the tables of docs/configuration.md must hold exactly those keys with
// those defaults (their bounds and meanings are the page's own). A key added to a config struct without a
// line in the page, a line for a key that no longer exists, or a default changed on one side only fails here,
// naming the key and the row to write.
#include <gtest/gtest.h>

#include <filesystem>
#include <map>
#include <sstream>
#include <string>
#include <vector>

#include "test_support.hpp"

namespace loopgate {
namespace {

namespace fs = std::filesystem;

struct Row {
  std::string default_text;
  int line = 0;
};

// The cells of a Markdown table row "| a | b | c |" (trimmed), or nothing when `text` is not one.
std::vector<std::string> cells(const std::string& text) {
  std::vector<std::string> result;
  if (text.size() < 2 || text.front() != '|') return result;
  std::string cell;
  for (std::size_t k = 1; k < text.size(); ++k) {
    if (text[k] == '|') {
      const auto first = cell.find_first_not_of(' ');
      const auto last = cell.find_last_not_of(' ');
      result.push_back(first == std::string::npos ? "" : cell.substr(first, last - first + 1));
      cell.clear();
    } else {
      cell += text[k];
    }
  }
  return result;
}

// Rows whose first cell is a key in backticks ("`section.key`"), by key, from `text` between the line
// `begin` and the next line starting with "<!--" (or the end). Duplicate keys are test failures.
std::map<std::string, Row> key_rows(const std::string& text, const std::string& begin,
                                    const std::string& what) {
  std::istringstream in(text);
  std::map<std::string, Row> rows;
  std::string line;
  int number = 0;
  bool inside = begin.empty();
  while (std::getline(in, line)) {
    ++number;
    if (!begin.empty() && line == begin) {
      inside = true;
      continue;
    }
    if (inside && !begin.empty() && line.rfind("<!--", 0) == 0) break;
    if (!inside) continue;
    const std::vector<std::string> c = cells(line);
    if (c.size() < 2 || c[0].size() < 3 || c[0].front() != '`' || c[0].back() != '`') continue;
    const std::string key = c[0].substr(1, c[0].size() - 2);
    if (key.find('.') == std::string::npos) continue;
    EXPECT_TRUE(rows.emplace(key, Row{c[1], number}).second)
        << what << ":" << number << ": `" << key << "` twice";
  }
  return rows;
}

// Runs `loopgate config-reference ARGS` and returns its rows.
std::map<std::string, Row> generated(const std::string& args) {
  std::string output;
  const std::string command =
      testing::loopgate_binary().string() + " config-reference " + args + " 2>/dev/null";
  const int status = testing::run_command(command, &output);
  EXPECT_EQ(status, 0) << command << "\n" << output;
  return key_rows(output, "", "config-reference " + args);
}

// What differs between the page `text` (the table below `marker`) and the code's rows: one message per key
// missing from the page, documented but unknown, or with another default.
std::vector<std::string> differences(const std::string& text, const std::string& marker,
                                     const std::map<std::string, Row>& code, const std::string& page) {
  std::vector<std::string> problems;
  const std::map<std::string, Row> docs = key_rows(text, marker, page);
  for (const auto& [key, row] : code) {
    const auto it = docs.find(key);
    if (it == docs.end()) {
      problems.push_back(page + ": key `" + key + "` is not documented below '" + marker +
                         "'; add the row  | `" + key + "` | " + row.default_text + " | BOUNDS | MEANING |");
    } else if (it->second.default_text != row.default_text) {
      problems.push_back(page + ":" + std::to_string(it->second.line) + ": `" + key + "` default " +
                         it->second.default_text + ", the code's is " + row.default_text);
    }
  }
  for (const auto& [key, row] : docs) {
    if (code.count(key) == 0) {
      problems.push_back(page + ":" + std::to_string(row.line) + ": `" + key +
                         "` is documented but the code has no such key");
    }
  }
  return problems;
}

std::string marker_for(const std::string& args) {
  return "<!-- loopgate config-reference" + (args.empty() ? "" : " " + args) + " -->";
}

std::string page_text() {
  return testing::read_file(fs::path(LOOPGATE_SOURCE_DIR) / "docs/configuration.md");
}

// Every key of the code is documented with its default, and every documented key exists.
void expect_in_sync(const std::string& args) {
  const std::string page = "docs/configuration.md";
  const std::string text = page_text();
  ASSERT_FALSE(text.empty()) << "cannot read " << LOOPGATE_SOURCE_DIR << "/" << page;
  const std::string marker = marker_for(args);
  ASSERT_NE(text.find("\n" + marker + "\n"), std::string::npos) << page << " has no line " << marker;
  const std::map<std::string, Row> code = generated(args);
  ASSERT_GT(code.size(), 20u) << "config-reference " << args << " printed too few keys";
  for (const std::string& problem : differences(text, marker, code, page)) ADD_FAILURE() << problem;
}

TEST(E2eConfigReference, EveryRunKeyIsDocumentedWithItsDefault) {
  expect_in_sync("");
}

TEST(E2eConfigReference, EverySimulationKeyIsDocumentedWithItsDefault) {
  expect_in_sync("--simulation");
}

TEST(E2eConfigReference, AMissingKeyAChangedDefaultAndAnUnknownKeyAreEachNamed) {
  // The page with run.method's row removed, run.mode's default changed and a key the code does not have.
  const std::string marker = marker_for("");
  std::string text = page_text();
  const std::map<std::string, Row> code = generated("");
  ASSERT_TRUE(code.count("run.method") == 1 && code.count("run.mode") == 1);
  std::istringstream in(text);
  std::string edited;
  for (std::string line; std::getline(in, line);) {
    if (line.rfind("| `run.method` |", 0) == 0) continue;
    if (line.rfind("| `run.mode` |", 0) == 0) line = "| `run.mode` | `sometimes` | x | y |";
    edited += line + "\n";
    if (line == marker) edited += "| `run.no_such_key` | `1` | x | y |\n";
  }
  const std::vector<std::string> problems = differences(edited, marker, code, "page");
  ASSERT_EQ(problems.size(), 3u);
  std::string all;
  for (const std::string& p : problems) all += p + "\n";
  EXPECT_NE(all.find("`run.method` is not documented"), std::string::npos) << all;
  EXPECT_NE(all.find("`run.mode` default `sometimes`"), std::string::npos) << all;
  EXPECT_NE(all.find("`run.no_such_key` is documented but the code has no such key"), std::string::npos)
      << all;
}

}  // namespace
}  // namespace loopgate
