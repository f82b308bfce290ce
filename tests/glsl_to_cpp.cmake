# Turns a GLSL file written in the common subset of GLSL and C++ into C++: double literals lose their
# `lf` suffix. Usage: cmake -DIN=file.glsl -DOUT=file.hpp -P glsl_to_cpp.cmake
file(READ ${IN} text)
string(REGEX REPLACE "([0-9])lf" "\\1" text "${text}")
file(WRITE ${OUT} "${text}")
