#pragma once
/// \file shared_files.hpp
/// Where octocd finds the files it ships beside its code, laid out as in the source tree:
/// the scenes (datasets/scenes/), the dataset fetch script (datasets/fetch.sh with
/// SHA256SUMS), the named bench sweeps (bench/sweeps/) and the report generator
/// (report/make_report.py, report/paper_tables.json). `cmake --install` puts them under
/// PREFIX/share/octocd/ (docs/install.md), so an installed octocd needs no source tree and
/// its prefix may be moved.

#include <string>

namespace octocd {

/// The folder of octocd's shipped files, the first of:
/// 1. $OCTOCD_SOURCE_DIR when set and non-empty (a source tree or a share/octocd folder);
/// 2. FOLDER/../share/octocd when it holds datasets/scenes/, FOLDER being the folder of the
///    running executable (/proc/self/exe, symbolic links resolved) or of the shared object
///    holding this code (the Python extension): an installed octocd, wherever its prefix
///    now lies;
/// 3. the source tree this octocd was built from (compiled in).
/// Never throws; the folder may not exist (the callers' messages name the file they miss).
std::string shared_dir();

}  // namespace octocd
