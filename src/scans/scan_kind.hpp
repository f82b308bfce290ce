// Scan kinds (docs/library.md, "How to add a scan"): each kind a type with one interface, which reads
// its keys of a simulation file's [scan] table and generates the boresight pointing of any range of
// its samples; the pipeline finds a kind by its name or ScanKind through one registry, scan_kinds().
#pragma once

#include <cstddef>
#include <memory>
#include <span>
#include <vector>

#include "io/toml_table.hpp"
#include "pisco/pointing.hpp"
#include "pisco/pointing_file.hpp"
#include "pisco/quaternion.hpp"
#include "pisco/simulation_config.hpp"

namespace pisco::detail {

// A scan's boresight pointing, for any range of its samples, in the form the scan produces.
class ScanGenerator {
 public:
  virtual ~ScanGenerator() = default;
  virtual std::size_t samples() const = 0;
  // Quaternions (satellite scans, pointing files) or angles (the others).
  virtual bool quaternions() const = 0;
  // Samples [first, first + count) into `angles` or `quats`, whichever quaternions() says, cleared first.
  virtual void generate(std::size_t first, std::size_t count, Pointing& angles, std::vector<Quat>& quats) const = 0;
  // Whether each sample comes from its own time alone, so that blocks of samples may be generated on
  // threads of their own with the same values (the constant-elevation and satellite scans).
  virtual bool by_blocks() const { return false; }
  // The pointing file a scan reads, if it reads one (its plate angles are read from it too).
  virtual const BoresightFile* file() const { return nullptr; }
};

// One kind of scan: its name (the [scan] type), its keys and its generator. `sample_rate` is the
// rate of a scan whose samples have times (sample i at i / rate), 0 for the others.
struct ScanKindEntry {
  ScanKind kind;
  const char* name;
  void (*read)(Table& t, ScanConfig& s);  // its keys of the [scan] table (type is read already)
  std::unique_ptr<ScanGenerator> (*make)(const ScanConfig& s);
  double (*sample_rate)(const ScanConfig& s);
  std::size_t (*samples)(const ScanConfig& s);  // 0 where the scan's samples are known only when made
};

// Every kind, in the order of ScanKind; the kind of a name or of a ScanKind.
std::span<const ScanKindEntry* const> scan_kinds();
const ScanKindEntry& scan_kind(ScanKind kind);
const ScanKindEntry* scan_kind_named(const std::string& name);

// The keys that the kinds share: the psi angles of the generated test scans (psi_deg), the samples of
// a scan of duration_hours at `sample_rate`, and a UTC time "YYYY-MM-DDTHH:MM:SSZ" as seconds since 1970.
std::vector<double> read_psi(Table& t);
std::size_t read_samples(Table& t, double sample_rate);
double parse_utc(Table& t, const std::string& key, const std::string& text);

// The kinds (src/scans/kinds/), each one entry.
extern const ScanKindEntry pixel_centres_scan_kind, random_offsets_scan_kind, raster_scan_kind, ces_scan_kind,
    satellite_scan_kind, pointing_file_scan_kind;

}  // namespace pisco::detail
