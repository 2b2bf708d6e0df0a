// `octocd`: the command line's dispatch; each subcommand lives in its own file
// (commands.hpp: run.cpp, validate.cpp, bench.cpp, replay.cpp, compare.cpp, report.cpp,
// tools.cpp's trace-summary, view.cpp).
#include <signal.h>

#include <cstdio>
#include <cstring>
#include <new>
#include <string>
#include <vector>

#include <CLI/CLI.hpp>

#include "commands.hpp"
#include "octocd/error.hpp"
#include "octocd/process_engines.hpp"
#include "octocd/text.hpp"
#include "octocd/version.hpp"


int main(int argc, char** argv) {
  // A file size limit (ulimit -f) or a full file system is an error message and exit 1,
  // never death by SIGXFSZ (exit 153, no message, a 0-byte or temporary file left): a
  // write past the limit fails with EFBIG and the writer says which file and what it kept.
  ::signal(SIGXFSZ, SIG_IGN);
  CLI::App app{
      "octocd: GPU hierarchical Octree-AABB collision detection and response (CPU reference), reference\n"
      "engines on the same scenes, and validators that judge any engine's run.\n"
      "Exit codes: 0 ok, 1 runtime failure, 2 bad input, 3 a check failed (validate, compare, replay),\n"
      "4 the performance gate failed (report --baseline), 130/143 stopped by SIGINT/SIGTERM (what\n"
      "was finished is kept: a trace's frames, validate's verdict of the frames judged, bench's points).",
      "octocd"};  // a fixed name: `--help` reads the same whatever path ran it (docs/cli.md)
  app.set_version_flag("--version", std::string("octocd ") + octocd::build_id());
  app.require_subcommand(1);

  // --engines-file FILE (before the command): the registry, which the commands' help texts
  // and name checks read, includes its process engines, so it is read before they are
  // registered; a bad engines file is bad input (exit 2).
  std::string engines_file;
  for (int i = 1; i < argc && argv[i][0] == '-'; ++i) {
    if (std::strcmp(argv[i], "--engines-file") == 0 && i + 1 < argc) engines_file = argv[++i];
    else if (std::strncmp(argv[i], "--engines-file=", 15) == 0) engines_file = argv[i] + 15;
  }
  try {
    octocd::set_engines_file(engines_file);
    (void)octocd::engine_infos();
  } catch (const std::exception& e) {
    std::fprintf(stderr, "octocd: error: %s\n", octocd::printable_line(e.what()).c_str());
    return 2;
  }
  app.add_option("--engines-file", engines_file,
                 "An engines file of process engines (docs/bring-your-engine.md)");
  std::vector<octocd::cli::Command> commands;
  try {
    commands = octocd::cli::add_commands(app);
  } catch (const CLI::ConstructionError& e) {
    // A process engine's settings option --NAME that another option of a command has.
    std::fprintf(stderr, "octocd: error: the engines files: %s; allowed: a process engine name that is no option of "
                 "octocd (its settings option is --NAME)\n", octocd::printable_line(e.what()).c_str());
    return 2;
  }


  try {
    app.parse(argc, argv);
  } catch (const CLI::ParseError& e) {
    const int rc = app.exit(e);
    return rc == 0 ? 0 : 2;
  }

  try {
    for (const octocd::cli::Command& c : commands)
      if (c.selected()) return c.run();
  } catch (const octocd::InputError& e) {
    std::fprintf(stderr, "octocd: error: %s\n", octocd::printable_line(e.what()).c_str());
    return 2;
  } catch (const octocd::RuntimeError& e) {
    std::fprintf(stderr, "octocd: runtime failure: %s\n", octocd::printable_line(e.what()).c_str());
    return 1;
  } catch (const std::bad_alloc&) {
    std::fprintf(stderr, "octocd: runtime failure: out of memory (the scene, trace or result needs more than "
                         "this process may allocate, e.g. under ulimit -v; no input was found damaged)\n");
    return 1;
  } catch (const std::exception& e) {
    std::fprintf(stderr, "octocd: runtime failure: %s\n", octocd::printable_line(e.what()).c_str());
    return 1;
  }
  return 0;
}
