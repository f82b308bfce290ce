# Installs PISCO-VK into a scratch prefix, then configures, builds and runs a tiny consumer project
# that finds it with find_package(pisco) and links pisco::pisco.
# Inputs: PISCO_SOURCE_DIR, PISCO_BINARY_DIR, WORK_DIR.
file(REMOVE_RECURSE "${WORK_DIR}")
function(step what)
  execute_process(COMMAND ${ARGN} RESULT_VARIABLE rc OUTPUT_VARIABLE out ERROR_VARIABLE err)
  if(NOT rc EQUAL 0)
    message(FATAL_ERROR "consumer: ${what} failed (${rc})\n${out}\n${err}")
  endif()
  message(STATUS "consumer: ${what}\n${out}")
endfunction()
step("install" ${CMAKE_COMMAND} --install "${PISCO_BINARY_DIR}" --prefix "${WORK_DIR}/prefix")
step("configure" ${CMAKE_COMMAND} -S "${PISCO_SOURCE_DIR}/tests/consumer/project" -B "${WORK_DIR}/build"
     -G Ninja -DCMAKE_PREFIX_PATH=${WORK_DIR}/prefix)
step("build" ${CMAKE_COMMAND} --build "${WORK_DIR}/build")
step("run" "${WORK_DIR}/build/consumer")
