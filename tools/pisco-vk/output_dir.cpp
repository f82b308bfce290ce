#include "output_dir.hpp"

#include <fcntl.h>
#include <signal.h>
#include <sys/file.h>
#include <unistd.h>

#include <cerrno>
#include <cstring>
#include <mutex>
#include <regex>

#include "pisco/error.hpp"
#include "signals.hpp"

namespace fs = std::filesystem;

namespace pisco_cli {
namespace {

// One output directory a process: shared with the stop-signal watcher, under the mutex.
struct State {
  std::mutex mutex;
  std::vector<fs::path> made;  // the directories this run made, deepest last
  fs::path lock_file;
  int lock_fd = -1;
  bool keep = false;
};
State& state() {
  static State* s = new State();  // never destroyed: the watcher may use it while the process ends
  return *s;
}

// Under the mutex. No allocation needed beyond what the paths hold: safe from the watcher thread.
void release_locked(State& s) {
  if (s.lock_fd >= 0) {
    ::unlink(s.lock_file.c_str());  // before the unlock: a run that takes the lock next makes its own
    ::close(s.lock_fd);
    s.lock_fd = -1;
  }
  if (!s.keep)
    for (auto it = s.made.rbegin(); it != s.made.rend(); ++it) ::rmdir(it->c_str());  // only if empty
  s.made.clear();
}

void release_on_stop() {
  State& s = state();
  std::lock_guard lock(s.mutex);
  release_locked(s);
}

std::string process_of(int fd) {
  char text[32] = {};
  if (::pread(fd, text, sizeof text - 1, 0) <= 0) return "another process";
  const long pid = std::strtol(text, nullptr, 10);
  return pid > 0 ? "process " + std::to_string(pid) : "another process";
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

  s.lock_file = dir / ".pisco-vk.lock";
  const int fd = ::open(s.lock_file.c_str(), O_RDWR | O_CREAT | O_CLOEXEC, 0644);
  if (fd < 0) {
    const std::string why = std::strerror(errno);
    release_locked(s);
    throw pisco::Error(s.lock_file.string() + ": cannot create the run's lock file (" + why + ")");
  }
  if (::flock(fd, LOCK_EX | LOCK_NB) != 0) {
    const std::string who = process_of(fd);
    ::close(fd);
    release_locked(s);
    throw pisco::Error(dir.string() + ": another pisco-vk run (" + who +
                       ") is writing into this directory; wait for it to end or choose another output directory");
  }
  const std::string pid = std::to_string(::getpid()) + "\n";
  if (::ftruncate(fd, 0) != 0 || ::pwrite(fd, pid.data(), pid.size(), 0) != ssize_t(pid.size())) {
    // The lock holds without the number: only the message of a second run is the poorer.
  }
  s.lock_fd = fd;

  // Temporary files of runs that were killed (SIGKILL, a crash, a power cut): NAME.tmp-PID whose
  // process has ended. Under the lock no live run of this program writes here; a live process of
  // that number is left alone, whatever it is.
  static const std::regex temporary(R"((.+)\.tmp-([0-9]{1,10}))");
  for (const auto& e : fs::directory_iterator(dir, ec)) {
    std::smatch m;
    const std::string name = e.path().filename().string();
    if (!std::regex_match(name, m, temporary)) continue;
    const long pid = std::stol(m[2].str());
    if (pid <= 0 || pid == ::getpid() || ::kill(pid_t(pid), 0) == 0 || errno != ESRCH) continue;
    std::error_code rec;
    if (fs::remove(e.path(), rec))
      say("pisco-vk: removed " + e.path().string() + ", a temporary file left by process " + m[2].str() +
          ", which has ended");
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
