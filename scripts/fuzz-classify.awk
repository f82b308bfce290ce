# Reads the log of one fuzz target run on one input (scripts/run-fuzz.sh) and prints one line:
#   <where> <TAB> <kind> <TAB> <frame>
# where: "pisco" when the finding is in PISCO-VK's code (a reader, the library, the fuzz target),
# "third-party" when the report's first frame outside the sanitizers, libFuzzer, the C and C++
# runtimes is in one of the libraries PISCO-VK calls (CFITSIO, HDF5, HEALPix), "none" when the input ran
# cleanly. kind: what was reported (SEGV, heap-buffer-overflow, timeout, out-of-memory, leak, undefined
# behaviour, an exception that escaped, ...); frame: that first frame, the finding's signature.
# Variable `root`: the source tree, whose files are PISCO-VK's.
function frame_of(line,    s) {
  s = line
  sub(/^ *#[0-9]+ 0x[0-9a-f]+ /, "", s)
  sub(/^in /, "", s)
  sub(/^ +/, "", s)
  sub(/ \(BuildId: [0-9a-f]+\)$/, "", s)
  gsub(/\+0x[0-9a-f]+\)/, ")", s)
  return s
}
# Frames that are the machinery of the report, not its cause: the sanitizers' runtime, their interceptors
# (memcpy, memmove, ...) and libFuzzer, all in the fuzz target's executable without a source line (the
# target's own code has one), the allocator's entry points, and the C and C++ runtimes (glibc's frames
# name its sources by relative paths: "__strcpy_chk debug/./debug/strcpy_chk.c:30:5").
function machinery(f) {
  return f ~ /__sanitizer|__asan|__lsan|__ubsan|__interceptor|__interception|fuzzer::|^(malloc|calloc|realloc|free|posix_memalign|aligned_alloc) / ||
         f ~ /operator new|operator delete|libc\.so|libstdc\+\+\.so|libgcc_s\.so|libm\.so|^_start / ||
         f ~ /^[^ ]+ [a-z_]+\/\.\.?\/[^ ]*:[0-9]+(:[0-9]+)?$/ ||
         f ~ /\(.*\/tests\/fuzz\/fuzz_[a-z0-9_]+\)$/
}
function third_party(f) { return f ~ /libcfitsio|libhdf5|libhealpix|libsharp|libtomlplusplus|libcurl|libsz|libz\./ }
# "src/io/hdf5.cpp:208" of a frame in the source tree (its function names are long templates).
function location(f,    m) {
  m = f
  sub(/^.* \//, "/", m)
  sub(/:[0-9]+$/, "", m)
  return substr(m, length(root) + 2)
}
BEGIN { kind = ""; frame = ""; own = ""; where = ""; in_report = 0 }
/^pisco fuzz: finding:/ && kind == "" {
  kind = "escaped exception"; frame = $0; sub(/^pisco fuzz: finding: /, "", frame); where = "pisco"; next
}
/ runtime error: / && kind == "" {
  kind = "undefined behaviour"
  frame = $0; sub(/: runtime error:.*/, "", frame)
  if (index(frame, root "/") == 1) { where = "pisco"; frame = substr(frame, length(root) + 2) }
  in_report = 1; next
}
/ERROR: (AddressSanitizer|LeakSanitizer|libFuzzer)/ && kind == "" {
  kind = $0
  sub(/^.*ERROR: (AddressSanitizer|LeakSanitizer|libFuzzer): /, "", kind)
  sub(/ on (unknown )?address.*/, "", kind)
  sub(/: memory ranges .*/, "", kind)
  sub(/ \(pc .*/, "", kind)
  sub(/\(malloc\([0-9]+\)\)/, "(malloc)", kind)
  sub(/ \(used: .*/, " (rss)", kind)
  sub(/ after [0-9]+ seconds/, "", kind)
  sub(/ trying to allocate 0x[0-9a-f]+ bytes/, "", kind)
  in_report = 1; next
}
# The report's first stack: its first frame of its own (frame), and its first frame in the library's
# sources (own: where PISCO-VK's code was when it happened, or called the library that failed).
in_report == 1 && /^ *#[0-9]+ 0x/ {
  f = frame_of($0)
  if (frame == "" && !machinery(f)) frame = f
  if (own == "" && index(f, " " root "/src/") > 0) own = location(f)
  next
}
in_report == 1 && frame != "" { in_report = 2 }
END {
  if (kind == "") { print "none\t-\t-"; exit }
  if (where == "") where = third_party(frame) ? "third-party" : "pisco"
  if (where == "third-party" && own != "") frame = frame ", called from " own
  else if (where == "pisco" && kind != "escaped exception" && kind != "undefined behaviour" && own != "") frame = own
  if (frame == "") frame = "(no frame of its own in the report)"
  print where "\t" kind "\t" frame
}
