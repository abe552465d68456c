// loopgate aggregate: many runs' summary.json and compare.json, found under the given folders, as one table
// (a row per run and method): DIR/aggregate.csv (every number at full precision, empty cells where a run has
// no value), DIR/aggregate.md (the same rows rounded, printed on stdout), and DIR/aggregate.png drawn by
// `scripts/plot.py aggregate DIR` (AP and time per run and method).
//
// Finding: a folder holding compare.json is one compare (a row per method it lists; its method folders are
// not read again), a folder holding summary.json is one run, any other folder is searched below (symbolic
// links are not followed). A folder that holds a run's files (frames.csv, timing.csv) but no summary.json is
// named on the console and skipped (the run stopped before writing it); an OUT argument with no summary at
// all below it is an error. A file that is not JSON, or lacks a key every summary has, or holds a value of
// the wrong type, is an error naming the file (and line, or key): the table never silently drops a run.
#include <spdlog/fmt/fmt.h>
#include <spdlog/spdlog.h>

#include <CLI/CLI.hpp>
#include <algorithm>
#include <cstdio>
#include <cstdlib>
#include <filesystem>
#include <fstream>
#include <functional>
#include <memory>
#include <nlohmann/json.hpp>
#include <optional>
#include <string>
#include <vector>

#include "app/commands.hpp"
#include "app/plot_script.hpp"
#include "app/summary_fields.hpp"
#include "core/error.hpp"
#include "io/file_guard.hpp"
#include "io/writers.hpp"
#include "pipeline/methods/method_registry.hpp"

namespace loopgate::app {

namespace {

namespace fs = std::filesystem;
using nlohmann::json;

struct AggregateOptions {
  std::vector<std::string> inputs;
  std::string out_dir;
  bool no_plots = false;
  std::string plot_script;
};

// One summary.json or compare.json found, with the label of its folder.
struct Source {
  fs::path file;
  bool compare = false;
  std::string run;  // folder_label() of its folder
};

// The label of a folder: its path relative to the OUT argument; the argument's own name when it is the
// folder, or when several arguments are given (then as a prefix, so their rows stay apart).
std::string folder_label(const fs::path& dir, const fs::path& top, const std::string& top_name, bool prefix) {
  const std::string rel = dir.lexically_relative(top).generic_string();
  if (rel.empty() || rel == ".") return top_name;
  return prefix ? top_name + "/" + rel : rel;
}

// The summaries below `dir` (see the file comment); `skipped` gets the run folders without a summary.
void find_sources(const fs::path& dir, const fs::path& top, const std::string& top_name, bool prefix,
                  std::vector<Source>& out, std::vector<fs::path>& skipped) {
  std::error_code ec;
  const std::string label = folder_label(dir, top, top_name, prefix);
  if (fs::is_regular_file(dir / "compare.json", ec)) {
    out.push_back({dir / "compare.json", true, label});
    return;
  }
  if (fs::is_regular_file(dir / "summary.json", ec)) {
    out.push_back({dir / "summary.json", false, label});
    return;
  }
  if (fs::is_regular_file(dir / "frames.csv", ec) || fs::is_regular_file(dir / "timing.csv", ec))
    skipped.push_back(dir);
  std::vector<fs::path> children;
  for (const fs::directory_entry& entry : fs::directory_iterator(dir, ec)) {
    std::error_code entry_ec;
    if (entry.is_directory(entry_ec) && !entry.is_symlink(entry_ec)) children.push_back(entry.path());
  }
  if (ec) throw DataError(dir, "cannot list the folder: " + ec.message());
  std::sort(children.begin(), children.end());
  for (const fs::path& child : children) find_sources(child, top, top_name, prefix, out, skipped);
}

// The JSON of `file`; DataError naming the file and line when it is not JSON or not an object.
json read_json(const fs::path& file) {
  require_regular_file(file, "a loopgate summary");
  std::error_code ec;
  const std::uintmax_t size = fs::file_size(file, ec);
  std::ifstream in(file, std::ios::binary);
  std::string text(ec ? 0 : static_cast<std::size_t>(size), '\0');
  if (ec || !in.read(text.data(), static_cast<std::streamsize>(text.size())))
    throw DataError(file, "cannot read the file");
  try {
    json value = json::parse(text);
    if (!value.is_object()) throw DataError(file, 1, "expected a JSON object (a loopgate summary)");
    return value;
  } catch (const json::parse_error& e) {
    const std::size_t byte = std::min<std::size_t>(e.byte, text.size());
    const std::size_t line =
        1 + static_cast<std::size_t>(std::count(text.begin(), text.begin() + byte, '\n'));
    // nlohmann's reason without its "[json.exception.parse_error.101] parse error at line L, column C: "
    // prefix
    std::string reason = e.what();
    if (const std::size_t colon = reason.find(": "); colon != std::string::npos)
      reason = reason.substr(colon + 2);
    throw DataError(file, line, "not valid JSON: " + reason);
  }
}

// The summary of one row with what messages need: its file and the key prefix inside it ("gated." in a
// compare.json).
struct Summary {
  const json& s;
  const fs::path& file;
  std::string prefix;

  std::string key(const std::vector<std::string>& path) const {
    std::string out = prefix;
    for (std::size_t k = 0; k < path.size(); ++k) out += (k ? "." : "") + path[k];
    return out;
  }
  [[noreturn]] void bad(const std::vector<std::string>& path, const std::string& expected,
                        const json* got) const {
    throw DataError(file,
                    fmt::format("key '{}': expected {}{}", key(path), expected,
                                got ? fmt::format(", got {} {}", got->type_name(), got->dump().substr(0, 40))
                                    : std::string(", absent")));
  }
  // A key every summary of this program has.
  std::string text(const std::vector<std::string>& path) const {
    const json* v = find_path(s, path);
    if (v == nullptr || !v->is_string()) bad(path, "a string", v);
    return v->get<std::string>();
  }
  double number(const std::vector<std::string>& path) const {
    const json* v = find_path(s, path);
    if (v == nullptr || !v->is_number()) bad(path, "a number", v);
    return v->get<double>();
  }
  // A key some runs have (ground truth, loop correction, ...): absent or null is no value, another type an
  // error.
  std::optional<double> optional_number(const std::vector<std::string>& path) const {
    const json* v = find_path(s, path);
    if (v == nullptr || v->is_null()) return std::nullopt;
    if (!v->is_number()) bad(path, "a number (or absent)", v);
    return v->get<double>();
  }
  std::optional<std::string> optional_text(const std::vector<std::string>& path) const {
    const json* v = find_path(s, path);
    if (v == nullptr || v->is_null()) return std::nullopt;
    if (!v->is_string()) bad(path, "a string (or absent)", v);
    return v->get<std::string>();
  }
  bool flag(const std::vector<std::string>& path) const {
    const json* v = find_path(s, path);
    if (v == nullptr) return false;
    if (!v->is_boolean()) bad(path, "true or false (or absent)", v);
    return v->get<bool>();
  }
};

// The words of a command line as provenance records it (shell-quoted where needed).
std::vector<std::string> shell_words(const std::string& line) {
  std::vector<std::string> words;
  std::string word;
  bool in_word = false, quoted = false;
  for (std::size_t k = 0; k < line.size(); ++k) {
    const char c = line[k];
    if (quoted) {
      if (c == '\'') {
        quoted = false;
      } else {
        word += c;
      }
    } else if (c == '\'') {
      quoted = in_word = true;
    } else if (c == '\\' && k + 1 < line.size()) {
      word += line[++k];
      in_word = true;
    } else if (c == ' ' || c == '\t') {
      if (in_word) words.push_back(word);
      word.clear();
      in_word = false;
    } else {
      word += c;
      in_word = true;
    }
  }
  if (in_word) words.push_back(word);
  return words;
}

// The --config FILE of the command line that made the run, or "" when none was given.
std::string config_file_of(const std::string& command_line) {
  const std::vector<std::string> words = shell_words(command_line);
  for (std::size_t k = 0; k < words.size(); ++k) {
    if (words[k] == "--config" && k + 1 < words.size()) return words[k + 1];
    if (words[k].rfind("--config=", 0) == 0) return words[k].substr(9);
  }
  return "";
}

// One row of the table: text cells, and numbers kept as numbers until formatted.
struct Row {
  std::string run, dataset, config, config_hash, method, mode, status, version;
  std::optional<double> frames, loops, loops_true, loops_false, ap, r100, r99, r95, wall_s, describe_match_ms,
      describe_match_decode_ms, realtime_factor, ate_m, ate_corrected_m;
};

// A run's row from its summary; `compare` (may be null) is the compare.json holding it, for the fields a
// compare keeps beside the summaries (loop correction, provenance).
Row make_row(const Summary& sum, const std::string& run, const std::string& compare_name,
             const json* compare) {
  Row row;
  row.run = run;
  row.mode = sum.text({"mode"});
  const std::string method = sum.text({"method"});
  const std::string standardize = sum.optional_text({"config", "standardize", "mode"}).value_or("off");
  if (!compare_name.empty()) {
    row.method = compare_name;
  } else if (const MethodEntry* m = find_method_entry(method, row.mode, standardize)) {
    row.method = m->name;
  } else {
    row.method = row.mode == "odometry" ? "odometry" : method;
  }
  row.wall_s = sum.number({"wall_s"});
  row.status = sum.flag({"failed"}) ? "failed" : sum.flag({"interrupted"}) ? "interrupted" : "ok";

  if (auto dataset = sum.optional_text({"config", "run", "dataset"}); dataset && !dataset->empty()) {
    row.dataset = *dataset;
  } else if (auto reference = sum.optional_text({"reference", "root"})) {
    row.dataset = *reference + " vs " + sum.optional_text({"query", "root"}).value_or("?");
  }
  // provenance: the summary's own; a compare.json's top level for summaries written before it had one.
  const json* provenance = find_path(sum.s, {"provenance"});
  const Summary prov_sum = provenance ? sum : Summary{compare ? *compare : sum.s, sum.file, ""};
  const std::vector<std::string> p = {"provenance"};
  const auto prov = [&](const char* key) {
    std::vector<std::string> path = p;
    path.emplace_back(key);
    return prov_sum.optional_text(path).value_or("");
  };
  row.version = prov("version");
  row.config_hash = prov("config_hash");
  row.config = config_file_of(prov("command_line"));

  row.frames = sum.optional_number({"frames_processed"});
  if (!row.frames) row.frames = sum.optional_number({"query_frames"});
  row.loops = sum.optional_number({"loops"});
  row.loops_true = sum.optional_number({"evaluation", "loop_truth", "loops_true"});
  row.loops_false = sum.optional_number({"evaluation", "loop_truth", "loops_false"});
  row.ap = sum.optional_number({"evaluation", "precision_recall", "average_precision"});
  row.r100 = sum.optional_number({"evaluation", "precision_recall", "recall_at_100"});
  row.r99 = sum.optional_number({"evaluation", "precision_recall", "recall_at_99"});
  row.r95 = sum.optional_number({"evaluation", "precision_recall", "recall_at_95"});
  row.realtime_factor = sum.optional_number({"realtime_factor"});
  if (const json* stages = find_path(sum.s, {"stages"})) {
    if (!stages->is_object()) sum.bad({"stages"}, "an object of per-stage timings", stages);
    for (const char* stage : {"describe", "match", "decode"}) {
      if (stages->contains(stage)) sum.number({"stages", stage, "total_ms"});  // a clear error if malformed
    }
    sum.optional_number({"end_of_stream_ms"});
    row.describe_match_ms = detection_ms(sum.s);
    row.describe_match_decode_ms = detection_with_decode_ms(sum.s);
  }
  if (sum.flag({"trajectory_accuracy", "available"}))
    row.ate_m = sum.optional_number({"trajectory_accuracy", "rmse_m"});
  // `run` with verify.enabled: in the summary; `compare`: in the method's "loop_correction".
  if (sum.flag({"trajectory_accuracy_corrected", "available"})) {
    row.ate_corrected_m = sum.optional_number({"trajectory_accuracy_corrected", "rmse_m"});
  } else if (sum.flag({"loop_correction", "trajectory_accuracy_corrected", "available"})) {
    row.ate_corrected_m = sum.optional_number({"loop_correction", "trajectory_accuracy_corrected", "rmse_m"});
  }
  return row;
}

std::vector<Row> rows_of(const Source& source) {
  const json doc = read_json(source.file);
  if (!source.compare) return {make_row(Summary{doc, source.file, ""}, source.run, "", nullptr)};
  const json* methods = find_path(doc, {"methods"});
  if (methods == nullptr || !methods->is_array())
    Summary{doc, source.file, ""}.bad({"methods"}, "an array of the method names the compare ran", methods);
  std::vector<Row> rows;
  for (const json& name : *methods) {
    if (!name.is_string())
      Summary{doc, source.file, ""}.bad({"methods"}, "an array of method names (strings)", &name);
    const std::string method = name.get<std::string>();
    const json* summary = find_path(doc, {method});
    if (summary == nullptr || !summary->is_object()) {
      Summary{doc, source.file, ""}.bad(
          {method}, "an object holding the summary of method '" + method + "' (listed in 'methods')",
          summary);
    }
    rows.push_back(make_row(Summary{*summary, source.file, method + "."}, source.run, method, &doc));
  }
  return rows;
}

// A column of the table: its CSV header, its Markdown header and how a row shows in it.
struct Column {
  const char* csv;
  const char* markdown;
  std::function<std::optional<double>(const Row&)> number;  // numeric columns
  std::function<std::string(const Row&)> text;              // text columns
  int decimals = 0;                                         // Markdown rounding of numbers
  bool in_markdown = true;
};

std::vector<Column> columns() {
  const auto num = [](const char* csv, const char* md, std::optional<double> Row::*field, int decimals) {
    return Column{csv, md, [field](const Row& r) { return r.*field; }, nullptr, decimals, true};
  };
  const auto txt = [](const char* csv, const char* md, std::string Row::*field, bool in_markdown = true) {
    return Column{csv, md, nullptr, [field](const Row& r) { return r.*field; }, 0, in_markdown};
  };
  return {
      txt("run", "run", &Row::run),
      txt("dataset", "dataset", &Row::dataset),
      txt("config", "config", &Row::config),
      txt("config_hash", "config hash", &Row::config_hash, false),
      txt("method", "method", &Row::method),
      txt("mode", "mode", &Row::mode),
      txt("status", "status", &Row::status),
      num("frames", "frames", &Row::frames, 0),
      num("loops", "loops", &Row::loops, 0),
      num("loops_true", "true", &Row::loops_true, 0),
      num("loops_false", "false", &Row::loops_false, 0),
      num("average_precision", "AP", &Row::ap, 3),
      num("recall_at_100", "R@P100", &Row::r100, 3),
      num("recall_at_99", "R@P99", &Row::r99, 3),
      num("recall_at_95", "R@P95", &Row::r95, 3),
      num("wall_s", "wall (s)", &Row::wall_s, 2),
      num("describe_match_ms", "describe+match (ms)", &Row::describe_match_ms, 1),
      num("describe_match_decode_ms", "with decode (ms)", &Row::describe_match_decode_ms, 1),
      num("realtime_factor", "real-time factor", &Row::realtime_factor, 1),
      num("ate_m", "ATE (m)", &Row::ate_m, 3),
      num("ate_corrected_m", "ATE corrected (m)", &Row::ate_corrected_m, 3),
      txt("version", "version", &Row::version),
  };
}

// aggregate.csv: numbers in their shortest exact form, empty cells where a run has no value.
void write_csv(const fs::path& file, const std::vector<Row>& rows) {
  const std::vector<Column> cols = columns();
  std::vector<std::string> header;
  for (const Column& c : cols) header.emplace_back(c.csv);
  CsvWriter csv(file, header);
  for (const Row& row : rows) {
    std::vector<std::string> cells;
    for (const Column& c : cols) {
      if (c.text) {
        cells.push_back(c.text(row));
      } else {
        const auto v = c.number(row);
        cells.push_back(v ? fmt::format("{}", *v) : std::string());
      }
    }
    csv.write_row(cells);
  }
  csv.close();
}

// A text file whole or absent, like every output (written under FILE.partial, then renamed).
void write_text(const fs::path& file, const std::string& text) {
  const fs::path partial = partial_path(file);
  {
    std::ofstream out(partial, std::ios::binary | std::ios::trunc);
    out << text;
    out.flush();
    if (!out) {
      std::error_code ec;
      fs::remove(partial, ec);
      throw DataError(file, "cannot write the file (disk full, or no permission?)");
    }
  }
  std::error_code ec;
  fs::rename(partial, file, ec);
  if (ec) throw DataError(file, "cannot rename " + partial.string() + ": " + ec.message());
}

// A path shown relative to the working directory when it lies below it (the table stays readable).
std::string short_path(const std::string& path) {
  if (path.empty()) return "-";
  std::error_code ec;
  const fs::path cwd = fs::current_path(ec);
  if (ec || !fs::path(path).is_absolute()) return path;
  const fs::path rel = fs::path(path).lexically_proximate(cwd);
  const std::string text = rel.generic_string();
  return text.rfind("..", 0) == 0 ? path : text;
}

std::string make_markdown(const std::vector<Row>& rows) {
  std::vector<Column> cols = columns();
  std::erase_if(cols, [](const Column& c) { return !c.in_markdown; });
  std::string out = "|";
  for (const Column& c : cols) out += fmt::format(" {} |", c.markdown);
  out += "\n|";
  for (const Column& c : cols) out += c.text ? " --- |" : " ---: |";
  out += '\n';
  for (const Row& row : rows) {
    out += "|";
    for (const Column& c : cols) {
      std::string cell;
      if (c.text) {
        cell = c.text(row);
        if (std::string(c.csv) == "dataset" || std::string(c.csv) == "config") cell = short_path(cell);
        if (cell.empty()) cell = "-";
      } else {
        const auto v = c.number(row);
        cell = v ? format_fixed(*v, c.decimals) : "-";
      }
      std::string escaped;
      for (const char ch : cell) escaped += ch == '|' ? std::string("\\|") : std::string(1, ch);
      out += " " + escaped + " |";
    }
    out += '\n';
  }
  return out;
}

// scripts/plot.py aggregate DIR; a failure is a warning (the table stands).
void write_plot(const AggregateOptions& options, const fs::path& out_dir) {
  run_plot_script(options.plot_script, {"aggregate", out_dir.string()}, "aggregate");
}

int aggregate_command(const AggregateOptions& options) {
  std::vector<Source> sources;
  std::vector<fs::path> skipped;
  // "out/x/" names itself x; "." names itself after the working directory. Two folders of one name (a/out,
  // b/out) are named by their paths as given instead, so that their rows keep apart.
  std::vector<std::string> names;
  for (const std::string& input : options.inputs) {
    const fs::path dir = input;
    std::error_code ec;
    std::string name = dir.lexically_normal().filename().string();
    if (name.empty() || name == ".") name = fs::absolute(dir, ec).lexically_normal().filename().string();
    if (name.empty()) name = fs::absolute(dir, ec).lexically_normal().parent_path().filename().string();
    names.push_back(name);
  }
  const std::vector<std::string> basenames = names;
  for (std::size_t k = 0; k < names.size(); ++k) {
    if (std::count(basenames.begin(), basenames.end(), basenames[k]) > 1) {
      std::string path = fs::path(options.inputs[k]).lexically_normal().generic_string();
      while (path.size() > 1 && path.back() == '/') path.pop_back();
      names[k] = path;
    }
  }
  for (std::size_t k = 0; k < options.inputs.size(); ++k) {
    const fs::path dir = options.inputs[k];
    std::error_code ec;
    if (!fs::is_directory(dir, ec)) {
      throw DataError(dir, fs::exists(dir, ec) ? "expected a folder of runs (or a run or compare folder)"
                                               : "no such folder");
    }
    const std::size_t before = sources.size();
    find_sources(dir, dir, names[k], options.inputs.size() > 1, sources, skipped);
    if (sources.size() == before) {
      throw DataError(dir,
                      "no summary.json or compare.json in this folder or below it (expected the --out "
                      "folder of a run or compare, or a folder holding such folders)");
    }
  }
  // Every row label names one folder: the same folder given twice (or once inside another argument) would
  // give two rows of one label.
  for (std::size_t a = 0; a < sources.size(); ++a) {
    for (std::size_t b = a + 1; b < sources.size(); ++b) {
      if (sources[a].run != sources[b].run) continue;
      std::error_code ec;
      const bool same = fs::equivalent(sources[a].file, sources[b].file, ec);
      throw DataError(sources[b].file,
                      "row label '" + sources[b].run + "' is also that of " + sources[a].file.string() +
                          (same ? " (the same file: a folder given twice, or inside another argument)" : "") +
                          ": give each folder once");
    }
  }
  for (const fs::path& dir : skipped) {
    spdlog::warn(
        "aggregate: {}: a run's files but no summary.json (the run stopped before writing it?), skipped",
        dir.string());
  }
  std::vector<Row> rows;
  for (const Source& source : sources) {
    std::vector<Row> found = rows_of(source);
    rows.insert(rows.end(), found.begin(), found.end());
  }

  const fs::path out_dir =
      options.out_dir.empty() ? fs::path(options.inputs.front()) / "aggregate" : fs::path(options.out_dir);
  const OutputLock lock(out_dir, "loopgate aggregate");
  const std::string markdown = make_markdown(rows);
  write_csv(out_dir / "aggregate.csv", rows);
  write_text(out_dir / "aggregate.md", markdown);
  std::printf("%s", markdown.c_str());
  std::printf("%zu rows from %zu summaries (%zu compare, %zu run); %s, %s\n", rows.size(), sources.size(),
              static_cast<std::size_t>(
                  std::count_if(sources.begin(), sources.end(), [](const Source& s) { return s.compare; })),
              static_cast<std::size_t>(
                  std::count_if(sources.begin(), sources.end(), [](const Source& s) { return !s.compare; })),
              (out_dir / "aggregate.csv").c_str(), (out_dir / "aggregate.md").c_str());
  if (!options.no_plots) write_plot(options, out_dir);
  std::fflush(stdout);
  return kExitOk;
}

}  // namespace

void add_aggregate_command(CLI::App& app, int& exit_code) {
  auto options = std::make_shared<AggregateOptions>();
  CLI::App* cmd = app.add_subcommand(
      "aggregate",
      "One table of many runs: reads every summary.json / compare.json under the given folders and writes "
      "aggregate.csv, aggregate.md (printed) and aggregate.png (AP and time per run and method)");
  cmd->add_option("OUT", options->inputs,
                  "run or compare folders (--out of `run` / `compare`), or folders holding them (e.g. a "
                  "batch ROOT)")
      ->required();
  cmd->add_option("--out", options->out_dir, "output folder (default: the first OUT/aggregate)");
  cmd->add_flag("--no-plots", options->no_plots, "do not call scripts/plot.py aggregate");
  cmd->add_option("--plot-script", options->plot_script,
                  "path of plot.py (default: scripts/plot.py of the installed or source tree)");
  cmd->callback([options, &exit_code] { exit_code = aggregate_command(*options); });
}

}  // namespace loopgate::app
