#pragma once
/// \file shards.hpp
/// `octocd validate --trace-in F --shard i/N` and `octocd validate --merge A.json ...`
/// (docs/validation-output.md, "Shards"): a trace's frames split into N contiguous
/// blocks judged by separate jobs (a Slurm job array), and their JSON verdicts joined.

#include <cstdint>
#include <string>
#include <utility>
#include <vector>

#include <nlohmann/json.hpp>

#include "octocd/expect.hpp"
#include "octocd/shard_spec.hpp"
#include "octocd/validation.hpp"

namespace octocd {

/// Parses "i/N" (`--shard`): integers with 1 <= N <= 100000 and 0 <= i < N. Throws
/// InputError naming `--shard`, the text and the allowed form.
ShardSpec parse_shard(const std::string& text);

/// What identifies the run a shard belongs to; shards merge only when all of it is equal.
struct ShardIdentity {
  std::string trace;          ///< the trace's file name
  std::uint64_t trace_bytes = 0;  ///< its size in bytes
  std::string engine;         ///< the trace's engine attribute
  std::int64_t bodies = 0;
  std::int64_t frames = 0;    ///< frames judged by the whole (unsharded) run
  int every = 1;              ///< checked frames: f % every == 0 (global frame numbers)
  std::string against;        ///< "fcl" (FCL references on) or "none"
  Tolerances tol;             ///< every tolerance's value
};

/// The "shard" object of a shard's JSON (`--json` with `--shard`): index, count, first and
/// last frame, and the identity (every tolerance by name).
nlohmann::ordered_json shard_json(ShardSpec s, const ShardIdentity& id);

/// The joined verdict of shards (merge_validations).
struct MergedValidation {
  std::vector<ValidationResult> results;
  RunName run;                     ///< the trace (from the shards)
  ShardIdentity identity;
  std::vector<std::string> files;  ///< the shards' files, in shard order
};

/// Reads the shards' JSON files (`validate --trace-in ... --shard i/N --json FILE`) and
/// joins them into the verdict of the unsharded run: per row, counts of failing items are
/// summed and the rows that measure their largest figure (contact-geometry, penetration)
/// take the largest; judged and seconds are
/// summed; a row fails when any shard's fails and is n/a when every shard's is; per
/// cause, counts summed, worst the largest, examples the first kMaxExamples in frame
/// order, items the sorted union (kMaxItems at most; incomplete when any shard's was or
/// the union is longer), causes in the row's documented order. The detail is the first
/// failing shard's (its first failure), else the first shard's.
/// Throws InputError (exit 2) naming the file when a file is not a shard's JSON, when
/// shards overlap (the same index twice) or one is missing, or when they come from
/// different traces, engines, frame counts, checks (--every, --against) or tolerances.
MergedValidation merge_validations(const std::vector<std::string>& files);

/// The same on parsed documents; `names[k]` names `docs[k]` in errors.
MergedValidation merge_validation_docs(const std::vector<nlohmann::json>& docs, const std::vector<std::string>& names);

}  // namespace octocd
