// Runs `pisco-vk` as a user would, without a shell (posix_spawn), for the cli and robustness tests:
// exit status or signal, stdout and stderr together, a time limit, extra environment variables, and
// the checks of docs/formats.md, "Errors and partial files".
#pragma once

#include <fcntl.h>
#include <poll.h>
#include <signal.h>
#include <spawn.h>
#include <sys/wait.h>
#include <unistd.h>

#include <chrono>
#include <filesystem>
#include <functional>
#include <map>
#include <string>
#include <vector>

namespace pisco_test {

struct CliResult {
  bool exited = false;  // exited normally with `status`; else killed by `signal`
  int status = -1;
  int signal = 0;
  bool timed_out = false;
  double seconds = 0.0;
  std::string output;  // stdout and stderr
  // The number of lines starting "pisco-vk: error:".
  std::size_t error_lines() const {
    std::size_t n = 0;
    for (std::size_t at = output.find("pisco-vk: error:"); at != std::string::npos;
         at = output.find("pisco-vk: error:", at + 1))
      if (at == 0 || output[at - 1] == '\n') ++n;
    return n;
  }
  std::string error_line() const {
    const auto at = output.find("pisco-vk: error:");
    return at == std::string::npos ? std::string() : output.substr(at, output.find('\n', at) - at);
  }
  std::string describe() const {
    return timed_out ? "timed out" : exited ? "exit status " + std::to_string(status) : "killed by signal " + std::to_string(signal);
  }
};

// Started child: its pid and the read end of its output pipe.
struct CliProcess {
  pid_t pid = -1;
  int out = -1;
  std::chrono::steady_clock::time_point start;
};

// Starts `program` (a path, or a name looked up on PATH) with `args`, the environment plus `env`
// (PISCO_TEST_FAULT only where `env` sets it), in `cwd` when given.
inline CliProcess start_process(const std::string& program, const std::vector<std::string>& args,
                                const std::map<std::string, std::string>& env = {},
                                const std::filesystem::path& cwd = {}) {
  std::vector<std::string> argv_s{program};
  argv_s.insert(argv_s.end(), args.begin(), args.end());
  std::vector<char*> argv;
  for (auto& a : argv_s) argv.push_back(a.data());
  argv.push_back(nullptr);
  std::vector<std::string> env_s;
  for (char** e = environ; *e; ++e) {
    const std::string kv(*e);
    const std::string key = kv.substr(0, kv.find('='));
    if (!env.count(key) && key != "PISCO_TEST_FAULT") env_s.push_back(kv);
  }
  for (const auto& [k, v] : env) env_s.push_back(k + "=" + v);
  std::vector<char*> envp;
  for (auto& e : env_s) envp.push_back(e.data());
  envp.push_back(nullptr);
  int fds[2];
  if (::pipe2(fds, O_CLOEXEC) != 0) return {};
  posix_spawn_file_actions_t actions;
  posix_spawn_file_actions_init(&actions);
  posix_spawn_file_actions_adddup2(&actions, fds[1], STDOUT_FILENO);
  posix_spawn_file_actions_adddup2(&actions, fds[1], STDERR_FILENO);
  if (!cwd.empty()) posix_spawn_file_actions_addchdir_np(&actions, cwd.c_str());
  CliProcess p;
  p.start = std::chrono::steady_clock::now();
  if (posix_spawnp(&p.pid, argv[0], &actions, nullptr, argv.data(), envp.data()) != 0) p.pid = -1;
  posix_spawn_file_actions_destroy(&actions);
  ::close(fds[1]);
  p.out = fds[0];
  return p;
}

inline CliProcess start_cli(const std::vector<std::string>& args, const std::map<std::string, std::string>& env = {},
                            const std::filesystem::path& cwd = {}) {
  return start_process(PISCO_VK_EXE, args, env, cwd);
}

// Reads the child's output until it ends (or `timeout_s` passes: then it is killed), and reaps it.
// `on_output` sees the output read so far, after each read (to act mid-run, e.g. send a signal).
inline CliResult finish_cli(CliProcess p, double timeout_s = 120.0,
                            const std::function<void(const std::string&)>& on_output = nullptr) {
  CliResult r;
  if (p.pid < 0) {
    r.output = "could not start the program";
    return r;
  }
  const auto deadline = p.start + std::chrono::duration<double>(timeout_s);
  char buf[4096];
  for (;;) {
    const auto left = std::chrono::duration_cast<std::chrono::milliseconds>(deadline - std::chrono::steady_clock::now());
    if (left.count() <= 0) {
      r.timed_out = true;
      ::kill(p.pid, SIGKILL);
      break;
    }
    pollfd pfd{p.out, POLLIN, 0};
    const int ready = ::poll(&pfd, 1, static_cast<int>(std::min<long long>(left.count(), 50)));
    if (ready > 0) {
      const ssize_t n = ::read(p.out, buf, sizeof buf);
      if (n <= 0) break;
      r.output.append(buf, static_cast<std::size_t>(n));
    }
    if (on_output) on_output(r.output);
  }
  ::close(p.out);
  int status = 0;
  ::waitpid(p.pid, &status, 0);
  r.seconds = std::chrono::duration<double>(std::chrono::steady_clock::now() - p.start).count();
  r.exited = WIFEXITED(status);
  r.status = r.exited ? WEXITSTATUS(status) : -1;
  r.signal = WIFSIGNALED(status) ? WTERMSIG(status) : 0;
  return r;
}

inline CliResult run_cli(const std::vector<std::string>& args, const std::map<std::string, std::string>& env = {},
                         double timeout_s = 120.0, const std::filesystem::path& cwd = {}) {
  return finish_cli(start_cli(args, env, cwd), timeout_s);
}

// Every file under dir (recursively), as paths relative to it; empty when dir does not exist.
inline std::vector<std::string> files_under(const std::filesystem::path& dir) {
  std::vector<std::string> out;
  std::error_code ec;
  if (!std::filesystem::exists(dir, ec)) return out;
  for (const auto& e : std::filesystem::recursive_directory_iterator(dir, ec))
    if (!e.is_directory()) out.push_back(std::filesystem::relative(e.path(), dir).string());
  return out;
}

inline std::string joined(const std::vector<std::string>& v) {
  std::string s;
  for (const auto& x : v) s += (s.empty() ? "" : ", ") + x;
  return s;
}

// Temporary files (".tmp-<pid>") under dir.
inline std::vector<std::string> temporaries_under(const std::filesystem::path& dir) {
  std::vector<std::string> out;
  for (const auto& f : files_under(dir))
    if (f.find(".tmp") != std::string::npos) out.push_back(f);
  return out;
}

}  // namespace pisco_test
