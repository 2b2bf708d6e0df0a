#pragma once
/// \file bench_main.hpp
/// What the bench programs' main functions share (not a public header): the exit codes of
/// an escaped exception.

#include <exception>
#include <iostream>

#include "octocd/error.hpp"

namespace octocd::bench {

/// Runs `body` (a bench program's measurement, returning its exit code) and returns that
/// code; an exception escaping it is said on stderr as one line naming `program` and exits
/// 2 for InputError ("<program>: bad input: <what>"), 1 for any other std::exception
/// ("<program>: runtime failure: <what>", e.g. no CUDA device).
template <class Body>
int exit_code_of(const char* program, Body&& body) {
  try {
    return body();
  } catch (const InputError& e) {
    std::cerr << program << ": bad input: " << e.what() << "\n";
    return 2;
  } catch (const std::exception& e) {
    std::cerr << program << ": runtime failure: " << e.what() << "\n";
    return 1;
  }
}

}  // namespace octocd::bench
