/// \file bullet_broadphase.cpp
/// Bullet reference broadphases `bullet-dbvt` (btDbvtBroadphase) and `bullet-sap`
/// (bt32BitAxisSweep3) behind octocd::BroadPhase (design.md section 5.1).
///
/// Both are used incrementally, as Bullet's own world uses them: one proxy per body is
/// created on the first call (user pointer = address of the body's index in a vector we
/// own; collision group 1, mask all), then every call does setAabb for each body and
/// calculateOverlappingPairs, and reads the overlapping pair cache.
///
/// Bullet's own overlap rule. btDbvt's Intersect(btDbvtAabbMm, btDbvtAabbMm) is
/// inclusive (a.mi <= b.mx && a.mx >= b.mi on every axis; the SSE variant tests
/// `b.mx < a.mi || a.mx < b.mi`, the same rule), i.e. the rule of Eq. 6. But the pair
/// cache of btDbvtBroadphase is NOT the set of overlapping AABBs:
///  - leaves are fattened: a moved leaf is stored grown by gDbvtMargin (0.05 m) and by a
///    velocity prediction (m_prediction), and it is not re-inserted while the new AABB
///    stays inside the fattened one; pairs are found and kept on the fattened volumes,
///    so the cache holds pairs whose real AABBs are up to ~0.1 m apart, and pairs
///    persist until the fattened volumes separate (lazy cleanup, m_needcleanup).
/// Hence the exact filter (octocd::overlaps on the real AABBs) IS needed for
/// `bullet-dbvt`; without it the answer would be a strict superset. The superset
/// property itself holds because a fattened leaf always contains the real AABB.
///
/// bt32BitAxisSweep3 quantises every AABB to 32-bit integers over its world box: a min
/// is floored to an even integer and a max is ceiled to an odd one, and coordinates
/// outside the world box are clamped to it. Both maps are monotone, so two AABBs that
/// overlap inclusively (even touching faces) still overlap after quantisation: the sweep
/// reports a superset (plus pairs closer than one quantum, and pairs among bodies
/// clamped onto the same face of the world box). The quantisation is done in float
/// (btScalar): (p - worldMin) * (2^32 - 2) / worldSize, so the effective resolution is
/// about worldSize / 2^24 (float mantissa) rather than worldSize / 2^32. We give the
/// sweep the scene domain grown 64 times about its centre (a cube of 64 times the
/// domain's longest side), so bodies up to ~32 domain sizes outside the domain are not
/// clamped (clamping would still be correct, only slower), at a resolution of about
/// 64 * side / 2^24 ~ side / 2.6e5. The exact filter then removes the extra pairs, so
/// the result is exact.

#include <btBulletCollisionCommon.h>

#include <BulletCollision/BroadphaseCollision/btAxisSweep3.h>
#include <BulletCollision/BroadphaseCollision/btDbvtBroadphase.h>

#include <algorithm>
#include <cmath>
#include <cstdint>
#include <memory>
#include <string>
#include <vector>

#include "reference_detail.hpp"

namespace octocd::reference_detail {

namespace {

btVector3 to_bt(const Vec3& v) { return btVector3(v.x, v.y, v.z); }

/// Shared driver: owns the Bullet broadphase, a dispatcher (only used by Bullet to free
/// collision algorithms of removed pairs; we never create any) and the proxies.
class BulletBroadPhase final : public LibraryBroadPhase {
 public:
  BulletBroadPhase(BroadPhaseId id, const Aabb& domain)
      : LibraryBroadPhase(id), dbvt_(id == BroadPhaseId::bullet_dbvt), domain_(domain) {}

  ~BulletBroadPhase() override {
    if (!broadphase_) return;
    // Empty the pair cache first, last pair first (O(1) each through its hash): destroyProxy
    // scans the whole pair array for the proxy's pairs, so destroying the proxies of a full
    // cache costs proxies x pairs (minutes at 64,000 bodies).
    btOverlappingPairCache* cache = broadphase_->getOverlappingPairCache();
    btBroadphasePairArray& pairs = cache->getOverlappingPairArray();
    for (int n = pairs.size(); n > 0; n = pairs.size()) {
      const btBroadphasePair& last = pairs[n - 1];
      cache->removeOverlappingPair(last.m_pProxy0, last.m_pProxy1, dispatcher_.get());
      if (pairs.size() >= n) break;  // not found by its hash: leave the rest to destroyProxy
    }
    // The sweep and prune owns its handles (freed with it); removing them one by one
    // re-sorts its edge lists each time (proxies^2). The dbvt's proxies are its own
    // allocations: destroy them (a tree removal each, now that no pair is left).
    if (dbvt_)
      for (btBroadphaseProxy* p : proxies_) broadphase_->destroyProxy(p, dispatcher_.get());
  }

 private:
  bool built() const override { return broadphase_ != nullptr; }
  std::size_t bodies() const override { return proxies_.size(); }

  void move(const std::vector<Aabb>& boxes) override {
    for (std::size_t i = 0; i < boxes.size(); ++i)
      broadphase_->setAabb(proxies_[i], to_bt(boxes[i].min), to_bt(boxes[i].max), dispatcher_.get());
  }

  void collect(std::vector<Pair>& candidates) override {
    broadphase_->calculateOverlappingPairs(dispatcher_.get());
    const btBroadphasePairArray& arr = broadphase_->getOverlappingPairCache()->getOverlappingPairArray();
    candidates.reserve(static_cast<std::size_t>(arr.size()));
    for (int k = 0; k < arr.size(); ++k) {
      const btBroadphasePair& bp = arr[k];
      const auto a = *static_cast<const std::uint32_t*>(bp.m_pProxy0->m_clientObject);
      const auto b = *static_cast<const std::uint32_t*>(bp.m_pProxy1->m_clientObject);
      candidates.push_back({a, b});
    }
  }

  // Approximate: proxies, tree nodes (2 per leaf) or sweep edges, the pair cache.
  std::uint64_t library_bytes() const override {
    const std::uint64_t per_proxy =
        dbvt_ ? sizeof(btDbvtProxy) + 2 * sizeof(btDbvtNode)
              : sizeof(bt32BitAxisSweep3::Handle) + 6 * 2 * sizeof(unsigned int);
    const btBroadphasePairArray& arr = broadphase_->getOverlappingPairCache()->getOverlappingPairArray();
    return proxies_.size() * (per_proxy + sizeof(std::uint32_t)) +
           static_cast<std::uint64_t>(arr.capacity()) * sizeof(btBroadphasePair);
  }

  void create(const std::vector<Aabb>& boxes) override {
    config_ = std::make_unique<btDefaultCollisionConfiguration>();
    dispatcher_ = std::make_unique<btCollisionDispatcher>(config_.get());
    if (dbvt_) {
      broadphase_ = std::make_unique<btDbvtBroadphase>();
    } else {
      // World box: cube about the domain centre, 64 x the longest domain side (>= 1 m).
      const Vec3 c = center(domain_);
      float side = std::max({domain_.max.x - domain_.min.x, domain_.max.y - domain_.min.y,
                             domain_.max.z - domain_.min.z});
      if (!(std::isfinite(side) && side > 0.0f)) side = 1.0f;
      const float h = 32.0f * side;
      const btVector3 lo(c.x - h, c.y - h, c.z - h);
      const btVector3 hi(c.x + h, c.y + h, c.z + h);
      // maxHandles = n + 1 (handle 0 is the sentinel); no raycast accelerator (it would
      // maintain a second, dbvt, broadphase that we do not use).
      const auto max_handles = static_cast<unsigned int>(boxes.size() + 2);
      broadphase_ = std::make_unique<bt32BitAxisSweep3>(lo, hi, max_handles, nullptr, true);
    }
    ids_.resize(boxes.size());
    proxies_.resize(boxes.size());
    for (std::size_t i = 0; i < boxes.size(); ++i) {
      ids_[i] = static_cast<std::uint32_t>(i);
      proxies_[i] = broadphase_->createProxy(
          to_bt(boxes[i].min), to_bt(boxes[i].max), BOX_SHAPE_PROXYTYPE, &ids_[i],
          btBroadphaseProxy::DefaultFilter, btBroadphaseProxy::AllFilter, dispatcher_.get());
    }
  }

  bool dbvt_;  // btDbvtBroadphase (bullet-dbvt); else bt32BitAxisSweep3 (bullet-sap)
  Aabb domain_;
  std::unique_ptr<btDefaultCollisionConfiguration> config_;
  std::unique_ptr<btCollisionDispatcher> dispatcher_;
  std::unique_ptr<btBroadphaseInterface> broadphase_;
  std::vector<std::uint32_t> ids_;  // user pointers point here; never resized after create
  std::vector<btBroadphaseProxy*> proxies_;
};

}  // namespace

std::unique_ptr<BroadPhase> make_bullet_broadphase(BroadPhaseId id, const Aabb& domain) {
  return std::make_unique<BulletBroadPhase>(id, domain);
}

}  // namespace octocd::reference_detail
