# Turns a GLSL file written in the common subset of GLSL and C++ into C++: double literals lose their
# `lf` suffix, and `#include "name.glsl"` becomes `#include "name_host.hpp"` (the include's own
# conversion). Usage: cmake -DIN=file.glsl -DOUT=file.hpp -P glsl_to_cpp.cmake
file(READ ${IN} text)
string(REGEX REPLACE "([0-9])lf" "\\1" text "${text}")
string(REGEX REPLACE "#include \"([A-Za-z0-9_]+)\\.glsl\"" "#include \"\\1_host.hpp\"" text "${text}")
file(WRITE ${OUT} "${text}")
