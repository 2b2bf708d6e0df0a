// `octocd`: the command line's dispatch; each subcommand lives in its own file
// (commands.hpp: run.cpp, validate.cpp, bench.cpp, replay.cpp, compare.cpp, report.cpp,
// tools.cpp's trace-summary, view.cpp).
#include <signal.h>

#include <cstdio>
#include <new>
#include <string>
#include <vector>

#include <CLI/CLI.hpp>

#include "commands.hpp"
#include "octocd/error.hpp"
#include "octocd/version.hpp"


int main(int argc, char** argv) {
  // A file size limit (ulimit -f) or a full file system is an error message and exit 1,
  // never death by SIGXFSZ (exit 153, no message, a 0-byte or temporary file left): a
  // write past the limit fails with EFBIG and the writer says which file and what it kept.
  ::signal(SIGXFSZ, SIG_IGN);
  CLI::App app{
      "octocd: GPU hierarchical Octree-AABB collision detection and response (CPU reference).\n"
      "Exit codes: 0 ok, 1 runtime failure, 2 bad input, 3 a check failed (validate, compare, replay),\n"
      "4 the performance gate failed (report --baseline: a point slower, or missing or failed in the new run),\n"
      "130/143 stopped by SIGINT/SIGTERM, within 1 s (run and validate\n"
      "stop between frames and close the trace, validate inside a frame's checks too; a step still\n"
      "running 0.5 s after the signal is cut short; validate then reports the frames judged so far as an\n"
      "incomplete verdict, its JUnit with a 'stopped' error case; bench keeps its finished points).",
      "octocd"};  // a fixed name: `--help` reads the same whatever path ran it (docs/cli.md)
  app.set_version_flag("--version", std::string("octocd ") + octocd::build_id());
  app.require_subcommand(1);

  const std::vector<octocd::cli::Command> commands = octocd::cli::add_commands(app);


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
    std::fprintf(stderr, "octocd: error: %s\n", e.what());
    return 2;
  } catch (const octocd::RuntimeError& e) {
    std::fprintf(stderr, "octocd: runtime failure: %s\n", e.what());
    return 1;
  } catch (const std::bad_alloc&) {
    std::fprintf(stderr, "octocd: runtime failure: out of memory (the scene needs more than this "
                         "process may allocate)\n");
    return 1;
  } catch (const std::exception& e) {
    std::fprintf(stderr, "octocd: runtime failure: %s\n", e.what());
    return 1;
  }
  return 0;
}
