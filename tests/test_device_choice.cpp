// The device choice shared by the vulkan and cuda backends (src/gpu/device_choice.hpp), and the
// library-wide NSIDE check (pisco::check_nside), without any device.
#include <gtest/gtest.h>

#include <string>
#include <vector>

#include "gpu/device_choice.hpp"
#include "pisco/healpix_map.hpp"
#include "support.hpp"

namespace {

using pisco::detail::choose_device;
using pisco::detail::DeviceCandidate;
using pisco_test::expect_error;

// Two CPU devices around a discrete GPU, and an integrated GPU the backend cannot use.
const std::vector<DeviceCandidate> devices{
    {"llvmpipe (LLVM 15.0.6, 256 bits)", "llvmpipe [cpu]", 1, ""},
    {"NVIDIA H100 80GB HBM3", "NVIDIA H100 [discrete]", 4, ""},
    {"Intel(R) UHD Graphics", "", 3, "has no compute queue"},
    {"llvmpipe (LLVM 16)", "", 1, ""},
};

TEST(DeviceChoice, AutoTakesTheUsableDeviceOfHighestRankFirstAmongEquals) {
  EXPECT_EQ(choose_device("vk", "Vulkan", devices, "auto"), 1u);
  EXPECT_EQ(choose_device("vk", "Vulkan", devices, ""), 1u);
  const std::vector<DeviceCandidate> cpus{devices[0], devices[2], devices[3]};
  EXPECT_EQ(choose_device("vk", "Vulkan", cpus, "auto"), 0u);
}

TEST(DeviceChoice, IndexOrCaseInsensitivePartOfTheName) {
  EXPECT_EQ(choose_device("vk", "Vulkan", devices, "3"), 3u);
  EXPECT_EQ(choose_device("vk", "Vulkan", devices, "h100"), 1u);
  EXPECT_EQ(choose_device("vk", "Vulkan", devices, "LLVMPIPE"), 0u);  // the first match
}

TEST(DeviceChoice, ErrorsNameTheBackendTheRequestAndTheDevices) {
  expect_error([] { choose_device("vk", "Vulkan", devices, "4"); }, "vk: device index 4 is out of range");
  expect_error([] { choose_device("vk", "Vulkan", devices, "4"); }, "Vulkan devices: 0: llvmpipe [cpu]; 1: NVIDIA H100");
  expect_error([] { choose_device("vk", "Vulkan", devices, "99999999999999999999999"); }, "out of range");
  expect_error([] { choose_device("vk", "Vulkan", devices, "nosuch"); }, "no device named 'nosuch'");
  expect_error([] { choose_device("vk", "Vulkan", devices, "nosuch"); }, "2: Intel(R) UHD Graphics (has no compute queue)");
  expect_error([] { choose_device("vk", "Vulkan", devices, "2"); }, "device '2' (Intel(R) UHD Graphics) has no compute queue");
  expect_error([] { choose_device("vk", "Vulkan", devices, "intel"); }, "has no compute queue");
  expect_error([] { choose_device("vk", "Vulkan", {devices[2]}, "auto"); }, "vk: no usable device");
  expect_error([] { choose_device("cuda", "CUDA", {}, "auto"); }, "cuda: device 'auto' requested, but no CUDA devices");
}

TEST(CheckNside, PowersOfTwoUpToTheLargestTheLibraryIndexes) {
  for (long long n = 1; n <= pisco::max_nside; n *= 2) EXPECT_NO_THROW(pisco::check_nside(n, "t"));
  expect_error([] { pisco::check_nside(0, "here"); }, "here: NSIDE = 0 is not a power of two in [1, 8192]");
  expect_error([] { pisco::check_nside(12, "f.fits"); }, "f.fits: NSIDE = 12 is not a power of two");
  expect_error([] { pisco::check_nside(-4, "x"); }, "NSIDE = -4");
  expect_error([] { pisco::check_nside(2LL * pisco::max_nside, "x"); }, "NSIDE = 16384");
  expect_error([] { pisco::check_nside(1LL << 40, "x"); }, "not a power of two in [1, 8192]");
}

TEST(Unseen, HealpyTolerance) {
  EXPECT_TRUE(pisco::is_unseen(pisco::unseen));
  EXPECT_TRUE(pisco::is_unseen(double(float(pisco::unseen))));
  EXPECT_FALSE(pisco::is_unseen(0.0));
  EXPECT_FALSE(pisco::is_unseen(-1.6e30));
}

}  // namespace
