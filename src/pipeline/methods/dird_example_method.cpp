// Example of the walkthrough in docs/architecture.md § Adding a method: DIRD on every frame under a name of
// its own, delegating every hook to the registry's "full" row.
#include <memory>

#include "pipeline/methods/method_registry.hpp"

namespace loopgate {
namespace {

class DirdExample final : public DetectionMethod {
 public:
  explicit DirdExample(const MethodContext& context) : inner_(find_method_entry("full")->make(context)) {}
  std::string name() const override { return "dird-example"; }
  std::string mode() const override { return inner_->mode(); }
  bool needs_every_image() const override { return inner_->needs_every_image(); }
  void gate(FrameRecord& r) override { inner_->gate(r); }
  void describe(FrameRecord& r) override { inner_->describe(r); }
  void match(FrameRecord& r) override { inner_->match(r); }
  void finish() override { inner_->finish(); }
  std::optional<int> verdict_delay_frames() const override { return inner_->verdict_delay_frames(); }
  void add_frame_cells(const FrameRecord& r, CsvRow& row) const override { inner_->add_frame_cells(r, row); }
  std::optional<FrameVerdict> detection(std::size_t seq) override { return inner_->detection(seq); }
  void write_files(const std::filesystem::path& out_dir) const override { inner_->write_files(out_dir); }
  nlohmann::json summary() const override { return inner_->summary(); }
  MethodEvaluation evaluation() const override { return inner_->evaluation(); }
  std::optional<std::pair<std::size_t, Descriptor>> example_descriptor() const override {
    return inner_->example_descriptor();
  }

 private:
  std::unique_ptr<DetectionMethod> inner_;
};

}  // namespace

std::unique_ptr<DetectionMethod> make_dird_example(const MethodContext& context) {
  return std::make_unique<DirdExample>(context);
}

}  // namespace loopgate
