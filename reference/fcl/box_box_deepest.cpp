// The deepest contact of FCL 0.7's box-box test (see box_box_deepest.hpp).
//
// The separating-axis tests, the edge-edge contact and the face clipping below are the
// body of fcl::detail::boxBox2 (FCL 0.7, fcl/narrowphase/detail/primitive_shape_algorithm/
// box_box-inl.h; BSD licence: Copyright (c) 2011-2014, Willow Garage, Inc.; Copyright (c)
// 2014-2016, Open Source Robotics Foundation; after ODE's dBoxBox by Russell L. Smith),
// statement for statement, on concrete Eigen types: the same IEEE operations in the same
// order (the build keeps -ffp-contract=off), so the same bits as the library's
// instantiation. Only the end differs: FCL emits up to maxc = 4 contacts (culling the
// others around the deepest, cullPoints2) into a vector; here the deepest alone is
// placed. FCL's deepest emitted contact is the first point of maximum depth (cullPoints2
// emits it first; without culling the points come in order), which is the point kept.
// lineClosestApproach and intersectRectQuad2 are FCL's own (libfcl's instantiations).
#include "octocd/box_box_deepest.hpp"

#include <fcl/narrowphase/detail/primitive_shape_algorithm/box_box.h>

#include <cmath>
#include <limits>

namespace octocd {

namespace {
using S = double;
using V3 = fcl::Vector3<S>;
using M3 = fcl::Matrix3<S>;
}  // namespace

bool box_box_deepest(const std::array<double, 3>& side_a, const std::array<double, 9>& rotation_a,
                     const std::array<double, 3>& position_a, const std::array<double, 3>& side_b,
                     const std::array<double, 9>& rotation_b, const std::array<double, 3>& position_b,
                     BoxBoxContact& out) {
  const V3 side1(side_a[0], side_a[1], side_a[2]), side2(side_b[0], side_b[1], side_b[2]);
  const V3 T1(position_a[0], position_a[1], position_a[2]), T2(position_b[0], position_b[1], position_b[2]);
  M3 R1, R2;
  for (int i = 0; i < 3; ++i)
    for (int j = 0; j < 3; ++j) {
      R1(i, j) = rotation_a[static_cast<std::size_t>(3 * i + j)];
      R2(i, j) = rotation_b[static_cast<std::size_t>(3 * i + j)];
    }
  V3 normal;
  const S fudge_factor = S(1.05);
  V3 normalC = V3::Zero();  // set with code > 6
  S s, s2, l;
  int invert_normal, code;

  V3 p = T2 - T1; // get vector from centers of box 1 to box 2, relative to box 1
  V3 pp = R1.transpose() * p; // get pp = p relative to body 1

  // get side lengths / 2
  V3 A = side1 * 0.5;
  V3 B = side2 * 0.5;

  // Rij is R1'*R2, i.e. the relative rotation between R1 and R2
  M3 R = R1.transpose() * R2;
  M3 Q = R.cwiseAbs();

  // for all 15 possible separating axes:
  //   * see if the axis separates the boxes. if so, return 0.
  //   * find the depth of the penetration along the separating axis (s2)
  //   * if this is the largest depth so far, record it.
  // the normal vector will be set to the separating axis with the smallest
  // depth. note: normalR is set to point to a column of R1 or R2 if that is
  // the smallest depth normal so far. otherwise normalR is 0 and normalC is
  // set to a vector relative to body 1. invert_normal is 1 if the sign of
  // the normal should be flipped.

  int best_col_id = -1;
  const M3* normalR = 0;
  S tmp = 0;

  s = - std::numeric_limits<S>::max();
  invert_normal = 0;
  code = 0;

  // separating axis = u1, u2, u3
  tmp = pp[0];
  s2 = std::abs(tmp) - (Q.row(0).dot(B) + A[0]);
  if(s2 > 0) { return false; }
  if(s2 > s)
  {
    s = s2;
    best_col_id = 0;
    normalR = &R1;
    invert_normal = (tmp < 0);
    code = 1;
  }

  tmp = pp[1];
  s2 = std::abs(tmp) - (Q.row(1).dot(B) + A[1]);
  if(s2 > 0) { return false; }
  if(s2 > s)
  {
    s = s2;
    best_col_id = 1;
    normalR = &R1;
    invert_normal = (tmp < 0);
    code = 2;
  }

  tmp = pp[2];
  s2 = std::abs(tmp) - (Q.row(2).dot(B) + A[2]);
  if(s2 > 0) { return false; }
  if(s2 > s)
  {
    s = s2;
    best_col_id = 2;
    normalR = &R1;
    invert_normal = (tmp < 0);
    code = 3;
  }

  // separating axis = v1, v2, v3
  tmp = R2.col(0).dot(p);
  s2 = std::abs(tmp) - (Q.col(0).dot(A) + B[0]);
  if(s2 > 0) { return false; }
  if(s2 > s)
  {
    s = s2;
    best_col_id = 0;
    normalR = &R2;
    invert_normal = (tmp < 0);
    code = 4;
  }

  tmp = R2.col(1).dot(p);
  s2 = std::abs(tmp) - (Q.col(1).dot(A) + B[1]);
  if(s2 > 0) { return false; }
  if(s2 > s)
  {
    s = s2;
    best_col_id = 1;
    normalR = &R2;
    invert_normal = (tmp < 0);
    code = 5;
  }

  tmp = R2.col(2).dot(p);
  s2 =  std::abs(tmp) - (Q.col(2).dot(A) + B[2]);
  if(s2 > 0) { return false; }
  if(s2 > s)
  {
    s = s2;
    best_col_id = 2;
    normalR = &R2;
    invert_normal = (tmp < 0);
    code = 6;
  }


  // This is used to detect zero-length axes which arise from taking the cross
  // product of parallel edges.
  S eps = std::numeric_limits<S>::epsilon();

  // We are performing the mathematical test: 0 > 0 (which should always be
  // false). However, zero can sometimes be 1e-16 or 1.5e-16. Thus,
  // mathematically we would interpret a scenario as 0 > 0 but end up with
  // 1.5e-16 > 1e-16. The former evaluates to false, the latter evaluates to
  // true; a clear falsehood.
  // (See http://gamma.cs.unc.edu/users/gottschalk/main.pdf, page 83).
  //
  // Gottschalk simply offers the value 1e-6 without any justification.
  // For double-precision values, that is quite a large epsilon; we can do
  // better. The idea is that this fictional zero can be scaled by the boxes'
  // dimensions and summed up four times. To account for that zero, we need to
  // make sure our epsilon is large enough to account for the *maximum* scale
  // factor and the sum. We pad Q by that amount so that the error will *not*
  // be the largest term.
  {
    using std::max;
    // For small boxes (dimensions all less than 1), limit the scale factor to
    // be no smaller than 10 * eps. This assumes all dimensions are strictly
    // non-negative.
    S scale_factor = max(max(A.maxCoeff(), B.maxCoeff()), S(1.0)) * S(10) * eps;
    Q.array() += scale_factor;
  }

  V3 n;

  // separating axis = u1 x (v1,v2,v3)
  tmp = pp[2] * R(1, 0) - pp[1] * R(2, 0);
  s2 = std::abs(tmp) - (A[1] * Q(2, 0) + A[2] * Q(1, 0) + B[1] * Q(0, 2) + B[2] * Q(0, 1));
  if(s2 > 0) { return false; }
  n = V3(0, -R(2, 0), R(1, 0));
  l = n.norm();
  if(l > eps)
  {
    s2 /= l;
    if(s2 * fudge_factor > s)
    {
      s = s2;
      best_col_id = -1;
      normalC = n / l;
      invert_normal = (tmp < 0);
      code = 7;
    }
  }

  tmp = pp[2] * R(1, 1) - pp[1] * R(2, 1);
  s2 = std::abs(tmp) - (A[1] * Q(2, 1) + A[2] * Q(1, 1) + B[0] * Q(0, 2) + B[2] * Q(0, 0));
  if(s2 > 0) { return false; }
  n = V3(0, -R(2, 1), R(1, 1));
  l = n.norm();
  if(l > eps)
  {
    s2 /= l;
    if(s2 * fudge_factor > s)
    {
      s = s2;
      best_col_id = -1;
      normalC = n / l;
      invert_normal = (tmp < 0);
      code = 8;
    }
  }

  tmp = pp[2] * R(1, 2) - pp[1] * R(2, 2);
  s2 = std::abs(tmp) - (A[1] * Q(2, 2) + A[2] * Q(1, 2) + B[0] * Q(0, 1) + B[1] * Q(0, 0));
  if(s2 > 0) { return false; }
  n = V3(0, -R(2, 2), R(1, 2));
  l = n.norm();
  if(l > eps)
  {
    s2 /= l;
    if(s2 * fudge_factor > s)
    {
      s = s2;
      best_col_id = -1;
      normalC = n / l;
      invert_normal = (tmp < 0);
      code = 9;
    }
  }

  // separating axis = u2 x (v1,v2,v3)
  tmp = pp[0] * R(2, 0) - pp[2] * R(0, 0);
  s2 = std::abs(tmp) - (A[0] * Q(2, 0) + A[2] * Q(0, 0) + B[1] * Q(1, 2) + B[2] * Q(1, 1));
  if(s2 > 0) { return false; }
  n = V3(R(2, 0), 0, -R(0, 0));
  l = n.norm();
  if(l > eps)
  {
    s2 /= l;
    if(s2 * fudge_factor > s)
    {
      s = s2;
      best_col_id = -1;
      normalC = n / l;
      invert_normal = (tmp < 0);
      code = 10;
    }
  }

  tmp = pp[0] * R(2, 1) - pp[2] * R(0, 1);
  s2 = std::abs(tmp) - (A[0] * Q(2, 1) + A[2] * Q(0, 1) + B[0] * Q(1, 2) + B[2] * Q(1, 0));
  if(s2 > 0) { return false; }
  n = V3(R(2, 1), 0, -R(0, 1));
  l = n.norm();
  if(l > eps)
  {
    s2 /= l;
    if(s2 * fudge_factor > s)
    {
      s = s2;
      best_col_id = -1;
      normalC = n / l;
      invert_normal = (tmp < 0);
      code = 11;
    }
  }

  tmp = pp[0] * R(2, 2) - pp[2] * R(0, 2);
  s2 = std::abs(tmp) - (A[0] * Q(2, 2) + A[2] * Q(0, 2) + B[0] * Q(1, 1) + B[1] * Q(1, 0));
  if(s2 > 0) { return false; }
  n = V3(R(2, 2), 0, -R(0, 2));
  l = n.norm();
  if(l > eps)
  {
    s2 /= l;
    if(s2 * fudge_factor > s)
    {
      s = s2;
      best_col_id = -1;
      normalC = n / l;
      invert_normal = (tmp < 0);
      code = 12;
    }
  }

  // separating axis = u3 x (v1,v2,v3)
  tmp = pp[1] * R(0, 0) - pp[0] * R(1, 0);
  s2 = std::abs(tmp) - (A[0] * Q(1, 0) + A[1] * Q(0, 0) + B[1] * Q(2, 2) + B[2] * Q(2, 1));
  if(s2 > 0) { return false; }
  n = V3(-R(1, 0), R(0, 0), 0);
  l = n.norm();
  if(l > eps)
  {
    s2 /= l;
    if(s2 * fudge_factor > s)
    {
      s = s2;
      best_col_id = -1;
      normalC = n / l;
      invert_normal = (tmp < 0);
      code = 13;
    }
  }

  tmp = pp[1] * R(0, 1) - pp[0] * R(1, 1);
  s2 = std::abs(tmp) - (A[0] * Q(1, 1) + A[1] * Q(0, 1) + B[0] * Q(2, 2) + B[2] * Q(2, 0));
  if(s2 > 0) { return false; }
  n = V3(-R(1, 1), R(0, 1), 0);
  l = n.norm();
  if(l > eps)
  {
    s2 /= l;
    if(s2 * fudge_factor > s)
    {
      s = s2;
      best_col_id = -1;
      normalC = n / l;
      invert_normal = (tmp < 0);
      code = 14;
    }
  }

  tmp = pp[1] * R(0, 2) - pp[0] * R(1, 2);
  s2 = std::abs(tmp) - (A[0] * Q(1, 2) + A[1] * Q(0, 2) + B[0] * Q(2, 1) + B[1] * Q(2, 0));
  if(s2 > 0) { return false; }
  n = V3(-R(1, 2), R(0, 2), 0);
  l = n.norm();
  if(l > eps)
  {
    s2 /= l;
    if(s2 * fudge_factor > s)
    {
      s = s2;
      best_col_id = -1;
      normalC = n / l;
      invert_normal = (tmp < 0);
      code = 15;
    }
  }

  if (!code) { return false; }

  // if we get to this point, the boxes interpenetrate. compute the normal
  // in global coordinates.
  if(best_col_id != -1)
    normal = normalR->col(best_col_id);
  else
    normal = R1 * normalC;

  if(invert_normal)
    normal = -normal;

  const S depth_value = -s;
  const S* depth = &depth_value; // s is negative when the boxes are in collision

  // compute contact point(s)

  if(code > 6)
  {
    // an edge from box 1 touches an edge from box 2.
    // find a point pa on the intersecting edge of box 1
    V3 pa(T1);
    S sign;

    for(int j = 0; j < 3; ++j)
    {
      sign = (R1.col(j).dot(normal) > 0) ? 1 : -1;
      pa += R1.col(j) * (A[j] * sign);
    }

    // find a point pb on the intersecting edge of box 2
    V3 pb(T2);

    for(int j = 0; j < 3; ++j)
    {
      sign = (R2.col(j).dot(normal) > 0) ? -1 : 1;
      pb += R2.col(j) * (B[j] * sign);
    }

    S alpha, beta;
    V3 ua(R1.col((code-7)/3));
    V3 ub(R2.col((code-7)%3));

    fcl::detail::lineClosestApproach<S>(pa, ua, pb, ub, &alpha, &beta);
    pa += ua * alpha;
    pb += ub * beta;

    V3 pointInWorld((pa + pb) * 0.5);
    out.normal = {normal[0], normal[1], normal[2]};
    out.pos = {pointInWorld[0], pointInWorld[1], pointInWorld[2]};
    out.depth = *depth;
    return true;
  }

  // okay, we have a face-something intersection (because the separating
  // axis is perpendicular to a face). define face 'a' to be the reference
  // face (i.e. the normal vector is perpendicular to this) and face 'b' to be
  // the incident face (the closest face of the other box).

  const M3 *Ra, *Rb;
  const V3 *pa, *pb;
  const V3 *Sa, *Sb;

  if(code <= 3)
  {
    Ra = &R1;
    Rb = &R2;
    pa = &T1;
    pb = &T2;
    Sa = &A;
    Sb = &B;
  }
  else
  {
    Ra = &R2;
    Rb = &R1;
    pa = &T2;
    pb = &T1;
    Sa = &B;
    Sb = &A;
  }

  // nr = normal vector of reference face dotted with axes of incident box.
  // anr = absolute values of nr.
  V3 normal2, nr, anr;
  if(code <= 3)
    normal2 = normal;
  else
    normal2 = -normal;

  nr = Rb->transpose() * normal2;
  anr = nr.cwiseAbs();

  // find the largest compontent of anr: this corresponds to the normal
  // for the indident face. the other axis numbers of the indicent face
  // are stored in a1,a2.
  int lanr, a1, a2;
  if(anr[1] > anr[0])
  {
    if(anr[1] > anr[2])
    {
      a1 = 0;
      lanr = 1;
      a2 = 2;
    }
    else
    {
      a1 = 0;
      a2 = 1;
      lanr = 2;
    }
  }
  else
  {
    if(anr[0] > anr[2])
    {
      lanr = 0;
      a1 = 1;
      a2 = 2;
    }
    else
    {
      a1 = 0;
      a2 = 1;
      lanr = 2;
    }
  }

  // compute center point of incident face, in reference-face coordinates
  V3 center;
  if(nr[lanr] < 0)
    center = (*pb) - (*pa) + Rb->col(lanr) * ((*Sb)[lanr]);
  else
    center = (*pb) - (*pa) - Rb->col(lanr) * ((*Sb)[lanr]);

  // find the normal and non-normal axis numbers of the reference box
  int codeN, code1, code2;
  if(code <= 3)
    codeN = code-1;
  else codeN = code-4;

  if(codeN == 0)
  {
    code1 = 1;
    code2 = 2;
  }
  else if(codeN == 1)
  {
    code1 = 0;
    code2 = 2;
  }
  else
  {
    code1 = 0;
    code2 = 1;
  }

  // find the four corners of the incident face, in reference-face coordinates
  S quad[8]; // 2D coordinate of incident face (x,y pairs)
  S c1, c2, m11, m12, m21, m22;
  c1 = Ra->col(code1).dot(center);
  c2 = Ra->col(code2).dot(center);
  // optimize this? - we have already computed this data above, but it is not
  // stored in an easy-to-index format. for now it's quicker just to recompute
  // the four dot products.
  V3 tempRac = Ra->col(code1);
  m11 = Rb->col(a1).dot(tempRac);
  m12 = Rb->col(a2).dot(tempRac);
  tempRac = Ra->col(code2);
  m21 = Rb->col(a1).dot(tempRac);
  m22 = Rb->col(a2).dot(tempRac);

  S k1 = m11 * (*Sb)[a1];
  S k2 = m21 * (*Sb)[a1];
  S k3 = m12 * (*Sb)[a2];
  S k4 = m22 * (*Sb)[a2];
  quad[0] = c1 - k1 - k3;
  quad[1] = c2 - k2 - k4;
  quad[2] = c1 - k1 + k3;
  quad[3] = c2 - k2 + k4;
  quad[4] = c1 + k1 + k3;
  quad[5] = c2 + k2 + k4;
  quad[6] = c1 + k1 - k3;
  quad[7] = c2 + k2 - k4;

  // find the size of the reference face
  S rect[2];
  rect[0] = (*Sa)[code1];
  rect[1] = (*Sa)[code2];

  // intersect the incident and reference faces
  S ret[16];
  int n_intersect = fcl::detail::intersectRectQuad2<S>(rect, quad, ret);
  if(n_intersect < 1) { return false; } // this should never happen

  // convert the intersection points into reference-face coordinates,
  // and compute the contact position and depth for each point. only keep
  // those points that have a positive (penetrating) depth. delete points in
  // the 'ret' array as necessary so that 'point' and 'ret' correspond.
  V3 points[8]; // penetrating contact points
  S dep[8]; // depths for those points
  S det1 = 1.f/(m11*m22 - m12*m21);
  m11 *= det1;
  m12 *= det1;
  m21 *= det1;
  m22 *= det1;
  int cnum = 0; // number of penetrating contact points found
  for(int j = 0; j < n_intersect; ++j)
  {
    S u1 =  m22*(ret[j*2]-c1) - m12*(ret[j*2+1]-c2);
    S u2 = -m21*(ret[j*2]-c1) + m11*(ret[j*2+1]-c2);
    points[cnum] = center + Rb->col(a1) * u1 + Rb->col(a2) * u2;
    dep[cnum] = (*Sa)[codeN] - normal2.dot(points[cnum]);
    if(dep[cnum] >= 0)
    {
      ret[cnum*2] = ret[j*2];
      ret[cnum*2+1] = ret[j*2+1];
      cnum++;
    }
  }
  if(cnum < 1) { return false; } // this should never happen

  // The deepest point: the first of maximum depth (FCL's first emitted contact).
  int i1 = 0;
  S maxdepth = dep[0];
  for (int i = 1; i < cnum; ++i) {
    if (dep[i] > maxdepth) {
      maxdepth = dep[i];
      i1 = i;
    }
  }
  const V3 pointInWorld = code < 4 ? V3(points[i1] + (*pa) + normal * (dep[i1] / 2))
                                   : V3(points[i1] + (*pa) - normal * (dep[i1] / 2));
  out.normal = {normal[0], normal[1], normal[2]};
  out.pos = {pointInWorld[0], pointInWorld[1], pointInWorld[2]};
  out.depth = dep[i1];
  return true;
}

}  // namespace octocd
