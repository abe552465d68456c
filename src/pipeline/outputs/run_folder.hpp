// The output folder of a run: the files a run writes there, and the guards that run before anything is
// written (no output over an input, no mixing with another run's outputs).
#pragma once

#include <filesystem>
#include <string>
#include <vector>

#include "pipeline/pipeline_config.hpp"

namespace loopgate {

// Every file a run may write into its output folder (frames.csv, ..., summary.json).
const std::vector<std::string>& run_output_file_names();

// Throws ConfigError when `out_dir` already holds another run's outputs (any of `names`, files or folders)
// and `force` is false: outputs of two runs must not mix in one folder. The message names what
// was found and says --force replaces it. `command` names the refusing command ("run", "compare").
void refuse_previous_outputs(const std::filesystem::path& out_dir, const std::vector<std::string>& names,
                             bool force, const std::string& command);

// Throws ConfigError when an input the run reads (odometry.file with source file; `extra` inputs of the
// command, e.g. its --config file) is one of the files it writes into `out_dir`: a previous run's
// trajectory.tum given as odometry.file would be read, then overwritten.
void refuse_outputs_over_inputs(const PipelineConfig& config, const std::filesystem::path& out_dir,
                                const std::vector<std::filesystem::path>& extra_inputs = {});

}  // namespace loopgate
