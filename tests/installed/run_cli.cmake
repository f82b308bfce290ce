# The installed command line runs from its prefix with nothing on LD_LIBRARY_PATH: it finds libpisco
# through its relative RPATH ($ORIGIN/../lib, tools/CMakeLists.txt).
# Run with cmake -P; inputs: PISCO_SOURCE_DIR, PISCO_BINARY_DIR, WORK_DIR, PISCO_VERSION.
cmake_minimum_required(VERSION 3.22)
include("${CMAKE_CURRENT_LIST_DIR}/common.cmake")

pisco_install_fresh()
set(exe "${WORK_DIR}/prefix/bin/pisco-vk")
if(NOT EXISTS "${exe}")
  message(FATAL_ERROR "the install has no ${exe}")
endif()
set(clean_env "${CMAKE_COMMAND}" -E env --unset=LD_LIBRARY_PATH)

pisco_step("pisco-vk --version" COMMAND ${clean_env} "${exe}" --version OUTPUT out)
if(NOT out MATCHES "pisco-vk ${PISCO_VERSION}")
  message(FATAL_ERROR "pisco-vk --version printed '${out}', expected 'pisco-vk ${PISCO_VERSION}'")
endif()
pisco_step("pisco-vk devices" COMMAND ${clean_env} "${exe}" devices OUTPUT out)
if(NOT out MATCHES "cpu +available")
  message(FATAL_ERROR "pisco-vk devices does not list the cpu backend as available:\n${out}")
endif()

# The RPATH is relative: the prefix still works once moved.
file(RENAME "${WORK_DIR}/prefix" "${WORK_DIR}/moved")
pisco_step("pisco-vk --version from a moved prefix" COMMAND ${clean_env} "${WORK_DIR}/moved/bin/pisco-vk" --version)
