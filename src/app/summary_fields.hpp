// Reading the fields of loopgate's own summary.json / compare.json: shared by `compare` (its table and
// ratios) and `aggregate` (many runs' table), so both read a field the same way.
#pragma once

#include <nlohmann/json.hpp>
#include <string>
#include <vector>

namespace loopgate::app {

// The value at `path` (object keys) inside `root`, or nullptr when a key is absent or a parent is no object.
inline const nlohmann::json* find_path(const nlohmann::json& root, const std::vector<std::string>& path) {
  const nlohmann::json* node = &root;
  for (const auto& key : path) {
    if (!node->is_object() || !node->contains(key)) return nullptr;
    node = &node->at(key);
  }
  return node;
}

// The summed time of one stage (summary "stages".<stage>."total_ms"), 0 when the run had no such stage.
inline double stage_total_ms(const nlohmann::json& summary, const char* stage) {
  const auto& stages = summary.at("stages");
  return stages.contains(stage) ? stages.at(stage).at("total_ms").get<double>() : 0.0;
}

// Time of the loop-detection work, as compare shows it: describe + match of the time accounting (thread CPU
// time; images read inside describe are decode, the end-of-stream work is match; docs/architecture.md § Time
// accounting), and the same with decode. Summaries written before the accounting existed: the stages' wall
// times (describe + match + the end-of-stream step; decode as the decode stage).
inline double detection_ms(const nlohmann::json& s) {
  if (s.contains("time_accounting")) {
    const auto& a = s.at("time_accounting");
    return a.value("describe_ms", 0.0) + a.value("match_ms", 0.0);
  }
  return stage_total_ms(s, "describe") + stage_total_ms(s, "match") + s.value("end_of_stream_ms", 0.0);
}
inline double detection_with_decode_ms(const nlohmann::json& s) {
  if (s.contains("time_accounting")) return detection_ms(s) + s.at("time_accounting").value("decode_ms", 0.0);
  return detection_ms(s) + stage_total_ms(s, "decode");
}

}  // namespace loopgate::app
