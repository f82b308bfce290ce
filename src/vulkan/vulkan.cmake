# The vulkan backend (docs/vulkan.md): GLSL compute shaders compiled to SPIR-V at build time and embedded in
# libpisco; Vulkan 1.2 loaded at run time through volk (Debian's libvulkan-volk-dev), whose global
# function pointers are compiled with hidden visibility so that they never clash with the Vulkan loader
# of an application that embeds the library. Device-level calls go through a per-device VolkDeviceTable.
option(PISCO_WITH_VULKAN "Build the vulkan backend (Vulkan headers, volk and glslangValidator)" ON)
if(NOT PISCO_WITH_VULKAN)
  return()
endif()

find_package(Vulkan REQUIRED)  # headers; the loader itself is opened by volk at run time
find_path(PISCO_VOLK_INCLUDE_DIR volk.h REQUIRED)
find_file(PISCO_VOLK_SOURCE volk.c PATHS ${PISCO_VOLK_INCLUDE_DIR} NO_DEFAULT_PATH REQUIRED)
find_program(PISCO_GLSLANG glslangValidator REQUIRED)

# Shaders -> SPIR-V as C arrays (glslangValidator --vn), with depfiles so that an edited include
# rebuilds the kernels that use it.
set(pisco_shader_dir ${PROJECT_SOURCE_DIR}/src/kernel)
set(pisco_spv_dir ${CMAKE_CURRENT_BINARY_DIR}/spv)
file(MAKE_DIRECTORY ${pisco_spv_dir})
set(pisco_spv_headers)
# The kernel is built twice: with float64, and with its float64 work in float-float (PISCO_FF=1) for
# devices without shaderFloat64 (docs/vulkan.md, "Devices without float64").
# The adjoint kernel (adjoint.comp) likewise.
foreach(variant convolve convolve_ff adjoint adjoint_ff)
  set(out ${pisco_spv_dir}/${variant}.spv.h)
  string(REGEX REPLACE "_ff$" "" source ${variant})
  if(variant MATCHES "_ff$")
    set(defines -DPISCO_FF=1)
  else()
    set(defines -DPISCO_FF=0)
  endif()
  add_custom_command(
    OUTPUT ${out}
    COMMAND ${PISCO_GLSLANG} --target-env vulkan1.2 -Os --quiet ${defines}
            --vn pisco_spv_${variant} --depfile ${out}.d -o ${out} ${pisco_shader_dir}/${source}.comp
    DEPENDS ${pisco_shader_dir}/${source}.comp
    DEPFILE ${out}.d
    COMMENT "SPIR-V: src/kernel/${source}.comp (${variant})"
    VERBATIM)
  list(APPEND pisco_spv_headers ${out})
endforeach()
add_custom_target(pisco_shaders DEPENDS ${pisco_spv_headers})

add_library(pisco_volk OBJECT ${CMAKE_CURRENT_SOURCE_DIR}/vulkan/volk.c)
target_include_directories(pisco_volk PRIVATE ${PISCO_VOLK_INCLUDE_DIR} ${Vulkan_INCLUDE_DIRS})
set_target_properties(pisco_volk PROPERTIES C_VISIBILITY_PRESET hidden POSITION_INDEPENDENT_CODE ON)
target_compile_definitions(pisco_volk PRIVATE VK_NO_PROTOTYPES)

target_sources(pisco PRIVATE
  vulkan/context.cpp
  vulkan/buffer.cpp
  vulkan/pipeline.cpp
  vulkan/tables.cpp
  vulkan/vulkan_backend.cpp
  $<TARGET_OBJECTS:pisco_volk>)
add_dependencies(pisco pisco_shaders)
target_include_directories(pisco PRIVATE ${PISCO_VOLK_INCLUDE_DIR} ${Vulkan_INCLUDE_DIRS} ${pisco_spv_dir}
                                         ${PROJECT_SOURCE_DIR}/src/kernel)
target_compile_definitions(pisco PRIVATE PISCO_HAVE_VULKAN VK_NO_PROTOTYPES)
target_link_libraries(pisco PRIVATE ${CMAKE_DL_LIBS})
set(PISCO_HAVE_VULKAN ON)
# Vulkan structures are written {sType} with the rest zeroed, the API's own idiom.
set_source_files_properties(vulkan/context.cpp vulkan/buffer.cpp vulkan/pipeline.cpp vulkan/tables.cpp vulkan/vulkan_backend.cpp
  PROPERTIES COMPILE_OPTIONS -Wno-missing-field-initializers)
