# Helpers of the tests that install PISCO-VK into a scratch prefix and use it from there, as a user
# would (tests/consumer/run_consumer.cmake, run_cli.cmake, run_readme_example.cmake). Included by
# scripts run with cmake -P; inputs: PISCO_SOURCE_DIR, PISCO_BINARY_DIR, WORK_DIR.
foreach(var PISCO_SOURCE_DIR PISCO_BINARY_DIR WORK_DIR)
  if(NOT ${var})
    message(FATAL_ERROR "pass -D${var}=...")
  endif()
endforeach()
if(NOT EXISTS "${PISCO_BINARY_DIR}/CMakeCache.txt")
  message(FATAL_ERROR "${PISCO_BINARY_DIR} is not a configured build directory")
endif()

# A value from the parent build's cache (generator, make program, compiler, build type).
function(pisco_parent_cache var out)
  file(STRINGS "${PISCO_BINARY_DIR}/CMakeCache.txt" line REGEX "^${var}:[A-Z]+=")
  string(REGEX REPLACE "^${var}:[A-Z]+=" "" value "${line}")
  set(${out} "${value}" PARENT_SCOPE)
endfunction()

pisco_parent_cache(CMAKE_BUILD_TYPE pisco_build_type)
if(NOT pisco_build_type)
  set(pisco_build_type Release)
endif()

# Runs one step; on failure stops with the step's command and output. The output (stdout and
# stderr) is left in ${out_var} when given as OUTPUT out_var.
function(pisco_step what)
  cmake_parse_arguments(S "" "OUTPUT" "COMMAND" ${ARGN})
  execute_process(COMMAND ${S_COMMAND} RESULT_VARIABLE rc OUTPUT_VARIABLE out ERROR_VARIABLE err)
  if(NOT rc EQUAL 0)
    list(JOIN S_COMMAND " " command)
    message(FATAL_ERROR "${what} failed (${rc})\n$ ${command}\n${out}\n${err}")
  endif()
  message(STATUS "${what} ok\n${out}${err}")
  if(S_OUTPUT)
    set(${S_OUTPUT} "${out}${err}" PARENT_SCOPE)
  endif()
endfunction()

# A fresh WORK_DIR with the build tree installed into WORK_DIR/prefix.
function(pisco_install_fresh)
  file(REMOVE_RECURSE "${WORK_DIR}")
  file(MAKE_DIRECTORY "${WORK_DIR}")
  pisco_step("install" COMMAND "${CMAKE_COMMAND}" --install "${PISCO_BINARY_DIR}" --config "${pisco_build_type}"
             --prefix "${WORK_DIR}/prefix")
endfunction()

# Configures and builds the CMake project in `source` against the package in WORK_DIR/prefix, with the
# parent build's generator, make program, compiler and build type; sets ${exe_var} to the path of
# its executable `target`.
function(pisco_build_against_prefix source target exe_var)
  pisco_parent_cache(CMAKE_GENERATOR generator)
  pisco_parent_cache(CMAKE_MAKE_PROGRAM make_program)
  pisco_parent_cache(CMAKE_CXX_COMPILER cxx_compiler)
  if(NOT generator)
    set(generator Ninja)
  endif()
  set(args -G "${generator}" "-DCMAKE_BUILD_TYPE=${pisco_build_type}" "-DCMAKE_PREFIX_PATH=${WORK_DIR}/prefix")
  if(make_program)
    list(APPEND args "-DCMAKE_MAKE_PROGRAM=${make_program}")
  endif()
  if(cxx_compiler)
    list(APPEND args "-DCMAKE_CXX_COMPILER=${cxx_compiler}")
  endif()
  pisco_step("configure" COMMAND "${CMAKE_COMMAND}" -S "${source}" -B "${WORK_DIR}/build" ${args})
  pisco_step("build" COMMAND "${CMAKE_COMMAND}" --build "${WORK_DIR}/build" --config "${pisco_build_type}")
  # Single-config generators put the executable in the build directory, multi-config ones below it.
  set(exe "${WORK_DIR}/build/${target}")
  if(NOT EXISTS "${exe}")
    set(exe "${WORK_DIR}/build/${pisco_build_type}/${target}")
  endif()
  set(${exe_var} "${exe}" PARENT_SCOPE)
endfunction()
