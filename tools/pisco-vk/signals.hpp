// How `pisco-vk` stops and starts other programs: every signal whose default action ends a process
// and that can be caught (SIGHUP, SIGINT, SIGTERM, SIGQUIT, SIGUSR1, SIGUSR2, SIGALRM, SIGPIPE,
// SIGXFSZ) ends it at once with no temporary file left behind, and child programs (the plotting
// tool) are started with an argument vector, never through a shell.
#pragma once

#include <string>
#include <vector>

namespace pisco_cli {

// The process-directed ones are blocked in every thread and taken by one watcher thread; SIGPIPE and
// SIGXFSZ, sent to the thread whose write failed, are relayed to it by a handler. The watcher
// forwards the signal to a running child and gives it 3 s to end, removes the temporary files of the
// writers in progress (pisco::remove_temporary_files) and runs the on_stop cleanup, says so on
// stderr in one line and ends the process with status 128 + the signal, within milliseconds whatever
// the other threads are doing (a convolution, a write). A signal that was ignored when the process
// started (nohup) stays ignored. Call at the start of main, before any thread is started: threads
// inherit the mask.
void handle_stop_signals();

// Run by the watcher after the temporary files are gone (the run lock, directories the run made).
void on_stop(void (*f)());

// True once a stop signal has come: the watcher is ending the process. An error caused by the
// signal (a write that failed with EPIPE or EFBIG) must then not end it first: wait_for_stop() waits
// for the watcher's exit.
bool stopping_by_signal();
void wait_for_stop();

struct ChildStatus {
  int spawn_error = 0;  // errno of a program that could not be started (ENOENT: not installed)
  bool exited = false;  // exited normally, with `code`; else killed by `signal`
  int code = 0;
  int signal = 0;
};

// Runs args[0] (found on PATH when it has no '/') with the arguments args[1...], through posix_spawn:
// no shell, each argument passed as it is. Its stdout goes to /dev/null when `quiet`; it starts with
// no signal blocked and the default actions. Waits for it; a stop signal meanwhile is forwarded to it.
ChildStatus run_child(const std::vector<std::string>& args, bool quiet);

}  // namespace pisco_cli
