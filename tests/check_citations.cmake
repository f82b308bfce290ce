# ctest citations: comments, docstrings and help texts cite files that are in the repository
# (e.g. "docs/validation.md, H3"), never documents it does not hold. Fails, naming the file and quoting the line,
# when a tracked file cites a numbered design section, a lettered validation case by a bare name,
# a top-level design or validation document, or a folder outside the repository.
#
#   cmake -DSOURCE_DIR=<repository root> -P tests/check_citations.cmake
#
# The files are git's tracked files when git and the repository's .git are there, else the sources
# under the repository's own folders. This script is left out of the search (its patterns would
# match themselves), and the patterns are spelled with bracket classes for the same reason.

if(NOT SOURCE_DIR)
  message(FATAL_ERROR "check_citations: pass -DSOURCE_DIR=<repository root>")
endif()
get_filename_component(SOURCE_DIR "${SOURCE_DIR}" ABSOLUTE)
get_filename_component(self "${CMAKE_CURRENT_LIST_FILE}" ABSOLUTE)

set(files "")
find_package(Git QUIET)
if(GIT_FOUND AND EXISTS "${SOURCE_DIR}/.git")
  execute_process(COMMAND "${GIT_EXECUTABLE}" -C "${SOURCE_DIR}" ls-files
                  OUTPUT_VARIABLE listed RESULT_VARIABLE rc ERROR_QUIET)
  if(rc EQUAL 0)
    string(REPLACE "\n" ";" listed "${listed}")
    foreach(f IN LISTS listed)
      if(NOT f STREQUAL "")
        list(APPEND files "${SOURCE_DIR}/${f}")
      endif()
    endforeach()
  endif()
endif()
if(NOT files)
  set(globs "")
  foreach(dir src include tools tests scripts python shaders assets docs examples cmake)
    foreach(ext cpp hpp h c cu cuh py pyi md toml txt cmake glsl comp sh in sbatch)
      list(APPEND globs "${SOURCE_DIR}/${dir}/*.${ext}")
    endforeach()
  endforeach()
  file(GLOB_RECURSE files ${globs})
  list(APPEND files "${SOURCE_DIR}/CMakeLists.txt" "${SOURCE_DIR}/README.md"
                    "${SOURCE_DIR}/BENCHMARKS.md")
endif()

# "DESIGN 3", "VALIDATION H3", "DESIGN.md", "VALIDATION.md", "../shared".
set(pattern "[D]ESIGN [0-9]|[V]ALIDATION [A-Z]|[D]ESIGN[.]md|[V]ALIDATION[.]md|[.][.]/[s]hared")

set(found 0)
foreach(f IN LISTS files)
  get_filename_component(fa "${f}" ABSOLUTE)
  if(fa STREQUAL self OR NOT EXISTS "${fa}" OR IS_DIRECTORY "${fa}")
    continue()
  endif()
  file(STRINGS "${fa}" lines REGEX "${pattern}")
  if(NOT lines)
    continue()
  endif()
  file(RELATIVE_PATH rel "${SOURCE_DIR}" "${fa}")
  foreach(line IN LISTS lines)
    string(STRIP "${line}" line)
    message("${rel}: cites a document outside the repository: ${line}")
    math(EXPR found "${found} + 1")
  endforeach()
endforeach()

list(LENGTH files count)
if(found GREATER 0)
  message(FATAL_ERROR "check_citations: ${found} citation(s) of documents the repository does not "
                      "hold; cite a file in the repository instead (e.g. docs/validation.md, H3)")
endif()
message(STATUS "check_citations: ${count} files, no citation outside the repository")
