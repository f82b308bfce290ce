// [scan] type = "file": a boresight pointing file, read a range at a time (pisco::BoresightFile;
// docs/formats.md, "Pointing files"). A file of each detector's own angles is read by the pipeline
// detector by detector instead (ScanSource).
#include "pisco/pointing_file.hpp"
#include "scans/kinds/precomputed.hpp"

namespace pisco::detail {
namespace {

class PointingFile : public ScanGenerator {
 public:
  explicit PointingFile(const std::filesystem::path& file) : file_(file) {}
  std::size_t samples() const override { return file_.size(); }
  bool quaternions() const override { return true; }
  void generate(std::size_t first, std::size_t count, Pointing&, std::vector<Quat>& quats) const override {
    file_.read(first, count, quats);
  }
  const BoresightFile* file() const override { return &file_; }

 private:
  BoresightFile file_;
};

}  // namespace

const ScanKindEntry pointing_file_scan_kind{
    ScanKind::file, "file",
    [](Table& t, ScanConfig& s) {
      s.file = t.input_file("file");
      if (s.file.empty()) t.fail("file", "a scan of type \"file\" needs file = \"pointing.h5\"");
    },
    [](const ScanConfig& s) -> std::unique_ptr<ScanGenerator> { return std::make_unique<PointingFile>(s.file); },
    untimed, known_when_made};

}  // namespace pisco::detail
