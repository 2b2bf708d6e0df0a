#pragma once
/// \file shard_spec.hpp
/// ShardSpec: which share of a trace's frames a `validate --shard i/N` job judges, and
/// shard_frames, its block of frames (the harness's octocd/shards.hpp parses `--shard` and
/// merges the shards' verdicts).

#include <cstdint>
#include <utility>

namespace octocd {

/// One share of a trace's frames: shard `index` of `count` (0 <= index < count); the
/// frames are shard_frames(spec, F), a contiguous block.
struct ShardSpec {
  int index = 0;
  int count = 1;  ///< 1: the whole trace (no sharding)
};

/// The frames shard `s` judges of a trace of `frames` frames (numbered 1 .. frames): the
/// contiguous block floor(i F / N) + 1 .. floor((i + 1) F / N) (empty, first > last, when
/// N > F). Blocks of consecutive shards touch and together cover every frame once.
inline std::pair<std::int64_t, std::int64_t> shard_frames(ShardSpec s, std::int64_t frames) {
  const auto edge = [&](std::int64_t k) {
    // floor(k F / N): k F <= 10^5 x 10^8 (trace_limits::kMaxFrames) fits in 64 bits.
    return k * frames / s.count;
  };
  return {edge(s.index) + 1, edge(s.index + 1)};
}

}  // namespace octocd
