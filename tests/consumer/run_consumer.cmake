# Installs PISCO-VK into a scratch prefix, then configures, builds and runs a tiny consumer project
# that finds it with find_package(pisco) and links pisco::pisco.
# Run with cmake -P; inputs: PISCO_SOURCE_DIR, PISCO_BINARY_DIR, WORK_DIR.
cmake_minimum_required(VERSION 3.22)
foreach(var PISCO_SOURCE_DIR PISCO_BINARY_DIR WORK_DIR)
  if(NOT ${var})
    message(FATAL_ERROR "consumer: pass -D${var}=...")
  endif()
endforeach()
if(NOT EXISTS "${PISCO_BINARY_DIR}/CMakeCache.txt")
  message(FATAL_ERROR "consumer: ${PISCO_BINARY_DIR} is not a configured build directory")
endif()
file(REMOVE_RECURSE "${WORK_DIR}")
file(MAKE_DIRECTORY "${WORK_DIR}")

# Reuse the parent build's generator, make program, compiler and build type.
function(parent_cache var out)
  file(STRINGS "${PISCO_BINARY_DIR}/CMakeCache.txt" line REGEX "^${var}:[A-Z]+=")
  string(REGEX REPLACE "^${var}:[A-Z]+=" "" value "${line}")
  set(${out} "${value}" PARENT_SCOPE)
endfunction()
parent_cache(CMAKE_GENERATOR generator)
parent_cache(CMAKE_MAKE_PROGRAM make_program)
parent_cache(CMAKE_CXX_COMPILER cxx_compiler)
parent_cache(CMAKE_BUILD_TYPE build_type)
if(NOT generator)
  set(generator Ninja)
endif()
if(NOT build_type)
  set(build_type Release)
endif()
set(configure_args -G "${generator}" "-DCMAKE_BUILD_TYPE=${build_type}"
    "-DCMAKE_PREFIX_PATH=${WORK_DIR}/prefix")
if(make_program)
  list(APPEND configure_args "-DCMAKE_MAKE_PROGRAM=${make_program}")
endif()
if(cxx_compiler)
  list(APPEND configure_args "-DCMAKE_CXX_COMPILER=${cxx_compiler}")
endif()

# Runs one step; on failure stops with the step's output.
function(step what)
  execute_process(COMMAND ${ARGN} RESULT_VARIABLE rc OUTPUT_VARIABLE out ERROR_VARIABLE err)
  if(NOT rc EQUAL 0)
    list(JOIN ARGN " " command)
    message(FATAL_ERROR "consumer: ${what} failed (${rc})\n$ ${command}\n${out}\n${err}")
  endif()
  message(STATUS "consumer: ${what} ok\n${out}${err}")
endfunction()

step("install" "${CMAKE_COMMAND}" --install "${PISCO_BINARY_DIR}" --config "${build_type}"
     --prefix "${WORK_DIR}/prefix")
step("configure" "${CMAKE_COMMAND}" -S "${PISCO_SOURCE_DIR}/tests/consumer/project"
     -B "${WORK_DIR}/build" ${configure_args})
step("build" "${CMAKE_COMMAND}" --build "${WORK_DIR}/build" --config "${build_type}")

# Single-config generators put the executable in the build directory, multi-config ones below it.
set(exe "${WORK_DIR}/build/consumer")
if(NOT EXISTS "${exe}")
  set(exe "${WORK_DIR}/build/${build_type}/consumer")
endif()
step("run" "${exe}")
