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
std::atomic<void (*)()> cleanup{nullptr};  // the run's own cleanup (lock, empty directories)

static_assert(std::atomic<bool>::is_always_lock_free, "set from a signal handler");

// The signals whose default action ends the process and that can be caught. SIGPIPE and SIGXFSZ are
// sent to the thread whose write failed; the others to the process.
constexpr int process_signals[] = {SIGHUP, SIGINT, SIGTERM, SIGQUIT, SIGUSR1, SIGUSR2, SIGALRM};
constexpr int thread_signals[] = {SIGPIPE, SIGXFSZ};
// Carries a thread-directed signal to the watcher (its number in the value): a real-time signal,
// blocked everywhere, queued by the handler with sigqueue (async-signal-safe).
int relay_signal() { return SIGRTMIN + 3; }

sigset_t handled;  // the signals this process handles: those not ignored when it started

bool ignored(int sig) {
  struct sigaction old{};
  return ::sigaction(sig, nullptr, &old) == 0 && old.sa_handler == SIG_IGN;
}

const char* signal_name(int sig) {
  switch (sig) {
    case SIGHUP: return "SIGHUP";
    case SIGINT: return "SIGINT";
    case SIGTERM: return "SIGTERM";
    case SIGQUIT: return "SIGQUIT";
    case SIGUSR1: return "SIGUSR1";
    case SIGUSR2: return "SIGUSR2";
    case SIGALRM: return "SIGALRM";
    case SIGPIPE: return "SIGPIPE (a closed pipe)";
    case SIGXFSZ: return "SIGXFSZ (the file size limit)";
    default: return "a signal";
  }
}

// In the thread whose write raised SIGPIPE or SIGXFSZ: that write fails (EPIPE, EFBIG) once this
// returns, and the error it causes must not end the process before the watcher does.
void relay(int sig) {
  const int saved = errno;
  stopping = true;
  union sigval v{};
  v.sival_int = sig;
  ::sigqueue(::getpid(), relay_signal(), v);
  errno = saved;
}

[[noreturn]] void watch(sigset_t set) {
  siginfo_t info{};
  int sig = -1;
  while ((sig = ::sigwaitinfo(&set, &info)) < 0) {
  }
  if (sig == relay_signal()) sig = info.si_value.sival_int;
  stopping = true;
  // A child just started gets the signal too (its pid is set once posix_spawn has returned).
  for (int i = 0; i < 100 && spawning.load(); ++i) ::usleep(10000);
  if (const pid_t c = child.load(); c > 0) {
    // The plotting tool removes its own temporary files when signalled.
    ::kill(c, sig == SIGPIPE || sig == SIGXFSZ ? SIGTERM : sig);
    for (int i = 0; i < 300 && child.load() == c; ++i) ::usleep(10000);
    if (child.load() == c) ::kill(c, SIGKILL);
  }
  const std::size_t removed = pisco::remove_temporary_files();
  if (auto f = cleanup.load()) f();
  char text[256];
  const int n = std::snprintf(text, sizeof text, "%spisco-vk: stopped by %s; %zu temporary file%s removed, no output "
                              "left half-written\n", ::isatty(STDERR_FILENO) ? "\n" : "", signal_name(sig), removed,
                              removed == 1 ? "" : "s");
  if (n > 0) (void)!::write(STDERR_FILENO, text, std::min<std::size_t>(std::size_t(n), sizeof text - 1));
  ::_exit(128 + sig);
}

}  // namespace

void handle_stop_signals() {
  sigemptyset(&handled);
  sigset_t wait_for;
  sigemptyset(&wait_for);
  // A signal ignored by the parent (nohup, a shell's background job) stays ignored: blocked, Linux
  // would keep it pending for the watcher instead of dropping it.
  for (int sig : process_signals)
    if (!ignored(sig)) {
      sigaddset(&handled, sig);
      sigaddset(&wait_for, sig);
    }
  sigaddset(&wait_for, relay_signal());
  pthread_sigmask(SIG_BLOCK, &wait_for, nullptr);
  for (int sig : thread_signals)
    if (!ignored(sig)) {
      sigaddset(&handled, sig);
      struct sigaction a{};
      a.sa_handler = relay;
      sigemptyset(&a.sa_mask);
      a.sa_flags = SA_RESTART;
      ::sigaction(sig, &a, nullptr);
    }
  std::thread(watch, wait_for).detach();
}

void on_stop(void (*f)()) { cleanup = f; }

bool stopping_by_signal() { return stopping.load(); }

void wait_for_stop() {
  while (stopping) ::pause();
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
  // The child starts with the actions this process started with: the handled signals at their
  // defaults, the ignored ones still ignored (posix_spawn keeps SIG_IGN).
  sigset_t none, defaults = handled;
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
  wait_for_stop();
  st.exited = WIFEXITED(status);
  st.code = st.exited ? WEXITSTATUS(status) : 0;
  st.signal = WIFSIGNALED(status) ? WTERMSIG(status) : 0;
  return st;
}

}  // namespace pisco_cli
