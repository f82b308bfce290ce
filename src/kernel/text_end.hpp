// Closes what kernel/text_begin.hpp opened: the common subset's macros as they were before. No
// include guard.
#undef PISCO_TEMPLATE_TEXT
#pragma pop_macro("PISCO_F64")
#pragma pop_macro("PISCO_PRECISE")
#pragma pop_macro("PISCO_INOUT")
#pragma pop_macro("PISCO_OUT")
#pragma pop_macro("PISCO_FN")
