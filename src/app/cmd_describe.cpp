// loopgate describe: DIRD descriptors of image files, one CSV line per image, optional descriptor pictures.
#include <spdlog/spdlog.h>

#include <CLI/CLI.hpp>
#include <exception>
#include <filesystem>
#include <fstream>
#include <iostream>
#include <memory>
#include <opencv2/imgcodecs.hpp>
#include <opencv2/imgproc.hpp>
#include <set>
#include <string>
#include <vector>

#include "app/commands.hpp"
#include "core/error.hpp"
#include "io/config.hpp"
#include "io/dataset.hpp"
#include "io/file_guard.hpp"
#include "io/writers.hpp"
#include "stages/dird/dird_extractor.hpp"

namespace loopgate::app {

namespace {

struct DescribeOptions {
  std::vector<std::string> images;
  std::string out_file;
  std::string picture_dir;
  int picture_scale = 1;
  std::string normalization = "libdird";
  bool flip_vertical = false;
};

// RFC 4180 quoting when the path holds a comma, a quote or a line break.
std::string csv_field(const std::string& text) {
  if (text.find_first_of(",\"\r\n") == std::string::npos) return text;
  std::string quoted = "\"";
  for (char c : text) {
    if (c == '"') quoted += '"';
    quoted += c;
  }
  return quoted + "\"";
}

// Decodes an image for DIRD: grey/BGR/BGRA, 16-bit unsigned samples scaled to 8 bits by the rule of every
// reader (to_8bit_samples, io/dataset.hpp). Other sample types or channel layouts are refused with the same
// words as `loopgate run`, so that an image describe accepts is one a run accepts, read the same way.
// Throws DataError naming the file.
cv::Mat read_image(const std::filesystem::path& path) {
  std::error_code ec;
  if (!std::filesystem::exists(path, ec)) throw DataError(path, "no such image file");
  require_regular_file(path, "the image");  // a directory, a FIFO: say what it is
  image_codecs_ready();
  cv::Mat image = cv::imread(path.string(), cv::IMREAD_UNCHANGED);
  if (image.empty()) throw DataError(path, "cannot decode image, expected an 8-bit PNG, JPEG or PGM file");
  image = to_8bit_samples(image, path, "");  // 16-bit unsigned scaled to 8 bits, as `run` does
  if (image.channels() != 1 && image.channels() != 3 && image.channels() != 4) {
    throw DataError(
        path, "image has " + std::to_string(image.channels()) + " channels, expected grey, RGB or RGBA");
  }
  return image;
}

std::filesystem::path picture_path(const std::filesystem::path& dir, const std::filesystem::path& image,
                                   std::set<std::string>& used) {
  std::string stem = image.stem().string();
  if (stem.empty()) stem = "image";
  std::string name = stem + ".png";
  for (int k = 2; used.count(name) != 0; ++k) name = stem + "-" + std::to_string(k) + ".png";
  used.insert(name);
  return dir / name;
}

int run_describe(const DescribeOptions& opt) {
  DirdConfig config;
  config.normalization = enum_value<DirdNormalization>(opt.normalization).value();
  config.flip_vertical = opt.flip_vertical;
  const DirdExtractor extractor(config);

  // Every output path is known before anything is written: none may be an input (`--out IMAGE`
  // truncated the image before reading it; `--picture DIR` replaced the input PNGs when DIR was their
  // folder).
  std::set<std::string> used_names;
  std::vector<std::filesystem::path> pictures;
  std::vector<NamedPath> inputs, outputs;
  for (const std::string& image_path : opt.images) {
    inputs.push_back({"an input image", image_path});
    if (!opt.picture_dir.empty()) {
      pictures.push_back(picture_path(opt.picture_dir, image_path, used_names));
      outputs.push_back({"--picture's file", pictures.back()});
    }
  }
  if (!opt.out_file.empty()) outputs.push_back({"--out", opt.out_file});
  refuse_outputs_over_inputs(outputs, inputs);

  // The CSV is whole or absent: written under a temporary name, renamed when complete.
  std::ofstream file;
  const std::filesystem::path partial =
      opt.out_file.empty() ? std::filesystem::path() : partial_path(opt.out_file);
  if (!opt.out_file.empty()) {
    if (const auto parent = std::filesystem::path(opt.out_file).parent_path(); !parent.empty())
      std::filesystem::create_directories(parent);
    file.open(partial, std::ios::out | std::ios::trunc);
    if (!file) throw DataError(opt.out_file, "cannot open the output file for writing");
  }
  std::ostream& out = opt.out_file.empty() ? std::cout : file;
  if (!opt.picture_dir.empty()) std::filesystem::create_directories(opt.picture_dir);

  std::size_t failures = 0;
  std::string line;
  for (std::size_t index = 0; index < opt.images.size(); ++index) {
    const std::string& image_path = opt.images[index];
    try {
      const cv::Mat image = read_image(image_path);
      const Descriptor descriptor = extractor.extract(image);
      line = csv_field(image_path);
      for (std::uint8_t b : descriptor) {
        line += ',';
        line += std::to_string(static_cast<int>(b));
      }
      line += '\n';
      out << line;
      if (!opt.picture_dir.empty()) {
        cv::Mat picture = descriptor_picture(descriptor);
        if (opt.picture_scale > 1) {
          cv::resize(picture, picture, cv::Size(), opt.picture_scale, opt.picture_scale, cv::INTER_NEAREST);
        }
        const std::filesystem::path& png = pictures[index];
        if (!cv::imwrite(png.string(), picture)) throw DataError(png, "cannot write the descriptor picture");
      }
    } catch (const DataError& e) {
      spdlog::error("describe: {}", e.what());
      ++failures;
    } catch (const cv::Exception& e) {
      spdlog::error("describe: {}: {}", image_path, e.what());
      ++failures;
    }
  }
  out.flush();
  if (!out) {
    std::error_code ec;
    if (!partial.empty()) std::filesystem::remove(partial, ec);
    throw DataError(opt.out_file.empty() ? "<stdout>" : opt.out_file, "write failed");
  }
  if (!opt.out_file.empty()) {
    file.close();
    std::error_code ec;
    if (file) std::filesystem::rename(partial, opt.out_file, ec);
    if (!file || ec) {
      std::filesystem::remove(partial, ec);
      throw DataError(opt.out_file, "write failed");
    }
  }
  if (failures > 0) {
    spdlog::error("describe: {} of {} images failed", failures, opt.images.size());
    return kExitFailure;
  }
  // Only when the CSV goes to a file: standard output carries the CSV itself.
  if (!opt.out_file.empty()) {
    spdlog::info("describe: {} descriptors ({} normalisation{}) -> {}", opt.images.size(), opt.normalization,
                 opt.flip_vertical ? ", flipped vertically" : "", opt.out_file);
  }
  return kExitOk;
}

}  // namespace

void add_describe_command(CLI::App& app, int& exit_code) {
  auto opt = std::make_shared<DescribeOptions>();
  CLI::App* cmd = app.add_subcommand(
      "describe",
      "DIRD descriptors of images: one CSV line per image, 'path,b0,...,b3455' (3456 bytes). Colour images "
      "are converted to grey with BT.601 weights (rounded). An unreadable image is reported by name, the "
      "others are still described, and the exit status is non-zero.");
  cmd->add_option("images", opt->images, "Image files")->required();
  cmd->add_option("--out", opt->out_file, "CSV output file (default: standard output)");
  cmd->add_option(
      "--picture", opt->picture_dir,
      "Also write each descriptor as a PNG picture into this directory, named after the image "
      "(paper Fig. 3): the 3456 bytes row-major as 54 rows x 64 columns, byte value = grey level");
  cmd->add_option("--picture-scale", opt->picture_scale, "Enlarge the pictures N times (nearest neighbour)")
      ->capture_default_str()
      ->check(CLI::Range(1, 64));
  cmd->add_option("--normalization", opt->normalization,
                  "libdird (bit-exact with the reference) or l2 (for low-contrast input)")
      ->capture_default_str()
      ->check(CLI::IsMember({"libdird", "l2"}));
  cmd->add_flag("--flip-vertical", opt->flip_vertical,
                "Read images bottom-up, as the reference command-line tool does");
  cmd->callback([opt, &exit_code]() {
    try {
      exit_code = run_describe(*opt);
    } catch (const std::exception& e) {
      spdlog::error("describe: {}", e.what());
      exit_code = kExitFailure;
    }
  });
}

}  // namespace loopgate::app
