// The configuration system: sections of typed parameters loaded from YAML, overridden from the command
// line (`--set section.key=value`), printed at start and echoed as JSON into the run summary.
//
// A section is any struct with
//   template <class Self, class V>
//   static void fields(Self& self, V&& v) {  // fields are bool, int, int64_t, double or std::string
//     v("key", self.field); ...
//   }
//   void validate() const;                   // throws ConfigError naming the key
// and a top-level configuration is any struct with
//   template <class Self, class V>
//   static void sections(Self& self, V&& v) { v("run", self.run); v("sync", self.sync); ... }
// Self is the struct or the const struct: one list of keys serves loading (non-const), printing and the JSON
// echo (const). Adding a section (e.g. DirdConfig "dird") is one member and one line in sections().
//
// YAML layout: a mapping of section name -> mapping of key -> scalar. Unknown sections or keys, values of
// the wrong type and non-scalar values throw ConfigError naming "section.key" (and file:line for YAML).
#pragma once

#include <cstdint>
#include <filesystem>
#include <map>
#include <nlohmann/json.hpp>
#include <optional>
#include <string>
#include <string_view>
#include <type_traits>
#include <vector>

#include "core/enum_names.hpp"
#include "core/error.hpp"
#include "core/validate.hpp"  // require / require_one_of for validate(), re-exported here

namespace loopgate {

// One raw (still textual) value and where it came from ("FILE:LINE" or "--set").
struct RawConfigValue {
  std::string text;
  std::string origin;
  // A path key (config_path_keys()) read from a YAML file with a relative value: the value as written; `text`
  // then holds it resolved beside that file. Empty for values from the command line (--set, --dataset),
  // which stay relative to the working directory.
  std::string written;
};

// The keys that hold a file or folder path: in a YAML file a relative one is relative to the file's folder.
const std::vector<std::string>& config_path_keys();

// Raw values by section and key, before they are given types.
class RawConfig {
 public:
  // Parses a YAML file. Throws ConfigError (file name, line) for unreadable files, bad YAML, a top level
  // that is not a mapping of mappings, or non-scalar values.
  static RawConfig from_yaml_file(const std::filesystem::path& file);
  static RawConfig from_yaml_string(const std::string& text, const std::string& origin = "<string>");

  // Applies "section.key=value" (throws ConfigError when the form is wrong).
  void apply_override(const std::string& assignment);
  void set(const std::string& section, const std::string& key, const std::string& value,
           const std::string& origin);

  const std::map<std::string, std::map<std::string, RawConfigValue>>& sections() const { return sections_; }

  // Throws ConfigError for a path key resolved beside its YAML file (RawConfigValue::written) that names
  // nothing there: the key, the file and line, the value as written and the resolved path. A key read only
  // when another holds a given word (odometry.file: odometry.source file) is checked only then.
  void require_resolved_paths_exist() const;

 private:
  const RawConfigValue* find(const std::string& name) const;  // "section.key"; nullptr when absent

  std::map<std::string, std::map<std::string, RawConfigValue>> sections_;
};

// The value of the enum E named `name`, or nullopt when it is not one of the words of its table (for a word
// read outside the configuration, e.g. a command-line option checked against the same words).
template <class E>
requires std::is_enum_v<E> std::optional<E> enum_value(std::string_view name) {
  for (const EnumName<E>& n : enum_names(E{}))
    if (n.name == name) return n.value;
  return std::nullopt;
}

namespace config_detail {

// Conversions from text with the expected type named in errors ("bool", "int", "int64", "double", "string").
bool parse_bool(const std::string& name, const RawConfigValue& value);
int parse_int(const std::string& name, const RawConfigValue& value);
std::int64_t parse_int64(const std::string& name, const RawConfigValue& value);
double parse_double(const std::string& name, const RawConfigValue& value);
[[noreturn]] void throw_unknown(const std::string& what, const std::string& name, const std::string& origin,
                                const std::vector<std::string>& allowed);
// "NAME: 'TEXT' is not one of a|b|c (ORIGIN)".
[[noreturn]] void throw_bad_word(const std::string& name, const RawConfigValue& value,
                                 const std::string& choices);

template <class T>
void assign(const std::string& name, const RawConfigValue& value, T& field) {
  if constexpr (std::is_same_v<T, bool>) {
    field = parse_bool(name, value);
  } else if constexpr (std::is_same_v<T, int>) {
    field = parse_int(name, value);
  } else if constexpr (std::is_same_v<T, std::int64_t>) {
    field = parse_int64(name, value);
  } else if constexpr (std::is_same_v<T, double>) {
    field = parse_double(name, value);
  } else if constexpr (std::is_same_v<T, std::string>) {
    field = value.text;
  } else if constexpr (std::is_enum_v<T>) {
    for (const EnumName<T>& n : enum_names(field)) {
      if (n.name == value.text) {
        field = n.value;
        return;
      }
    }
    throw_bad_word(name, value, enum_choices(field));
  } else {
    static_assert(sizeof(T) == 0, "config fields are bool, int, int64_t, double, std::string or an enum");
  }
}

// Text form used when printing (doubles in shortest round-trip form).
std::string format_value(bool value);
std::string format_value(int value);
std::string format_value(std::int64_t value);
std::string format_value(double value);
std::string format_value(const std::string& value);
template <class E>
requires std::is_enum_v<E> std::string format_value(E value) {
  return std::string(enum_name(value));
}
// The JSON echo of a field (an enum as its name).
template <class T>
nlohmann::json json_value(const T& value) {
  if constexpr (std::is_enum_v<T>) {
    return std::string(enum_name(value));
  } else {
    return value;
  }
}

}  // namespace config_detail

// Applies the raw values of one section to `section` (keys must exist in its fields()).
template <class Section>
void apply_section(const std::string& section_name, const std::map<std::string, RawConfigValue>& values,
                   Section& section) {
  for (const auto& [key, value] : values) {
    bool found = false;
    std::vector<std::string> keys;
    std::remove_cvref_t<Section>::fields(section, [&](std::string_view field_key, auto& field) {
      keys.emplace_back(field_key);
      if (field_key == key) {
        config_detail::assign(section_name + "." + key, value, field);
        found = true;
      }
    });
    if (!found) config_detail::throw_unknown("key", section_name + "." + key, value.origin, keys);
  }
}

namespace config_detail {
// Rethrows `error` (from a validate()) with the origin of the key it names ("section.key: ..."), when that
// key was set in `raw`: "... (FILE:LINE)" or "... (--set ...)". Errors about a default or about several keys
// are rethrown as they are.
[[noreturn]] void rethrow_with_origin(const RawConfig& raw, const ConfigError& error);
}  // namespace config_detail

// Applies every raw value to `config` (a struct with sections()), then validates it once: config.validate()
// when the configuration has one (every section and the rules between sections), else every section's
// validate(). A validation error names where the key it names was set (file:line, --set, a flag).
template <class Config>
void apply_config(const RawConfig& raw, Config& config) {
  for (const auto& [section_name, values] : raw.sections()) {
    bool found = false;
    std::vector<std::string> names;
    Config::sections(config, [&](std::string_view name, auto& section) {
      names.emplace_back(name);
      if (name == section_name) {
        apply_section(section_name, values, section);
        found = true;
      }
    });
    if (!found) {
      const std::string origin = values.empty() ? std::string{} : values.begin()->second.origin;
      config_detail::throw_unknown("section", section_name, origin, names);
    }
  }
  try {
    if constexpr (requires { config.validate(); }) {
      config.validate();
    } else {
      Config::sections(config, [](std::string_view, const auto& section) { section.validate(); });
    }
  } catch (const ConfigError& e) {
    config_detail::rethrow_with_origin(raw, e);
  }
}

// A command-line flag that sets one config key ("run.mode" from --mode): parsed by the same typed parser as
// YAML and --set, and named in errors ("run.mode: 'x' is not one of gated|full|odometry (--mode)").
struct FlagValue {
  std::string key;  // "section.key"
  std::string value;
  std::string flag;  // "--mode"
};

// Whether load_config() requires the paths a YAML file names (config_path_keys()) to exist: the commands that
// use them do (an error naming the key, file and line); reading a shipped config for its values does not.
enum class ConfigPaths { kAsWritten, kMustExist };

// Loads `file` (when not empty), applies the --set overrides in order, then the flags, validates (once).
template <class Config>
Config load_config(const std::filesystem::path& file, const std::vector<std::string>& overrides = {},
                   const std::vector<FlagValue>& flags = {}, ConfigPaths paths = ConfigPaths::kAsWritten) {
  RawConfig raw = file.empty() ? RawConfig{} : RawConfig::from_yaml_file(file);
  for (const auto& assignment : overrides) raw.apply_override(assignment);
  for (const FlagValue& f : flags) {
    const std::size_t dot = f.key.find('.');
    raw.set(f.key.substr(0, dot), f.key.substr(dot + 1), f.value, f.flag);
  }
  if (paths == ConfigPaths::kMustExist) raw.require_resolved_paths_exist();
  Config config;
  apply_config(raw, config);
  return config;
}

// {"section": {"key": value, ...}, ...} with JSON types matching the fields.
template <class Config>
nlohmann::json config_to_json(const Config& config) {
  nlohmann::json json = nlohmann::json::object();
  Config::sections(config, [&](std::string_view name, const auto& section) {
    nlohmann::json& out = json[std::string(name)];
    out = nlohmann::json::object();
    std::remove_cvref_t<decltype(section)>::fields(section, [&](std::string_view key, const auto& field) {
      out[std::string(key)] = config_detail::json_value(field);
    });
  });
  return json;
}

// "section.key = value" lines, one per parameter, in the order of sections() and fields().
template <class Config>
std::vector<std::string> config_to_lines(const Config& config) {
  std::vector<std::string> lines;
  Config::sections(config, [&](std::string_view name, const auto& section) {
    std::remove_cvref_t<decltype(section)>::fields(section, [&](std::string_view key, const auto& field) {
      lines.push_back(std::string(name) + "." + std::string(key) + " = " +
                      config_detail::format_value(field));
    });
  });
  return lines;
}

// Logs the configuration through spdlog at debug level (`--log-level debug`), one line per parameter; the
// console shows the result instead, the run folder keeps the configuration (write_config_yaml).
void log_config_lines(const std::vector<std::string>& lines);

// YAML text of config_to_json(): one mapping per section, each value in flow style, loadable as --config.
std::string config_yaml_text(const nlohmann::json& sections, const std::string& header);

// Writes config_yaml_text() to `file` (the effective configuration of a run, beside its outputs). A failure
// is an IoError naming the file.
void write_config_yaml(const std::filesystem::path& file, const nlohmann::json& sections,
                       const std::string& header);

}  // namespace loopgate
