#pragma once
/// \file temp_files.hpp
/// Test files in the temp folder removed when the test program ends.

#include <gtest/gtest.h>

#include <cstdlib>
#include <filesystem>
#include <functional>
#include <system_error>
#include <utility>

namespace octocd::test {

/// A GoogleTest environment that removes `path()` (a file or a folder with everything in
/// it) after the program's last test, unless OCTOCD_KEEP_TEST_FILES is set. Register it
/// with remove_at_exit(); a path that does not exist is no error.
class RemoveAtExit : public ::testing::Environment {
 public:
  explicit RemoveAtExit(std::function<std::filesystem::path()> path) : path_(std::move(path)) {}
  void TearDown() override {
    std::error_code ec;
    if (!std::getenv("OCTOCD_KEEP_TEST_FILES")) std::filesystem::remove_all(path_(), ec);
  }

 private:
  std::function<std::filesystem::path()> path_;
};

/// Registers RemoveAtExit for the path `path` returns (called at the end, so a path
/// decided on first use, such as one with the process id, works); returns the environment.
inline ::testing::Environment* remove_at_exit(std::function<std::filesystem::path()> path) {
  return ::testing::AddGlobalTestEnvironment(new RemoveAtExit(std::move(path)));
}

}  // namespace octocd::test
