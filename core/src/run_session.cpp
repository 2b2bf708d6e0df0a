/// \file run_session.cpp
/// RunSession: the stop machinery of stop.cpp (handlers, bound, kept text, tracked
/// temporaries and children) held by one object per command.

#include "octocd/run_session.hpp"

#include <atomic>
#include <cstdio>
#include <cstdlib>
#include <utility>

#include <fmt/format.h>

#include "octocd/trace.hpp"

namespace octocd {
namespace {

std::atomic<RunSession*> g_current{nullptr};

}  // namespace

RunSession::RunSession(std::string command, RunSessionSettings settings)
    : command_(std::move(command)), signals_(settings.bound_s, settings.second) {
  g_current.store(this);
}

RunSession::~RunSession() {
  forget_read_back();
  stop_clean_up();
  g_current.store(nullptr);
}

RunSession* RunSession::current() { return g_current.load(); }

void RunSession::keep(const std::string& text) {
  kept_ = text;
  set_stop_kept(text);
}

void RunSession::keep_read_back(std::function<std::string()> reader, double bound_s) {
  set_stop_kept_reader(std::move(reader), bound_s);
}

void RunSession::forget_read_back() { set_stop_kept_reader({}); }

RunSession::KeptTrace::KeptTrace(RunSession* session, TraceWriter* trace, std::string path, std::string tail)
    : session_(session), trace_(trace), path_(std::move(path)), tail_(std::move(tail)) {}

RunSession::KeptTrace::KeptTrace(KeptTrace&& other) noexcept
    : session_(std::exchange(other.session_, nullptr)),
      trace_(other.trace_),
      path_(std::move(other.path_)),
      tail_(std::move(other.tail_)),
      flushed_(other.flushed_) {}

RunSession::KeptTrace::~KeptTrace() { end(); }

void RunSession::KeptTrace::end() {
  if (session_) session_->forget_read_back();
  session_ = nullptr;
}

void RunSession::KeptTrace::keep_flushed() {
  const std::int64_t flushed = trace_->flushed_frames();
  if (flushed == flushed_) return;
  flushed_ = flushed;
  session_->keep(flushed > 0 ? fmt::format("the trace {} holds frames 1..{} (its last flush){}", path_, flushed, tail_)
                             : fmt::format("the trace {} holds no frame (none flushed yet){}", path_, tail_));
}

void RunSession::KeptTrace::frame_written() {
  if (session_) keep_flushed();
}

RunSession::KeptTrace RunSession::keep_trace(TraceWriter& trace, const std::string& path, const std::string& tail,
                                             double bound_s) {
  KeptTrace kept(this, &trace, path, tail);
  kept.keep_flushed();
  keep_read_back(
      [&trace, path, tail]() -> std::string {
        const std::int64_t frames = trace.read_back_frames_and_hold();
        if (frames < 0) return "";
        return frames > 0 ? fmt::format("the trace {} holds frames 1..{} (read back){}", path, frames, tail)
                          : fmt::format("the trace {} holds no frame (read back){}", path, tail);
      },
      bound_s);
  return kept;
}

bool RunSession::add_temporary(const std::string& path) { return stop_track_temporary(path, true); }

void RunSession::forget_temporary(const std::string& path) { (void)stop_track_temporary(path, false); }

bool RunSession::add_child(int group) { return stop_track_child(group, true); }

void RunSession::forget_child(int group) { (void)stop_track_child(group, false); }

int RunSession::stopped(int sig, const std::string& where) {
  stop_clean_up();
  std::fflush(stdout);
  std::fprintf(stderr, "octocd %s: stopped by %s%s%s%s\n", command_.c_str(), stop_signal_name(sig), where.c_str(),
               kept_.empty() ? "" : "; ", kept_.c_str());
  std::fflush(stderr);
  return stop_exit_code(sig);
}

int RunSession::stopped_after_frame(int sig, std::int64_t done, std::int64_t total, const std::string& trace,
                                    const std::string& kept_tail, const std::string& where_tail) {
  if (trace.empty())
    keep("");
  else
    keep((done > 0 ? fmt::format("the trace {} holds frames 1..{}", trace, done)
                   : fmt::format("the trace {} holds no frame", trace)) +
         kept_tail);
  return stopped(sig, fmt::format(" after frame {} of {}{}", done, total, where_tail));
}

void RunSession::end_now(int sig, const std::string& where) {
  const int code = stopped(sig, where);
  std::_Exit(code);
}

}  // namespace octocd
