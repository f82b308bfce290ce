// pisco.Simulation: a simulation file run as `pisco-vk run` runs it (docs/python.md, "A whole
// simulation"), through pisco::Simulation (simulation.hpp), with the GIL released while it runs.
#include <filesystem>
#include <optional>
#include <string>
#include <vector>

#include <nanobind/nanobind.h>
#include <nanobind/stl/filesystem.h>
#include <nanobind/stl/optional.h>
#include <nanobind/stl/string.h>
#include <nanobind/stl/vector.h>

#include "pisco/engine.hpp"
#include "pisco/error.hpp"
#include "pisco/simulation.hpp"

namespace nb = nanobind;
using namespace nb::literals;

namespace pisco::python {
namespace {

// The run's account, kept for the result (progress is not reported).
class LogLines final : public RunObserver {
 public:
  void log(const std::string& line) override {
    lines.push_back(!line.empty() && line.back() == '\n' ? line.substr(0, line.size() - 1) : line);
  }
  std::vector<std::string> lines;
};

nb::dict result_dict(const SimulationResult& r, std::vector<std::string> log) {
  nb::dict d;
  std::vector<std::string> files;
  for (const auto& f : r.written) files.push_back(f.string());
  d["files"] = files;
  d["tod"] = r.tod_file.empty() ? nb::none() : nb::cast(r.tod_file.string());
  d["samples"] = r.samples;
  d["detectors"] = r.detectors;
  d["samples_per_detector"] = r.samples_per_detector;
  d["mean_disc_pixels"] = r.mean_disc_pixels;
  d["convolution_seconds"] = r.convolution_seconds;
  d["seconds"] = r.seconds;
  d["backend"] = r.backend;
  d["device"] = r.device;
  d["flagged"] = r.flagged;
  d["solved_pixels"] = r.solved_pixels;
  if (r.deconvolution_iterations > 0) {  // [mapmaker] type = "deconvolve"
    d["deconvolution_iterations"] = r.deconvolution_iterations;
    d["deconvolution_residual"] = r.deconvolution_residual;
    d["deconvolution_converged"] = r.deconvolution_converged;
  }
  d["warnings"] = r.warnings;
  d["nothing_solved"] = r.nothing_solved.empty() ? nb::none() : nb::cast(r.nothing_solved);
  d["log"] = std::move(log);
  return d;
}

// Overrides of the file's settings, as pisco-vk run's -o, -b and -d give them.
void apply(Simulation& s, const std::optional<std::filesystem::path>& output_dir,
           const std::optional<std::string>& backend, const std::optional<std::string>& device) {
  if (output_dir) {
    if (output_dir->empty()) throw nb::value_error("output_dir: expected a directory name, got an empty string");
    s.config().output.dir = *output_dir;
  }
  if (backend) s.config().engine.set_backend(*backend, s.config().source);
  if (device) pisco::set_engine_option(s.config().engine.options, "device", *device);  // keyed "device"
}

Simulation from_file(const std::filesystem::path& path, const std::optional<std::filesystem::path>& output_dir,
                     const std::optional<std::string>& backend, const std::optional<std::string>& device,
                     const std::optional<std::filesystem::path>& data_dir) {
  SimulationOptions options;
  if (data_dir) options.data_dir = *data_dir;
  std::optional<Simulation> s;
  {
    nb::gil_scoped_release release;
    s.emplace(Simulation::from_file(path, options));
  }
  apply(*s, output_dir, backend, device);
  return std::move(*s);
}

}  // namespace

void bind_simulation(nb::module_& m) {
  nb::class_<Simulation>(m, "Simulation",
                         "A whole simulation from a simulation file (docs/config.md), as `pisco-vk run` runs it: sky,\n"
                         "beams, focal plane, scan, engine, then the TOD file, binned maps and spectra in the output\n"
                         "directory (no plots).")
      .def(
          "__init__",
          [](Simulation* self, const std::filesystem::path& path, const std::optional<std::filesystem::path>& output_dir,
             const std::optional<std::string>& backend, const std::optional<std::string>& device,
             const std::optional<std::filesystem::path>& data_dir) {
            new (self) Simulation(from_file(path, output_dir, backend, device, data_dir));
          },
          "path"_a, "output_dir"_a = nb::none(), "backend"_a = nb::none(), "device"_a = nb::none(),
          "data_dir"_a = nb::none(), "The same as Simulation.from_file.")
      .def_static("from_file", &from_file, "path"_a, "output_dir"_a = nb::none(), "backend"_a = nb::none(),
                  "device"_a = nb::none(), "data_dir"_a = nb::none(),
                  "Reads a simulation file (TOML; docs/config.md); raises pisco.Error naming the file and key.\n"
                  "output_dir, backend, device: override [output] dir, [engine] backend and device.\n"
                  "data_dir: where assets/spectra/tensor_bb_r1.txt is (default: the library's).")
      .def_prop_ro("source", [](const Simulation& s) { return s.config().source.string(); }, "The simulation file.")
      .def_prop_rw(
          "output_dir", [](const Simulation& s) { return s.config().output.dir.string(); },
          [](Simulation& s, const std::filesystem::path& dir) { apply(s, dir, std::nullopt, std::nullopt); },
          "The output directory ([output] dir).")
      .def_prop_rw(
          "backend", [](const Simulation& s) { return s.config().engine.options.backend; },
          [](Simulation& s, const std::string& b) { s.config().engine.set_backend(b, s.config().source); },
          "The engine's backend ([engine] backend): auto, cpu, simd, vulkan, cuda.")
      .def_prop_ro("detectors",
                   [](const Simulation& s) {
                     std::vector<std::string> names;
                     for (const auto& d : s.config().detectors) names.push_back(d.name);
                     return names;
                   },
                   "The detectors' names.")
      .def(
          "run",
          [](const Simulation& s) {
            LogLines log;
            SimulationResult r;
            {
              nb::gil_scoped_release release;
              r = s.run(&log);
            }
            // What pisco-vk prints as warnings (and exits with status 5 for): Python warnings too.
            for (const std::string& w : r.warnings)
              if (PyErr_WarnEx(PyExc_RuntimeWarning, w.c_str(), 1) != 0) throw nb::python_error();
            return result_dict(r, std::move(log.lines));
          },
          "Runs it, the GIL released: writes the TOD file, maps and spectra into the output directory (each\n"
          "whole or not at all) and returns a dict: files (paths written, in order), tod (its path or None),\n"
          "samples, detectors, samples_per_detector, mean_disc_pixels, convolution_seconds, seconds, backend,\n"
          "device, flagged, solved_pixels, nothing_solved (None, or why the maps solve no pixel) and log (the\n"
          "lines pisco-vk run prints), warnings (what pisco-vk prints as warnings, each also issued as a\n"
          "RuntimeWarning); with [mapmaker] type = \"deconvolve\", also deconvolution_iterations,\n"
          "deconvolution_residual and deconvolution_converged.")
      .def("__repr__", [](const Simulation& s) {
        return "pisco.Simulation('" + s.config().source.string() + "', output_dir='" + s.config().output.dir.string() +
               "')";
      });
}

}  // namespace pisco::python
