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

/// Every help line's largest width (characters), docs/cli.md keeps the details.
constexpr std::size_t kHelpWidth = 100;

/// `text` with its lines broken at spaces so that none exceeds `width` characters (a
/// word longer than `width` stays whole on its own line); its own line breaks are kept.
std::string wrap(const std::string& text, std::size_t width) {
  std::string out, line;
  std::istringstream lines(text);
  std::string paragraph;
  bool first = true;
  while (std::getline(lines, paragraph)) {
    if (!first) out += '\n';
    first = false;
    line.clear();
    const std::size_t indent = paragraph.find_first_not_of(' ');
    const std::string lead = indent == std::string::npos ? std::string() : paragraph.substr(0, indent);
    std::istringstream words(paragraph);
    std::string word;
    while (words >> word) {
      if (!line.empty() && line.size() + 1 + word.size() > width) {
        out += line + '\n';
        line = lead;
      } else if (!line.empty()) {
        line += ' ';
      } else {
        line = lead;
      }
      line += word;
    }
    out += line;
  }
  if (!text.empty() && text.back() == '\n') out += '\n';
  return out;
}

/// Help within kHelpWidth characters a line for `octocd` and every command: descriptions,
/// options and footers wrapped beside their column; `octocd --help`'s list of subcommands
/// one entry each, the description's first clause (up to ". ", "; ", ": " or " (");
/// `octocd CMD --help` prints the whole description.
class HelpFormatter : public CLI::Formatter {
 public:
  std::string make_subcommand(const CLI::App* sub) const override {
    const std::string& text = sub->get_description();
    std::size_t end = text.size();
    for (const char* stop : {". ", "; ", ": ", " ("}) end = std::min(end, text.find(stop));
    std::stringstream out;
    CLI::detail::format_help(out, sub->get_display_name(true), column(text.substr(0, end)), get_column_width());
    return out.str();
  }
  std::string make_option_desc(const CLI::Option* opt) const override {
    return column(CLI::Formatter::make_option_desc(opt));
  }
  std::string make_description(const CLI::App* app) const override {
    return wrap(CLI::Formatter::make_description(app), kHelpWidth);
  }
  std::string make_footer(const CLI::App* app) const override {
    return wrap(CLI::Formatter::make_footer(app), kHelpWidth);
  }

 private:
  /// Text of the column right of the names (from get_column_width()).
  std::string column(const std::string& text) const {
    return wrap(text, kHelpWidth - std::min<std::size_t>(get_column_width(), kHelpWidth - 40));
  }
};

}  // namespace

std::vector<Command> add_commands(CLI::App& app) {
  app.formatter(std::make_shared<HelpFormatter>());
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
