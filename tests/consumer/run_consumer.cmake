# Installs PISCO-VK into a scratch prefix, then configures, builds and runs a tiny consumer project
# that finds it with find_package(pisco) and links pisco::pisco.
# Run with cmake -P; inputs: PISCO_SOURCE_DIR, PISCO_BINARY_DIR, WORK_DIR.
cmake_minimum_required(VERSION 3.22)
include("${CMAKE_CURRENT_LIST_DIR}/../installed/common.cmake")

pisco_install_fresh()
pisco_build_against_prefix("${PISCO_SOURCE_DIR}/tests/consumer/project" consumer exe)
pisco_step("run" COMMAND "${exe}")
