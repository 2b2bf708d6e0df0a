#pragma once
/// \file shard_spec.hpp
/// ShardSpec: which share of a trace's frames a `validate --shard i/N` job judges
/// (octocd/shards.hpp has the rest).

namespace octocd {

/// One share of a trace's frames: shard `index` of `count` (0 <= index < count); the
/// frames are shard_frames(spec, F), a contiguous block.
struct ShardSpec {
  int index = 0;
  int count = 1;  ///< 1: the whole trace (no sharding)
};

}  // namespace octocd
