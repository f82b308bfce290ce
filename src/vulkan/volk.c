/* volk's implementation, compiled into libpisco with hidden visibility (see vulkan.cmake): its global
   vk* function pointers stay private to the library. */
#define VOLK_IMPLEMENTATION
#include <volk.h>
