// pisco.Engine: the C++ engine behind a lock, with the GIL released while it runs (docs/python.md).
//
// One Python Engine may be used from several threads: its calls are serialized by its own mutex,
// taken after the GIL is released, so that other engines (and any other Python code) run meanwhile.
// close() waits for the calls in progress and frees the device's memory; later calls raise.
#include <algorithm>
#include <functional>
#include <cmath>
#include <cstdint>
#include <map>
#include <memory>
#include <atomic>
#include <mutex>
#include <thread>
#include <new>
#include <numbers>
#include <optional>
#include <span>
#include <string>
#include <type_traits>
#include <vector>

#include <nanobind/nanobind.h>
#include <nanobind/ndarray.h>
#include <nanobind/stl/filesystem.h>
#include <nanobind/stl/function.h>
#include <nanobind/stl/optional.h>
#include <nanobind/stl/string.h>
#include <nanobind/stl/vector.h>

#include "args.hpp"
#include "arrays.hpp"
#include "pisco/deconvolution.hpp"
#include "pisco/engine.hpp"
#include "pisco/error.hpp"

namespace nb = nanobind;
using namespace nb::literals;

namespace pisco::python {
namespace {

// The pointing of one call, checked and viewed (no copy): angles or boresight quaternions.
struct PointingArgs {
  std::optional<ConstVector> theta, phi, psi;
  std::optional<ConstMatrix> quats;
  std::size_t size = 0;

  PointingView angles() const {
    return {{theta->data(), size}, {phi->data(), size}, {psi->data(), size}};
  }
  QuatPointingView quaternions() const {
    return {{reinterpret_cast<const Quat*>(quats->data()), size}};
  }
};

// `call` names the method in the messages ("convolve", "flag_samples").
PointingArgs pointing_args(nb::handle theta, nb::handle phi, nb::handle psi, nb::handle quats,
                           const std::string& call = "convolve") {
  const bool angles = !theta.is_none() || !phi.is_none() || !psi.is_none();
  if (angles == !quats.is_none())
    throw nb::type_error((call + ": give either theta, phi and psi (the boresight's angles) or boresight_quats "
                                 "(one quaternion x, y, z, w per sample), not both and not neither").c_str());
  PointingArgs p;
  if (angles) {
    if (theta.is_none() || phi.is_none() || psi.is_none())
      throw nb::type_error((call + ": theta, phi and psi must all be given").c_str());
    p.theta = const_vector(theta, "theta");
    p.phi = const_vector(phi, "phi");
    p.psi = const_vector(psi, "psi");
    p.size = p.theta->shape(0);
    if (p.phi->shape(0) != p.size || p.psi->shape(0) != p.size)
      throw nb::value_error((call + ": theta, phi and psi have different lengths (" + std::to_string(p.size) + ", " +
                             std::to_string(p.phi->shape(0)) + ", " + std::to_string(p.psi->shape(0)) + ")").c_str());
  } else {
    p.quats = const_matrix(quats, "boresight_quats", 4);
    p.size = p.quats->shape(0);
  }
  return p;
}

// A per-sample array of one call (a view, no copy), or none: a 1-D float64 array of the pointing's
// length. Whether the detector needs it is the engine's to say (pisco.Error): the plate's angles
// (hwp_angle) for a detector with a plate, each sample's time (time) for a beam that changes with time.
std::optional<ConstVector> samples_arg(nb::handle arg, const char* name, std::size_t n) {
  if (arg.is_none()) return std::nullopt;
  ConstVector v = const_vector(arg, name);
  if (v.shape(0) != n)
    throw nb::value_error((std::string(name) + ": " + std::to_string(v.shape(0)) + " samples, but the pointing has " +
                           std::to_string(n)).c_str());
  return v;
}

std::optional<ConstVector> hwp_args(nb::handle hwp_angle, std::size_t n) { return samples_arg(hwp_angle, "hwp_angle", n); }
std::optional<ConstVector> time_args(nb::handle time, std::size_t n) { return samples_arg(time, "time", n); }

std::span<const double> span_of(const std::optional<ConstVector>& v) {
  if (!v) return {};
  return {v->data(), v->shape(0)};
}

// Runs without the GIL: the first non-finite plate angle, named, or an empty string.
std::string check_hwp_values(const std::optional<ConstVector>& v) {
  if (!v) return {};
  const std::size_t n = v->shape(0);
  const std::size_t bad = first_non_finite(v->data(), n);
  if (bad < n)
    return "hwp_angle[" + std::to_string(bad) + "] is " + format_double(v->data()[bad]) +
           ": the plate's angles must be finite";
  return {};
}

// Non-finite values, theta outside [0, pi] and quaternions far from unit norm, named by argument and
// sample (the engine would report them too, as pisco.Error and without the argument's name).
// Runs without the GIL; returns the message of the first problem, or an empty string.
std::string check_values(const PointingArgs& p) {
  if (p.theta) {
    const char* names[3] = {"theta", "phi", "psi"};
    const double* data[3] = {p.theta->data(), p.phi->data(), p.psi->data()};
    for (int k = 0; k < 3; ++k) {
      const std::size_t bad = first_non_finite(data[k], p.size);
      if (bad < p.size)
        return std::string(names[k]) + "[" + std::to_string(bad) + "] is " + format_double(data[k][bad]) +
               ": the pointing must be finite";
    }
    for (std::size_t i = 0; i < p.size; ++i)
      if (data[0][i] < 0.0 || data[0][i] > std::numbers::pi)
        return "theta[" + std::to_string(i) + "] = " + format_double(data[0][i]) + " is outside [0, pi]";
    return {};
  }
  const double* q = p.quats->data();
  for (std::size_t i = 0; i < p.size; ++i)
    if (const std::string problem = rotation_problem({q[4 * i], q[4 * i + 1], q[4 * i + 2], q[4 * i + 3]});
        !problem.empty())
      return "boresight_quats[" + std::to_string(i) + "] " + problem;
  return {};
}

class PyEngine {
 public:
  PyEngine(const Sky& sky, nb::handle beams, const FocalPlane& focal_plane, const std::string& backend,
           const std::string& device, long long chunk_samples, const std::string& normalization,
           long long threads, const std::string& arithmetic, const std::string& unseen, const std::string& quadrature) {
    std::vector<Beamsor> beam_list;
    if (nb::isinstance<Beamsor>(beams)) {
      beam_list.push_back(nb::cast<Beamsor>(beams));
    } else {
      for (nb::handle b : beams) {
        if (!nb::isinstance<Beamsor>(b))
          throw nb::type_error(("beams: expected a pisco.Beamsor or a sequence of them, found " + describe(b)).c_str());
        beam_list.push_back(nb::cast<Beamsor>(b));
      }
    }
    // Each keyword through the library's table of settings (pisco::set_engine_option), whose errors
    // carry the setting's name: the keyword's.
    EngineOptions options;
    set_engine_option(options, "backend", backend);
    set_engine_option(options, "arithmetic", arithmetic);
    set_engine_option(options, "device", device);
    set_engine_option(options, "chunk_samples", static_cast<long long>(unsigned_arg<std::size_t>(chunk_samples, "chunk_samples")));
    set_engine_option(options, "threads", static_cast<long long>(unsigned_arg<unsigned>(threads, "threads")));
    set_engine_option(options, "normalization", normalization);
    set_engine_option(options, "unseen", unseen);
    set_engine_option(options, "quadrature", quadrature);
    for (const auto& d : focal_plane.detectors()) names_.push_back(d.name);
    bool out_of_memory = false;
    {
      nb::gil_scoped_release release;
      try {
        engine_ = std::make_unique<Engine>(sky, beam_list, focal_plane, options);
      } catch (const std::bad_alloc&) {
        out_of_memory = true;
      }
    }
    if (out_of_memory) {
      std::size_t nodes = 0;
      for (const Beamsor& b : beam_list)
        nodes = std::max(nodes, b.is_radial() ? std::size_t(b.grid_size())
                                              : std::size_t(b.grid_size()) * std::size_t(b.grid_size()));
      raise_memory_error("pisco.Engine: memory ran out while setting up for a sky of NSIDE " +
                         std::to_string(sky.nside()) + " (" + std::to_string(sky.npix()) +
                         " pixels; the engine keeps copies of its I, Q, U, V maps, " +
                         bytes_text(32.0 * double(sky.npix())) + " each), " + std::to_string(beam_list.size()) +
                         " beam(s) of up to " + std::to_string(nodes) + " grid nodes and " +
                         std::to_string(focal_plane.size()) + " detector(s)");
    }
  }

  ~PyEngine() {
    if (!engine_ || in_flight_.empty()) return;
    try {
      engine_->wait();  // submissions still writing into arrays this object keeps alive
    } catch (...) {
    }
  }
  PyEngine(const PyEngine&) = delete;
  PyEngine& operator=(const PyEngine&) = delete;

  nb::object convolve(nb::handle detector, nb::handle theta, nb::handle phi, nb::handle psi, nb::handle quats,
                      nb::handle out, bool accumulate, nb::handle hwp_angle, nb::handle time_arg) {
    const std::size_t d = detector_index(detector);
    const PointingArgs p = pointing_args(theta, phi, psi, quats);
    const std::optional<ConstVector> h = hwp_args(hwp_angle, p.size);
    const std::optional<ConstVector> time = time_args(time_arg, p.size);
    nb::object result = output(out, p.size, accumulate);
    Vector tod = vector(result, "out");
    bool out_of_memory = false;
    const std::string problem = checked_run(p, h, [&](Engine& e) {
      try {
        if (p.theta)
          e.convolve(d, p.angles(), {tod.data(), p.size}, accumulate, span_of(h), span_of(time));
        else
          e.convolve(d, p.quaternions(), {tod.data(), p.size}, accumulate, span_of(h), span_of(time));
      } catch (const std::bad_alloc&) {
        out_of_memory = true;
      }
    });
    if (!problem.empty()) throw nb::value_error(problem.c_str());
    if (out_of_memory) raise_memory_error(chunk_memory("convolve", d, p.size));
    return result;
  }

  // Several detectors on one chunk of boresight pointing (Engine::submit of a list, then wait): a list
  // of their TODs, written into (or, with accumulate, added to) out's arrays when given.
  nb::object convolve_detectors(nb::handle detectors_arg, nb::handle theta, nb::handle phi, nb::handle psi,
                                nb::handle quats, nb::handle out, bool accumulate, nb::handle hwp_angle,
                                nb::handle time_arg) {
    if (nb::isinstance<nb::str>(detectors_arg))
      throw nb::type_error("convolve_detectors: detectors must be a sequence of indices or names, not one name");
    // A numpy array of indices as Python integers.
    nb::object detectors = nb::hasattr(detectors_arg, "tolist") ? detectors_arg.attr("tolist")()
                                                                 : nb::borrow(detectors_arg);
    std::vector<std::size_t> ds;
    for (nb::handle d : detectors) ds.push_back(detector_index(d));
    const PointingArgs p = pointing_args(theta, phi, psi, quats, "convolve_detectors");
    const std::optional<ConstVector> h = hwp_args(hwp_angle, p.size);
    const std::optional<ConstVector> time = time_args(time_arg, p.size);
    nb::list results;
    if (out.is_none()) {
      if (accumulate) throw nb::type_error("convolve_detectors: accumulate=True adds into `out`, which must then be given");
      for (std::size_t k = 0; k < ds.size(); ++k) results.append(nb::module_::import_("numpy").attr("empty")(p.size, "float64"));
    } else {
      for (nb::handle o : out) {
        check_output_size(o, p.size);
        results.append(nb::borrow(o));
      }
      if (results.size() != ds.size())
        throw nb::value_error(("convolve_detectors: out holds " + std::to_string(results.size()) + " arrays for " +
                               std::to_string(ds.size()) + " detectors (expected one a detector)").c_str());
    }
    std::vector<Vector> tods;
    for (nb::handle r : results) tods.push_back(vector(r, "out"));
    std::vector<std::span<double>> spans;
    for (Vector& t : tods) spans.emplace_back(t.data(), p.size);
    bool out_of_memory = false;
    const std::string problem = checked_run(p, h, [&](Engine& e) {
      // On an error, the detectors queued before it have completed into their arrays (Engine::submit).
      try {
        e.wait(p.theta ? e.submit(ds, p.angles(), spans, accumulate, span_of(h), span_of(time))
                       : e.submit(ds, p.quaternions(), spans, accumulate, span_of(h), span_of(time)));
      } catch (const std::bad_alloc&) {
        out_of_memory = true;
      }
    });
    if (!problem.empty()) throw nb::value_error(problem.c_str());
    if (out_of_memory)
      raise_memory_error("Engine.convolve_detectors: memory ran out for a chunk of " + std::to_string(p.size) +
                         " samples of " + std::to_string(ds.size()) + " detectors; give shorter chunks");
    return results;
  }

  // Point sources (Engine::add_sources) at these samples, added into `out` (or new zeros).
  nb::object add_sources(nb::handle detector, nb::handle time_arg, const std::vector<SourceTrack>& sources,
                         nb::handle theta, nb::handle phi, nb::handle psi, nb::handle quats, nb::handle out,
                         nb::handle hwp_angle) {
    const std::size_t d = detector_index(detector);
    const PointingArgs p = pointing_args(theta, phi, psi, quats, "add_sources");
    const std::optional<ConstVector> h = hwp_args(hwp_angle, p.size);
    const ConstVector time = const_vector(time_arg, "time");
    if (time.shape(0) != p.size)
      throw nb::value_error(("add_sources: time has " + std::to_string(time.shape(0)) +
                             " samples, but the pointing has " + std::to_string(p.size)).c_str());
    if (!out.is_none()) check_output_size(out, p.size);
    nb::object result = out.is_none() ? nb::module_::import_("numpy").attr("zeros")(p.size, "float64") : nb::borrow(out);
    Vector tod = vector(result, "out");
    const std::string problem = checked_run(p, h, [&](Engine& e) {
      const std::span<const double> t{time.data(), p.size};
      if (p.theta)
        e.add_sources(d, p.angles(), t, sources, {tod.data(), p.size}, span_of(h));
      else
        e.add_sources(d, p.quaternions(), t, sources, {tod.data(), p.size}, span_of(h));
    });
    if (!problem.empty()) throw nb::value_error(problem.c_str());
    return result;
  }

  // A^T tod of one detector (Scatter::adjoint), the diagonal of A^T A (diagonal) or A^T A s for the
  // engine's sky s (normal), added into `out` ((4, npix) float64: I, Q, U, V), or into new zeros.
  enum class Scatter { adjoint, diagonal, normal };
  nb::object adjoint(nb::handle detector, nb::handle tod_arg, nb::handle theta, nb::handle phi, nb::handle psi,
                     nb::handle quats, nb::handle out, nb::handle hwp_angle, nb::handle time_arg, Scatter what) {
    const std::size_t d = detector_index(detector);
    const char* call = what == Scatter::diagonal ? "adjoint_diagonal" : what == Scatter::normal ? "normal" : "adjoint";
    const PointingArgs p = pointing_args(theta, phi, psi, quats, call);
    const std::optional<ConstVector> h = hwp_args(hwp_angle, p.size);
    const std::optional<ConstVector> time = time_args(time_arg, p.size);
    std::optional<ConstVector> tod;
    if (what == Scatter::adjoint) {
      tod = const_vector(tod_arg, "tod");
      if (tod->shape(0) != p.size)
        throw nb::value_error(("adjoint: tod has " + std::to_string(tod->shape(0)) + " samples, but the pointing has " +
                               std::to_string(p.size)).c_str());
    }
    const std::size_t npix = open().npix();
    nb::object result;
    if (out.is_none()) {
      result = nb::module_::import_("numpy").attr("zeros")(nb::make_tuple(4, npix), "float64");
    } else {
      const nb::tuple shape = nb::cast<nb::tuple>(out.attr("shape"));
      if (shape.size() != 2 || nb::cast<std::size_t>(shape[0]) != 4 || nb::cast<std::size_t>(shape[1]) != npix)
        throw nb::value_error((std::string(call) + ": out must have shape (4, " + std::to_string(npix) +
                               ") (I, Q, U, V at the engine's NSIDE)").c_str());
      result = nb::borrow(out);
    }
    Vector rows[4] = {vector(result[0], "out[0]"), vector(result[1], "out[1]"), vector(result[2], "out[2]"),
                      vector(result[3], "out[3]")};
    std::string problem;
    bool out_of_memory = false;
    {
      nb::gil_scoped_release release;
      problem = check_values(p);
      if (problem.empty()) problem = check_hwp_values(h);
      if (problem.empty() && tod) {
        const std::size_t bad = first_non_finite(tod->data(), p.size);
        if (bad < p.size) problem = "tod[" + std::to_string(bad) + "] is " + format_double(tod->data()[bad]) + ": the adjoint needs finite values";
      }
      if (problem.empty()) {
        const auto lock = hold();
        Engine& e = open();
        try {
          if (what == Scatter::diagonal) {
            if (p.theta) e.adjoint_diagonal(d, p.angles(), span_of(h), span_of(time));
            else e.adjoint_diagonal(d, p.quaternions(), span_of(h), span_of(time));
          } else if (what == Scatter::normal) {
            if (p.theta) e.normal(d, p.angles(), span_of(h), span_of(time));
            else e.normal(d, p.quaternions(), span_of(h), span_of(time));
          } else {
            const std::span<const double> t{tod->data(), p.size};
            if (p.theta) e.adjoint(d, p.angles(), t, span_of(h), span_of(time));
            else e.adjoint(d, p.quaternions(), t, span_of(h), span_of(time));
          }
          e.take_adjoint({{rows[0].data(), npix}, {rows[1].data(), npix}, {rows[2].data(), npix}, {rows[3].data(), npix}});
        } catch (const std::bad_alloc&) {
          out_of_memory = true;
        }
      }
    }
    if (!problem.empty()) throw nb::value_error(problem.c_str());
    if (out_of_memory) raise_memory_error(chunk_memory(call, d, p.size));
    return result;
  }

  void set_sky(const Sky& sky) {
    nb::gil_scoped_release release;
    const auto lock = hold();
    open().set_sky(sky);
  }

  void prepare() {
    nb::gil_scoped_release release;
    const auto lock = hold();
    open().prepare();
  }

  std::uint64_t submit(nb::handle detector, nb::handle theta, nb::handle phi, nb::handle psi, nb::handle quats,
                       nb::handle out, bool accumulate, nb::handle hwp_angle, nb::handle time_arg) {
    const std::size_t d = detector_index(detector);
    const PointingArgs p = pointing_args(theta, phi, psi, quats);
    const std::optional<ConstVector> h = hwp_args(hwp_angle, p.size);
    const std::optional<ConstVector> time = time_args(time_arg, p.size);
    if (out.is_none()) throw nb::type_error("submit: out is required (the array the TOD is written to by wait())");
    check_output_size(out, p.size);
    Vector tod = vector(out, "out");
    std::uint64_t ticket = 0;
    bool out_of_memory = false;
    const std::string problem = checked_run(p, h, [&](Engine& e) {
      // The plate's angles, like the pointing, are read before submit() returns.
      try {
        ticket = p.theta ? e.submit(d, p.angles(), {tod.data(), p.size}, accumulate, span_of(h), span_of(time))
                         : e.submit(d, p.quaternions(), {tod.data(), p.size}, accumulate, span_of(h), span_of(time));
      } catch (const std::bad_alloc&) {
        out_of_memory = true;
      }
    });
    if (!problem.empty()) throw nb::value_error(problem.c_str());
    if (out_of_memory) raise_memory_error(chunk_memory("submit", d, p.size));
    in_flight_[ticket] = nb::borrow(out);  // kept alive until wait() has written it
    return ticket;
  }

  // Masked skies: a new bool array, True where the sample's disc holds an UNSEEN sky pixel.
  nb::object flag_samples(nb::handle detector, nb::handle theta, nb::handle phi, nb::handle psi, nb::handle quats) {
    const std::size_t d = detector_index(detector);
    const PointingArgs p = pointing_args(theta, phi, psi, quats, "flag_samples");
    nb::object result = nb::module_::import_("numpy").attr("zeros")(p.size, "bool");
    auto flags = nb::cast<nb::ndarray<bool, nb::ndim<1>, nb::c_contig, nb::device::cpu>>(result);
    // bool is one byte holding 0 or 1: the engine's uint8 flags are written into it in place.
    static_assert(sizeof(bool) == sizeof(std::uint8_t));
    const std::span<std::uint8_t> out(reinterpret_cast<std::uint8_t*>(flags.data()), p.size);
    const std::string problem = checked_run(p, std::nullopt, [&](Engine& e) {
      if (p.theta)
        e.flag_samples(d, p.angles(), out);
      else
        e.flag_samples(d, p.quaternions(), out);
    });
    if (!problem.empty()) throw nb::value_error(problem.c_str());
    return result;
  }

  void wait(std::optional<long long> ticket_arg) {
    std::optional<std::uint64_t> ticket;
    if (ticket_arg) ticket = unsigned_arg<std::uint64_t>(*ticket_arg, "ticket");
    // The submissions waited for are done even when one of them failed (a non-finite TOD sample):
    // their arrays are released either way.
    const auto release_arrays = [&] {
      if (ticket)
        in_flight_.erase(in_flight_.begin(), in_flight_.upper_bound(*ticket));
      else
        in_flight_.clear();
    };
    bool out_of_memory = false;
    try {
      nb::gil_scoped_release release;
      const auto lock = hold();
      Engine& e = open();
      try {
        if (ticket)
          e.wait(*ticket);
        else
          e.wait();
      } catch (const std::bad_alloc&) {
        out_of_memory = true;
      }
    } catch (const pisco::Error&) {
      release_arrays();
      throw;
    }
    release_arrays();
    if (out_of_memory) raise_memory_error("Engine.wait: memory ran out completing the submissions");
  }

  void close() {
    {
      nb::gil_scoped_release release;
      const auto lock = hold();
      engine_.reset();
    }
    in_flight_.clear();
  }

  bool closed() const { return !engine_; }
  // The engine's lock, taken without the GIL. Inside DeconvolvingMapmaker.solve, whose thread holds
  // it for the whole solve, a call from the survey raises instead of waiting for itself.
  std::unique_lock<std::mutex> hold() {
    if (solver_.load() == std::this_thread::get_id())
      throw nb::value_error("Engine: used by the survey of a DeconvolvingMapmaker.solve that is running on it; "
                            "the survey must only yield the chunks");
    return std::unique_lock<std::mutex>(mutex_);
  }
  // The engine for DeconvolvingMapmaker's calls, under hold(): raises once close() has freed it.
  Engine& open_for(const char* call) {
    if (!engine_)
      throw nb::value_error((std::string(call) + ": its engine was closed (Engine.close()); make the "
                                                 "DeconvolvingMapmaker with an open engine").c_str());
    return *engine_;
  }
  // Marks the thread that holds the lock for a DeconvolvingMapmaker.solve (default id: none).
  void set_solver(std::thread::id id) { solver_.store(id); }
  std::string backend_name() { return locked([](Engine& e) { return e.backend_name(); }); }
  std::string device_name() { return locked([](Engine& e) { return e.device_name(); }); }
  double mean_disc_pixels() { return locked([](Engine& e) { return e.mean_disc_pixels(); }); }
  std::uint64_t polar_samples() { return locked([](Engine& e) { return e.polar_samples(); }); }
  std::uint64_t staged_samples() { return locked([](Engine& e) { return e.staged_samples(); }); }
  int sidelobe_nside() { return locked([](Engine& e) { return e.sidelobe_nside(); }); }
  std::size_t unseen_pixels() { return locked([](Engine& e) { return e.unseen_pixels(); }); }
  FocalPlane focal_plane() { return locked([](Engine& e) { return e.focal_plane(); }); }
  std::size_t size() const { return names_.size(); }
  std::size_t npix() { return open().npix(); }
  // For pisco.DeconvolvingMapmaker, which drives this engine.
  Engine& engine() { return open(); }
  std::size_t detector(nb::handle d) const { return detector_index(d); }

 private:
  Engine& open() {
    if (!engine_) throw nb::value_error("Engine: used after close()");
    return *engine_;
  }

  template <class F>
  std::invoke_result_t<F, Engine&> locked(F f) {
    nb::gil_scoped_release release;
    const auto lock = hold();
    return f(open());
  }

  std::size_t detector_index(nb::handle detector) const {
    if (nb::isinstance<nb::str>(detector)) {
      const auto name = nb::cast<std::string>(detector);
      for (std::size_t i = 0; i < names_.size(); ++i)
        if (names_[i] == name) return i;
      throw nb::key_error(("detector: the focal plane has no detector named '" + name + "'").c_str());
    }
    long long i = 0;
    if (!nb::try_cast(detector, i, false))
      throw nb::type_error(("detector: expected an index or a name, got " + describe(detector)).c_str());
    if (i < 0 || i >= static_cast<long long>(names_.size()))
      throw nb::index_error(("detector: index " + std::to_string(i) + " but the focal plane has " +
                             std::to_string(names_.size()) + " detectors").c_str());
    return static_cast<std::size_t>(i);
  }

  std::string chunk_memory(const char* call, std::size_t detector, std::size_t samples) const {
    return "Engine." + std::string(call) + ": memory ran out for a chunk of " + std::to_string(samples) +
           " samples of detector '" + names_[detector] + "'; give shorter chunks";
  }

  static void check_output_size(nb::handle out, std::size_t n) {
    check_array(out, "out", 1, 0, true);
    const auto len = nb::cast<std::size_t>(nb::cast<nb::tuple>(out.attr("shape"))[0]);
    if (len != n)
      throw nb::value_error(("out: " + std::to_string(len) + " samples, but the pointing has " + std::to_string(n))
                                .c_str());
  }

  // The pointing's and plate angles' values checked without the GIL, then `work` on the engine under
  // its lock; returns the first bad value, named (the work not done), or an empty string.
  template <class Work>
  std::string checked_run(const PointingArgs& p, const std::optional<ConstVector>& h, Work&& work) {
    nb::gil_scoped_release release;
    std::string problem = check_values(p);
    if (problem.empty()) problem = check_hwp_values(h);
    if (!problem.empty()) return problem;
    const auto lock = hold();
    work(open());
    return {};
  }

  // `out`, checked, or a new array of n samples (accumulating needs the caller's array).
  static nb::object output(nb::handle out, std::size_t n, bool accumulate) {
    if (out.is_none()) {
      if (accumulate) throw nb::type_error("convolve: accumulate=True adds into `out`, which must then be given");
      return nb::module_::import_("numpy").attr("empty")(n, "float64");
    }
    check_output_size(out, n);
    return nb::borrow(out);
  }

  // The outputs of submissions not yet waited for, kept alive until then. Declared before engine_,
  // so destroyed after it: the engine completes its work before the arrays can go.
  std::map<std::uint64_t, nb::object> in_flight_;
  std::mutex mutex_;
  std::atomic<std::thread::id> solver_{};
  std::vector<std::string> names_;
  std::unique_ptr<Engine> engine_;
};

// pisco.DeconvolvingMapmaker: pisco::DeconvolvingMapmaker over a pisco.Engine (kept alive), the survey
// a Python callable returning an iterable of chunks (dicts), called once an iteration.
class PyMapmaker {
 public:
  PyMapmaker(nb::object engine, int max_iterations, double tolerance, double regularization, double target_fwhm,
             const std::string& regularize, double rcond_min, int coverage_nside)
      : owner_(std::move(engine)), py_(nb::cast<PyEngine&>(owner_)) {
    DeconvolutionOptions o;
    o.rcond_min = rcond_min;
    o.coverage_nside = coverage_nside;
    o.max_iterations = max_iterations;
    o.tolerance = tolerance;
    o.regularization = regularization;
    o.target_fwhm = target_fwhm;
    if (regularize == "polarization") o.regularize = DeconvolutionOptions::Regularize::polarization;
    else if (regularize != "all")
      throw nb::value_error(("DeconvolvingMapmaker: regularize = '" + regularize + "'; expected 'all' or 'polarization'").c_str());
    maker_ = std::make_unique<DeconvolvingMapmaker>(py_.engine(), o);
  }

  void add(nb::handle detector, nb::handle tod_arg, nb::handle theta, nb::handle phi, nb::handle psi, nb::handle quats,
           nb::handle hwp_angle) {
    const Chunk c = chunk(detector, theta, phi, psi, quats, hwp_angle, "DeconvolvingMapmaker.add");
    const ConstVector tod = const_vector(tod_arg, "tod");
    if (tod.shape(0) != c.chunk.size())
      throw nb::value_error(("DeconvolvingMapmaker.add: tod has " + std::to_string(tod.shape(0)) +
                             " samples, but the pointing has " + std::to_string(c.chunk.size())).c_str());
    nb::gil_scoped_release release;
    const auto lock = py_.hold();
    py_.open_for("DeconvolvingMapmaker.add");
    maker_->add(c.chunk, {tod.data(), tod.shape(0)});
  }

  nb::dict solve(nb::callable survey, nb::object progress) {
    const auto replay = [&](const std::function<void(const SurveyChunk&)>& visit) {
      nb::gil_scoped_acquire gil;
      const nb::object chunks = survey();
      for (nb::handle item : chunks) {
        if (!nb::isinstance<nb::dict>(item))
          throw nb::type_error("DeconvolvingMapmaker.solve: the survey must yield dicts with 'detector' and the "
                               "pointing ('theta', 'phi', 'psi' or 'boresight_quats'; 'hwp_angle' for plates)");
        const nb::dict d = nb::borrow<nb::dict>(item);
        const auto get = [&](const char* key) -> nb::object {
          return d.contains(key) ? nb::object(d[key]) : nb::none();
        };
        if (!d.contains("detector")) throw nb::key_error("DeconvolvingMapmaker.solve: a chunk has no 'detector'");
        const Chunk c = chunk(d["detector"], get("theta"), get("phi"), get("psi"), get("boresight_quats"),
                              get("hwp_angle"), "DeconvolvingMapmaker.solve");
        nb::gil_scoped_release release;
        visit(c.chunk);  // under the engine's lock, which solve() holds
      }
    };
    std::function<void(const DeconvolutionProgress&)> report;
    if (!progress.is_none())
      report = [&](const DeconvolutionProgress& p) {
        nb::gil_scoped_acquire gil;
        progress(p.iteration, p.residual, p.seconds);
      };
    DeconvolvedMaps m;
    {
      // The engine's lock for the whole solve: the solver's own calls (its sky, its adjoint maps) and
      // the survey's chunks, so that no other thread's call and no close() comes between them.
      nb::gil_scoped_release release;
      const auto lock = py_.hold();
      py_.open_for("DeconvolvingMapmaker.solve");
      py_.set_solver(std::this_thread::get_id());
      struct Unmark {
        PyEngine& e;
        ~Unmark() { e.set_solver({}); }
      } unmark{py_};
      m = maker_->solve(replay, report);
    }
    nb::dict out;
    const auto array = [](const std::vector<double>& v) {
      nb::object a = nb::module_::import_("numpy").attr("empty")(v.size(), "float64");
      Vector w = vector(a, "maps");
      std::copy(v.begin(), v.end(), w.data());
      return a;
    };
    out["nside"] = m.nside;
    out["I"] = array(m.I);
    out["Q"] = array(m.Q);
    out["U"] = array(m.U);
    out["V"] = array(m.V);
    if (!m.smoothed_I.empty()) {
      out["smoothed_I"] = array(m.smoothed_I);
      out["smoothed_Q"] = array(m.smoothed_Q);
      out["smoothed_U"] = array(m.smoothed_U);
    }
    out["iterations"] = m.iterations;
    out["converged"] = m.converged;
    out["left_out"] = m.left_out;
    out["polarization_pixels"] = m.polarization_pixels;
    out["polarization_unconstrained"] = m.polarization_unconstrained;
    if (!m.converged && !m.residuals.empty()) {
      const std::string w = "DeconvolvingMapmaker.solve did not converge: residual " + std::to_string(m.residuals.back()) +
                            " of ||A^T d|| after " + std::to_string(m.iterations) +
                            " iterations, above the tolerance; raise max_iterations or tolerance, or add regularization";
      if (PyErr_WarnEx(PyExc_RuntimeWarning, w.c_str(), 1) != 0) throw nb::python_error();
    }
    if (m.polarization_unconstrained &&
        PyErr_WarnEx(PyExc_RuntimeWarning,
                     "DeconvolvingMapmaker.solve: the survey's polarization angles constrain Q and U in no pixel; "
                     "the maps hold I alone (Q and U unseen)",
                     1) != 0)
      throw nb::python_error();
    out["residuals"] = array(m.residuals);
    out["seconds"] = m.seconds;
    out["seconds_per_iteration"] = m.seconds_per_iteration;
    return out;
  }

 private:
  // A chunk's arguments, checked, and the views into them (kept alive with it).
  struct Chunk {
    PointingArgs p;
    std::optional<ConstVector> h;
    SurveyChunk chunk;
  };
  Chunk chunk(nb::handle detector, nb::handle theta, nb::handle phi, nb::handle psi, nb::handle quats,
              nb::handle hwp_angle, const char* call) {
    Chunk c;
    c.chunk.detector = py_.detector(detector);
    c.p = pointing_args(theta, phi, psi, quats, call);
    c.h = hwp_args(hwp_angle, c.p.size);
    std::string problem = check_values(c.p);
    if (problem.empty()) problem = check_hwp_values(c.h);
    if (!problem.empty()) throw nb::value_error(problem.c_str());
    if (c.p.theta) c.chunk.angles = c.p.angles();
    else c.chunk.quats = c.p.quaternions();
    c.chunk.quaternions = !c.p.theta;
    c.chunk.hwp_angle = span_of(c.h);
    return c;
  }

  nb::object owner_;
  PyEngine& py_;
  std::unique_ptr<DeconvolvingMapmaker> maker_;
};

// pisco.SourceTrack: a point source's track, fixed or moving.
void bind_source_track(nb::module_& m) {
  nb::class_<SourceTrack>(m, "SourceTrack",
                          "A point source's track (pisco/sources.hpp, docs/sources.md): its direction and flux at a\n"
                          "sequence of strictly increasing times; between two, the great circle at a constant rate and\n"
                          "the flux linear in time; one point: a source fixed for all time. Flux: the integral of the\n"
                          "source's Stokes brightness, in the sky's units times steradians (COSMO Q and U).")
      .def(
          "__init__",
          [](SourceTrack* t, std::string name, std::vector<double> time, std::vector<double> theta,
             std::vector<double> phi, std::vector<double> I, std::vector<double> Q, std::vector<double> U,
             std::vector<double> V) {
            new (t) SourceTrack{std::move(name), std::move(time), std::move(theta), std::move(phi),
                                std::move(I),    std::move(Q),    std::move(U),     std::move(V)};
            t->check("SourceTrack");
          },
          "name"_a, "time"_a, "theta"_a, "phi"_a, "I"_a, "Q"_a = std::vector<double>{}, "U"_a = std::vector<double>{},
          "V"_a = std::vector<double>{},
          "Arrays of one value per time (Q, U, V may be left out: zero); pisco.Error names a bad point.")
      .def_static(
          "fixed",
          [](std::string name, double theta, double phi, double I, double Q, double U, double V) {
            SourceTrack t = SourceTrack::fixed(std::move(name), theta, phi, I, Q, U, V);
            t.check("SourceTrack.fixed");
            return t;
          },
          "name"_a, "theta"_a, "phi"_a, "I"_a, "Q"_a = 0.0, "U"_a = 0.0, "V"_a = 0.0, "A source fixed at (theta, phi).")
      .def_ro("name", &SourceTrack::name)
      .def_ro("time", &SourceTrack::time)
      .def_ro("theta", &SourceTrack::theta)
      .def_ro("phi", &SourceTrack::phi)
      .def_ro("I", &SourceTrack::I)
      .def_ro("Q", &SourceTrack::Q)
      .def_ro("U", &SourceTrack::U)
      .def_ro("V", &SourceTrack::V)
      .def_static(
          "read_csv",
          [](const std::filesystem::path& path, std::string name) { return SourceTrack::read_csv(path, std::move(name)); },
          "path"_a, "name"_a,
          "The track in a CSV track file (docs/formats.md, 'Source tracks': columns time_s, theta_deg, phi_deg,\n"
          "I and optionally Q, U, V), named `name`; pisco.Error names the file, line and column of a fault.")
      .def("write_csv", &SourceTrack::write_csv, "path"_a,
           "Writes the track as a CSV track file (every column, all digits), whole or not at all.")
      .def("__repr__", [](const SourceTrack& t) {
        return "SourceTrack('" + t.name + "', " + std::to_string(t.time.size()) + " points)";
      });
}

// pisco.DeconvolvingMapmaker: the beam-deconvolving map-maker over an engine.
void bind_mapmaker(nb::module_& m) {
  nb::class_<PyMapmaker>(m, "DeconvolvingMapmaker",
                         "The beam-deconvolving map-maker (docs/physics.md, 'Map-making with the beams'):\n"
                         "conjugate gradients on (A^T A + lambda) s = A^T d with each detector's own beam.\n\n"
                         "DeconvolvingMapmaker(engine, max_iterations=100, tolerance=1e-6, regularization=0.0,\n"
                         "                     target_fwhm=0.0, regularize='all', rcond_min=1e-3, coverage_nside=0)\n\n"
                         "regularize: 'all' Stokes parameters, or 'polarization' (Q, U, V) only. rcond_min and\n"
                         "coverage_nside: Q, U and V are solved only where the survey's angles constrain them (the\n"
                         "binned 3x3 matrices at coverage_nside, 0 for the engine's NSIDE / 4).\n"
                         "engine: a pisco.Engine whose backend has the adjoint; its sky is replaced as the solver\n"
                         "iterates (set_sky it again afterwards). add() each chunk's TOD, then solve(survey), survey\n"
                         "a callable returning the same chunks each time, as dicts: {'detector': ..., 'theta': ...,\n"
                         "'phi': ..., 'psi': ...} or {'detector': ..., 'boresight_quats': ...}, with 'hwp_angle'\n"
                         "for detectors with a plate.")
      .def(nb::init<nb::object, int, double, double, double, const std::string&, double, int>(), "engine"_a,
           "max_iterations"_a = 100, "tolerance"_a = 1e-6, "regularization"_a = 0.0, "target_fwhm"_a = 0.0,
           "regularize"_a = "all", "rcond_min"_a = 1e-3, "coverage_nside"_a = 0)
      .def("add", &PyMapmaker::add, "detector"_a, "tod"_a, "theta"_a = nb::none(), "phi"_a = nb::none(),
           "psi"_a = nb::none(), nb::kw_only(), "boresight_quats"_a = nb::none(), "hwp_angle"_a = nb::none(),
           "Adds a chunk's TOD to the right-hand side A^T d.")
      .def("solve", &PyMapmaker::solve, "survey"_a, "progress"_a = nb::none(),
           "Solves; progress(iteration, residual, seconds) after each iteration when given. Returns a\n"
           "dict: nside, I, Q, U, V (UNSEEN where no beam reaches, Q, U and V also where the angles do not\n"
           "constrain them), smoothed_I/Q/U with a target_fwhm, iterations, converged, residuals, seconds,\n"
           "seconds_per_iteration, left_out (what was left out, a line each), polarization_pixels and\n"
           "polarization_unconstrained. A solve that does not converge, or that constrains no pixel's\n"
           "polarization, also issues a RuntimeWarning.");
}

// Engine.convolve and Engine.add_sources: a detector's TOD from the sky and from point sources.
void bind_engine_forward(nb::class_<PyEngine>& cls) {
  cls.def("convolve", &PyEngine::convolve, "detector"_a, "theta"_a = nb::none(), "phi"_a = nb::none(),
          "psi"_a = nb::none(), nb::kw_only(), "boresight_quats"_a = nb::none(), "out"_a = nb::none(),
          "accumulate"_a = false, "hwp_angle"_a = nb::none(), "time"_a = nb::none(),
          "The TOD of one detector (an index or its name) for a chunk of boresight pointing.\n\n"
          "Pointing: theta, phi, psi (1-D float64 arrays, radians), or boresight_quats ((n, 4) float64,\n"
          "x, y, z, w, TOAST's and litebird_sim's layout); the engine applies the detector's offset.\n"
          "out: a writable 1-D float64 array of n samples, written (or added to, with accumulate=True);\n"
          "None allocates one. Returns out. Arrays are used in place, never copied: a wrong dtype raises\n"
          "TypeError, a wrong shape, a strided or read-only array or a non-finite value ValueError.\n"
          "hwp_angle: the half-wave plate's angle per sample (1-D float64, radians, in the focal-plane\n"
          "frame: TOAST's hwp_angle), required for a detector with a plate (Detector.hwp) and refused for\n"
          "one without (pisco.Error). time: each sample's time (1-D float64, seconds), required for a\n"
          "detector whose beam changes with time (Detector.beam_sequence) and ignored for others. The GIL\n"
          "is released while the engine runs.")
      .def("add_sources", &PyEngine::add_sources, "detector"_a, "time"_a, "sources"_a, "theta"_a = nb::none(),
           "phi"_a = nb::none(), "psi"_a = nb::none(), nb::kw_only(), "boresight_quats"_a = nb::none(),
           "out"_a = nb::none(), "hwp_angle"_a = nb::none(),
           "Point sources, fixed or moving (pisco.SourceTrack), added into the TOD of one detector: the\n"
           "detector's beam evaluated at each source's direction per sample, exactly (no pixelization, the\n"
           "same near the poles as anywhere), with its half-wave plate and split beam; docs/sources.md.\n\n"
           "time: each sample's time on the sources' clock (1-D float64). Pointing and hwp_angle as for\n"
           "convolve(). out: a writable 1-D float64 array the sources are added to (a TOD from convolve());\n"
           "None: new zeros. Returns out. Needs normalization='integral'. Computed on the host in float64,\n"
           "the same whatever the backend.");
}

// Engine.adjoint, .adjoint_diagonal and .normal: the TOD scattered back onto the sky, for map-making.
void bind_engine_adjoint(nb::class_<PyEngine>& cls) {
  cls.def("adjoint",
          [](PyEngine& e, nb::handle detector, nb::handle tod, nb::handle theta, nb::handle phi, nb::handle psi,
             nb::handle quats, nb::handle out, nb::handle hwp, nb::handle time) {
            return e.adjoint(detector, tod, theta, phi, psi, quats, out, hwp, time, PyEngine::Scatter::adjoint);
          },
          "detector"_a, "tod"_a, "theta"_a = nb::none(), "phi"_a = nb::none(), "psi"_a = nb::none(), nb::kw_only(),
          "boresight_quats"_a = nb::none(), "out"_a = nb::none(), "hwp_angle"_a = nb::none(), "time"_a = nb::none(),
          "The adjoint of convolve(): A^T tod, the TOD of one detector scattered back onto the sky with the\n"
          "same weights, offsets, plates and quadrature, so that sum(sky * A^T d) = sum(A sky * d).\n\n"
          "Pointing, hwp_angle and time as for convolve(); tod: 1-D float64, one value per sample. out: a (4, npix)\n"
          "float64 array (I, Q, U, V at the engine's NSIDE) the result is added into; None: new zeros.\n"
          "Returns out. Backends without it raise pisco.UnavailableError (capabilities['adjoint']).")
      .def("adjoint_diagonal",
           [](PyEngine& e, nb::handle detector, nb::handle theta, nb::handle phi, nb::handle psi, nb::handle quats,
              nb::handle out, nb::handle hwp, nb::handle time) {
             return e.adjoint(detector, nb::none(), theta, phi, psi, quats, out, hwp, time, PyEngine::Scatter::diagonal);
           },
           "detector"_a, "theta"_a = nb::none(), "phi"_a = nb::none(), "psi"_a = nb::none(), nb::kw_only(),
           "boresight_quats"_a = nb::none(), "out"_a = nb::none(), "hwp_angle"_a = nb::none(), "time"_a = nb::none(),
           "The diagonal of A^T A for these samples (squared scatter weights per pixel and Stokes parameter),\n"
           "added into out ((4, npix)) or new zeros: a preconditioner for iterative map-making.")
      .def("normal",
           [](PyEngine& e, nb::handle detector, nb::handle theta, nb::handle phi, nb::handle psi, nb::handle quats,
              nb::handle out, nb::handle hwp, nb::handle time) {
             return e.adjoint(detector, nb::none(), theta, phi, psi, quats, out, hwp, time, PyEngine::Scatter::normal);
           },
           "detector"_a, "theta"_a = nb::none(), "phi"_a = nb::none(), "psi"_a = nb::none(), nb::kw_only(),
           "boresight_quats"_a = nb::none(), "out"_a = nb::none(), "hwp_angle"_a = nb::none(), "time"_a = nb::none(),
           "A^T A sky for these samples: adjoint(convolve(...)) of the engine's sky (set_sky's), added into\n"
           "out ((4, npix)) or new zeros; one pass over each disc where the backend can (simd), the same\n"
           "result as the two calls. An iterative map-maker's step.");
}

// The engine's sky, its asynchronous submissions, its figures and its life as a context manager.
void bind_engine_state(nb::class_<PyEngine>& cls) {
  cls.def("set_sky", &PyEngine::set_sky, "sky"_a,
          "Replaces the sky (the same NSIDE), keeping beams, detectors and options.")
      .def("prepare", &PyEngine::prepare,
           "Completes the set-up that runs in the background (the sky's polar copy, started at construction\n"
           "and set_sky), without the GIL; otherwise the first submission near a pole completes it.")
      .def_prop_ro("npix", [](PyEngine& e) { return e.npix(); }, "Pixels of the engine's sky (12 NSIDE^2).")
      .def("submit", &PyEngine::submit, "detector"_a, "theta"_a = nb::none(), "phi"_a = nb::none(),
           "psi"_a = nb::none(), nb::kw_only(), "boresight_quats"_a = nb::none(), "out"_a = nb::none(),
           "accumulate"_a = false, "hwp_angle"_a = nb::none(), "time"_a = nb::none(),
           "Like convolve(), asynchronously: the pointing (hwp_angle, time) are read before submit() returns\n"
           "a ticket; out (required) is written by the time wait(ticket) returns.")
      .def("convolve_detectors", &PyEngine::convolve_detectors, "detectors"_a, "theta"_a = nb::none(),
           "phi"_a = nb::none(), "psi"_a = nb::none(), nb::kw_only(), "boresight_quats"_a = nb::none(),
           "out"_a = nb::none(), "accumulate"_a = false, "hwp_angle"_a = nb::none(), "time"_a = nb::none(),
           "Like convolve() for several detectors (indices or names) on the same boresight pointing: a list\n"
           "of their TODs, each the bits convolve() gives, written into out's arrays when given (a list, or a\n"
           "2-D array's rows; accumulate=True adds into them). The pointing is checked once, and a GPU backend\n"
           "stages it once in each of its two slots rather than once per detector. hwp_angle goes to the\n"
           "detectors with a plate, time to those whose beam changes with time. Without the GIL.")
      .def("flag_samples", &PyEngine::flag_samples, "detector"_a, "theta"_a = nb::none(), "phi"_a = nb::none(),
           "psi"_a = nb::none(), nb::kw_only(), "boresight_quats"_a = nb::none(),
           "Masked skies (unseen='flag'): a new 1-D bool array, True where the sample's disc (the\n"
           "detector's, its offset applied; the convolution's own disc: the sky pixels whose centres lie\n"
           "within the beam's rho_max) holds a pixel UNSEEN in the sky. Such samples are convolved with\n"
           "those pixels taken as 0: leave them out of maps. All False with no UNSEEN pixel or another\n"
           "policy. Pointing as for convolve(), checked alike; computed on the host, without the GIL.")
      .def("wait", &PyEngine::wait, "ticket"_a = nb::none(),
           "Waits for submission `ticket` and every earlier one (all, without a ticket).")
      .def("close", &PyEngine::close, "Frees the engine (its device memory); later calls raise ValueError.")
      .def_prop_ro("closed", &PyEngine::closed)
      .def_prop_ro("backend", &PyEngine::backend_name, "The backend in use ('cpu', 'simd', 'vulkan', 'cuda').")
      .def_prop_ro("device", &PyEngine::device_name, "The device in use.")
      .def_prop_ro("sidelobe_nside", &PyEngine::sidelobe_nside,
                   "The NSIDE of the band-limited sky the split beams' outer parts are summed on (0: no split beam).")
      .def_prop_ro("polar_samples", &PyEngine::polar_samples,
                   "Samples summed so far on the sky's polar copy (quadrature='corrected': those whose disc\n"
                   "reaches near a HEALPix pole).")
      .def_prop_ro("staged_samples", &PyEngine::staged_samples,
                   "Pointing samples staged for the device so far (vulkan, cuda; 0 on cpu and simd): once a\n"
                   "detector, or once a slot for convolve_detectors.")
      .def_prop_ro("mean_disc_pixels", &PyEngine::mean_disc_pixels,
                   "Mean number of sky pixels summed per sample so far.")
      .def_prop_ro("unseen_pixels", &PyEngine::unseen_pixels,
                   "The number of UNSEEN sky pixels taken as 0 (unseen='zero' or 'flag').")
      .def_prop_ro("focal_plane", &PyEngine::focal_plane, "The engine's focal plane (a copy).")
      .def("__len__", &PyEngine::size)
      .def("__enter__", [](nb::handle self) { return nb::borrow(self); })
      .def("__exit__", [](PyEngine& e, nb::handle, nb::handle, nb::handle) { e.close(); }, "exc_type"_a = nb::none(),
           "exc_value"_a = nb::none(), "traceback"_a = nb::none())
      .def("__repr__", [](PyEngine& e) {
        if (e.closed()) return std::string("pisco.Engine(closed)");
        return "pisco.Engine(backend='" + e.backend_name() + "', device='" + e.device_name() + "', " +
               std::to_string(e.size()) + " detectors)";
      });
}

}  // namespace

void bind_engine(nb::module_& m) {
  bind_source_track(m);
  bind_mapmaker(m);
  nb::class_<PyEngine> cls(
      m, "Engine",
      "The convolution engine: the sky, beams and focal plane are set up once for a backend,\n"
      "then chunks of pointing become TOD.\n\n"
      "Engine(sky, beams, focal_plane, backend='auto', device='auto', chunk_samples=0,\n"
      "       normalization='integral', threads=0, arithmetic='auto', unseen='error',\n"
      "       quadrature='corrected')\n\n"
      "beams: one pisco.Beamsor or a sequence (Detector.beam indexes it). backend: 'cpu', 'simd',\n"
      "'vulkan', 'cuda' or 'auto' (the best present: pisco.devices()). device (vulkan, cuda): an\n"
      "index or part of a name; simd: its instruction set. threads (cpu, simd): 0 for all.\n"
      "chunk_samples (vulkan, cuda): 0 fits the device. arithmetic (vulkan): 'auto', 'float64' or\n"
      "'float-float', the kernel's float64 work; 'auto' takes float-float on devices without float64.\n"
      "A setting other than its default for a named backend without it is a pisco.InputError.\n"
      "unseen: the sky's UNSEEN pixels (a masked map): 'error' (the default: pisco.Error naming\n"
      "their number and the first), 'zero' (taken as 0), or 'flag' (taken as 0, and\n"
      "flag_samples() tells which samples' discs hold one).\n"
      "quadrature: 'corrected' (the default: samples near the HEALPix poles are summed on a copy of\n"
      "the sky turned by 90 deg, exact for skies band-limited to 2 NSIDE, and the rings where the\n"
      "polar caps meet the belt weighted) or 'plain' (the equal-weight pixel sum everywhere).\n"
      "Usable as a context manager; close() frees the device's memory.");
  cls.def(nb::init<const Sky&, nb::handle, const FocalPlane&, const std::string&, const std::string&, long long,
                   const std::string&, long long, const std::string&, const std::string&, const std::string&>(),
          "sky"_a, "beams"_a, "focal_plane"_a, "backend"_a = "auto", "device"_a = "auto", "chunk_samples"_a = 0,
          "normalization"_a = "integral", "threads"_a = 0, "arithmetic"_a = "auto", "unseen"_a = "error",
          "quadrature"_a = "corrected");
  bind_engine_forward(cls);
  bind_engine_adjoint(cls);
  bind_engine_state(cls);
}

}  // namespace pisco::python
