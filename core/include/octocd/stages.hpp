#pragma once
/// \file stages.hpp
/// The stages of the CPU reference step (design.md section 4), one file each, mirroring gpu/src:
///
///     stage            CPU (core/src/)                       CUDA (gpu/src/)
///     integrate        integrate.cpp  integrate_bodies       integrate.cu
///     world AABBs      integrate.cpp  update_world_aabbs     integrate.cu
///     broadphase       broadphase_*.cpp (BroadPhase)         broadphase_*.cu
///     midphase         midphase.cpp   confirm_pairs          midphase.cu
///     response         response.cpp   respond                response.cu
///     clamp            integrate.cpp  clamp_velocities       integrate.cu
///     metrics          metrics.cpp    frame_state_metrics    metrics.cu
///
/// World::step (world.cpp) calls them in this order, times them and records the frame.
/// Each per-body or per-contact formula is the OCTOCD_HD function of octocd/math.hpp the
/// kernels call too. The response is also offered as its parts (pass_contact_terms,
/// sum_contact_terms, apply_contact_sums, contact_records) so that a test build of the
/// step can change one part (tests/faults/planted_faults.hpp) and run the rest as is.

#include <cstdint>
#include <vector>

#include "octocd/engine.hpp"
#include "octocd/math.hpp"

namespace octocd {

/// Paper Eq. 1-3 (octocd::integrate, no external force) for every body of `state`:
/// v += dt g, x += dt v; static bodies (w = 0) do not move. dt in s, gravity in m/s^2.
void integrate_bodies(BodyState& state, Vec3 gravity, float dt);

/// design.md section 4.2: boxes[i] = model.local_box(i) translated to x[i] (m), for every body.
/// `boxes` must already hold x.size() entries (it is overwritten, not resized).
void update_world_aabbs(const Model& model, const std::vector<Vec3>& x, std::vector<Aabb>& boxes);

/// Paper Eq. 23 (octocd::clamp_velocity) for every dynamic body: each velocity
/// component clamped to [-v_max, v_max] (m/s).
void clamp_velocities(BodyState& state, float v_max);

/// Midphase and narrow phase of the step (design.md sections 5.2-5.3) over the broadphase's pairs:
/// confirmed[k] = 1 when confirm_contact accepts pairs[k] (the shapes placed at state.x
/// with world AABBs `boxes`, theta of their shapes, the scene's midphase), else 0;
/// static-static pairs are 0 and not tested. Pairs run in parallel on the worker team
/// (octocd/parallel.hpp, current_threads(), from 64 pairs on); the result does not depend
/// on the thread count. Sets m.dynamic_pairs,
/// m.box_tests, m.box_pairs and m.vertex_tests. `confirmed` is resized to pairs.size().
void confirm_pairs(const Model& model, const BodyState& state, const std::vector<Aabb>& boxes,
                   const std::vector<Pair>& pairs, std::vector<std::uint8_t>& confirmed, FrameMetrics& m);

/// Buffers of the response stage, owned by the caller and reused across steps (they
/// grow, never shrink).
struct ResponseScratch {
  std::vector<Aabb> pass_aabbs;      ///< per body: world AABBs the current pass reads (m)
  std::vector<ContactTerms> terms;   ///< per candidate pair: its terms in the current pass
  std::vector<Vec3> dx_sum;          ///< per body: sum of its contacts' corrections (m)
  std::vector<Vec3> dv_sum;          ///< per body: sum of its contacts' velocity changes (m/s)
  std::vector<std::uint32_t> count;  ///< per body: its kept contacts in the current pass

  /// Bytes held (capacities).
  std::uint64_t memory_bytes() const;
};

/// One pass's per-contact terms (design.md section 6; octocd::contact_terms, Eq. 9-22): terms[k] for
/// each confirmed pair k from the world AABBs `boxes` and the velocities state.v; an
/// unconfirmed pair gets empty terms (pen.hit false), as does one Eq. 9 discards.
/// `terms` is resized to pairs.size().
void pass_contact_terms(const std::vector<Aabb>& boxes, const BodyState& state, const std::vector<Pair>& pairs,
                        const std::vector<std::uint8_t>& confirmed, const ContactParams& params,
                        std::vector<ContactTerms>& terms);

/// The per-body reduction of one pass (design.md section 6 Jacobi, ARCHITECTURE "one written order"):
/// from zero, for every kept contact (terms[k].pen.hit) in pair order, dx_sum[a] += dx_a,
/// dx_sum[b] += dx_b, dv_sum[a] += dv_a, dv_sum[b] += dv_b and both counts + 1. The sums
/// hold as many entries as there are bodies (sized by the caller).
void sum_contact_terms(const std::vector<Pair>& pairs, const std::vector<ContactTerms>& terms,
                       ResponseScratch& sums);

/// octocd::apply_contact_sums for every dynamic body: x += dx_sum / count (corrections
/// averaged), v += dv_sum; bodies without contacts are unchanged.
void apply_contact_sums(BodyState& state, const ResponseScratch& sums);

/// The first pass's contact records (what traces, validators and contacts() see): one per
/// kept contact, in pair order, with the pre-response velocities of state.v. Appends to
/// `out`.
void contact_records(const std::vector<Pair>& pairs, const std::vector<ContactTerms>& terms,
                     const BodyState& state, std::vector<ContactRecord>& out);

/// The response stage (design.md section 6): params.iterations Jacobi passes over the confirmed pairs.
/// Pass 0 reads `boxes` (the Aabbs stage's), later passes the world AABBs of the state
/// the previous pass left; each pass computes every contact's terms, sums them per body
/// and applies them. contacts = the first pass's records (cleared first). No clamp.
void respond(const Model& model, BodyState& state, const std::vector<Aabb>& boxes, const std::vector<Pair>& pairs,
             const std::vector<std::uint8_t>& confirmed, const ContactParams& params, ResponseScratch& scratch,
             std::vector<ContactRecord>& contacts);

/// The state's part of the frame metrics (design.md section 8): penetration mean, max and share above
/// `slop` over `contacts` (the first pass's records), kinetic energy and momentum of the
/// dynamic bodies (accumulated in double, in body order). Throws RuntimeError naming the
/// frame (m.frame), body and group when a dynamic body's position or velocity is not
/// finite.
void frame_state_metrics(const Model& model, const BodyState& state, const std::vector<ContactRecord>& contacts,
                         float slop, FrameMetrics& m);

}  // namespace octocd
