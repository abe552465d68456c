// Does a faster PNG decoder pay? The decode of one frame as loopgate did it before (OpenCV
// imdecode, IMREAD_UNCHANGED, then grey when the file is colour), OpenCV decoding straight to grey,
// loopgate's decode today (io/png_grey.hpp: libdeflate for 8-bit grey PNGs, else OpenCV), and, when the build
// found Debian's libspng (spng.pc), libspng decoding to 8-bit grey. Every variant decodes the same files,
// read into memory once (no disk in the timing), round-robin; each checks that its pixels equal OpenCV's.
//
// Images: the real EuRoC V1_01 excerpt of ../shared/data (752 x 480 grey PNG), or the folder in
// LOOPGATE_BENCH_IMAGES (e.g. a rendered preset's mav0/cam0/data). Skips with a message when neither exists.
//   build/release/bench_io_decode --benchmark_repetitions=5 --benchmark_report_aggregates_only=true
#include <benchmark/benchmark.h>

#include <algorithm>
#include <cstdlib>
#include <filesystem>
#include <fstream>
#include <iterator>
#include <opencv2/core.hpp>
#include <opencv2/imgcodecs.hpp>
#include <opencv2/imgproc.hpp>
#include <string>
#include <vector>

#include "io/png_grey.hpp"

#ifdef LOOPGATE_HAVE_SPNG
#include <spng.h>
#endif

namespace {

namespace fs = std::filesystem;

struct EncodedImages {
  fs::path folder;
  std::vector<std::vector<unsigned char>> files;
};

const EncodedImages& images() {
  static const EncodedImages loaded = [] {
    EncodedImages out;
    const char* env = std::getenv("LOOPGATE_BENCH_IMAGES");
    out.folder = env != nullptr
                     ? fs::path(env)
                     : fs::path(LOOPGATE_SHARED_DATA_DIR) / "euroc/V1_01_easy_micro/mav0/cam0/data";
    std::error_code ec;
    if (!fs::is_directory(out.folder, ec)) return out;
    std::vector<fs::path> paths;
    for (const auto& entry : fs::directory_iterator(out.folder, ec))
      if (entry.path().extension() == ".png") paths.push_back(entry.path());
    std::sort(paths.begin(), paths.end());
    if (paths.size() > 200) paths.resize(200);
    for (const fs::path& path : paths) {
      std::ifstream in(path, std::ios::binary);
      out.files.emplace_back(std::istreambuf_iterator<char>(in), std::istreambuf_iterator<char>());
    }
    return out;
  }();
  return loaded;
}

bool require_images(benchmark::State& state) {
  if (!images().files.empty()) return true;
  state.SkipWithError(("no PNG images in " + images().folder.string() +
                       " (shared data absent; set LOOPGATE_BENCH_IMAGES to a folder of PNGs)")
                          .c_str());
  return false;
}

// Today's path (LoadedDataset::decode): decode as stored, convert colour to grey.
cv::Mat decode_unchanged(const std::vector<unsigned char>& bytes) {
  cv::Mat image = cv::imdecode(bytes, cv::IMREAD_UNCHANGED);
  if (image.channels() == 1) return image;
  cv::Mat grey;
  cv::cvtColor(image, grey, image.channels() == 4 ? cv::COLOR_BGRA2GRAY : cv::COLOR_BGR2GRAY);
  return grey;
}

cv::Mat decode_grey(const std::vector<unsigned char>& bytes) {
  return cv::imdecode(bytes, cv::IMREAD_GRAYSCALE);
}

void report(benchmark::State& state, std::size_t pixels) {
  state.counters["images"] = static_cast<double>(images().files.size());
  state.counters["Mpx/s"] =
      benchmark::Counter(static_cast<double>(pixels) * 1e-6, benchmark::Counter::kIsRate);
}

template <class Decode>
void run_decoder(benchmark::State& state, Decode decode) {
  if (!require_images(state)) return;
  const auto& files = images().files;
  for (std::size_t k = 0; k < files.size(); ++k) {  // same pixels as today's path, or the benchmark is void
    if (cv::norm(decode(files[k]), decode_unchanged(files[k]), cv::NORM_INF) != 0) {
      state.SkipWithError(("pixels differ from OpenCV's on file " + std::to_string(k)).c_str());
      return;
    }
  }
  std::size_t next = 0, pixels = 0;
  for (auto _ : state) {
    const cv::Mat image = decode(files[next]);
    pixels += image.total();
    benchmark::DoNotOptimize(image.data);
    next = (next + 1) % files.size();
  }
  report(state, pixels);
}

void BM_DecodeOpenCvUnchanged(benchmark::State& state) {
  run_decoder(state, decode_unchanged);
}
BENCHMARK(BM_DecodeOpenCvUnchanged)->Unit(benchmark::kMicrosecond);

void BM_DecodeOpenCvGrey(benchmark::State& state) {
  run_decoder(state, decode_grey);
}
BENCHMARK(BM_DecodeOpenCvGrey)->Unit(benchmark::kMicrosecond);

// loopgate's path (LoadedDataset::decode): the 8-bit grey fast path (libdeflate's inflate and
// our unfiltering), today's path for every other file.
cv::Mat decode_loopgate(const std::vector<unsigned char>& bytes) {
  cv::Mat grey = loopgate::decode_png_grey8(bytes.data(), bytes.size());
  return grey.empty() ? decode_unchanged(bytes) : grey;
}

void BM_DecodeLoopgate(benchmark::State& state) {
  run_decoder(state, decode_loopgate);
}
BENCHMARK(BM_DecodeLoopgate)->Unit(benchmark::kMicrosecond);

#ifdef LOOPGATE_HAVE_SPNG
// libspng to 8-bit grey (SPNG_FMT_G8: grey files only; colour files are skipped with a message).
cv::Mat decode_spng(const std::vector<unsigned char>& bytes) {
  spng_ctx* ctx = spng_ctx_new(0);
  cv::Mat out;
  spng_ihdr ihdr{};
  std::size_t size = 0;
  if (spng_set_png_buffer(ctx, bytes.data(), bytes.size()) == 0 && spng_get_ihdr(ctx, &ihdr) == 0 &&
      ihdr.color_type == SPNG_COLOR_TYPE_GRAYSCALE && ihdr.bit_depth == 8 &&
      spng_decoded_image_size(ctx, SPNG_FMT_G8, &size) == 0) {
    out.create(static_cast<int>(ihdr.height), static_cast<int>(ihdr.width), CV_8UC1);
    if (spng_decode_image(ctx, out.data, size, SPNG_FMT_G8, 0) != 0) out.release();
  }
  spng_ctx_free(ctx);
  return out;
}

void BM_DecodeSpngGrey(benchmark::State& state) {
  if (!require_images(state)) return;
  if (decode_spng(images().files.front()).empty()) {
    state.SkipWithError("libspng: the images are not 8-bit grey PNGs");
    return;
  }
  run_decoder(state, decode_spng);
}
BENCHMARK(BM_DecodeSpngGrey)->Unit(benchmark::kMicrosecond);
#endif

}  // namespace

BENCHMARK_MAIN();
