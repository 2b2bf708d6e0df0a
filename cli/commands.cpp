// The subcommands' registration in help order (commands.hpp).
#include "commands.hpp"

#include <algorithm>
#include <memory>
#include <sstream>
#include <string>

#include "tools.hpp"
#include "view.hpp"

namespace octocd::cli {

namespace {

/// A command of tools.hpp's kind (OPTIONS, add_X_command, X_command) as a Command.
template <class Options>
Command command(CLI::App& app, CLI::App* (*add)(CLI::App&, Options&), int (*run)(const Options&)) {
  const auto options = std::make_shared<Options>();
  CLI::App* sub = add(app, *options);
  return {[sub] { return sub->parsed(); }, [options, run] { return run(*options); }};
}

}  // namespace

namespace {

/// `octocd --help`'s list of subcommands: one line each, the description's first clause
/// (up to ". ", "; ", ": " or " ("); `octocd CMD --help` prints the whole description.
class CommandListFormatter : public CLI::Formatter {
 public:
  std::string make_subcommand(const CLI::App* sub) const override {
    const std::string& text = sub->get_description();
    std::size_t end = text.size();
    for (const char* stop : {". ", "; ", ": ", " ("}) end = std::min(end, text.find(stop));
    std::stringstream out;
    CLI::detail::format_help(out, sub->get_display_name(true), text.substr(0, end), get_column_width());
    return out.str();
  }
};

}  // namespace

std::vector<Command> add_commands(CLI::App& app) {
  app.formatter(std::make_shared<CommandListFormatter>());
  app.footer("Run `octocd COMMAND --help` for a command's arguments, options and exit codes (docs/cli.md).");
  std::vector<Command> commands;
  commands.push_back(add_run_command(app));
  commands.push_back(add_validate_command(app));
  commands.push_back(command<BenchOptions>(app, &add_bench_command, &bench_command));
  commands.push_back(command<ReplayOptions>(app, &add_replay_command, &replay_command));
  commands.push_back(command<CompareOptions>(app, &add_compare_command, &compare_command));
  commands.push_back(command<ReportOptions>(app, &add_report_command, &report_command));
  commands.push_back(command<TraceSummaryOptions>(app, &add_trace_summary_command, &trace_summary_command));
  commands.push_back(command<HistoryAppendOptions>(app, &add_history_append_command, &history_append_command));
  const auto view = std::make_shared<ViewCommand>(app);
  commands.push_back({[view] { return view->selected(); }, [view] { return view->run(); }});
  commands.push_back(add_engines_command(app));
  return commands;
}

}  // namespace octocd::cli
