/// \file fcl_broadphase.cpp
/// FCL 0.7 reference broadphases behind octocd::BroadPhase (design.md section 5.1):
/// `fcl-dynamic-aabb-tree`, `fcl-sap`, `fcl-interval-tree`, `fcl-spatial-hash`,
/// `fcl-naive`, all with S = double. All but fcl-sap are incremental (see below).
///
/// Each body is an fcl::CollisionObject holding its own fcl::Box whose sides are the
/// AABB's sides plus 2 kPad, translated to the AABB's centre with identity rotation;
/// FCL's computeAABB() then gives [centre - side/2, centre + side/2], the float AABB
/// grown by kPad (centre and sides of two floats are exact in double). Objects are created and registered on the first
/// call; afterwards each call resizes the box, sets the translation, recomputes the AABB
/// and calls manager->update(). Candidates come from manager->collide(&data, callback)
/// whose callback records the two objects' body indices (user data) and returns false
/// (= do not stop).
///
/// FCL's overlap rule: fcl::AABB<S>::overlap is inclusive (it rejects only when
/// min > other.max or max < other.min on some axis), the rule of Eq. 6. But not every
/// manager uses it to find candidates: SaPCollisionManager and
/// IntervalTreeCollisionManager sort endpoints and treat equal endpoints as
/// non-overlapping, so they MISS pairs that touch exactly on a face (measured: 17 of
/// 1979 pairs missed by fcl-sap, 23 by fcl-interval-tree on the 1000-body test set).
/// Therefore every FCL AABB is grown by kPad = 1e-7 m on each side (in double, so the
/// grown box strictly contains the float AABB for coordinates up to ~1e8 m): touching
/// pairs become strictly overlapping for FCL, and FCL then reports a superset.
/// Every candidate then goes through octocd::overlaps() on the original float AABBs and
/// the result is sorted and de-duplicated, which removes the extra pairs (closer than
/// 2e-7 m) and makes the result exact; the unit test checks it against flat.

#include <fcl/broadphase/broadphase_SaP.h>
#include <fcl/broadphase/broadphase_bruteforce.h>
#include <fcl/broadphase/broadphase_dynamic_AABB_tree.h>
#include <fcl/broadphase/broadphase_interval_tree.h>
#include <fcl/broadphase/broadphase_spatialhash.h>
#include <fcl/geometry/shape/box.h>
#include <fcl/narrowphase/collision_object.h>

#include <cstdint>
#include <memory>
#include <string>
#include <vector>

#include "reference_detail.hpp"

namespace octocd::reference_detail {

namespace {

using S = double;

/// Padding (m) added on every side of each AABB handed to FCL (see the file comment).
constexpr S kPad = 1e-7;

/// Collect callback: records (a, b) from the objects' user data; never stops.
bool collect_pair(fcl::CollisionObject<S>* o1, fcl::CollisionObject<S>* o2, void* cdata) {
  auto* cands = static_cast<std::vector<Pair>*>(cdata);
  const auto a = *static_cast<const std::uint32_t*>(o1->getUserData());
  const auto b = *static_cast<const std::uint32_t*>(o2->getUserData());
  cands->push_back({a, b});
  return false;
}

class FclBroadPhase final : public LibraryBroadPhase {
 public:
  FclBroadPhase(BroadPhaseId id, float cell_size, const Aabb& domain)
      : LibraryBroadPhase(id), id_(id), cell_size_(cell_size), domain_(domain) {}

 private:
  bool built() const override { return manager_ != nullptr; }
  std::size_t bodies() const override { return objects_.size(); }

  void move(const std::vector<Aabb>& boxes) override {
    for (std::size_t i = 0; i < boxes.size(); ++i) place(i, boxes[i]);
    if (id_ == BroadPhaseId::fcl_sap) {
      // FCL 0.7's SaPCollisionManager::update() (update_) loops forever on our moved
      // test sets (observed with 100 bodies: the endpoint lists get corrupted), so
      // fcl-sap is rebuilt every call instead of updated: not incremental.
      manager_->clear();
      manager_->registerObjects(raw_);
      manager_->setup();
    } else {
      manager_->update();
    }
  }

  void collect(std::vector<Pair>& candidates) override { manager_->collide(&candidates, &collect_pair); }

  // Approximate: our objects and shapes; the manager's own structures are not counted.
  std::uint64_t library_bytes() const override {
    return objects_.size() * (sizeof(fcl::CollisionObject<S>) + sizeof(fcl::Box<S>) + sizeof(std::uint32_t));
  }

  void place(std::size_t i, const Aabb& b) {
    fcl::Box<S>& box = *shapes_[i];
    box.side = fcl::Vector3<S>(S(b.max.x) - S(b.min.x) + 2 * kPad,
                               S(b.max.y) - S(b.min.y) + 2 * kPad,
                               S(b.max.z) - S(b.min.z) + 2 * kPad);
    box.computeLocalAABB();
    objects_[i]->setTranslation(fcl::Vector3<S>((S(b.min.x) + S(b.max.x)) * 0.5,
                                                 (S(b.min.y) + S(b.max.y)) * 0.5,
                                                 (S(b.min.z) + S(b.max.z)) * 0.5));
    objects_[i]->computeAABB();
  }

  void create(const std::vector<Aabb>& boxes) override {
    if (id_ == BroadPhaseId::fcl_dynamic_aabb_tree) {
      manager_ = std::make_unique<fcl::DynamicAABBTreeCollisionManager<S>>();
    } else if (id_ == BroadPhaseId::fcl_sap) {
      manager_ = std::make_unique<fcl::SaPCollisionManager<S>>();
    } else if (id_ == BroadPhaseId::fcl_interval_tree) {
      manager_ = std::make_unique<fcl::IntervalTreeCollisionManager<S>>();
    } else if (id_ == BroadPhaseId::fcl_spatial_hash) {
      manager_ = std::make_unique<fcl::SpatialHashingCollisionManager<S>>(
          S(cell_size_), fcl::Vector3<S>(domain_.min.x, domain_.min.y, domain_.min.z),
          fcl::Vector3<S>(domain_.max.x, domain_.max.y, domain_.max.z),
          static_cast<unsigned int>(std::max<std::size_t>(1000, boxes.size())));
    } else {
      manager_ = std::make_unique<fcl::NaiveCollisionManager<S>>();
    }
    const std::size_t n = boxes.size();
    ids_.resize(n);
    shapes_.resize(n);
    objects_.resize(n);
    std::vector<fcl::CollisionObject<S>*>& raw = raw_;
    raw.resize(n);
    for (std::size_t i = 0; i < n; ++i) {
      ids_[i] = static_cast<std::uint32_t>(i);
      shapes_[i] = std::make_shared<fcl::Box<S>>(1.0, 1.0, 1.0);
      objects_[i] = std::make_unique<fcl::CollisionObject<S>>(shapes_[i]);
      objects_[i]->setUserData(&ids_[i]);
      place(i, boxes[i]);
      raw[i] = objects_[i].get();
    }
    manager_->registerObjects(raw);
    manager_->setup();
  }

  BroadPhaseId id_;
  float cell_size_;
  Aabb domain_;
  std::vector<std::uint32_t> ids_;  // user data points here; never resized after create
  std::vector<std::shared_ptr<fcl::Box<S>>> shapes_;
  std::vector<std::unique_ptr<fcl::CollisionObject<S>>> objects_;
  std::vector<fcl::CollisionObject<S>*> raw_;  // objects_ as raw pointers, for FCL
  // Declared last so it is destroyed first, while the objects it refers to still exist.
  std::unique_ptr<fcl::BroadPhaseCollisionManager<S>> manager_;
};

}  // namespace

std::unique_ptr<BroadPhase> make_fcl_broadphase(BroadPhaseId id, float cell_size, const Aabb& domain) {
  return std::make_unique<FclBroadPhase>(id, cell_size, domain);
}

}  // namespace octocd::reference_detail
