# The cuda backend (docs/cuda.md): built when nvcc is found. The CUDA runtime is linked statically, so
# libpisco loads and runs on machines without the toolkit or the driver (the backend then reports
# itself unavailable, with the runtime's reason). Included from src/CMakeLists.txt at directory scope,
# where enable_language(CUDA) is allowed.
include(CheckLanguage)
check_language(CUDA)
if(CMAKE_CUDA_COMPILER)
  set(pisco_cuda_default ON)
else()
  set(pisco_cuda_default OFF)
  message(STATUS "cuda backend: no CUDA compiler (nvcc) found; set CMAKE_CUDA_COMPILER to build it")
endif()
option(PISCO_WITH_CUDA "Build the cuda backend (needs nvcc)" ${pisco_cuda_default})
if(NOT PISCO_WITH_CUDA)
  return()
endif()
if(NOT CMAKE_CUDA_COMPILER)
  message(FATAL_ERROR "PISCO_WITH_CUDA is ON but no CUDA compiler was found; set CMAKE_CUDA_COMPILER")
endif()

# Ampere and Hopper (H100 is sm_90) unless the user chose: -DCMAKE_CUDA_ARCHITECTURES=...
if(NOT DEFINED CMAKE_CUDA_ARCHITECTURES)
  set(CMAKE_CUDA_ARCHITECTURES "80;90" CACHE STRING "CUDA architectures of the cuda backend")
endif()
enable_language(CUDA)
find_package(CUDAToolkit REQUIRED)
message(STATUS "cuda backend: nvcc ${CMAKE_CUDA_COMPILER_VERSION}, architectures ${CMAKE_CUDA_ARCHITECTURES}")

target_sources(pisco PRIVATE
  cuda/chunk.cpp
  cuda/context.cpp
  cuda/device_choice.cpp
  cuda/device_data.cpp
  cuda/convolve.cu
  cuda/cuda_backend.cpp)
# The pisco target exists before CUDA is enabled, so its CUDA properties are set here. The kernel and
# the headers it shares with the reference are C++17 (CMake 3.25 knows no CUDA20 dialect for nvcc).
set_target_properties(pisco PROPERTIES
  CUDA_ARCHITECTURES "${CMAKE_CUDA_ARCHITECTURES}"
  CUDA_STANDARD 17
  CUDA_STANDARD_REQUIRED ON
  CUDA_RUNTIME_LIBRARY None)  # CUDA::cudart_static below, explicitly
target_compile_options(pisco PRIVATE $<$<COMPILE_LANGUAGE:CUDA>:-Xcompiler=-Wall,-Wextra>)
target_link_libraries(pisco PRIVATE CUDA::cudart_static)
target_compile_definitions(pisco PRIVATE PISCO_HAVE_CUDA)
# Named in the error a device of another architecture gets.
string(REPLACE ";" "," pisco_cuda_arch_list "${CMAKE_CUDA_ARCHITECTURES}")
# Each kernel variant's registers: for the blocks an SM of convolve.cu's min_blocks, or (OFF) as ptxas
# chooses, for a build to compare with on a GPU (tools/gpu_steps.sh; docs/cuda.md, "Budgets").
option(PISCO_CUDA_REGISTERS_BY_VARIANT "Compile each cuda kernel variant for the blocks an SM of convolve.cu's min_blocks" ON)
set(pisco_convolve_definitions "PISCO_CUDA_ARCHITECTURES=\"${pisco_cuda_arch_list}\"")
if(NOT PISCO_CUDA_REGISTERS_BY_VARIANT)
  list(APPEND pisco_convolve_definitions PISCO_CUDA_PTXAS_REGISTERS)
endif()
set_source_files_properties(cuda/convolve.cu PROPERTIES COMPILE_DEFINITIONS "${pisco_convolve_definitions}")
