// The extension module pisco._pisco (docs/python.md): skies, beamsors, focal planes and helpers.
// The engine is bound in engine.cpp. The package python/pisco/ re-exports these names and adds the
// framework adapters (pisco.toast, pisco.litebird).
#include <array>
#include <cmath>
#include <complex>
#include <cstdint>
#include <new>
#include <filesystem>
#include <numbers>
#include <optional>
#include <string>
#include <utility>
#include <vector>

#include <nanobind/nanobind.h>
#include <nanobind/ndarray.h>
#include <nanobind/stl/filesystem.h>
#include <nanobind/stl/function.h>
#include <nanobind/stl/optional.h>
#include <nanobind/stl/string.h>
#include <nanobind/stl/tuple.h>
#include <nanobind/stl/vector.h>

#include "args.hpp"
#include "arrays.hpp"
#include "pisco/pisco.hpp"

namespace nb = nanobind;
using namespace nb::literals;

namespace pisco::python {
void bind_engine(nb::module_& m);
void bind_simulation(nb::module_& m);  // simulation.cpp

namespace {

using NumpyVector = nb::ndarray<nb::numpy, double, nb::ndim<1>>;
using NumpyConstVector = nb::ndarray<nb::numpy, const double, nb::ndim<1>>;

// A numpy array of 4 doubles (x, y, z, w), a copy.
nb::ndarray<nb::numpy, double, nb::shape<4>> quat_array(const Quat& q) {
  auto* data = new double[4]{q.x, q.y, q.z, q.w};
  nb::capsule owner(data, [](void* p) noexcept { delete[] static_cast<double*>(p); });
  return nb::ndarray<nb::numpy, double, nb::shape<4>>(data, {4}, owner);
}

// A rotation (x, y, z, w): unit to within pisco.unit_quat_tolerance, the rounding normalized away; a
// quaternion further from unit norm is a mistake, refused (ValueError naming `name` and the norm).
Quat quat_from(nb::handle obj, const char* name) {
  std::vector<double> v;
  if (!nb::try_cast(obj, v) || v.size() != 4)
    throw nb::value_error((std::string(name) + ": expected four numbers (x, y, z, w), got " + describe(obj)).c_str());
  const Quat q{v[0], v[1], v[2], v[3]};
  if (const std::string problem = rotation_problem(q); !problem.empty())
    throw nb::value_error((std::string(name) + ": the quaternion (" + format_double(q.x) + ", " + format_double(q.y) +
                           ", " + format_double(q.z) + ", " + format_double(q.w) + ") " + problem)
                              .c_str());
  return normalized(q);
}

// The four Stokes maps of a sky of this NSIDE, as "2.58e+10 bytes".
std::string sky_bytes(long long nside) { return bytes_text(4.0 * 12.0 * double(nside) * double(nside) * 8.0); }

void check_nside_value(long long nside, const char* name) {
  if (!valid_nside(nside))
    throw nb::value_error((std::string(name) + ": NSIDE = " + std::to_string(nside) +
                           " is not a power of two in [1, " + std::to_string(max_nside) + "]").c_str());
}

// The library's Mueller check (pisco::check_mueller) as a ValueError.
void check_mueller_arg(const Mueller& m, const std::string& name, MuellerBounds bounds) {
  try {
    check_mueller(m, name, bounds);
  } catch (const pisco::Error& e) {
    throw nb::value_error(e.what());
  }
}

// A 4x4 Mueller matrix given as 4 rows of 4 numbers, finite (ValueError naming `name`).
Mueller mueller_from(nb::handle obj, const std::string& name) {
  Mueller m{};
  std::vector<std::vector<double>> rows;
  if (!nb::try_cast(obj, rows) || rows.size() != 4)
    throw nb::value_error((name + ": expected a 4x4 matrix, got " + describe(obj)).c_str());
  for (int i = 0; i < 4; ++i) {
    if (rows[i].size() != 4) throw nb::value_error((name + ": expected a 4x4 matrix").c_str());
    for (int j = 0; j < 4; ++j) m[i][j] = rows[i][j];
  }
  check_mueller_arg(m, name, MuellerBounds::finite);
  return m;
}

// The `sidelobes` argument of the beam builders: None, rho_main, or (rho_main[, taper[, nside]]).
pisco::SidelobeSplit split_from(nb::handle value) {
  pisco::SidelobeSplit s;
  if (value.is_none()) return s;
  try {
    if (nb::isinstance<nb::float_>(value) || nb::isinstance<nb::int_>(value)) {
      s.rho_main = nb::cast<double>(value);
      return s;
    }
    const auto items = nb::cast<std::vector<double>>(value);
    if (items.empty() || items.size() > 3) throw nb::value_error("");
    s.rho_main = items[0];
    if (items.size() > 1) s.taper = items[1];
    if (items.size() > 2) {
      if (items[2] != std::floor(items[2]) || !(items[2] >= 0 && items[2] <= 8192)) throw nb::value_error("");
      s.nside = static_cast<int>(items[2]);
    }
  } catch (const std::exception&) {
    throw nb::value_error("sidelobes: expected None, rho_main (radians) or (rho_main, taper, nside)");
  }
  return s;
}

// far_sidelobe: None or (level_db, radius, width[, angle[, asymmetry]]), angles in radians.
FarSidelobe far_sidelobe_from(nb::handle far) {
  FarSidelobe f;
  if (far.is_none()) return f;
  std::vector<double> v;
  try {
    v = nb::cast<std::vector<double>>(far);
  } catch (const nb::cast_error&) {
    throw nb::value_error("far_sidelobe: expected None or (level_db, radius, width[, angle[, asymmetry]])");
  }
  if (v.size() < 3 || v.size() > 5)
    throw nb::value_error("far_sidelobe: expected (level_db, radius, width[, angle[, asymmetry]]), radians");
  if (!(v[0] <= 0.0 && v[0] >= -200.0))
    throw nb::value_error("far_sidelobe: level_db must lie in [-200, 0] (dB of the main beam's peak)");
  f.level = std::pow(10.0, v[0] / 10.0);
  f.radius = v[1];
  f.width = v[2];
  if (v.size() > 3) f.angle = v[3];
  if (v.size() > 4) f.asymmetry = v[4];
  return f;
}

BeamOptions beam_options(double rho_max, double grid_step, double cross_polar, const std::string& pattern,
                         nb::handle mueller, nb::handle sidelobes = nb::none(), nb::handle far = nb::none()) {
  BeamOptions o;
  o.rho_max = rho_max;
  o.grid_step = grid_step;
  o.cross_polar = cross_polar;
  if (pattern == "uniform")
    o.cross_polar_pattern = CrossPolarPattern::uniform;
  else if (pattern == "quadrupole")
    o.cross_polar_pattern = CrossPolarPattern::quadrupole;
  else
    throw nb::value_error(("cross_polar_pattern: expected 'uniform' or 'quadrupole', got '" + pattern + "'").c_str());
  // Its bounds are the library's check (check_beam_options, keyed "mueller"), when the beam is made.
  if (!mueller.is_none()) o.mueller = mueller_from(mueller, "mueller");
  o.split = split_from(sidelobes);
  o.far_sidelobe = far_sidelobe_from(far);
  return o;
}

nb::ndarray<nb::numpy, double, nb::shape<4, 4>> mueller_array(const Mueller& m) {
  auto* data = new double[16];
  for (int i = 0; i < 4; ++i)
    for (int j = 0; j < 4; ++j) data[i * 4 + j] = m[i][j];
  nb::capsule owner(data, [](void* p) noexcept { delete[] static_cast<double*>(p); });
  return nb::ndarray<nb::numpy, double, nb::shape<4, 4>>(data, {4, 4}, owner);
}

// A (4, 4) Mueller matrix argument: any real array-like of that shape (a list of rows, an int or float
// numpy array), converted once; TypeError for what is not numbers, ValueError naming `name` for a
// wrong shape or a non-finite entry.
Mueller mueller_arg(nb::handle obj, const std::string& name) {
  nb::module_ numpy = nb::module_::import_("numpy");
  if (nb::hasattr(obj, "dtype") && to_string(obj.attr("dtype").attr("kind")) == "c")
    throw nb::type_error((name + ": expected a real (4, 4) Mueller matrix, got a " + describe(obj)).c_str());
  nb::object array;
  try {
    array = numpy.attr("asarray")(obj, "float64");
  } catch (nb::python_error&) {
    throw nb::type_error((name + ": expected a (4, 4) Mueller matrix of numbers, got " + describe(obj)).c_str());
  }
  const nb::tuple shape = nb::cast<nb::tuple>(array.attr("shape"));
  if (shape.size() != 2 || nb::cast<std::size_t>(shape[0]) != 4 || nb::cast<std::size_t>(shape[1]) != 4)
    throw nb::value_error((name + ": expected a (4, 4) Mueller matrix (rows: the Stokes parameters I, Q, U, V "
                           "leaving the element, columns: those arriving), got shape " + to_string(shape))
                              .c_str());
  array = numpy.attr("ascontiguousarray")(array);
  const auto view = nb::cast<nb::ndarray<const double, nb::shape<4, 4>, nb::c_contig, nb::device::cpu>>(array);
  Mueller m{};
  for (int i = 0; i < 4; ++i)
    for (int j = 0; j < 4; ++j) {
      const double v = view.data()[4 * i + j];
      if (!std::isfinite(v))
        throw nb::value_error((name + "[" + std::to_string(i) + "][" + std::to_string(j) + "] is " +
                               format_double(v) + ": Mueller matrices must be finite").c_str());
      m[i][j] = v;
    }
  return m;
}

// A plate's M0: a Mueller matrix argument within a passive element's bounds (docs/physics.md,
// "Physical bounds on Mueller matrices"), ValueError naming `mueller` otherwise.
Mueller plate_mueller_arg(nb::handle obj) {
  const Mueller m = mueller_arg(obj, "mueller");
  check_mueller_arg(m, "mueller", MuellerBounds::passive);
  return m;
}

HwpPlacement placement_from(const std::string& name) {
  if (name == "aperture") return HwpPlacement::aperture;
  if (name == "detector") return HwpPlacement::detector;
  throw nb::value_error(("placement: expected 'aperture' or 'detector', got '" + name + "'").c_str());
}

const char* placement_name(HwpPlacement p) { return p == HwpPlacement::detector ? "detector" : "aperture"; }

double finite_arg(double value, const char* name) {
  if (!std::isfinite(value))
    throw nb::value_error((std::string(name) + " is " + format_double(value) + ": expected a finite angle (radians)")
                              .c_str());
  return value;
}

// A (4, 4) read-only numpy array holding a copy of m.
nb::object mueller_readonly(const Mueller& m) {
  auto* data = new double[16];
  for (int i = 0; i < 4; ++i)
    for (int j = 0; j < 4; ++j) data[i * 4 + j] = m[i][j];
  nb::capsule owner(data, [](void* p) noexcept { delete[] static_cast<double*>(p); });
  return nb::cast(nb::ndarray<nb::numpy, const double, nb::shape<4, 4>>(data, {4, 4}, owner));
}

// None or a HalfWavePlate, for Detector.hwp and the `hwp` arguments.
std::optional<HalfWavePlate> plate_arg(nb::handle obj) {
  if (obj.is_none()) return std::nullopt;
  if (!nb::isinstance<HalfWavePlate>(obj))
    throw nb::type_error(("hwp: expected a pisco.HalfWavePlate or None, got " + describe(obj)).c_str());
  return nb::cast<HalfWavePlate>(obj);
}

std::string plate_repr(const HalfWavePlate& p) {
  const bool ideal = p.mueller == ideal_hwp_mueller();
  return std::string("pisco.HalfWavePlate(") + (ideal ? "ideal" : "mueller=[...]") + ", placement='" +
         placement_name(p.placement) + "', gamma=" + to_string(nb::repr(nb::float_(p.gamma))) + ")";
}

// A writable view of one Stokes map, keeping the Python Sky alive. Returned as a plain object: the
// view already has its owner, which a property's default reference_internal policy would set again.
nb::object stokes_view(nb::handle self, StokesIndex k) {
  auto map = nb::cast<Sky&>(self).stokes(k);
  return nb::cast(NumpyVector(map.data(), {map.size()}, self));
}

void bind_sky(nb::module_& m) {
  nb::class_<Sky>(m, "Sky",
                  "A polarized sky: HEALPix I, Q, U, V maps (RING ordering, COSMO polarization convention).\n\n"
                  "Sky(nside, units='K_CMB') is a sky of zeros; Sky.from_maps and Sky.read_fits fill one.\n"
                  "The maps I, Q, U, V are writable numpy views of the sky's own storage (no copy).")
      .def("__init__",
           [](Sky* self, long long nside, std::string units) {
             check_nside_value(nside, "nside");
             try {
               new (self) Sky(static_cast<int>(nside), std::move(units));
             } catch (const std::bad_alloc&) {
               raise_memory_error("pisco.Sky(nside=" + std::to_string(nside) + "): " + sky_bytes(nside) +
                                  " of maps could not be allocated");
             }
           },
           "nside"_a, "units"_a = "K_CMB")
      .def_static(
          "from_maps",
          [](nb::handle maps, std::string units) {
            // One 1-D float64 array per Stokes map (a (k, npix) array iterates as its rows), k = 1, 3 or 4.
            std::vector<nb::object> rows;
            if (nb::hasattr(maps, "ndim") && nb::cast<int>(maps.attr("ndim")) == 1) {
              rows.push_back(nb::borrow(maps));
            } else {
              for (nb::handle row : maps) rows.push_back(nb::borrow(row));
            }
            if (rows.size() != 1 && rows.size() != 3 && rows.size() != 4)
              throw nb::value_error(("maps: expected 1 (I), 3 (I, Q, U) or 4 (I, Q, U, V) maps, got " +
                                     std::to_string(rows.size())).c_str());
            std::vector<ConstVector> views;
            for (std::size_t k = 0; k < rows.size(); ++k) {
              const std::string name = "maps[" + std::to_string(k) + "]";
              views.push_back(const_vector(rows[k], name.c_str()));
            }
            const std::size_t npix = views[0].shape(0);
            long long nside = 1;
            while (12ll * nside * nside < static_cast<long long>(npix)) nside *= 2;
            if (12ll * nside * nside != static_cast<long long>(npix))
              throw nb::value_error(("maps: " + std::to_string(npix) +
                                     " pixels is not 12 NSIDE^2 for a power of two NSIDE").c_str());
            check_nside_value(nside, "maps");
            std::optional<Sky> made;
            try {
              made.emplace(static_cast<int>(nside), std::move(units));
            } catch (const std::bad_alloc&) {
              raise_memory_error("pisco.Sky.from_maps: a sky of NSIDE " + std::to_string(nside) + " (" +
                                 sky_bytes(nside) + " of maps) could not be allocated");
            }
            Sky& sky = *made;
            for (std::size_t k = 0; k < views.size(); ++k) {
              if (views[k].shape(0) != npix)
                throw nb::value_error(("maps[" + std::to_string(k) + "]: " + std::to_string(views[k].shape(0)) +
                                       " pixels, but maps[0] has " + std::to_string(npix)).c_str());
              const double* src = views[k].data();
              const std::size_t bad = first_non_finite(src, npix);
              if (bad < npix)
                throw nb::value_error(("maps[" + std::to_string(k) + "][" + std::to_string(bad) + "] is " +
                                       format_double(src[bad]) + ": sky maps must be finite").c_str());
              auto dst = sky.stokes(static_cast<StokesIndex>(k));
              std::copy(src, src + npix, dst.begin());
            }
            return std::move(sky);
          },
          "maps"_a, "units"_a = "K_CMB",
          "A sky from HEALPix RING maps: a (k, npix) float64 array or a sequence of k 1-D float64 arrays,\n"
          "k = 1 (I), 3 (I, Q, U) or 4 (I, Q, U, V), COSMO convention. The values are copied into the sky.")
      .def_static(
          "read_fits",
          [](const std::filesystem::path& path, const std::string& unseen) {
            const UnseenPolicy policy = unseen_policy_from(unseen);
            nb::gil_scoped_release release;
            return Sky::read_fits(path, policy);
          },
          "path"_a, "unseen"_a = "error",
          "Reads a HEALPix FITS map (1, 3 or 4 columns); NESTED is converted to RING, IAU to COSMO.\n\n"
          "unseen: what is done with UNSEEN pixels (pisco.unseen, a masked map): 'error' (the default:\n"
          "pisco.Error naming the file, the column, their number and the first), 'zero' (set to 0), or\n"
          "'flag' (kept as UNSEEN, for an Engine made with unseen='flag').")
      .def(
          "unseen_pixels",
          [](const Sky& s) {
            auto* pixels = new std::vector<std::int64_t>();
            for (std::size_t p : s.unseen_pixels()) pixels->push_back(static_cast<std::int64_t>(p));
            nb::capsule owner(pixels, [](void* p) noexcept { delete static_cast<std::vector<std::int64_t>*>(p); });
            return nb::ndarray<nb::numpy, std::int64_t, nb::ndim<1>>(pixels->data(), {pixels->size()}, owner);
          },
          "The RING indices of the pixels UNSEEN (pisco.unseen) in any Stokes map, ascending (int64).")
      .def("zero_unseen", &Sky::zero_unseen,
           "Sets the UNSEEN values of every Stokes map to 0; returns the number of pixels changed.")
      .def("write_fits", &Sky::write_fits, "path"_a,
           "Writes I, Q, U, V as a HEALPix FITS file (RING, COSMO), atomically.")
      .def_prop_ro("nside", &Sky::nside)
      .def_prop_ro("npix", &Sky::npix)
      .def_prop_ro("pixel_area", &Sky::pixel_area, "4 pi / npix, steradians.")
      .def_prop_rw("units", &Sky::units, &Sky::set_units)
      .def_prop_ro("I", [](nb::handle self) { return stokes_view(self, StokesIndex::I); })
      .def_prop_ro("Q", [](nb::handle self) { return stokes_view(self, StokesIndex::Q); })
      .def_prop_ro("U", [](nb::handle self) { return stokes_view(self, StokesIndex::U); })
      .def_prop_ro("V", [](nb::handle self) { return stokes_view(self, StokesIndex::V); })
      .def("__repr__", [](const Sky& s) {
        return "pisco.Sky(nside=" + std::to_string(s.nside()) + ", units='" + s.units() + "')";
      });
}

// Beamsor's analytic beams: gaussian, elliptical_gaussian, and from_field's beam of any field.
void bind_beamsor_analytic(nb::class_<Beamsor>& cls) {
  cls
      .def_static(
          "gaussian",
          [](double fwhm, double rho_max, double grid_step, double cross_polar, const std::string& pattern,
             nb::handle mueller, nb::handle sidelobes, nb::handle far) {
            return Beamsor::gaussian(fwhm, beam_options(rho_max, grid_step, cross_polar, pattern, mueller, sidelobes, far));
          },
          "fwhm"_a, "rho_max"_a = 5 * deg, "grid_step"_a = 0.0, "cross_polar"_a = 0.0,
          "cross_polar_pattern"_a = "uniform", "mueller"_a = nb::none(), "sidelobes"_a = nb::none(),
          "far_sidelobe"_a = nb::none(),
          "A circular Gaussian beam of full width at half maximum `fwhm` (radians), summed out to rho_max.\n"
          "grid_step 0 = fwhm / 16 (a round beam's radial profile: fwhm / 20). cross_polar: the cross-polar field ratio kappa ('uniform' or\n"
          "'quadrupole' pattern); mueller: a constant 4x4 Mueller matrix applied after the beam. far_sidelobe:\n"
          "(level_db, radius, width[, angle[, asymmetry]]), a ring of spillover (docs/beams.md, 'Far sidelobes').")
      .def_static(
          "elliptical_gaussian",
          [](double fwhm_x, double fwhm_y, double angle, double rho_max, double grid_step, double cross_polar,
             const std::string& pattern, nb::handle mueller, nb::handle sidelobes, nb::handle far) {
            return Beamsor::elliptical_gaussian(
                fwhm_x, fwhm_y, angle, beam_options(rho_max, grid_step, cross_polar, pattern, mueller, sidelobes, far));
          },
          "fwhm_x"_a, "fwhm_y"_a, "angle"_a = 0.0, "rho_max"_a = 5 * deg, "grid_step"_a = 0.0,
          "cross_polar"_a = 0.0, "cross_polar_pattern"_a = "uniform", "mueller"_a = nb::none(), "sidelobes"_a = nb::none(),
          "far_sidelobe"_a = nb::none(),
          "An elliptical Gaussian: fwhm_x along the direction `angle` (from theta' towards phi', radians),\n"
          "fwhm_y across it.")
      .def_static(
          "from_field",
          [](nb::callable field, double rho_max, double grid_step, std::string description, double feature_scale,
             bool radial, nb::handle sidelobes) {
            const Beamsor::Field f = [&field](double rho, double sigma) {
              nb::object value = field(rho, sigma);
              return mueller_from(value, "field(" + format_double(rho) + ", " + format_double(sigma) + ")");
            };
            return Beamsor::from_field(f, rho_max, grid_step, std::move(description), feature_scale, radial,
                                       split_from(sidelobes));
          },
          "field"_a, "rho_max"_a, "grid_step"_a, "description"_a = "python field", "feature_scale"_a = 0.0,
          "radial"_a = false, "sidelobes"_a = nb::none(),
          "Any beam: field(rho, sigma) returns the (unnormalized) 4x4 Mueller matrix at the antenna-basis\n"
          "direction (rho, sigma), sampled every grid_step out to rho_max. radial: the field does not depend\n"
          "on sigma (stored as a radial profile).");
}

// Beamsor's beams read or made from other codes' descriptions: a HEALPix beamsor file, a GRASP far
// field, a harmonic b_lm.
void bind_beamsor_files(nb::class_<Beamsor>& cls) {
  cls.def_static("read_fits", &Beamsor::read_healpix_fits, "path"_a, "rho_max"_a, "grid_step"_a = 0.0,
                 "Reads one of the paper's HEALPix beamsor files (columns B_TT, B_QT, ...); grid_step 0 = 1.25 pixels.")
      .def_static(
          "from_grasp",
          [](const std::filesystem::path& path, double rho_max, double grid_step, std::optional<int> set, double angle,
             nb::handle sidelobes) {
            const pisco::SidelobeSplit split = split_from(sidelobes);
            const auto all = pisco::GraspBeam::read(path);
            if (!set && all.size() > 1)
              throw pisco::Error(path.string() + " holds " + std::to_string(all.size()) +
                                 " beams (field sets or frequencies): choose one with set = 1.." + std::to_string(all.size()));
            const int k = set.value_or(1);
            if (k < 1 || k > static_cast<int>(all.size()))
              throw pisco::Error("set = " + std::to_string(k) + ", but " + path.string() + " holds " +
                                 std::to_string(all.size()) + " beam(s)");
            nb::gil_scoped_release release;
            return Beamsor::from_grasp(all[static_cast<std::size_t>(k - 1)], {rho_max, grid_step, angle, split, {}});
          },
          "path"_a, "rho_max"_a = 5 * deg, "grid_step"_a = 0.0, "set"_a = nb::none(), "angle"_a = 0.0,
          "sidelobes"_a = nb::none(),
          "A TICRA GRASP far field (.grd grid or .cut cuts; ICOMP 3: linear co- and cross-polar fields):\n"
          "I = |co|^2 + |cx|^2, Q = |co|^2 - |cx|^2, U = 2 Re(co cx*), V = 2 Im(co cx*) of a detector polarized\n"
          "along the file's x axis, interpolated onto the grid (grid_step 0 = 1/1.6 of the file's step). set: which\n"
          "of the file's beams (1, 2, ...; needed when it holds several). angle: the file's x axis from theta'\n"
          "towards phi' (a detector's zeta, so that a pair's B detector sees the optics turned by 90 deg).")
      .def_static(
          "from_blm",
          [](nb::object blm, double rho_max, double grid_step, double angle, std::optional<int> lmax,
             std::optional<int> mmax, nb::handle sidelobes) {
            const pisco::SidelobeSplit split = split_from(sidelobes);
            pisco::HarmonicBeam beam;
            nb::module_ os = nb::module_::import_("os");
            if (nb::isinstance<nb::str>(blm) || nb::isinstance(blm, os.attr("PathLike"))) {
              if (lmax || mmax) throw pisco::Error("from_blm: lmax and mmax come from the file; give them for arrays only");
              beam = pisco::HarmonicBeam::read_fits(nb::cast<std::string>(os.attr("fspath")(blm)));
            } else {
              nb::module_ np = nb::module_::import_("numpy");
              nb::object a = np.attr("ascontiguousarray")(np.attr("asarray")(blm, "dtype"_a = "complex128"));
              const int ndim = nb::cast<int>(a.attr("ndim"));
              if (ndim == 1) a = a.attr("reshape")(1, -1);
              else if (ndim != 2) throw pisco::Error("from_blm: expected an array of shape (1, n) or (3, n) (T or T, E, B in healpy's layout)");
              const auto rows = nb::cast<long>(a.attr("shape")[0]), n = nb::cast<long>(a.attr("shape")[1]);
              if (rows != 1 && rows != 3)
                throw pisco::Error("from_blm: expected 1 (T) or 3 (T, E, B) rows of coefficients, got " + std::to_string(rows));
              const auto flat = nb::cast<ConstMatrix>(a.attr("view")("float64"));
              // lmax and mmax: as given, or mmax = lmax (healpy's default layout) solved from n.
              int l = lmax.value_or(-1), m = mmax.value_or(-1);
              if (l < 0) {
                if (m < 0) {
                  const double x = (std::sqrt(1.0 + 8.0 * n) - 3) / 2;
                  l = m = static_cast<int>(std::lround(x));
                } else {
                  l = static_cast<int>((n + static_cast<long>(m) * (m + 1) / 2) / (m + 1)) - 1;
                }
              }
              if (m < 0) m = l;
              beam.lmax = l;
              beam.mmax = m;
              beam.source = "(arrays)";
              if (m >= 0 && m <= l && pisco::HarmonicBeam::size(l, m) != static_cast<std::size_t>(n))
                throw pisco::Error("from_blm: " + std::to_string(n) + " coefficients a row do not make lmax " + std::to_string(l) +
                                   ", mmax " + std::to_string(m) + " (which need " + std::to_string(pisco::HarmonicBeam::size(l, m)) + ")");
              std::vector<std::complex<double>>* parts[3] = {&beam.t, &beam.e, &beam.b};
              for (long r = 0; r < rows; ++r) {
                parts[r]->resize(static_cast<std::size_t>(n));
                for (long k = 0; k < n; ++k)
                  (*parts[r])[static_cast<std::size_t>(k)] = {flat(r, 2 * k), flat(r, 2 * k + 1)};
              }
            }
            nb::gil_scoped_release release;
            return Beamsor::from_harmonic(beam, {rho_max, grid_step, angle, split, {}});
          },
          "blm"_a, "rho_max"_a = 5 * deg, "grid_step"_a = 0.0, "angle"_a = 0.0, "lmax"_a = nb::none(), "mmax"_a = nb::none(),
          "sidelobes"_a = nb::none(),
          "A harmonic beam b_lm, the beam axis at the north pole: a healpy alm FITS file (healpy.write_alm;\n"
          "T or T, E, B) or an array of shape (n,), (1, n) or (3, n) in healpy's layout (lmax and mmax as given,\n"
          "else mmax = lmax). In ducc0's totalconvolve convention (TOAST's and litebird_sim's), synthesized\n"
          "exactly at every node; grid_step 0 = 0.75 / l_eff. angle: the beam frame's x axis from theta'.");
}

// What a Beamsor holds (its disc, grid, split and Mueller elements), and write_fits.
void bind_beamsor_contents(nb::class_<Beamsor>& cls) {
  cls.def("write_fits", &Beamsor::write_healpix_fits, "path"_a, "nside"_a,
          "Writes this beamsor as a HEALPix beamsor file at `nside`.")
      .def_prop_ro("rho_max", &Beamsor::rho_max, "The disc's radius (a split beam's: its main part's).")
      .def_prop_ro(
          "sidelobes", [](const Beamsor& b) -> std::optional<Beamsor> {
            if (!b.sidelobes()) return std::nullopt;
            return *b.sidelobes();
          },
          "A split beam's outer part (a Beamsor out to the whole beam's rho_max), else None.")
      .def_prop_ro("sidelobe_band_limit", &Beamsor::sidelobe_band_limit,
                   "A split beam's outer part's band limit l (0 for a beam that is not split).")
      .def_prop_ro("is_radial", &Beamsor::is_radial)
      .def_prop_ro("grid_size", &Beamsor::grid_size)
      .def_prop_ro("grid_step", &Beamsor::grid_step)
      .def_prop_ro("omega_tilde", &Beamsor::omega_tilde, "The integral of B_TT over the cap, steradians.")
      .def_prop_ro("description", &Beamsor::description)
      .def(
          "element",
          [](nb::handle self, int row, int col) -> nb::object {
            if (row < 0 || row > 3 || col < 0 || col > 3) throw nb::index_error("element: row and col are in 0..3");
            const auto values = nb::cast<const Beamsor&>(self).element(row, col);
            if (values.empty()) return nb::none();
            return nb::cast(NumpyConstVector(values.data(), {values.size()}, self));
          },
          "row"_a, "col"_a,
          "The grid values of Mueller element (row, col) as a read-only view (None for a zero element).")
      .def("at", [](const Beamsor& b, double x, double y) { return mueller_array(b.at(x, y)); }, "x"_a, "y"_a,
           "The interpolated Mueller matrix at orthographic (x, y) = sin(rho) (cos sigma, sin sigma).")
      .def("__repr__", [](const Beamsor& b) { return "pisco.Beamsor('" + b.description() + "')"; });
}

void bind_beamsor(nb::module_& m) {
  nb::class_<Beamsor> cls(m, "Beamsor",
                          "A beamsor: a field of 4x4 Mueller matrices over the beam's directions, sampled on a grid\n"
                          "out to rho_max (radians). Built by Beamsor.gaussian, .elliptical_gaussian, .from_field or\n"
                          ".read_fits.");
  bind_beamsor_analytic(cls);
  bind_beamsor_files(cls);
  bind_beamsor_contents(cls);
}

void bind_hwp(nb::module_& m) {
  nb::class_<HalfWavePlate>(
      m, "HalfWavePlate",
      "A half-wave plate (or any rotating Mueller element) in front of a detector (docs/physics.md,\n"
      "\"Half-wave plates\").\n\n"
      "HalfWavePlate(mueller=None, placement='aperture', gamma=0.0)\n\n"
      "mueller: M0, the plate's 4x4 Mueller matrix with its fast axis along the detector's polarization\n"
      "axis (rows: I, Q, U, V leaving the plate; columns: those arriving); None is the ideal plate\n"
      "diag(1, 1, -1, -1); a passive element's (docs/physics.md, \"Physical bounds on Mueller matrices\":\n"
      "M00 > 0, no more light out than in, within pisco.mueller_tolerance), else ValueError naming `mueller`.\n"
      "placement: 'aperture' (skyward of the optics, the default) or 'detector'\n"
      "(between the optics and the detector: four times the cost). gamma: the detector's polarization\n"
      "angle in the focal-plane frame (radians, TOAST's focal-plane `gamma`). At the plate's angle h\n"
      "(Engine.convolve's hwp_angle, in the focal-plane frame) the plate is M(theta) = R(-theta) M0\n"
      "R(theta), theta = h - gamma (mueller_at).")
      .def("__init__",
           [](HalfWavePlate* self, nb::handle mueller, const std::string& placement, double gamma) {
             HalfWavePlate p;
             if (!mueller.is_none()) p.mueller = plate_mueller_arg(mueller);
             p.placement = placement_from(placement);
             p.gamma = finite_arg(gamma, "gamma");
             new (self) HalfWavePlate(p);
           },
           "mueller"_a = nb::none(), "placement"_a = "aperture", "gamma"_a = 0.0)
      .def_prop_rw(
          "mueller", [](const HalfWavePlate& p) { return mueller_readonly(p.mueller); },
          [](HalfWavePlate& p, nb::handle v) { p.mueller = plate_mueller_arg(v); },
          "M0, the plate's Mueller matrix at theta = 0 (a read-only copy; assign a new (4, 4) array to change it).")
      .def_prop_rw(
          "placement", [](const HalfWavePlate& p) { return std::string(placement_name(p.placement)); },
          [](HalfWavePlate& p, const std::string& v) { p.placement = placement_from(v); },
          "'aperture' (skyward of the optics) or 'detector' (between the optics and the detector).")
      .def_prop_rw(
          "gamma", [](const HalfWavePlate& p) { return p.gamma; },
          [](HalfWavePlate& p, double v) { p.gamma = finite_arg(v, "gamma"); },
          "The detector's polarization angle in the focal-plane frame, radians.")
      .def_prop_ro("is_ideal", [](const HalfWavePlate& p) { return p.mueller == ideal_hwp_mueller(); },
                   "Whether M0 is exactly diag(1, 1, -1, -1).")
      .def(
          "mueller_at",
          [](const HalfWavePlate& p, double hwp_angle) {
            return mueller_readonly(rotated_mueller(p.mueller, hwp_angle - p.gamma));
          },
          "hwp_angle"_a,
          "The plate's Mueller matrix in the detector's frame at plate angle hwp_angle (focal-plane frame):\n"
          "R(-theta) M0 R(theta), theta = hwp_angle - gamma.")
      .def("__eq__",
           [](const HalfWavePlate& a, nb::handle b) {
             if (!nb::isinstance<HalfWavePlate>(b)) return false;
             const auto& p = nb::cast<const HalfWavePlate&>(b);
             return a.mueller == p.mueller && a.placement == p.placement && a.gamma == p.gamma;
           })
      .def("__copy__", [](const HalfWavePlate& p) { return p; })
      .def("__deepcopy__", [](const HalfWavePlate& p, nb::handle) { return p; }, "memo"_a)
      .def("__repr__", &plate_repr);
  m.def("ideal_hwp_mueller", []() { return mueller_readonly(ideal_hwp_mueller()); },
        "The ideal half-wave plate's Mueller matrix, diag(1, 1, -1, -1) (a read-only (4, 4) array).");
  m.def(
      "rotated_mueller",
      [](nb::handle m0, double angle) {
        return mueller_readonly(rotated_mueller(mueller_arg(m0, "m0"), finite_arg(angle, "angle")));
      },
      "m0"_a, "angle"_a,
      "R(-angle) m0 R(angle): a Mueller element turned by `angle` (radians) from the detector's axis,\n"
      "R(a) having rows (1,0,0,0), (0,cos2a,sin2a,0), (0,-sin2a,cos2a,0), (0,0,0,1).");
}

// A beam that changes with time (Detector.beam_sequence): pairs (time in seconds, beam index), or None
// for a fixed beam. Their order and count are the engine's to check (pisco.Error).
std::vector<BeamNode> sequence_arg(nb::handle v) {
  std::vector<BeamNode> nodes;
  if (v.is_none()) return nodes;
  if (nb::isinstance<nb::str>(v) || !nb::hasattr(v, "__iter__"))
    throw nb::type_error(("beam_sequence: expected a list of (time, beam) pairs, got " + describe(v)).c_str());
  std::size_t k = 0;
  for (nb::handle item : v) {
    const std::string where = "beam_sequence[" + std::to_string(k++) + "]";
    nb::tuple pair;
    if (!nb::try_cast(item, pair) || pair.size() != 2)
      throw nb::type_error((where + ": expected a (time, beam) pair, got " + describe(item)).c_str());
    double time = 0;
    long long beam = 0;
    if (!nb::try_cast(pair[0], time) || nb::isinstance<nb::bool_>(pair[0]))
      throw nb::type_error((where + ": the time must be a number (seconds), got " + describe(pair[0])).c_str());
    if (!nb::isinstance<nb::int_>(pair[1]) || nb::isinstance<nb::bool_>(pair[1]) || !nb::try_cast(pair[1], beam))
      throw nb::type_error((where + ": the beam must be an index (int), got " + describe(pair[1])).c_str());
    const std::string what = where + " beam";
    nodes.push_back({time, unsigned_arg<std::size_t>(beam, what.c_str())});
  }
  return nodes;
}

// None or a PlateBeams, for Detector.plate_beams and the `plate_beams` arguments.
std::optional<PlateBeams> plate_beams_arg(nb::handle obj) {
  if (obj.is_none()) return std::nullopt;
  if (!nb::isinstance<PlateBeams>(obj))
    throw nb::type_error(("plate_beams: expected a pisco.PlateBeams or None, got " + describe(obj)).c_str());
  return nb::cast<PlateBeams>(obj);
}

std::vector<std::size_t> beam_indices_arg(nb::handle v, const char* what) {
  std::vector<std::size_t> out;
  if (nb::isinstance<nb::str>(v) || !nb::hasattr(v, "__iter__"))
    throw nb::type_error((std::string(what) + ": expected a list of beam indices, got " + describe(v)).c_str());
  std::size_t k = 0;
  for (nb::handle item : v) {
    const std::string where = std::string(what) + "[" + std::to_string(k++) + "]";
    long long b = 0;
    if (!nb::isinstance<nb::int_>(item) || nb::isinstance<nb::bool_>(item) || !nb::try_cast(item, b))
      throw nb::type_error((where + ": expected a beam index (int), got " + describe(item)).c_str());
    out.push_back(unsigned_arg<std::size_t>(b, where.c_str()));
  }
  return out;
}

nb::list sequence_list(const std::vector<BeamNode>& nodes) {
  nb::list out;
  for (const BeamNode& n : nodes) out.append(nb::make_tuple(n.time, n.beam));
  return out;
}

// pisco.PlateBeams: a beam that turns with a half-wave plate.
void bind_plate_beams(nb::module_& m) {
  nb::class_<PlateBeams>(m, "PlateBeams",
                         "A beam that turns with a half-wave plate (docs/changing.md): the optics and the plate\n"
                         "simulated together at N plate angles.\n\n"
                         "PlateBeams(beams, period=pi, gamma=0.0, omega=0.0)\n\n"
                         "beams: the engine's beam indices at plate angles gamma + k period / N (k = 0 .. N - 1;\n"
                         "two or more); period: pi for a half-wave plate (radians; 2 pi for one whose turn by pi is\n"
                         "not the same plate); gamma: the plate angle (hwp_angle) of the first beam. At each\n"
                         "sample's hwp_angle the detector's beam is their trigonometric interpolant. The plate is in\n"
                         "the beams: give the detector no hwp. omega: the solid angle (sr) the TOD is normalized by;\n"
                         "0, their mean Omega~.")
      .def("__init__",
           [](PlateBeams* self, nb::handle beams, double period, double gamma, double omega) {
             PlateBeams p;
             p.beams = beam_indices_arg(beams, "beams");
             p.period = finite_arg(period, "period");
             p.gamma = finite_arg(gamma, "gamma");
             p.omega = finite_arg(omega, "omega");
             new (self) PlateBeams(std::move(p));
           },
           "beams"_a, "period"_a = std::numbers::pi, "gamma"_a = 0.0, "omega"_a = 0.0)
      .def_prop_rw(
          "beams", [](const PlateBeams& p) { return p.beams; },
          [](PlateBeams& p, nb::handle v) { p.beams = beam_indices_arg(v, "beams"); },
          "The beam indices at plate angles gamma + k period / N.")
      .def_prop_rw(
          "period", [](const PlateBeams& p) { return p.period; },
          [](PlateBeams& p, double v) { p.period = finite_arg(v, "period"); }, "The plate's period, radians.")
      .def_prop_rw(
          "gamma", [](const PlateBeams& p) { return p.gamma; },
          [](PlateBeams& p, double v) { p.gamma = finite_arg(v, "gamma"); },
          "The plate angle of the first beam, radians (focal-plane frame).")
      .def_prop_rw(
          "omega", [](const PlateBeams& p) { return p.omega; },
          [](PlateBeams& p, double v) { p.omega = finite_arg(v, "omega"); },
          "The solid angle (sr) their TOD is normalized by: 0, their mean Omega~ (the plate's mean transmission\n"
          "calibrated away); the beam's own Omega~ without the plate keeps the plate's losses, as HalfWavePlate does.")
      .def("__repr__", [](const PlateBeams& p) {
        return "pisco.PlateBeams(" + std::to_string(p.beams.size()) + " beams, period=" + format_double(p.period) +
               ", gamma=" + format_double(p.gamma) + ")";
      });
}

// pisco.Detector: one detector's fields, its offset, plate and changing beams.
void bind_detector(nb::module_& m) {
  nb::class_<Detector>(m, "Detector",
                       "A detector: name, polarization angle zeta (radians, from theta' towards phi'), cross-polar\n"
                       "leakage epsilon (efficiency 1 - epsilon), gain, the index of its beam, its offset from the\n"
                       "boresight as a quaternion (x, y, z, w), and its half-wave plate (a pisco.HalfWavePlate, or\n"
                       "None: then the engine's convolve() needs the plate's angles, hwp_angle). beam_sequence: a beam\n"
                       "that changes with time, [(time, beam), ...] (seconds, beam indices; docs/changing.md);\n"
                       "plate_beams: a beam that turns with a half-wave plate (a pisco.PlateBeams).")
      .def("__init__",
           [](Detector* self, std::string name, double zeta, double epsilon, double gain, long long beam,
              nb::handle offset, nb::handle hwp, nb::handle beam_sequence, nb::handle plate_beams) {
             Detector d{};
             d.name = std::move(name);
             d.zeta = zeta;
             d.epsilon = epsilon;
             d.gain = gain;
             d.beam = unsigned_arg<std::size_t>(beam, "beam");
             if (!offset.is_none()) d.offset = quat_from(offset, "offset");
             d.hwp = plate_arg(hwp);
             d.beam_sequence = sequence_arg(beam_sequence);
             d.plate_beams = plate_beams_arg(plate_beams);
             new (self) Detector(std::move(d));
           },
           "name"_a, "zeta"_a = 0.0, "epsilon"_a = 0.0, "gain"_a = 1.0, "beam"_a = 0, "offset"_a = nb::none(),
           "hwp"_a = nb::none(), "beam_sequence"_a = nb::none(), "plate_beams"_a = nb::none())
      .def_rw("name", &Detector::name)
      .def_rw("zeta", &Detector::zeta)
      .def_rw("epsilon", &Detector::epsilon)
      .def_rw("gain", &Detector::gain)
      .def_prop_rw(
          "beam", [](const Detector& d) { return d.beam; },
          [](Detector& d, long long v) { d.beam = unsigned_arg<std::size_t>(v, "beam"); },
          "The index of the detector's beam in the engine's beams (a non-negative integer).")
      .def_prop_rw(
          "offset", [](const Detector& d) { return nb::cast(quat_array(d.offset)); },
          [](Detector& d, nb::handle q) { d.offset = quat_from(q, "offset"); },
          "The offset quaternion (x, y, z, w): the rotation from the boresight's antenna basis to the detector's.")
      .def_prop_rw(
          "hwp", [](const Detector& d) { return d.hwp ? nb::cast(*d.hwp, nb::rv_policy::copy) : nb::none(); },
          [](Detector& d, nb::handle v) { d.hwp = plate_arg(v); },
          nb::for_setter(nb::arg("value").none()), "The detector's half-wave plate (a copy of it), or None.")
      .def_prop_rw(
          "beam_sequence", [](const Detector& d) { return sequence_list(d.beam_sequence); },
          [](Detector& d, nb::handle v) { d.beam_sequence = sequence_arg(v); },
          nb::for_setter(nb::arg("value").none()),
          "A beam that changes with time: [(time, beam), ...], times in seconds strictly ascending, at least\n"
          "two nodes; between two nodes the TOD is the two beams' linearly interpolated (docs/beams.md).\n"
          "Empty: the fixed beam `beam`. The engine's calls then need each sample's time (time=).")
      .def_prop_rw(
          "plate_beams",
          [](const Detector& d) { return d.plate_beams ? nb::cast(*d.plate_beams, nb::rv_policy::copy) : nb::none(); },
          [](Detector& d, nb::handle v) { d.plate_beams = plate_beams_arg(v); }, nb::for_setter(nb::arg("value").none()),
          "A beam that turns with a half-wave plate (a copy of the pisco.PlateBeams), or None.")
      .def("set_offset", &Detector::set_offset, "xi"_a, "eta"_a, "gamma"_a,
           "Sets the offset from focal-plane coordinates (xi, eta, gamma), radians (pisco.offset_quat).")
      .def("offset_xi_eta_gamma",
           [](const Detector& d) {
             double xi, eta, gamma;
             d.offset_xi_eta_gamma(xi, eta, gamma);
             return std::make_tuple(xi, eta, gamma);
           })
      .def("__repr__", [](const Detector& d) {
        return "pisco.Detector('" + d.name + "', zeta=" + format_double(d.zeta) + ", epsilon=" +
               format_double(d.epsilon) + ", gain=" + format_double(d.gain) + ", beam=" + std::to_string(d.beam) +
               (d.hwp ? ", hwp=" + plate_repr(*d.hwp) : std::string()) +
               (d.beam_sequence.empty() ? std::string()
                                        : ", beam_sequence=[" + std::to_string(d.beam_sequence.size()) + " nodes]") +
               ")";
      });
}

// FocalPlane.add and .add_pair: a detector, or a PSB pair, appended.
void bind_focal_plane_adders(nb::class_<FocalPlane>& cls) {
  cls
      .def(
          "add",
          [](FocalPlane& fp, nb::handle detector_or_name, double zeta, double epsilon, double gain, long long beam,
             nb::handle offset, nb::handle hwp, nb::handle beam_sequence, nb::handle plate_beams) {
            if (nb::isinstance<Detector>(detector_or_name)) {
              Detector d = nb::cast<Detector>(detector_or_name);
              if (!hwp.is_none()) d.hwp = plate_arg(hwp);
              if (!beam_sequence.is_none()) d.beam_sequence = sequence_arg(beam_sequence);
              if (!plate_beams.is_none()) d.plate_beams = plate_beams_arg(plate_beams);
              return fp.add(std::move(d));
            }
            if (!nb::isinstance<nb::str>(detector_or_name))
              throw nb::type_error(("detector: expected a pisco.Detector or a name, got " +
                                    describe(detector_or_name)).c_str());
            Detector d;
            d.name = nb::cast<std::string>(detector_or_name);
            d.zeta = zeta;
            d.epsilon = epsilon;
            d.gain = gain;
            d.beam = unsigned_arg<std::size_t>(beam, "beam");
            if (!offset.is_none()) d.offset = quat_from(offset, "offset");
            d.hwp = plate_arg(hwp);
            d.beam_sequence = sequence_arg(beam_sequence);
            d.plate_beams = plate_beams_arg(plate_beams);
            return fp.add(std::move(d));
          },
          "detector"_a, "zeta"_a = 0.0, "epsilon"_a = 0.0, "gain"_a = 1.0, "beam"_a = 0, "offset"_a = nb::none(),
          "hwp"_a = nb::none(), "beam_sequence"_a = nb::none(), "plate_beams"_a = nb::none(),
          "Adds a Detector, or one built from a name and these fields; returns its index. hwp: a\n"
          "pisco.HalfWavePlate for the detector (given with a Detector, it replaces the Detector's);\n"
          "beam_sequence: [(time, beam), ...], a beam that changes with time (Detector.beam_sequence);\n"
          "plate_beams: a pisco.PlateBeams, a beam that turns with a half-wave plate (Detector.plate_beams).")
      .def(
          "add_pair",
          [](FocalPlane& fp, const std::string& name, double zeta, long long beam_a_arg, long long beam_b_arg,
             double epsilon, double gain_a, double gain_b, nb::handle hwp) {
            const auto beam_a = unsigned_arg<std::size_t>(beam_a_arg, "beam_a");
            const auto beam_b = unsigned_arg<std::size_t>(beam_b_arg, "beam_b");
            const std::optional<HalfWavePlate> plate = plate_arg(hwp);
            if (!plate) return fp.add_pair(name, zeta, beam_a, beam_b, epsilon, gain_a, gain_b);
            FocalPlane pair;
            pair.add_pair(name, zeta, beam_a, beam_b, epsilon, gain_a, gain_b);
            std::vector<Detector> ds = pair.detectors();
            ds[0].hwp = plate;
            ds[1].hwp = plate;
            ds[1].hwp->gamma = plate->gamma - std::numbers::pi / 2;  // b's axis is 90 deg from a's
            const std::size_t first = fp.add(std::move(ds[0]));
            fp.add(std::move(ds[1]));
            return first;
          },
          "name"_a, "zeta"_a = 0.0, "beam_a"_a = 0, "beam_b"_a = 0, "epsilon"_a = 0.0, "gain_a"_a = 1.0,
          "gain_b"_a = 1.0, "hwp"_a = nb::none(),
          "Adds a PSB pair: name+'a' at zeta and name+'b' at zeta - 90 deg; returns the first's index.\n"
          "hwp: a pisco.HalfWavePlate in front of both, its gamma a's (b's is gamma - 90 deg).");
}

// A FocalPlane's detectors, by index or name, and FocalPlane.read_toast.
void bind_focal_plane_contents(nb::class_<FocalPlane>& cls) {
  cls.def("__len__", &FocalPlane::size)
      .def("__getitem__",
           [](const FocalPlane& fp, nb::handle key) -> Detector {
             if (nb::isinstance<nb::str>(key)) {
               const auto name = nb::cast<std::string>(key);
               for (const auto& d : fp.detectors())
                 if (d.name == name) return d;
               throw nb::key_error(("no detector named '" + name + "'").c_str());
             }
             long long i = 0;
             if (!nb::try_cast(key, i, false))
               throw nb::type_error(("expected a detector index or name, got " + describe(key)).c_str());
             if (i < 0) i += static_cast<long long>(fp.size());
             if (i < 0 || i >= static_cast<long long>(fp.size()))
               throw nb::index_error(("detector index out of range (the focal plane has " +
                                      std::to_string(fp.size()) + " detectors)").c_str());
             return fp[static_cast<std::size_t>(i)];
           })
      .def_prop_ro("detectors", &FocalPlane::detectors, "The detectors (copies), in order.")
      .def_prop_ro("names",
                   [](const FocalPlane& fp) {
                     std::vector<std::string> names;
                     for (const auto& d : fp.detectors()) names.push_back(d.name);
                     return names;
                   })
      .def_static(
          "read_toast",
          [](const std::filesystem::path& path, long long beam, nb::handle hwp) {
            const std::optional<HalfWavePlate> plate = plate_arg(hwp);
            ToastFocalPlane t = read_toast_focal_plane(path, unsigned_arg<std::size_t>(beam, "beam"));
            if (plate) {
              for (std::size_t i = 0; i < t.detectors.size(); ++i) {
                Detector& d = t.detectors[i];
                d.hwp = plate;
                if (i < t.gamma.size()) {
                  d.hwp->gamma = t.gamma[i];
                } else {  // no gamma column: the detector's polarization angle in the focal plane
                  d.hwp->gamma = default_hwp_gamma(d);
                }
              }
            }
            return FocalPlane(std::move(t.detectors));
          },
          "path"_a, "beam"_a = 0, "hwp"_a = nb::none(),
          "Reads a TOAST 3 focal-plane file (HDF5, Focalplane.save_hdf5): docs/formats.md maps its columns.\n"
          "hwp: a pisco.HalfWavePlate for every detector, each with its own gamma, the table's `gamma`\n"
          "column (without one, the detector's polarization angle in the focal plane: its offset's gamma\n"
          "plus zeta, as pisco-vk run does).")
      .def("__repr__", [](const FocalPlane& fp) { return "pisco.FocalPlane(" + std::to_string(fp.size()) + " detectors)"; });
}

void bind_focal_plane(nb::module_& m) {
  bind_plate_beams(m);
  bind_detector(m);
  nb::class_<FocalPlane> cls(m, "FocalPlane",
                             "The detectors of an engine, in order. FocalPlane() is empty; add() and add_pair() fill\n"
                             "it; FocalPlane.from_columns and FocalPlane.from_toast build one from tables.");
  cls.def(nb::init<>());
  bind_focal_plane_adders(cls);
  bind_focal_plane_contents(cls);

  m.def(
      "read_toast_focal_plane",
      [](const std::filesystem::path& path, long long beam) {
        ToastFocalPlane t = read_toast_focal_plane(path, unsigned_arg<std::size_t>(beam, "beam"));
        auto* fwhm = new std::vector<double>(std::move(t.fwhm));
        nb::capsule owner(fwhm, [](void* p) noexcept { delete static_cast<std::vector<double>*>(p); });
        return std::make_tuple(FocalPlane(std::move(t.detectors)),
                               NumpyVector(fwhm->data(), {fwhm->size()}, owner), t.sample_rate);
      },
      "path"_a, "beam"_a = 0,
      "Reads a TOAST 3 focal-plane file: (FocalPlane, fwhm per detector in radians (empty without the\n"
      "column), sample rate in Hz (0 when absent)).");
}

void bind_helpers(nb::module_& m) {
  nb::class_<BackendInfo>(m, "BackendInfo", "A backend the library knows, whether it runs here and what it can do.")
      .def_ro("name", &BackendInfo::name)
      .def_ro("available", &BackendInfo::available)
      .def_ro("detail", &BackendInfo::detail, "The device found, or why the backend is unavailable.")
      .def_prop_ro(
          "capabilities",
          [](const BackendInfo& b) {
            nb::dict d;
            d["float64"] = b.capabilities.float64;
            d["plates"] = b.capabilities.plates;
            d["adjoint"] = b.capabilities.adjoint;
            d["worker_threads"] = b.capabilities.worker_threads;
            d["normal"] = b.capabilities.normal;
            d["device_memory"] = b.capabilities.device_memory;
            return d;
          },
          "What it can do: float64 (every operation in float64), plates, adjoint, worker_threads (its own "
          "host threads: `threads` applies), normal (a one-pass normal on its float32 path), device_memory (bytes of the device auto picks; "
          "0: host memory).")
      .def("__repr__", [](const BackendInfo& b) {
        return "pisco.BackendInfo('" + b.name + "', available=" + (b.available ? "True" : "False") + ", '" +
               b.detail + "')";
      });
  m.def("devices", &Engine::backends,
        "The backends the library knows ('cpu', 'simd', 'vulkan', 'cuda'), built into it or not, each with whether\n"
        "it is available on this machine and its device or the reason it is not.");
  m.def("offset_quat", [](double xi, double eta, double gamma) { return quat_array(offset_quat(xi, eta, gamma)); },
        "xi"_a, "eta"_a, "gamma"_a, "The offset quaternion of focal-plane coordinates (xi, eta, gamma), radians.");
  m.def(
      "quat_from_pointing",
      [](double theta, double phi, double psi) { return quat_array(quat_from_pointing(theta, phi, psi)); },
      "theta"_a, "phi"_a, "psi"_a, "The rotation R_z(phi) R_y(theta) R_z(psi) (TOAST's ISO angles) as (x, y, z, w).");
  m.def(
      "quat_to_pointing",
      [](nb::handle q) {
        double theta, phi, psi;
        quat_to_pointing(quat_from(q, "q"), theta, phi, psi);
        return std::make_tuple(theta, phi, psi);
      },
      "q"_a, "The angles (theta, phi, psi) of a rotation (x, y, z, w).");
  m.def("default_hwp_gamma", [](const Detector& d) { return default_hwp_gamma(d); }, "detector"_a,
        "The gamma of a detector's half-wave plate when its table gives none: its polarization angle in the\n"
        "focal plane, the offset's gamma plus zeta (as pisco-vk run takes it).");
  m.def("valid_nside", [](long long nside) { return valid_nside(nside); }, "nside"_a,
        "Whether nside is a power of two in [1, 8192].");
  m.def("ang2pix", &ang2pix, "nside"_a, "theta"_a, "phi"_a, "The RING pixel containing (theta, phi).");
  m.def(
      "ground_sky",
      [](int nside, double value, std::vector<double> horizon, double width, std::string units) {
        GroundModel g;
        g.value = value;
        g.horizon = std::move(horizon);
        g.width = width;
        return ground_sky(nside, g, units);
      },
      "nside"_a, "value"_a, "horizon"_a = std::vector<double>{0.0}, "width"_a = 0.0, "units"_a = "uK_CMB",
      "A ground in the horizon frame (docs/ground.md): `value` (the map's units) below a horizon whose\n"
      "elevations (radians) are given at azimuths 0, 2 pi / N, ... from north towards east, 0 above it, a\n"
      "half cosine over `width` (radians) across it; HEALPix RING, colatitude pi/2 - elevation, longitude\n"
      "-azimuth (TOAST's boresight_azel frame). pisco.Error names a bad argument.");
  m.def("rayleigh_jeans_in", &rayleigh_jeans_in, "units"_a, "kelvin"_a, "frequency_ghz"_a = 0.0,
        "A Rayleigh-Jeans brightness temperature in K_RJ, uK_RJ, K_CMB or uK_CMB (at frequency_ghz).");
  m.attr("deg") = deg;
  m.attr("unit_quat_tolerance") = unit_quat_tolerance;
  m.attr("mueller_tolerance") = mueller_tolerance;
  m.attr("unseen") = unseen;
  m.attr("__version__") = version;
}

}  // namespace
}  // namespace pisco::python

namespace pisco::python {
namespace {

// pisco.Error (pisco::Error) and a subclass per pisco::ErrorKind, each with the class attribute
// `kind`: a caller can catch pisco.UnavailableError to fall back on another backend, or OSError-like
// failures as pisco.FileError, without reading messages (docs/python.md, "Errors").
PyObject* error_types[5] = {};

void bind_errors(nb::module_& m) {
  PyObject* base = PyErr_NewExceptionWithDoc(
      "pisco._pisco.Error", "An error of the C++ library (pisco::Error): its message names the file, key or sample.",
      PyExc_RuntimeError, nullptr);
  if (!base) throw nb::python_error();
  m.attr("Error") = nb::borrow(base);
  struct Kind {
    ErrorKind kind;
    const char* name;
    const char* doc;
  };
  const Kind kinds[] = {
      {ErrorKind::input, "InputError", "A bad argument, file content or configuration (also a ValueError)."},
      {ErrorKind::unavailable, "UnavailableError", "A backend, device, driver or library absent from this machine."},
      {ErrorKind::device, "DeviceError", "A device that failed while working: out of memory, lost, or a driver error."},
      {ErrorKind::io, "FileError", "A file that could not be opened, read, written or renamed."},
      {ErrorKind::internal, "InternalError", "A broken invariant of the library itself: a bug to report."},
  };
  nb::setattr(nb::borrow(base), "kind", nb::none());
  for (const Kind& k : kinds) {
    // InputError is also a ValueError: a bad argument is one, whichever check found it.
    PyObject* bases = k.kind == ErrorKind::input ? PyTuple_Pack(2, base, PyExc_ValueError) : nullptr;
    PyObject* type = PyErr_NewExceptionWithDoc((std::string("pisco._pisco.") + k.name).c_str(), k.doc,
                                               bases ? bases : base, nullptr);
    Py_XDECREF(bases);
    if (!type) throw nb::python_error();
    nb::setattr(nb::borrow(type), "kind", nb::str(error_kind_name(k.kind)));
    m.attr(k.name) = nb::borrow(type);
    error_types[static_cast<int>(k.kind)] = type;
  }
  nb::register_exception_translator([](const std::exception_ptr& p, void*) {
    try {
      std::rethrow_exception(p);
    } catch (const pisco::Error& e) {
      // An error that carries its key (a setting, keyword or field) is named by it: the keywords of
      // the bindings are the library's own names.
      PyErr_SetString(error_types[static_cast<int>(e.kind())], e.named().c_str());
    }
  });
}

}  // namespace
}  // namespace pisco::python

NB_MODULE(_pisco, m) {
  m.doc() = "PISCO-VK's C++ library: pixel-space beam convolution (see the package pisco).";
  pisco::python::bind_errors(m);
  pisco::python::bind_helpers(m);
  pisco::python::bind_sky(m);
  pisco::python::bind_beamsor(m);
  pisco::python::bind_hwp(m);
  pisco::python::bind_focal_plane(m);
  pisco::python::bind_engine(m);
  pisco::python::bind_simulation(m);
}
