#include "signals.hpp"

#include <fcntl.h>
#include <signal.h>
#include <spawn.h>
#include <sys/wait.h>
#include <unistd.h>

#include <atomic>
#include <cerrno>
#include <cstdio>
#include <cstring>
#include <thread>

#include "pisco/output_file.hpp"

namespace pisco_cli {
namespace {

std::atomic<pid_t> child{0};         // the child being waited for, 0 when none
std::atomic<bool> spawning{false};   // a child is being started: `child` is about to be set
std::atomic<bool> stopping{false};   // a stop signal came: the watcher is ending the process

sigset_t stop_signals() {
  sigset_t set;
  sigemptyset(&set);
  sigaddset(&set, SIGINT);
  sigaddset(&set, SIGTERM);
  sigaddset(&set, SIGHUP);
  return set;
}

const char* signal_name(int sig) {
  switch (sig) {
    case SIGINT: return "SIGINT";
    case SIGTERM: return "SIGTERM";
    case SIGHUP: return "SIGHUP";
    default: return "a signal";
  }
}

[[noreturn]] void watch() {
  const sigset_t set = stop_signals();
  int sig = 0;
  while (sigwait(&set, &sig) != 0) {
  }
  stopping = true;
  // A child just started gets the signal too (its pid is set once posix_spawn has returned).
  for (int i = 0; i < 100 && spawning.load(); ++i) ::usleep(10000);
  if (const pid_t c = child.load(); c > 0) {
    // The plotting tool removes its own temporary files when signalled.
    ::kill(c, sig);
    for (int i = 0; i < 300 && child.load() == c; ++i) ::usleep(10000);
    if (child.load() == c) ::kill(c, SIGKILL);
  }
  const std::size_t removed = pisco::remove_temporary_files();
  char text[256];
  const int n = std::snprintf(text, sizeof text, "%spisco-vk: stopped by %s; %zu temporary file%s removed, no output "
                              "left half-written\n", ::isatty(STDERR_FILENO) ? "\n" : "", signal_name(sig), removed,
                              removed == 1 ? "" : "s");
  if (n > 0) (void)!::write(STDERR_FILENO, text, std::min<std::size_t>(std::size_t(n), sizeof text - 1));
  ::_exit(128 + sig);
}

}  // namespace

void handle_stop_signals() {
  const sigset_t set = stop_signals();
  pthread_sigmask(SIG_BLOCK, &set, nullptr);
  std::thread(watch).detach();
}

ChildStatus run_child(const std::vector<std::string>& args, bool quiet) {
  ChildStatus st;
  std::vector<char*> argv;
  for (const auto& a : args) argv.push_back(const_cast<char*>(a.c_str()));
  argv.push_back(nullptr);
  posix_spawn_file_actions_t actions;
  posix_spawn_file_actions_init(&actions);
  if (quiet) posix_spawn_file_actions_addopen(&actions, STDOUT_FILENO, "/dev/null", O_WRONLY, 0);
  posix_spawnattr_t attr;
  posix_spawnattr_init(&attr);
  sigset_t none, defaults = stop_signals();
  sigemptyset(&none);
  posix_spawnattr_setsigmask(&attr, &none);
  posix_spawnattr_setsigdefault(&attr, &defaults);
  posix_spawnattr_setflags(&attr, POSIX_SPAWN_SETSIGMASK | POSIX_SPAWN_SETSIGDEF);
  std::fflush(stdout);
  std::fflush(stderr);
  pid_t pid = 0;
  spawning = true;
  st.spawn_error = posix_spawnp(&pid, argv[0], &actions, &attr, argv.data(), environ);
  if (st.spawn_error == 0) child = pid;
  spawning = false;
  posix_spawn_file_actions_destroy(&actions);
  posix_spawnattr_destroy(&attr);
  if (st.spawn_error != 0) return st;
  int status = 0;
  while (::waitpid(pid, &status, 0) < 0 && errno == EINTR) {
  }
  child = 0;
  // A stop signal came while the child ran: the watcher ends the process (status 128 + signal).
  while (stopping) ::pause();
  st.exited = WIFEXITED(status);
  st.code = st.exited ? WEXITSTATUS(status) : 0;
  st.signal = WIFSIGNALED(status) ? WTERMSIG(status) : 0;
  return st;
}

}  // namespace pisco_cli
