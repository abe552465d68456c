// loopgate config-reference: every configuration key with its default, as a Markdown table, walked from the
// config structs' fields() so that it cannot miss a key. docs/configuration.md holds the same keys with their
// bounds and meanings; the test config_reference_sync keeps the two in step.
#include <spdlog/spdlog.h>

#include <CLI/CLI.hpp>
#include <exception>
#include <iostream>
#include <memory>
#include <string>
#include <string_view>
#include <type_traits>

#include "app/commands.hpp"
#include "io/config.hpp"
#include "pipeline/pipeline_config.hpp"
#include "sim/simulator.hpp"

namespace loopgate::app {

namespace {

// The type of a field as a user writes it: the enum's words, or the YAML scalar type.
template <class T>
std::string type_name(const T& value) {
  if constexpr (std::is_same_v<T, bool>) {
    return "bool";
  } else if constexpr (std::is_same_v<T, int> || std::is_same_v<T, std::int64_t>) {
    return "int";
  } else if constexpr (std::is_same_v<T, double>) {
    return "number";
  } else if constexpr (std::is_same_v<T, std::string>) {
    return "text";
  } else {
    return enum_choices(value);
  }
}

// A default as a table cell: the printed value in backticks, an empty text as "(empty)".
std::string default_cell(const std::string& text) {
  return text.empty() ? "(empty)" : "`" + text + "`";
}

// "| `section.key` | default | type |" rows under one header, in the order of sections() and fields().
template <class Config>
void print_reference(const Config& config, std::ostream& out) {
  out << "| key | default | type |\n| --- | --- | --- |\n";
  Config::sections(config, [&](std::string_view section_name, const auto& section) {
    std::remove_cvref_t<decltype(section)>::fields(section, [&](std::string_view key, const auto& field) {
      std::string type = type_name(field);
      for (char& c : type) {
        if (c == '|') c = '/';  // a Markdown cell cannot hold '|'
      }
      out << "| `" << section_name << "." << key << "` | " << default_cell(config_detail::format_value(field))
          << " | " << type << " |\n";
    });
  });
}

}  // namespace

void add_config_reference_command(CLI::App& app, int& exit_code) {
  auto simulation = std::make_shared<bool>(false);
  CLI::App* cmd = app.add_subcommand(
      "config-reference",
      "Print every configuration key with its default as a Markdown table (docs/configuration.md explains "
      "each)");
  cmd->add_flag("--simulation", *simulation,
                "The keys of `simulate` (preset files) instead of those of run and compare");
  cmd->callback([simulation, &exit_code]() {
    try {
      // Named defaults, not temporaries: GCC 12 at -O3 reads a false "may be used uninitialized" into the
      // temporary's strings.
      if (*simulation) {
        const sim::SimulationConfig defaults;
        print_reference(defaults, std::cout);
      } else {
        const PipelineConfig defaults;
        print_reference(defaults, std::cout);
      }
      exit_code = kExitOk;
    } catch (const std::exception& e) {
      spdlog::error("config-reference: {}", e.what());
      exit_code = kExitFailure;
    }
  });
}

}  // namespace loopgate::app
