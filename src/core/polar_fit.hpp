// The least-squares fit of the sky around each pole that the polar copy reads near the poles
// (docs/physics.md, "The quadrature"): a band-limited field fitted to the pixels of each cap's first
// rings, jointly in every azimuthal mode, so that the modes a ring cannot resolve (ring t holds 4t
// pixels; a sky with power up to 3 NSIDE has modes up to about 2.45 t on it) are told apart by the
// pixels of the rings around. The fit is a fixed linear map of the pixels (a Chebyshev iteration of
// fixed length on the normal equations), so that its transpose is exact.
//
// Basis: lambda_lm(theta) e^{i m phi} around the cap's pole, theta the colatitude from it, for
// |m| <= M and l from the band limit down in steps of dl (complete over the fitted rings), each mode's
// functions whitened over the rings; four complex fields at once: I + iV and Q_c + iU_c (Q, U in the
// frame transported from the pole) of the north and the south cap, whose rings have the same geometry.
#pragma once

#include <array>
#include <complex>
#include <cstddef>
#include <map>
#include <memory>
#include <mutex>
#include <utility>
#include <vector>

#include <fftw3.h>

namespace pisco::detail {

class ThreadPool;

// FFTW's planner is not thread-safe (its execution is): plans are made and destroyed under one lock.
std::mutex& fftw_planner_mutex();

// The ring index of colatitude theta from a pole, continuous: z = 1 - t^2 / (3 NSIDE^2) in the
// polar cap, 4/3 - 2t / (3 NSIDE) in the belt.
double polar_ring_coordinate(double theta, int nside);

class PolarFit {
 public:
  using cd = std::complex<double>;
  static constexpr int kFields = 4;  // north I + iV, north Q_c + iU_c, south I + iV, south Q_c + iU_c
  using Values = std::array<cd, kFields>;

  // The fit of the first rings of each cap at `nside` for a copy of `reach` (radians); its zone (the
  // cap colatitude within which the copy reads it) is the reach rounded up to 16, 32 or kMaxZoneRings
  // rings, and kMarginRings rings beyond it are fitted too.
  PolarFit(int nside, double reach, ThreadPool& pool);
  ~PolarFit();
  PolarFit(const PolarFit&) = delete;
  PolarFit& operator=(const PolarFit&) = delete;

  // The rings it reads from each cap (counted from the pole, 1 to rings()): ring t's first pixel in
  // the north cap, its pixels, its colatitude from the pole and its first pixel's longitude.
  struct Ring {
    std::size_t start = 0;
    int n = 0;
    double theta = 0.0, phi0 = 0.0;
    std::size_t offset = 0;  // its samples' place in a samples vector
  };
  const std::vector<Ring>& rings() const noexcept { return rings_; }
  double zone() const noexcept { return zone_; }
  // Samples: ring by ring, pixel by pixel, the kFields values of each pixel.
  std::size_t sample_count() const noexcept { return samples_; }

  // The fitted field's modes on a fine grid in theta (the fit's output), and their transpose.
  using Modes = std::vector<cd>;
  Modes fit(const std::vector<cd>& samples, ThreadPool& pool) const;
  std::vector<cd> fit_transpose(const Modes& modes, ThreadPool& pool) const;
  Modes zero_modes() const { return Modes(modes_size(), cd(0.0)); }
  // The fields at (theta, phi) around the cap's pole, and the transpose: `bar` += its weights times v.
  Values value(const Modes& modes, double theta, double phi) const;
  void add_value_transpose(Modes& bar, double theta, double phi, const Values& v) const;

  // The largest zone, in rings; the rings fitted beyond it; the iteration's length, its floor (relative
  // to the spectrum's bound) and the whitening's ridge (relative to the largest Gram diagonal).
  static constexpr int kMaxZoneRings = 64;
  static constexpr int kMarginRings = 10;
  static constexpr int kIterations = 100;
  static constexpr double kFloor = 5e-3;
  static constexpr double kWhiten = 1e-4;
  // The rings a fit for that reach reads.
  static int rings_for(int nside, double reach);

 private:
  struct Mode {
    int m = 0;
    std::vector<double> at_rings;  // [j][t]: the whitened basis (L^-1 lambda_{l m})(theta_t)
    std::vector<double> at_grid;   // [j][g]: the same at g delta
  };
  // The constructor's steps.
  void read_rings(int T);
  void tabulate(int dl, ThreadPool& pool);
  void whiten_basis(ThreadPool& pool);
  void index_modes();
  void plan_transforms();
  void bound_spectrum(ThreadPool& pool);
  std::size_t modes_size() const { return std::size_t(2 * M_ + 1) * std::size_t(grid_) * kFields; }
  std::size_t coefficient_count() const { return coefficients_; }
  // A: coefficients -> samples; A^H: samples -> coefficients; N = A^H A.
  void forward(const std::vector<cd>& c, std::vector<cd>& samples, ThreadPool& pool) const;
  void adjoint(const std::vector<cd>& samples, std::vector<cd>& c, ThreadPool& pool) const;
  void normal(const std::vector<cd>& c, std::vector<cd>& out, std::vector<cd>& scratch, ThreadPool& pool) const;
  // The Chebyshev iteration's fixed polynomial in N applied to rhs (symmetric: its own transpose).
  std::vector<cd> solve(const std::vector<cd>& rhs, ThreadPool& pool) const;
  // Coefficients -> each mode's values at n points, from a table of Mode (at_rings or at_grid), and
  // the transpose.
  std::vector<cd> synthesize_modes(const std::vector<cd>& c, std::vector<double> Mode::*table, std::size_t n,
                                   ThreadPool& pool) const;
  std::vector<cd> analyze_modes(const std::vector<cd>& in, std::vector<double> Mode::*table, std::size_t n,
                                ThreadPool& pool) const;
  // Coefficients -> grid modes (E), and its transpose.
  Modes to_grid(const std::vector<cd>& c, ThreadPool& pool) const;
  std::vector<cd> from_grid(const Modes& g, ThreadPool& pool) const;
  void run_fft(int n, int sign, const cd* in, cd* out) const;

  int nside_ = 0, lband_ = 0, M_ = 0, grid_ = 0;
  double zone_ = 0.0, delta_ = 0.0, low_ = 0.0, high_ = 0.0;
  std::vector<Ring> rings_;
  std::vector<Mode> modes_;  // m = 0 .. M
  // Per signed m (index m + M): its basis functions and its coefficients' first place.
  std::vector<int> counts_;
  std::vector<std::size_t> offsets_;
  std::vector<cd> phases_;  // [t][m + M]: e^{i m phi0} of ring t
  std::size_t samples_ = 0, coefficients_ = 0;
  std::map<std::pair<int, int>, fftw_plan> plans_;
};

// The fit for (nside, reach), made once and kept among the last few made.
std::shared_ptr<const PolarFit> polar_fit_for(int nside, double reach, ThreadPool& pool);

}  // namespace pisco::detail
