#pragma once
/// \file command_table.hpp
/// The subcommands of `octocd` as the rows of cli/command_table.def: their identifiers,
/// names and help descriptions, and the one registration of a subcommand on the app that
/// every add_X_command starts with.

#include <cstddef>
#include <string>
#include <vector>

#include <CLI/CLI.hpp>

namespace octocd::cli {

/// A subcommand of `octocd`: one enumerator per row of cli/command_table.def, in help order.
enum class CommandId {
#define OCTOCD_COMMAND(ID, NAME, DESCRIPTION) ID,
#include "command_table.def"
#undef OCTOCD_COMMAND
};

/// The subcommand's name as typed after `octocd` (e.g. "trace-summary"); a static string.
inline const char* command_name(CommandId id) {
  static const char* const names[] = {
#define OCTOCD_COMMAND(ID, NAME, DESCRIPTION) NAME,
#include "command_table.def"
#undef OCTOCD_COMMAND
  };
  return names[static_cast<std::size_t>(id)];
}

/// The subcommand's help description (`octocd NAME --help`; `octocd --help` lists its first
/// clause); a static string.
inline const char* command_description(CommandId id) {
  static const char* const descriptions[] = {
#define OCTOCD_COMMAND(ID, NAME, DESCRIPTION) DESCRIPTION,
#include "command_table.def"
#undef OCTOCD_COMMAND
  };
  return descriptions[static_cast<std::size_t>(id)];
}

/// Every subcommand's name, in help order.
inline const std::vector<std::string>& command_names() {
  static const std::vector<std::string> names = {
#define OCTOCD_COMMAND(ID, NAME, DESCRIPTION) NAME,
#include "command_table.def"
#undef OCTOCD_COMMAND
  };
  return names;
}

/// Registers the subcommand `id` on `app` with its name and description from the table and
/// returns it (owned by `app`) for its own arguments and options.
inline CLI::App* add_table_command(CLI::App& app, CommandId id) {
  return app.add_subcommand(command_name(id), command_description(id));
}

}  // namespace octocd::cli
