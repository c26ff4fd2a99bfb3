// scalefuse command-line entry: subcommands register themselves (cli/commands.h); errors become
// one line on stderr and an exit code: 2 for bad input, 3 for the machine (disk full), 1 for
// internal errors.
#include <CLI/CLI.hpp>
#include <csignal>
#include <cstdio>
#include <exception>

#include "cli/commands.h"
#include "engine/error.h"
#include "scheduler/huge_pages.h"

int main(int argc, char** argv) {
  sf::reexec_with_heap_tunables(argv);  // returns unless it re-executes (scheduler/huge_pages.h)
  CLI::App app{"scalefuse: fusion of depth maps with multiple scales (Fuhrmann & Goesele 2011)"};
  app.require_subcommand(1);
  app.set_version_flag("--version", "scalefuse 0.1.0");
  sf::cli::add_fuse_command(app);
  sf::cli::add_synth_command(app);
  sf::cli::add_eval_command(app);
  sf::cli::add_job_commands(app);
  sf::cli::add_cluster_commands(app);
  // A file-size limit (ulimit -f) makes the write fail with EFBIG, reported like a full disk,
  // instead of killing the process mid-write.
  std::signal(SIGXFSZ, SIG_IGN);
  try {
    app.parse(argc, argv);
  } catch (const CLI::CallForHelp& e) {
    return app.exit(e);
  } catch (const CLI::CallForAllHelp& e) {
    return app.exit(e);
  } catch (const CLI::CallForVersion& e) {
    return app.exit(e);
  } catch (const CLI::ParseError& e) {
    app.exit(e);
    return 2;
  } catch (const sf::cli::JobInterrupted& e) {
    std::fprintf(stderr, "scalefuse: %s\n", e.what());
    return 128 + (e.signal > 0 ? e.signal : 15);
  } catch (const sf::InputError& e) {
    std::fprintf(stderr, "scalefuse: error: %s\n", e.what());
    return 2;
  } catch (const sf::ResourceError& e) {
    std::fprintf(stderr, "scalefuse: error: %s\n", e.what());
    return 3;
  } catch (const std::exception& e) {
    std::fprintf(stderr, "scalefuse: internal error: %s\n", e.what());
    return 1;
  }
  return 0;
}
