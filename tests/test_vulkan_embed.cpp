// An application with its own Vulkan loader (linked against libvulkan, calling vk* directly) embeds
// libpisco's vulkan backend: neither sees the other's function pointers. libpisco exports no vk* or
// volk* symbol (checked by the ctest `vulkan_symbols_hidden`), so the application's vkCreateInstance is
// the loader's own before, during and after a pisco engine's life.
#include <gtest/gtest.h>
#include <vulkan/vulkan.h>

#include <cmath>

#include "backend_fixtures.hpp"
#include "pisco/pisco.hpp"

namespace {

std::uint32_t application_devices() {
  VkApplicationInfo app{VK_STRUCTURE_TYPE_APPLICATION_INFO};
  app.apiVersion = VK_API_VERSION_1_1;
  VkInstanceCreateInfo ci{VK_STRUCTURE_TYPE_INSTANCE_CREATE_INFO};
  ci.pApplicationInfo = &app;
  VkInstance instance = VK_NULL_HANDLE;
  EXPECT_EQ(vkCreateInstance(&ci, nullptr, &instance), VK_SUCCESS);
  std::uint32_t n = 0;
  EXPECT_EQ(vkEnumeratePhysicalDevices(instance, &n, nullptr), VK_SUCCESS);
  vkDestroyInstance(instance, nullptr);
  return n;
}

TEST(VulkanEmbed, ApplicationLoaderAndPiscoCoexist) {
  if (const std::string why = pisco_test::backend_unavailable("vulkan"); !why.empty())
    GTEST_SKIP() << "vulkan backend unavailable: " << why;
  const std::uint32_t before = application_devices();
  ASSERT_GT(before, 0u);

  pisco::Sky sky(16);
  for (std::size_t i = 0; i < sky.npix(); ++i) sky.I()[i] = std::sin(0.01 * double(i));
  pisco::BeamOptions o;
  o.rho_max = 10 * pisco::deg;
  std::vector<pisco::Beamsor> beams{pisco::Beamsor::gaussian(4 * pisco::deg, o)};
  pisco::FocalPlane fp;
  fp.add({"d", 0, 0, 1, 0});
  pisco::Pointing p;
  for (int i = 0; i < 50; ++i) p.push_back(0.05 + 0.06 * i, 0.1 * i, 0.2 * i);
  std::vector<double> tod(p.size()), ref(p.size());
  {
    pisco::Engine engine(sky, beams, fp, {.backend = "vulkan"});
    EXPECT_EQ(application_devices(), before);  // while pisco holds its own instance and device
    engine.convolve(0, p, tod);
  }
  pisco::Engine cpu(sky, beams, fp, {.backend = "cpu"});
  cpu.convolve(0, p, ref);
  double rms = 0;
  for (double r : ref) rms += r * r;
  rms = std::sqrt(rms / double(ref.size()));
  for (std::size_t i = 0; i < p.size(); ++i) EXPECT_NEAR(tod[i], ref[i], 1e-4 * rms) << i;  // B1, docs/validation.md, "B"
  EXPECT_EQ(application_devices(), before);
}

}  // namespace
