#pragma once
/// \file coherent_plan.hpp
/// The host-side decisions of the device `octree` with a pair cache
/// (broadphase_octree_cache.cu): which work each find() enqueues (CoherentPlan) and, from what
/// that find() wrote into CoherentStatus, whether its pairs hold (Settled). Plain C++
/// (compiled by the host compiler and nvcc; tested without a device).
///
/// Plans: Plain runs the one-shot `octree` on the AABBs; Build fattens every AABB by the
/// margin d, keeps the fattened boxes' pairs (the one-shot `octree` on them) and writes
/// those whose AABBs overlap; Hit checks that every AABB still lies inside its fattened box
/// and writes the kept pairs whose AABBs overlap. A Hit whose check found a body outside
/// (escaped > 0) wrote an incomplete set: Rerun, with Build next (or, when the cache served
/// no call, Plain for 2, 4, .. kBackoffMax calls first: incoherent input). A Build whose
/// fattened pairs did not fit the cache: Regrow (the cache grows to needed_capacity()).
///
/// Rebuild ahead of a miss (the AABBs of the cuda engine translate only, so a body's
/// escape is its displacement since the build passing d on some axis): after each Hit,
/// used = d - (the smallest slack of an AABB side to its fattened side, over the bodies)
/// is the largest displacement since the build; rate = max(used's last increase, used /
/// hits since the build) bounds the per-step displacement of a body moving at constant
/// velocity; when used + kLookahead x rate >= d the next find() builds instead of hitting.
#include <algorithm>
#include <cstdint>
#include <cstring>

#include "device_broadphase.hpp"

namespace octocd {
namespace gpu {

/// The work a find() of the coherent octree enqueues (DeviceBroadPhase::plan()).
enum class CoherentPlan : int { Plain = 0, Build = 1, Hit = 2 };

/// What a find() writes for settle() (device, copied to pinned host memory by find()).
struct CoherentStatus {
  std::uint32_t escaped = 0;          ///< Hit: bodies whose AABB left its fattened box
  std::uint32_t min_slack_bits = 0;   ///< Hit: float bits of the smallest slack (m), kNoSlack if none
  std::uint32_t cache_total = 0;      ///< Build: the fattened boxes' pairs found
  float margin = 0.0f;                ///< Build: d (m) of the fattened boxes
};

/// min_slack_bits when no body has a finite slack (0x7f7f7f7f: 3.4e38 m; cudaMemset 0x7f).
constexpr std::uint32_t kNoSlack = 0x7f7f7f7fu;

/// The plan of the next find() and the verdict on the last (see the file comment).
class CoherencePlanner {
 public:
  /// Most calls run without a cache after caches that served no call.
  static constexpr std::uint32_t kBackoffMax = 64;
  /// Steps of the largest rate ahead that the predictor rebuilds.
  static constexpr float kLookahead = 2.0f;

  CoherentPlan plan() const {
    if (!ready_) return plain_left_ > 0 ? CoherentPlan::Plain : CoherentPlan::Build;
    return build_next_ ? CoherentPlan::Build : CoherentPlan::Hit;
  }

  /// Forgets the cache (a new body count): the next call is Plain, as the first.
  void reset() { *this = CoherencePlanner{}; }

  /// The verdict on a find() that ran plan `ran` and wrote `s`, with a cache of
  /// `cache_capacity` keys; updates the plan of the next call.
  Settled settle(CoherentPlan ran, const CoherentStatus& s, std::uint64_t cache_capacity) {
    switch (ran) {
      case CoherentPlan::Plain:
        ++plain_calls_;
        if (plain_left_ > 0) --plain_left_;
        return Settled::Valid;
      case CoherentPlan::Build:
        if (s.cache_total > cache_capacity) {
          needed_ = static_cast<std::uint64_t>(s.cache_total) + s.cache_total / 4 + 64;
          ready_ = false;
          plain_left_ = 0;
          return Settled::Regrow;
        }
        ++builds_;
        ready_ = true;
        build_next_ = false;
        hits_ = 0;
        used_prev_ = 0.0f;
        margin_ = s.margin;
        return Settled::Valid;
      case CoherentPlan::Hit:
        break;
    }
    if (s.escaped > 0) {
      ++misses_;
      ready_ = false;
      if (hits_ == 0) {  // the cache served no call: back off
        backoff_ = std::min(2 * backoff_, kBackoffMax);
        plain_left_ = backoff_;
      } else {
        backoff_ = 1;
        plain_left_ = 0;
      }
      return Settled::Rerun;
    }
    ++hits_;
    ++hit_calls_;
    float slack = 0.0f;
    std::memcpy(&slack, &s.min_slack_bits, sizeof slack);
    const float used = s.min_slack_bits == kNoSlack ? 0.0f : std::max(0.0f, margin_ - slack);
    const float rate = std::max(used - used_prev_, used / static_cast<float>(hits_));
    used_prev_ = used;
    build_next_ = margin_ > 0.0f && used + kLookahead * rate >= margin_;  // d = 0: nothing to predict
    if (build_next_) backoff_ = 1;  // this cache served calls
    return Settled::Valid;
  }

  /// Keys the cache must hold (0 until a Build overflowed it).
  std::uint64_t needed_capacity() const { return needed_; }
  /// Calls settled so far per kind (the bench's report): Plain, Build (valid), Hit (valid),
  /// and Hits that missed.
  std::uint64_t plain_calls() const { return plain_calls_; }
  std::uint64_t builds() const { return builds_; }
  std::uint64_t hit_calls() const { return hit_calls_; }
  std::uint64_t misses() const { return misses_; }

 private:
  bool ready_ = false;          // the cache and the fattened boxes are valid
  bool build_next_ = false;     // the predictor asks for a Build
  std::uint32_t plain_left_ = 1;  // Plain calls before the next Build (1: the first call)
  std::uint32_t backoff_ = 1;   // the last back-off (calls)
  std::uint64_t hits_ = 0;      // calls served by the current cache
  float margin_ = 0.0f;         // d of the current cache (m)
  float used_prev_ = 0.0f;      // `used` at the previous Hit
  std::uint64_t needed_ = 0;
  std::uint64_t plain_calls_ = 0, builds_ = 0, hit_calls_ = 0, misses_ = 0;
};

}  // namespace gpu
}  // namespace octocd
