#pragma once
// Each subcommand lives in its own cli/cmd_*.cc and registers itself on the top-level app.
// The callback it installs runs the command; errors propagate as exceptions to main(), which maps
// InputError to exit code 2 and everything else to 1.
#include <CLI/CLI.hpp>

#include <stdexcept>
#include <string>
#include <vector>

namespace sf::cli {

// The options of `fuse`, shared with `resume`.
struct FuseArgs {
  std::string input, output, config, export_vdb, stats_json, job, memory_limit;
  std::string format, colmap_maps, mve_depth, mve_image, mve_confidence, bbox, extract_mode, brick_size;
  std::vector<std::string> sets;
  std::vector<std::string> more_inputs;  // further input folders after `input` (a grown job)
  bool add = false;                      // scalefuse add: the inputs may extend the job's
  bool follow = false;                   // fuse --follow: the input folder is still being written
  std::string stop_file;                 // --follow ends when it exists (default: JOB/STOP)
  double settle_seconds = 2.0, poll_seconds = 1.0;
  int threads = 0;
  std::size_t checkpoint_every = 200;
  double checkpoint_seconds = 300;
  bool quiet = false, print_params = false;
  bool integrate_only = false;           // stop after the integration's checkpoint (resume extracts)
};
void run_fuse(const FuseArgs& args);

// A job stopped by SIGINT/SIGTERM after checkpointing: main() prints the message and exits with
// 128 + the signal number, as a shell expects of a process ended by that signal.
class JobInterrupted : public std::runtime_error {
 public:
  JobInterrupted(const std::string& what, int signal) : std::runtime_error(what), signal(signal) {}
  int signal;
};
void add_job_options(CLI::App* cmd, FuseArgs& args);  // threads, memory, checkpoints, outputs

void add_fuse_command(CLI::App& app);
void add_synth_command(CLI::App& app);
void add_eval_command(CLI::App& app);
void add_job_commands(CLI::App& app);  // resume, status

}  // namespace sf::cli
