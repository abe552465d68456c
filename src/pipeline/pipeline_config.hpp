// The top-level configuration of `loopgate run`: one struct per section, each with visit()/validate()
// (see io/config.hpp). To add a section (e.g. DirdConfig "dird", MatchConfig "match"): add a member and
// one line in visit_sections(); YAML loading, --set overrides, printing and the JSON echo follow.
#pragma once

#include <cstddef>
#include <optional>
#include <string>
#include <utility>

#include "stages/odometry/odometry_source.hpp"
#include "stages/sync/imu_sync.hpp"

namespace loopgate {

struct RunConfig {
  std::string dataset;          // dataset folder (the --dataset flag overrides it)
  std::string rate = "max";     // "max" (as fast as the graph drains) or R > 0 (R x real time)
  int threads = 2;              // worker threads of the graph
  int max_in_flight = 8;        // limiter: frames inside the graph at once
  std::string frames;           // "A:B" frame indices [A, B), "A:" or ":B"; empty = all
  std::string decode = "lazy";  // lazy (only frames a later stage needs pixels of) | all
  bool strict = false;          // open the dataset strictly (first bad row fails) instead of leniently
  int camera_index = 0;         // 0 or 1 (stereo layouts)
  double deadline_ms = 0;       // rate mode: time a frame may take from release to sink; 0 = frame period

  template <class V>
  void visit(V&& v) {
    v("dataset", dataset);
    v("rate", rate);
    v("threads", threads);
    v("max_in_flight", max_in_flight);
    v("frames", frames);
    v("decode", decode);
    v("strict", strict);
    v("camera_index", camera_index);
    v("deadline_ms", deadline_ms);
  }
  void validate() const;

  // nullopt for "max", else the rate factor R.
  std::optional<double> rate_factor() const;
  // [first, last) clamped to frame_count; throws ConfigError when the range is empty or malformed.
  std::pair<std::size_t, std::size_t> frame_range(std::size_t frame_count) const;
};

struct OutputConfig {
  bool trace = false;             // write trace.json (Chrome trace-event format, opens in Perfetto)
  std::string progress = "auto";  // auto (when stderr is a terminal) | on | off
  int flush_every = 100;          // frames between flushes of the streamed CSV/TUM files

  template <class V>
  void visit(V&& v) {
    v("trace", trace);
    v("progress", progress);
    v("flush_every", flush_every);
  }
  void validate() const;
};

struct PipelineConfig {
  RunConfig run;
  SyncConfig sync;
  OdometryConfig odometry;
  OutputConfig output;

  template <class V>
  void visit_sections(V&& v) {
    v("run", run);
    v("sync", sync);
    v("odometry", odometry);
    v("output", output);
  }
  void validate() const {
    run.validate();
    sync.validate();
    odometry.validate();
    output.validate();
  }
};

}  // namespace loopgate
