// Response formulas (paper Eq. 9-23, design.md section 6) against hand-computed values.
#include <gtest/gtest.h>

#include <cmath>

#include "octocd/math.hpp"

// This file's own names (its tests compile in unity batches with the folder's other files).
namespace octocd_test_response {

using namespace octocd;

namespace {

Aabb box(Vec3 c, Vec3 h) { return {c - h, c + h}; }

}  // namespace

TEST(Overlap, InclusiveOnTouchingFaces) {  // Eq. 6
  const Aabb a = box({0, 0, 0}, {1, 1, 1});
  EXPECT_TRUE(overlaps(a, box({2, 0, 0}, {1, 1, 1})));   // faces touch at x = 1
  EXPECT_FALSE(overlaps(a, box({2.001f, 0, 0}, {1, 1, 1})));
  EXPECT_TRUE(overlaps(a, box({2, 2, 2}, {1, 1, 1})));   // corners touch
}

TEST(Penetration, AxisDepthAndNormalFromBToA) {  // Eq. 9-10
  // A above B, overlapping 0.1 in y, 1.5 in x, 2 in z: normal +y, depth 0.1.
  const Aabb a = box({0.5f, 1.9f, 0}, {1, 1, 1});
  const Aabb b = box({0, 0, 0}, {1, 1, 1});
  const Penetration p = penetration(a, b, 1e-6f);
  ASSERT_TRUE(p.hit);
  EXPECT_EQ(p.axis, 1);
  EXPECT_NEAR(p.depth, 0.1f, 1e-6f);
  EXPECT_EQ(p.normal, (Vec3{0, 1, 0}));
  // Swapped roles: the normal flips so it still points from B to A.
  const Penetration q = penetration(b, a, 1e-6f);
  EXPECT_EQ(q.normal, (Vec3{0, -1, 0}));
  // A to the left of B along x with the least overlap on x: normal -x.
  const Penetration r = penetration(box({-1.95f, 0.2f, 0}, {1, 1, 1}), b, 1e-6f);
  ASSERT_TRUE(r.hit);
  EXPECT_EQ(r.axis, 0);
  EXPECT_NEAR(r.depth, 0.05f, 1e-6f);
  EXPECT_EQ(r.normal, (Vec3{-1, 0, 0}));
}

TEST(Penetration, TouchingIsNoContactAndCoincidentCentresUsePlusY) {
  const Aabb b = box({0, 0, 0}, {1, 1, 1});
  EXPECT_FALSE(penetration(box({2, 0, 0}, {1, 1, 1}), b, 1e-6f).hit);  // p_x = 0: discard
  // Same centre: the fixed axis +y, depth = the y overlap (2 here).
  const Penetration p = penetration(box({0, 0, 0}, {0.5f, 1, 0.25f}), b, 1e-6f);
  ASSERT_TRUE(p.hit);
  EXPECT_EQ(p.normal, (Vec3{0, 1, 0}));
  EXPECT_NEAR(p.depth, 2.0f, 1e-6f);
}

TEST(PositionCorrection, BaumgarteSlopSmoothingAndAlgorithm3Weights) {  // Eq. 11, 13
  ContactParams prm;
  prm.slop = 0.01f;
  prm.beta = 0.8f;
  prm.alpha = 0.5f;
  Penetration pen;
  pen.hit = true;
  pen.depth = 0.11f;
  pen.normal = {0, 0, -1};
  const Vec3 c = position_correction(pen, prm);
  // c = alpha * beta * (d_p - delta) * n = 0.5 * 0.8 * 0.1 * (0,0,-1)
  EXPECT_NEAR(c.z, -0.04f, 1e-7f);
  EXPECT_EQ(c.x, 0.0f);
  pen.depth = 0.005f;  // below slop: no correction
  EXPECT_EQ(position_correction(pen, prm).z, 0.0f);
  // Algorithm 3: A with m = 1 kg (w = 1), B with m = 3 kg (w = 1/3): the light body moves
  // 3/4 of c, the heavy one 1/4 (Eq. 12 would swap these).
  EXPECT_NEAR(correction_share(1.0f, 1.0f, 1.0f / 3.0f), 0.75f, 1e-7f);
  EXPECT_NEAR(correction_share(1.0f / 3.0f, 1.0f, 1.0f / 3.0f), 0.25f, 1e-7f);
  EXPECT_EQ(correction_share(0.0f, 0.0f, 1.0f), 0.0f);  // static body never moves
  EXPECT_EQ(correction_share(0.0f, 0.0f, 0.0f), 0.0f);
}

TEST(NormalImpulse, RestitutionAboveThreshold) {  // Eq. 16-19
  ContactParams prm;  // e 0.5, v_th 0.3, J_min 0.01
  // A (2 kg) falls at 3 m/s onto static B; n = +y.
  const ContactImpulse r = contact_impulse({0, -3, 0}, {0, 0, 0}, 0.5f, 0.0f, {0, 1, 0}, prm);
  EXPECT_FLOAT_EQ(r.normal_velocity, -3.0f);
  EXPECT_FLOAT_EQ(r.jn, 9.0f);  // -(1 + 0.5)(-3) / 0.5
  EXPECT_FLOAT_EQ(r.dv_a.y, 4.5f);  // returns at e * v = 1.5 m/s
  EXPECT_EQ(r.dv_b, (Vec3{0, 0, 0}));
}

TEST(NormalImpulse, BelowThresholdIsInelastic) {  // Eq. 17
  ContactParams prm;
  const ContactImpulse r = contact_impulse({0, -0.2f, 0}, {0, 0, 0}, 1.0f, 1.0f, {0, 1, 0}, prm);
  EXPECT_FLOAT_EQ(r.jn, 0.1f);  // -(1 + 0)(-0.2) / 2
  EXPECT_FLOAT_EQ(r.dv_a.y, 0.1f);
  EXPECT_FLOAT_EQ(r.dv_b.y, -0.1f);  // both end at -0.1 m/s: relative normal velocity 0
  EXPECT_FLOAT_EQ((Vec3{0, -0.2f, 0} + r.dv_a - r.dv_b).y, 0.0f);
}

TEST(NormalImpulse, FloorAndSeparation) {  // Eq. 18
  ContactParams prm;
  prm.impulse_floor = 0.05f;
  const ContactImpulse r = contact_impulse({0, -0.01f, 0}, {0, 0, 0}, 1.0f, 0.0f, {0, 1, 0}, prm);
  EXPECT_FLOAT_EQ(r.jn, 0.05f);  // 0.01 raised to J_min
  // Separating (v_n >= 0): no normal impulse, and no friction without one.
  const ContactImpulse s = contact_impulse({1, 0.5f, 0}, {0, 0, 0}, 1.0f, 1.0f, {0, 1, 0}, prm);
  EXPECT_EQ(s.jn, 0.0f);
  EXPECT_EQ(s.jt, 0.0f);
  EXPECT_EQ(s.dv_a, (Vec3{0, 0, 0}));
}

TEST(Friction, StickCancelsTangentialVelocity) {  // Eq. 20-22, static branch
  ContactParams prm;  // mu_s 0.6, mu_k 0.5
  // v_n = -2 (J_n = 1.5 * 2 / 1 = 3 with e = 0.5), v_t = 0.4 along x; J_t* = -0.4,
  // |J_t*| <= 0.6 * 3: stick.
  const ContactImpulse r = contact_impulse({0.4f, -2, 0}, {0, 0, 0}, 1.0f, 0.0f, {0, 1, 0}, prm);
  EXPECT_FLOAT_EQ(r.jn, 3.0f);
  EXPECT_TRUE(r.sticking);
  EXPECT_FLOAT_EQ(r.jt, -0.4f);
  EXPECT_EQ(r.tangent, (Vec3{1, 0, 0}));
  EXPECT_FLOAT_EQ(r.dv_a.x, -0.4f);  // tangential velocity removed
}

TEST(Friction, SlipAppliesKineticImpulseAgainstSliding) {  // Eq. 21, kinetic branch
  ContactParams prm;
  // v_n = -0.2 (< v_th: e_eff = 0), J_n = 0.2 / 1 = 0.2; v_t = (3, 0, -4), |v_t| = 5,
  // J_t* = -5, |J_t*| > 0.6 * 0.2: slip with J_t = -0.5 * 0.2 = -0.1 along t = (0.6, 0, -0.8).
  const ContactImpulse r = contact_impulse({3, -0.2f, -4}, {0, 0, 0}, 1.0f, 0.0f, {0, 1, 0}, prm);
  EXPECT_FLOAT_EQ(r.jn, 0.2f);
  EXPECT_FALSE(r.sticking);
  EXPECT_FLOAT_EQ(r.jt, -0.1f);
  EXPECT_NEAR(r.dv_a.x, -0.06f, 1e-7f);
  EXPECT_NEAR(r.dv_a.z, 0.08f, 1e-7f);
  // Friction never raises the tangential speed (section 3.3.2) and keeps |J_t| <= mu_s J_n.
  EXPECT_LE(std::fabs(r.jt), prm.mu_static * r.jn);
}

TEST(Impulse, DynamicPairConservesMomentum) {  // Eq. 19, 22 with w_A != w_B
  ContactParams prm;
  const Vec3 va{1, -2, 0.5f}, vb{-0.5f, 1, 0};
  const float wa = 1.0f / 2.0f, wb = 1.0f / 5.0f;
  const ContactImpulse r = contact_impulse(va, vb, wa, wb, {0, 1, 0}, prm);
  const Vec3 p_before = (1 / wa) * va + (1 / wb) * vb;
  const Vec3 p_after = (1 / wa) * (va + r.dv_a) + (1 / wb) * (vb + r.dv_b);
  EXPECT_NEAR(p_before.x, p_after.x, 1e-5f);
  EXPECT_NEAR(p_before.y, p_after.y, 1e-5f);
  EXPECT_NEAR(p_before.z, p_after.z, 1e-5f);
  // v_n = -3 >= v_th: J_n = 1.5 * 3 / 0.7
  EXPECT_NEAR(r.jn, 4.5f / 0.7f, 1e-5f);
}

TEST(Clamp, PerComponent) {  // Eq. 23
  const Vec3 v = clamp_velocity({60, -70, 3}, 50);
  EXPECT_EQ(v, (Vec3{50, -50, 3}));
}

TEST(Integrate, SemiImplicitEulerAndStaticBodies) {  // Eq. 1-3
  Vec3 x{0, 10, 0}, v{1, 0, 0};
  integrate(x, v, 0.5f, {0, -10, 0}, {0, 4, 0}, 0.1f);  // a = g + w F = (0, -8, 0)
  EXPECT_FLOAT_EQ(v.y, -0.8f);
  EXPECT_FLOAT_EQ(x.y, 10.0f - 0.08f);  // uses the new velocity
  EXPECT_FLOAT_EQ(x.x, 0.1f);
  Vec3 xs{1, 2, 3}, vs{0, 0, 0};
  integrate(xs, vs, 0.0f, {0, -10, 0}, {}, 0.1f);
  EXPECT_EQ(xs, (Vec3{1, 2, 3}));
}

TEST(PointBox, DistanceInsideAndOutside) {
  const Aabb b = box({0, 0, 0}, {1, 1, 1});
  EXPECT_EQ(distance2_point_aabb({0.5f, 0, 0}, b), 0.0f);
  EXPECT_FLOAT_EQ(distance2_point_aabb({2, 3, 1}, b), 1.0f + 4.0f);
}

}  // namespace octocd_test_response
