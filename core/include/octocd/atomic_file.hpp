#pragma once
/// \file atomic_file.hpp
/// The one way octocd writes a file (docs/robustness.md, "Output files"): result files
/// (`bench -o`, `replay --json`, `compare --json`, `run --summary-json`, `validate --junit`
/// and `--json`, `--write-expect`), view pages, XDMF sidecars and traces are made as a
/// temporary file in the target's folder under an unpredictable name (mkstemp: O_EXCL, so
/// nothing planted at a temporary name is followed) and renamed over the target, which must
/// be absent or a regular file. No file is written in place: a reader, a killed process or
/// a full disk never sees half of one, and a FIFO, device, folder or symbolic link at the
/// target is refused, never written through.

#include <cstdint>
#include <string>

namespace octocd {

/// The type word of a stat(2) `mode` that is not a regular file, for messages: "a folder",
/// "a FIFO", "a device", "a socket", "a symbolic link" (lstat only) or "not a plain file".
const char* file_type_word(unsigned mode);

/// What is at `path` when it is there and is not a regular file, from lstat (a symbolic
/// link is named as such, not followed): "a symbolic link (to T)", "a FIFO", "a device",
/// "a folder", "a socket" or "not a plain file"; "" when `path` is absent or a regular file.
/// Never throws; a path that cannot be examined (EACCES on its folder) gives "".
std::string output_path_kind(const std::string& path);

/// Checks, before any work, that `path` may receive an output file: absent in an existing
/// folder, or a regular file (replaced whole). Throws InputError "<label>: <path>: a FIFO,
/// not a regular file; allowed: a new file or a regular file (replaced by rename), in an
/// existing folder" for anything else (a device such as /dev/null, a FIFO, a folder, a
/// symbolic link, a socket) and, unless `folder_made_later` (the caller creates it, as
/// `bench -o` does), for a folder that does not exist. `label`: the option (e.g. "--json"),
/// left out with its ": " when empty.
void check_output_file(const std::string& path, const std::string& label, bool folder_made_later = false);

/// A temporary file beside `path`: PATH.tmp.XXXXXX in `path`'s folder, created with O_EXCL
/// and an unpredictable suffix (mkstemp), mode 0666 less the umask (as a plain create).
struct TemporaryFile {
  std::string path;  ///< its name
  int fd = -1;       ///< open for writing; the caller closes it
};

/// Creates a TemporaryFile beside `path` (check_output_file first). Throws InputError as
/// check_output_file, RuntimeError "<label>: <path>: cannot create a temporary file in
/// its folder: <strerror> (<ERRNAME>)" when the folder refuses (EACCES, ENOSPC, ...).
TemporaryFile create_temporary_beside(const std::string& path, const std::string& label);

/// Renames the temporary file `temporary` (made by create_temporary_beside) over `path`
/// once `path` is checked again to be absent or a regular file. On failure `temporary` is
/// removed and InputError (the target became something else) or RuntimeError (rename's
/// errno) is thrown naming `label` and `path`; `path` is then unchanged.
void rename_over(const std::string& temporary, const std::string& path, const std::string& label);

/// Writes `text` to `path` atomically: create_temporary_beside, POSIX write, fsync, then
/// rename_over. On any failure (ENOSPC, EFBIG under a file size limit with SIGXFSZ ignored,
/// EACCES, ...) the temporary file is removed, `path` is left as it was (its last complete
/// version, or absent), and RuntimeError says so: "<label>: <path>: writing failed:
/// <strerror> (<ERRNAME>); ..." (`label` and its ": " left out when empty, e.g. "--junit").
/// A target that is not absent or a regular file is InputError (check_output_file).
void write_file_atomically(const std::string& path, const std::string& text, const std::string& label = "");

/// Checks that `path`, an input file, is a regular file (symbolic links followed) before
/// it is opened, so that a FIFO never blocks and a device is never read: InputError
/// "<label>: <path>: not a regular file (a FIFO); allowed: <allowed>" (or "no such file",
/// "cannot be examined (<strerror>)"). `label` left out with its ": " when empty.
void check_input_file(const std::string& path, const std::string& label, const std::string& allowed);

/// Largest JSON file octocd reads (a sweep, an expectations file, a shard's verdict, a bench
/// result to resume): 64 MiB, as a scene file.
constexpr std::uint64_t kMaxJsonFileBytes = 64ull << 20;

/// The whole text of the input file `path`, opened without blocking (O_NONBLOCK) and
/// checked on the open descriptor (fstat) before a byte is read: a regular file of at most
/// `max_bytes`. InputError "<label>: <path>: not a regular file (a FIFO); allowed:
/// <allowed>" (also "no such file", "cannot be opened (<strerror>)", "N bytes; allowed: at
/// most M bytes ...") so a FIFO never blocks, /dev/zero is never read and nothing large is
/// allocated. `label` left out with its ": " when empty.
std::string read_input_file(const std::string& path, const std::string& label, const std::string& allowed,
                            std::uint64_t max_bytes = kMaxJsonFileBytes);

}  // namespace octocd
