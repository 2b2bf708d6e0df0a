#pragma once
/// \file commands.hpp
/// The subcommands of `octocd`, registered in help order and dispatched by main.cpp: `run`
/// (run.cpp), `validate` (validate.cpp) and `engines` (engines.cpp) through command.hpp's
/// add_X_command; `bench`, `replay`, `compare`, `report`, `trace-summary` (their files,
/// through tools.hpp's add_X_command / X_command pairs) and `view` (view.cpp). What `run`
/// and `validate` share is command_support.hpp.

#include <vector>

#include <CLI/CLI.hpp>

#include "command.hpp"

namespace octocd::cli {

/// Registers every subcommand on `app` in help order: run, validate, bench, replay,
/// compare, report, trace-summary, view, engines.
std::vector<Command> add_commands(CLI::App& app);

}  // namespace octocd::cli
