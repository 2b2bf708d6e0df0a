#pragma once
/// \file command.hpp
/// One subcommand of `octocd` after registration (Command), and the registrations of the
/// subcommands that return one: each is defined by its own file (run.cpp, validate.cpp,
/// engines.cpp) and called by commands.cpp, which registers them all in help order.

#include <functional>

#include <CLI/CLI.hpp>

#include "command_table.hpp"

namespace octocd::cli {

/// One subcommand after registration: whether CLI11 chose it, and running it (throws
/// InputError or RuntimeError like every command; returns the exit code). Owns its options.
struct Command {
  std::function<bool()> selected;
  std::function<int()> run;
};

/// Registers `run` on `app` (run.cpp).
Command add_run_command(CLI::App& app);

/// Registers `validate` on `app` (validate.cpp).
Command add_validate_command(CLI::App& app);

/// Registers `engines` on `app` (engines.cpp).
Command add_engines_command(CLI::App& app);

}  // namespace octocd::cli
