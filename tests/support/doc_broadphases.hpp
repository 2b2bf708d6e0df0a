#pragma once
// The broadphase table of docs/architecture.md ("Adding a broadphase"): the written statement
// of every broadphase (name, CPU library, device kind, promise, cost) that the registry's
// tests hold the code to (tests/core/test_broadphase_registry.cpp, test_broadphase.cpp,
// tests/reference/test_reference_broadphase.cpp). A new broadphase is a row there and a row
// of core/include/octocd/broadphase_table.def; the tests take their expected names from here.
#include <gtest/gtest.h>

#include <cstdlib>
#include <fstream>
#include <sstream>
#include <string>
#include <vector>

namespace octocd::test {

/// One row of the docs' table, its cells without the backquotes.
struct DocBroadPhase {
  std::string name, cpu, device, promise, cost;
};

/// The rows of the table in docs/architecture.md's section "Adding a broadphase", in order
/// ($OCTOCD_SOURCE_DIR, else the current folder). Empty when the file cannot be read (the
/// callers assert the rows they need).
inline std::vector<DocBroadPhase> doc_broadphases() {
  const char* root = std::getenv("OCTOCD_SOURCE_DIR");
  std::ifstream in(std::string(root ? root : ".") + "/docs/architecture.md");
  std::vector<DocBroadPhase> rows;
  std::string line;
  bool in_section = false;
  while (std::getline(in, line)) {
    if (line.rfind("## ", 0) == 0) in_section = line == "## Adding a broadphase";
    if (!in_section || line.rfind("| `", 0) != 0) continue;
    std::vector<std::string> cells;
    std::istringstream row(line.substr(1));
    std::string cell;
    while (std::getline(row, cell, '|')) {
      const auto b = cell.find_first_not_of(" `"), e = cell.find_last_not_of(" `");
      if (b != std::string::npos) cells.push_back(cell.substr(b, e - b + 1));
    }
    if (cells.size() == 5) rows.push_back({cells[0], cells[1], cells[2], cells[3], cells[4]});
    else ADD_FAILURE() << "docs/architecture.md: a broadphase row without 5 cells: " << line;
  }
  return rows;
}

/// The names of the rows for which keep(row) holds, in the table's order.
template <class Keep>
std::vector<std::string> doc_broadphase_names(Keep keep) {
  std::vector<std::string> names;
  for (const DocBroadPhase& r : doc_broadphases())
    if (keep(r)) names.push_back(r.name);
  return names;
}

}  // namespace octocd::test
