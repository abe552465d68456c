#include "pipeline/methods/method_registry.hpp"

#include <string>

#include "core/error.hpp"
#include "io/config.hpp"

namespace loopgate {

const MethodEntry* find_method_entry(std::string_view name) {
  for (const MethodEntry& m : kMethods) {
    if (name == m.name) return &m;
  }
  return nullptr;
}

const MethodEntry* find_method_entry(std::string_view detector, std::string_view mode,
                                     std::string_view standardize) {
  if (mode == "two-sequence") mode = "full";
  const MethodEntry* loose = nullptr;
  for (const MethodEntry& m : kMethods) {
    if (enum_name(m.detector) != detector || enum_name(m.mode) != mode) continue;
    if (standardize == enum_name(m.standardize)) return &m;
    if (m.detector != Detector::kDird && loose == nullptr) loose = &m;
  }
  return loose;
}

const MethodEntry* method_entry(const PipelineConfig& config) {
  if (!config.run.method_row.empty() && config.run.detects_loops())
    return find_method_entry(config.run.method_row);
  return find_method_entry(enum_name(config.run.method), enum_name(config.run.mode),
                           enum_name(config.standardize.mode));
}

std::string method_entry_names(bool two_sequence_only) {
  std::string out;
  for (const MethodEntry& m : kMethods) {
    if (two_sequence_only && !m.two_sequence) continue;
    out += (out.empty() ? "" : ",") + std::string(m.name);
  }
  return out;
}

const MethodEntry* expand_method_name(RawConfig& raw) {
  const auto run = raw.sections().find("run");
  if (run == raw.sections().end()) return nullptr;
  const auto method = run->second.find("method");
  if (method == run->second.end()) return nullptr;
  const RawConfigValue given = method->second;
  for (const EnumName<Detector>& d : enum_names(Detector{})) {
    if (given.text == d.name) return nullptr;  // a detector word: run.mode chooses gated or full
  }
  const MethodEntry* entry = find_method_entry(given.text);
  if (entry == nullptr) {
    throw ConfigError("run.method: '" + given.text + "' (" + given.origin + ") is not one of " +
                      std::string(enum_choices(Detector{})) + " or a method " + method_entry_names());
  }
  const auto mode = run->second.find("mode");
  if (mode != run->second.end() && mode->second.origin == "--mode" &&
      mode->second.text != enum_name(entry->mode)) {
    throw ConfigError("run.method: '" + given.text + "' (" + given.origin + ") is run.mode " +
                      std::string(enum_name(entry->mode)) + ", and --mode says " + mode->second.text);
  }
  const std::string origin = given.origin + ", run.method " + given.text;
  raw.set("run", "method", std::string(enum_name(entry->detector)), origin);
  raw.set("run", "mode", std::string(enum_name(entry->mode)), origin);
  if (entry->detector == Detector::kDird)
    raw.set("standardize", "mode", std::string(enum_name(entry->standardize)), origin);
  return entry;
}

void validate_method(const PipelineConfig& config) {
  const MethodEntry* method = method_entry(config);
  if (config.gate.feedback && method != nullptr && !method->streams_loops) {
    throw ConfigError(
        "gate.feedback: run.method seqslam decides its loops at the end of the stream, so no loop exists "
        "while the gate runs: use run.method dird or dird-seqslam, or gate.feedback=false");
  }
}

PipelineConfig load_pipeline_config(const std::filesystem::path& file,
                                    const std::vector<std::string>& overrides,
                                    const std::vector<FlagValue>& flags, ConfigPaths paths) {
  RawConfig raw = file.empty() ? RawConfig{} : RawConfig::from_yaml_file(file);
  for (const auto& assignment : overrides) raw.apply_override(assignment);
  for (const FlagValue& f : flags) {
    const std::size_t dot = f.key.find('.');
    raw.set(f.key.substr(0, dot), f.key.substr(dot + 1), f.value, f.flag);
  }
  const MethodEntry* named = expand_method_name(raw);
  if (paths == ConfigPaths::kMustExist) raw.require_resolved_paths_exist();
  PipelineConfig config;
  apply_config(raw, config);
  if (named != nullptr) config.run.method_row = named->name;
  validate_method(config);
  return config;
}

}  // namespace loopgate
