#pragma once
/// \file view.hpp
/// `octocd view TRACE.h5 [--frame F] [--pair A,B | --body I] [--window K] -o DIR` (design.md section 16,
/// octocd/view.hpp). `octocd validate --view DIR`'s page per failing example of a judged
/// trace is the harness's (octocd/failure_views.hpp).
#include <cstdint>
#include <memory>
#include <string>
#include <vector>

#include <CLI/CLI.hpp>
#include <nlohmann/json.hpp>

#include "octocd/failure_views.hpp"

namespace octocd::cli {

/// Registers `view` on `app`; after parsing, `selected()` says whether it was chosen and
/// `run()` writes the page (throwing InputError / RuntimeError like the other commands)
/// and returns its exit code (0).
class ViewCommand {
 public:
  explicit ViewCommand(CLI::App& app);
  ~ViewCommand();
  ViewCommand(const ViewCommand&) = delete;
  ViewCommand& operator=(const ViewCommand&) = delete;
  /// Whether `view` was given on the command line.
  bool selected() const;
  /// Writes the page; returns 0.
  int run();

 private:
  struct Impl;
  std::unique_ptr<Impl> impl_;
};

// What `validate --view` shares with the harness (octocd/failure_views.hpp), by the names
// the CLI's commands use.
using octocd::add_views_to_json;
using octocd::FailureViews;
using octocd::format_views;
using octocd::kMaxViewPages;
using octocd::view_link;
using octocd::ViewLink;
using octocd::with_views_in_details;
using octocd::write_failure_views;

}  // namespace octocd::cli
