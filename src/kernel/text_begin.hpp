// Opens a kernel text (a .glsl file written in the common subset of GLSL and C++, common.glsl) to
// C++, for the host and for CUDA devices: saves the macros of the common subset, which common.glsl
// also defines for the GLSL-as-C++ host tests, and sets them for C++ templates and host/device
// functions. Between this and kernel/text_end.hpp the includer defines its text's own macros (its
// number types, their constructors, the functions GLSL has built in) and includes the text. No
// include guard: included once for each text.
#pragma push_macro("PISCO_FN")
#pragma push_macro("PISCO_OUT")
#pragma push_macro("PISCO_INOUT")
#pragma push_macro("PISCO_PRECISE")
#pragma push_macro("PISCO_F64")
#undef PISCO_FN
#undef PISCO_OUT
#undef PISCO_INOUT
#undef PISCO_PRECISE
#undef PISCO_F64
#define PISCO_TEMPLATE_TEXT 1
#define PISCO_FN PISCO_HD
#define PISCO_OUT(T) T&
#define PISCO_INOUT(T) T&
#define PISCO_PRECISE
#define PISCO_F64 double
