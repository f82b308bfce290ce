// `pisco-vk run`: a whole simulation through pisco::Simulation (simulation.hpp; docs/library.md), with what
// the command line adds around it: the output directory's lock, the processes of an MPI run
// (cluster.hpp), the progress bar, the printed account and summary, and the plots.
#include "run.hpp"

#include <chrono>
#include <cstdio>
#include <cstdlib>
#include <cstring>
#include <functional>
#include <optional>
#include <string>

#include "cluster.hpp"
#include "output_dir.hpp"
#include "pisco/output_file.hpp"
#include "progress.hpp"
#include "signals.hpp"

namespace pisco_cli {
namespace {

namespace fs = std::filesystem;

// The library's view of the processes of the run (pisco::RunContext): the Cluster's, MPI's ranks in the
// MPI build.
class ClusterContext final : public pisco::RunContext {
 public:
  explicit ClusterContext(Cluster& cluster) : cl_(cluster) {}
  int rank() const override { return cl_.rank(); }
  int size() const override { return cl_.size(); }
  int node_rank() const override { return cl_.node_rank(); }
  int node_size() const override { return cl_.node_size(); }
  void step(const std::function<void()>& f) override { cl_.step(f); }
  void agree(const std::optional<std::string>& error) override { cl_.agree(error); }
  std::string broadcast(const std::string& text) override { return cl_.broadcast(text); }
  void barrier() override { cl_.barrier(); }
  double max(double v) override { return cl_.max(v); }
  std::uint64_t sum(std::uint64_t v) override { return cl_.sum(v); }
  double sum_of(double v) override { return cl_.sum_of(v); }
  std::uint64_t reduce(pisco::BinnedMapmaker& mapper) override { return cl_.reduce(mapper); }
  void sum_in_place(std::span<double> values) override { cl_.sum_in_place(values); }
  const void* mpi_communicator() const override { return cl_.mpi_communicator(); }
  void post_check(bool failed) override { cl_.post_check(failed); }
  bool stop() override { return cl_.stop(); }
  void finish_checks(std::size_t total, bool failed) override { cl_.finish_checks(total, failed); }
  // Fault injection for the tests (docs/scaling.md): PISCO_TEST_RANK_FAIL=R makes rank R fail after
  // its first job, as a rank whose device or disk fails mid-run would.
  bool inject_failure() const override {
    const char* fail_env = std::getenv("PISCO_TEST_RANK_FAIL");
    return fail_env != nullptr && std::atoi(fail_env) == cl_.rank();
  }

 private:
  Cluster& cl_;
};

// The run's account on stdout, its progress on stderr (progress.hpp).
class Printer final : public pisco::RunObserver {
 public:
  explicit Printer(bool quiet) : quiet_(quiet) {}
  void log(const std::string& line) override {
    if (!quiet_) std::fputs(line.c_str(), stdout);
    std::fflush(stdout);
  }
  void begin_convolution(std::uint64_t samples) override { progress_.emplace(samples, quiet_); }
  void advance(std::uint64_t samples) override {
    if (progress_) progress_->advance(samples);
  }
  void end_convolution() override {
    if (progress_) progress_->finish();
  }

 private:
  bool quiet_;
  std::optional<Progress> progress_;
};

// The plotting tool (tools/pisco_plot.py), started with an argument vector, never through a shell:
// the output directory reaches it as one argument whatever its characters. Nothing is read as an
// option: the script's path is absolute (Python would take a path beginning with '-' as its own
// option), and "--" ends the tool's options before the directory (argparse would take "-x" as one).
// Returns false when it cannot plot here (no Python, or no healpy or matplotlib: the tool exits with
// status 3), saying why; throws pisco::Error when it fails otherwise (a full disk: status 4; a crash).
bool run_plots(const fs::path& python, const fs::path& script, const fs::path& dir, bool quiet,
               const std::function<void(const std::string&)>& say) {
  std::error_code ec;
  fs::path absolute_script = fs::absolute(script, ec);
  if (ec) absolute_script = script;
  // Its temporary files carry this process's suffix, which the directory's lock records: if both are
  // killed, the next run there removes them.
  const std::vector<std::string> args{python.string(), absolute_script.string(),
                                      "--temporary-suffix=" + pisco::temporary_suffix(), "--", dir.string()};
  const ChildStatus st = run_child(args, quiet);
  if (st.spawn_error != 0) {
    say("plots: skipped (" + python.string() + " could not be started: " + std::strerror(st.spawn_error) + ")\n");
    return false;
  }
  if (st.exited && st.code == 0) return true;
  if (st.exited && st.code == 3) {
    say("plots: skipped (" + script.filename().string() + " cannot plot here; see above)\n");
    return false;
  }
  throw pisco::Error("plots: " + script.string() + " " +
                     (st.exited ? "failed with exit status " + std::to_string(st.code)
                                : "was killed by signal " + std::to_string(st.signal)) +
                     " writing into " + dir.string() + " (see its message above)");
}

}  // namespace

int run_simulation(const pisco::SimulationConfig& c, const RunOptions& ro) {
  const auto t0 = std::chrono::steady_clock::now();
  // Under MPI (cluster.hpp, docs/scaling.md): every rank runs this function; rank 0 alone speaks, and
  // every step that can fail on one rank is a collective step (Cluster::step), so that an error on
  // any rank ends every rank with that rank's message.
  Cluster& cl = Cluster::get();
  const bool quiet = ro.quiet || !cl.leader();
  auto say = [&](const char* fmt, auto... args) {
    if (!quiet) std::printf(fmt, args...);
    std::fflush(stdout);
  };
  say("pisco-vk %s: %s\n", pisco::version, c.source.empty() ? "built-in defaults" : c.source.string().c_str());

  // Made and locked first, so that a second run into it stops before its set-up; removed again if the
  // run fails before writing there.
  std::optional<OutputDirectory> out_dir;
  cl.step([&] {
    out_dir.emplace(c.output.dir, cl.leader(), [](const std::string& m) { std::fprintf(stderr, "%s\n", m.c_str()); });
  });

  ClusterContext context(cl);
  Printer printer(quiet);
  pisco::SimulationOptions options;
  options.data_dir = ro.data_dir;
  options.lock_output = false;  // out_dir holds it, until after the plots
  const pisco::SimulationResult r = pisco::Simulation(c, options).run(context, &printer);

  // Plots: rank 0's, of the maps it wrote. A run whose maps solve no pixel has none (exit status 4).
  cl.step([&] {
    if (c.output.plots && ro.plots && c.output.maps && r.nothing_solved.empty() && cl.leader()) {
      const fs::path plot_script = ro.data_dir / "tools" / "pisco_plot.py";
      if (!fs::exists(plot_script)) {
        say("plots: skipped (tools/pisco_plot.py not found)\n");
      } else {
        const fs::path python = fs::exists("/usr/bin/python3") ? "/usr/bin/python3" : "python3";
        run_plots(python, plot_script, c.output.dir, quiet, [&](const std::string& m) { say("%s", m.c_str()); });
      }
    }
  });

  out_dir->keep();
  const double wall = std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count();
  const double conv = r.convolution_seconds;
  if (!quiet) {
    std::printf("summary: %llu samples, %.1f pixels per disc, %.3g pixel evaluations/s, %.3g samples/s\n",
                static_cast<unsigned long long>(r.samples), r.mean_disc_pixels,
                double(r.samples) * r.mean_disc_pixels / conv, double(r.samples) / conv);
    std::printf("         device %s (%s); convolution %s, wall time %s\n", r.backend.c_str(), r.device.c_str(),
                human_seconds(conv).c_str(), human_seconds(wall).c_str());
    if (cl.parallel())
      std::printf("         %d ranks: %.3g samples/s per rank (the slowest's time); map reduction %.3g MB, "
                  "TOD %.3g MB written by all\n",
                  cl.size(), double(r.samples) / conv / cl.size(), double(r.reduced_bytes) / 1e6,
                  r.tod_file.empty() ? 0.0 : double(fs::file_size(r.tod_file)) / 1e6);
    for (const auto& f : r.written) std::printf("         wrote %s\n", f.string().c_str());
  }
  if (!r.nothing_solved.empty() || !r.warnings.empty()) std::fflush(stdout);
  if (cl.leader())
    for (const std::string& w : r.warnings) std::fprintf(stderr, "pisco-vk: warning: %s\n", w.c_str());
  if (!r.nothing_solved.empty()) {
    std::fprintf(stderr, "pisco-vk: warning: %s\n", r.nothing_solved.c_str());
    return exit_nothing_solved;
  }
  if (!r.warnings.empty()) return exit_warnings;
  return 0;
}

}  // namespace pisco_cli
