# README.md's library example, as written: the first ```cpp block after the heading "## Using the
# library" is extracted, built against an installed PISCO-VK in a project of its own
# (find_package(pisco), pisco::pisco) and run; it must exit with status 0 and print a line matching
# EXPECT. Run with cmake -P; inputs: PISCO_SOURCE_DIR, PISCO_BINARY_DIR, WORK_DIR, EXPECT.
cmake_minimum_required(VERSION 3.22)
include("${CMAKE_CURRENT_LIST_DIR}/common.cmake")

file(READ "${PISCO_SOURCE_DIR}/README.md" readme)
string(FIND "${readme}" "\n## Using the library\n" at)
if(at EQUAL -1)
  message(FATAL_ERROR "README.md has no heading '## Using the library'")
endif()
string(SUBSTRING "${readme}" ${at} -1 section)
string(FIND "${section}" "\n```cpp\n" open)
if(open EQUAL -1)
  message(FATAL_ERROR "README.md has no ```cpp block after '## Using the library'")
endif()
math(EXPR open "${open} + 8")  # past "\n```cpp\n"
string(SUBSTRING "${section}" ${open} -1 section)
string(FIND "${section}" "\n```" close)
if(close EQUAL -1)
  message(FATAL_ERROR "README.md: the ```cpp block after '## Using the library' is not closed")
endif()
math(EXPR close "${close} + 1")  # keep the last line's newline
string(SUBSTRING "${section}" 0 ${close} code)

pisco_install_fresh()
file(WRITE "${WORK_DIR}/project/main.cpp" "${code}")
file(WRITE "${WORK_DIR}/project/CMakeLists.txt" [=[
cmake_minimum_required(VERSION 3.22)
project(readme_example LANGUAGES CXX)
find_package(pisco 0.1 REQUIRED)
add_executable(readme_example main.cpp)
target_link_libraries(readme_example PRIVATE pisco::pisco)
]=])
pisco_build_against_prefix("${WORK_DIR}/project" readme_example exe)
pisco_step("run the README example" COMMAND "${exe}" OUTPUT out)
if(NOT out MATCHES "${EXPECT}")
  message(FATAL_ERROR "the README example ran, but printed no line matching '${EXPECT}':\n${out}")
endif()
