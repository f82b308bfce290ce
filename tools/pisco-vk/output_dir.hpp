// The output directory of a run (docs/formats.md, "Errors and partial files"): made with its missing
// parents, locked against a second run, cleared of the temporary files of runs that were killed, and
// removed again, with the parents it made, when the run fails before writing anything there.
#pragma once

#include <filesystem>
#include <string>
#include <vector>

namespace pisco_cli {

class OutputDirectory {
 public:
  // Makes `dir` and its missing parents. With `lock` (one process of a run: MPI's rank 0), takes the
  // directory's pisco::OutputLock (include/pisco/output_file.hpp), which removes the temporary files of
  // a killed run, telling `say` of each. Throws pisco::Error naming the directory: cannot be made, or
  // another run (named by its process) holds the lock, or the lock file is not this program's.
  OutputDirectory(const std::filesystem::path& dir, bool lock, void (*say)(const std::string&));
  // Releases the lock (the lock file is removed); unless keep() was called, removes the directories
  // this run made that are empty. Also done by the stop-signal watcher (signals.hpp, on_stop).
  ~OutputDirectory();
  OutputDirectory(const OutputDirectory&) = delete;
  OutputDirectory& operator=(const OutputDirectory&) = delete;

  // The run has ended well: what it made stays.
  void keep();
};

}  // namespace pisco_cli
