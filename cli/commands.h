#pragma once
// Each subcommand lives in its own cli/cmd_*.cc and registers itself on the top-level app.
// The callback it installs runs the command; errors propagate as exceptions to main(), which maps
// InputError to exit code 2 and everything else to 1.
#include <CLI/CLI.hpp>

namespace sf::cli {

void add_fuse_command(CLI::App& app);
void add_synth_command(CLI::App& app);
void add_eval_command(CLI::App& app);

}  // namespace sf::cli
