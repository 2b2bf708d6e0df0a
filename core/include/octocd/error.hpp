#pragma once
/// \file error.hpp
/// The two error kinds of octocd: bad input (exit code 2) and failures at run time
/// (exit code 1).

#include <stdexcept>
#include <string>

namespace octocd {

/// Bad input: a scene, mesh or option outside what is allowed. The message names the
/// file, the field (JSON pointer or option) and the allowed range. `octocd` exits with 2.
class InputError : public std::runtime_error {
 public:
  using std::runtime_error::runtime_error;
};

/// A failure while running (a NaN in the state, an I/O error on a trace). `octocd`
/// exits with 1.
class RuntimeError : public std::runtime_error {
 public:
  using std::runtime_error::runtime_error;
};

}  // namespace octocd
