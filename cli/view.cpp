// `octocd view` (cli/view.hpp; the page itself: octocd/view.hpp).
#include "view.hpp"
#include "tools.hpp"

#include <cstdio>
#include <regex>

#include <fmt/format.h>

#include "octocd/error.hpp"
#include "octocd/view.hpp"

namespace octocd::cli {

namespace {

/// "A,B" into two body indices; InputError naming --pair otherwise.
void parse_pair(const std::string& text, ViewSettings& s) {
  static const std::regex form(R"(^\s*(\d{1,10})\s*,\s*(\d{1,10})\s*$)");
  std::smatch m;
  const auto bad = [&] {
    return InputError(fmt::format("--pair: '{}'; allowed: two body indices A,B (e.g. --pair 3,7)", text));
  };
  if (!std::regex_match(text, m, form)) throw bad();
  const unsigned long long a = std::stoull(m[1].str()), b = std::stoull(m[2].str());
  if (a > 0xffffffffull || b > 0xffffffffull) throw bad();
  s.has_pair = true;
  s.pair_a = static_cast<std::uint32_t>(a);
  s.pair_b = static_cast<std::uint32_t>(b);
}

}  // namespace

struct ViewCommand::Impl {
  CLI::App* cmd = nullptr;
  std::string trace, pair, out, mesh_dir;
  std::int64_t frame = 0;
  std::int64_t body = -1;
  int window = 5;
};

ViewCommand::ViewCommand(CLI::App& app) : impl_(std::make_unique<Impl>()) {
  Impl& s = *impl_;
  s.cmd = add_table_command(app, CommandId::view);
  s.cmd->add_option("trace", s.trace,
                    "Trace (HDF5): octocd's (any --state-every: a frame without its own state is drawn at the "
                    "nearest recorded one) or an external trace (versions 1 and 2), read through the hardened reader")
      ->required();
  s.cmd->add_option("--frame", s.frame, "The frame shown first (1 .. the trace's frames; default: the first frame with a contact, else 1)");
  s.cmd->add_option("--pair", s.pair, "The item: a pair of bodies A,B (drawn with the bodies near it)");
  s.cmd->add_option("--body", s.body, "The item: one body I (drawn with the bodies near it)");
  s.cmd->add_option("--window", s.window,
                    fmt::format("Frames each side of --frame on the slider (0 .. {})", kMaxWindow))
      ->default_val(5);
  s.cmd->add_option("-o,--out", s.out, "Folder the page is written into (created when absent)")->required();
  s.cmd->add_option("--mesh-dir", s.mesh_dir,
                    "The only folder (besides the data dir) where the mesh files named by the trace's scene are looked "
                    "up (default: the trace's folder)");
}

ViewCommand::~ViewCommand() = default;

bool ViewCommand::selected() const { return impl_->cmd->parsed(); }

int ViewCommand::run() {
  const Impl& s = *impl_;
  ViewSettings vs;
  if (s.cmd->get_option("--frame")->count() > 0 && s.frame < 1)
    throw InputError(fmt::format("--frame: {}: outside the trace; allowed: 1 .. the trace's frames", s.frame));
  vs.frame = s.frame;
  vs.window = s.window;
  vs.mesh_dir = s.mesh_dir;
  if (!s.pair.empty()) parse_pair(s.pair, vs);
  if (s.cmd->get_option("--body")->count() > 0) {
    if (s.body < 0 || s.body > 0xffffffffll)
      throw InputError(fmt::format("--body: {}: does not exist; allowed: a body index 0 .. bodies - 1", s.body));
    vs.has_body = true;
    vs.body = static_cast<std::uint32_t>(s.body);
  }
  check_output_folder(s.out, "-o", false);  // before the trace is read
  const ViewPage page = write_view(s.trace, vs, s.out);
  fmt::print("wrote {} ({} bytes): frame {}, {} bodies, {} frames on the slider{}\n", page.path, page.bytes,
             page.frame, page.bodies, page.frames, page.note.empty() ? "" : "; note: " + page.note);
  return 0;
}

}  // namespace octocd::cli
