#include "core/masked_sky.hpp"

#include <algorithm>
#include <string>
#include <thread>
#include <utility>

#include "kernel/disc.hpp"
#include "kernel/frame.hpp"
#include "pisco/error.hpp"
#include "pisco/healpix_map.hpp"

namespace pisco {
namespace detail {

SkyView sky_for_backends(const SkyView& sky, UnseenPolicy policy, std::optional<Sky>& zeroed,
                            std::vector<std::uint32_t>& masked, std::size_t& unseen) {
  masked.clear();
  const std::vector<std::size_t> pixels = sky.unseen_pixels();
  unseen = pixels.size();
  if (pixels.empty()) return sky;
  if (policy == UnseenPolicy::error) sky.check_unseen("sky");
  zeroed.emplace(sky);
  zeroed->zero_unseen();
  if (policy == UnseenPolicy::flag) masked.assign(pixels.begin(), pixels.end());
  return SkyView(*zeroed);
}

namespace {

// Whether [begin, end) holds an element of the ascending `masked`.
bool holds_masked(const std::vector<std::uint32_t>& masked, std::uint32_t begin, std::uint32_t end) {
  const auto it = std::lower_bound(masked.begin(), masked.end(), begin);
  return it != masked.end() && *it < end;
}

bool disc_is_masked(const PreparedSky& sky, const PreparedDetector& det, const std::vector<std::uint32_t>& masked,
                    double theta, double phi) {
  bool hit = false;
  for_each_disc_range(sky.rings.data(), sky.nside, theta, phi, det.rho_max, det.cos_rho_max,
                      [&](std::uint32_t begin, std::uint32_t end) {
                        if (!hit && begin < end) hit = holds_masked(masked, begin, end);
                      });
  return hit;
}

void check_sizes(std::size_t pointing, std::size_t flags) {
  if (pointing != flags)
    throw Error("flag_samples: " + std::to_string(flags) + " flags for " + std::to_string(pointing) +
                " pointing samples (expected one flag per sample)");
}

}  // namespace

std::size_t flag_discs(const PreparedSky& sky, const PreparedDetector& det, const std::vector<std::uint32_t>& masked,
                       const PointingView& b, std::span<std::uint8_t> flags) {
  check_sizes(b.size(), flags.size());
  std::size_t n = 0;
  for (std::size_t i = 0; i < b.size(); ++i) {
    bool hit = false;
    if (!masked.empty()) {
      double theta = 0.0, phi = 0.0;
      angle_sample(b.theta[i], b.phi[i], b.psi[i], det.offset, 1.0, 0.0, theta, phi);
      hit = disc_is_masked(sky, det, masked, theta, phi);
    }
    flags[i] = hit ? 1 : 0;
    n += hit;
  }
  return n;
}

std::size_t flag_discs(const PreparedSky& sky, const PreparedDetector& det, const std::vector<std::uint32_t>& masked,
                       const QuatPointingView& b, std::span<std::uint8_t> flags) {
  check_sizes(b.size(), flags.size());
  std::size_t n = 0;
  for (std::size_t i = 0; i < b.size(); ++i) {
    bool hit = false;
    if (!masked.empty()) {
      const Quat& q = b.quats[i];
      double theta = 0.0, phi = 0.0;
      quat_sample({q.x, q.y, q.z, q.w}, det.offset, 1.0, 0.0, theta, phi);
      hit = disc_is_masked(sky, det, masked, theta, phi);
    }
    flags[i] = hit ? 1 : 0;
    n += hit;
  }
  return n;
}

}  // namespace detail

// ---- Engine: masked skies (declared in pisco/engine.hpp)

static const std::vector<std::size_t> no_nodes;

// A beam that changes with time or turns with the plate (`nodes`: the engine's detectors for its beams):
// a sample is flagged where any of their discs holds an UNSEEN pixel.
template <class View>
static std::size_t flag_view(const FocalPlane& fp, const detail::EngineInputs& in,
                             const std::vector<std::uint32_t>& masked, std::size_t detector,
                             const std::vector<std::size_t>& nodes, const View& boresight,
                             std::span<std::uint8_t> flags) {
  if (detector >= fp.size())
    throw Error("flag_samples: detector index " + std::to_string(detector) + " but the focal plane has " +
                std::to_string(fp.size()) + " detectors");
  const std::string origin = "flag_samples: pointing of detector '" + fp[detector].name + "'";
  check_pointing(boresight, origin.c_str());
  if (nodes.empty()) return detail::flag_discs(in.sky, in.detectors.at(detector), masked, boresight, flags);
  std::vector<std::uint8_t> node(flags.size());
  std::fill(flags.begin(), flags.end(), std::uint8_t(0));
  for (const std::size_t k : nodes) {
    detail::flag_discs(in.sky, in.detectors.at(k), masked, boresight, node);
    for (std::size_t i = 0; i < flags.size(); ++i) flags[i] |= node[i];
  }
  std::size_t n = 0;
  for (const std::uint8_t f : flags) n += f;
  return n;
}

std::size_t Engine::flag_samples(std::size_t detector, const PointingView& boresight,
                                 std::span<std::uint8_t> flags) const {
  return flag_view(focal_plane_, *inputs_, masked_, detector, has_nodes(detector) ? nodes_[detector] : no_nodes,
                   boresight, flags);
}

std::size_t Engine::flag_samples(std::size_t detector, const QuatPointingView& boresight,
                                 std::span<std::uint8_t> flags) const {
  return flag_view(focal_plane_, *inputs_, masked_, detector, has_nodes(detector) ? nodes_[detector] : no_nodes,
                   boresight, flags);
}

unsigned Engine::max_threads() noexcept {
  return 64 * std::max(1u, std::thread::hardware_concurrency());
}

}  // namespace pisco
