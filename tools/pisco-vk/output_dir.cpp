#include "output_dir.hpp"

#include <mutex>
#include <optional>

#include "pisco/error.hpp"
#include "pisco/output_file.hpp"
#include "signals.hpp"

namespace fs = std::filesystem;

namespace pisco_cli {
namespace {

// One output directory a process: shared with the stop-signal watcher, under the mutex.
struct State {
  std::mutex mutex;
  std::vector<fs::path> made;  // the directories this run made, deepest last
  std::optional<pisco::OutputLock> lock;
  bool keep = false;
};
State& state() {
  static State* s = new State();  // never destroyed: the watcher may use it while the process ends
  return *s;
}

// Under the mutex. No allocation needed beyond what the paths hold: safe from the watcher thread.
void release_locked(State& s) {
  s.lock.reset();
  if (!s.keep)
    for (auto it = s.made.rbegin(); it != s.made.rend(); ++it) ::rmdir(it->c_str());  // only if empty
  s.made.clear();
}

void release_on_stop() {
  State& s = state();
  std::lock_guard lock(s.mutex);
  release_locked(s);
}

}  // namespace

OutputDirectory::OutputDirectory(const fs::path& dir, bool lock, void (*say)(const std::string&)) {
  State& s = state();
  std::unique_lock guard(s.mutex);
  // A stop signal came (the watcher may have cleaned up already): make nothing, let it end the process
  // (without the mutex, which its cleanup takes).
  if (stopping_by_signal()) {
    guard.unlock();
    wait_for_stop();
  }
  s.keep = false;
  s.made.clear();
  std::vector<fs::path> missing;
  std::error_code ec;
  for (fs::path p = fs::absolute(dir, ec).lexically_normal(); !p.empty() && !fs::exists(p, ec); p = p.parent_path()) {
    missing.push_back(p);
    if (p == p.parent_path()) break;
  }
  if (!fs::create_directories(dir, ec) && ec)
    throw pisco::Error(dir.string() + ": cannot create the output directory (" + ec.message() + ")");
  s.made.assign(missing.rbegin(), missing.rend());
  on_stop(release_on_stop);
  if (!lock) return;

  try {
    s.lock.emplace(dir, [say](const std::string& m) { say("pisco-vk: " + m); });
  } catch (...) {
    release_locked(s);
    throw;
  }
}

OutputDirectory::~OutputDirectory() {
  State& s = state();
  std::lock_guard lock(s.mutex);
  release_locked(s);
}

void OutputDirectory::keep() {
  State& s = state();
  std::lock_guard lock(s.mutex);
  s.keep = true;
}

}  // namespace pisco_cli
