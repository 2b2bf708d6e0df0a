#pragma once
/// \file midphase_views.hpp
/// The host midphase types as the shared header's views (octocd/midphase_hd.hpp): what
/// confirm_contact and exhaustive_contact (midphase.cpp) hand to the OCTOCD_HD functions,
/// for callers (tests) that drive those functions directly.

#include "octocd/midphase.hpp"
#include "octocd/midphase_hd.hpp"

namespace octocd {

/// `s` as a PlacedView: the mesh's octree through raw pointers into `*s.octree` (borrowed:
/// valid while that octree lives and is not modified), or a box (is_mesh false) when
/// s.octree is null; position (m) and world AABB copied. Throws nothing.
hd::PlacedView placed_view(const PlacedShape& s);

/// `cfg` as a LevelList: aabb_only and its levels, at most hd::kMidphaseMaxLevels of them
/// (a valid MidphaseConfig never has more: levels are distinct in [0, 10]). Throws nothing.
hd::LevelList level_list(const MidphaseConfig& cfg);

}  // namespace octocd
