#pragma once
/// \file external_trace.hpp
/// An external trace (docs/trace-format.md, "External traces") written with the HDF5 C
/// API from arrays a test may break before writing: version 1 as octocd's own tests
/// always wrote it, and version 2 (design.md section 13: rotation, inertia, manifolds with points,
/// materials) through Trace::make_v2(). Shared by test_external and test_cli_external.
#include <gtest/gtest.h>
#include <hdf5.h>

#include <cmath>
#include <cstdint>
#include <map>
#include <string>
#include <vector>

namespace octocd::test {

/// A small external trace, held in arrays that a test may break before writing: 3 boxes
/// of half side 0.1 (body 0 static), two overlapping by the slop (1, 2) and one apart, 3
/// frames at rest without gravity, the pair and its contact in every frame.
struct Trace {
  static constexpr int kBodies = 3, kFrames = 3;
  std::vector<float> local_min, local_max, inverse_mass{0.0f, 1.0f, 1.0f};
  std::vector<float> position, velocity, aabb_min, aabb_max;  // (F+1) n 3, (F+1) n 3, F n 3
  std::vector<std::int64_t> pair_offsets{0, 1, 2, 3}, contact_offsets{0, 1, 2, 3};
  std::vector<std::uint32_t> pairs{1, 2, 1, 2, 1, 2}, contact_pair{1, 2, 1, 2, 1, 2};
  std::vector<float> normal{-1, 0, 0, -1, 0, 0, -1, 0, 0}, depth{0.001f, 0.001f, 0.001f}, jn{0, 0, 0}, jt{0, 0, 0};
  std::vector<std::string> skip;  // datasets to leave out
  hsize_t aabb_bodies = kBodies;  // rows per frame written to /aabbs (a wrong body count)

  // ---- Version 2 (written when non-empty; make_v2 fills them).
  int version = 1;
  std::vector<float> orientation, angular_velocity;  // (F+1) n 4, (F+1) n 3
  std::vector<float> inertia;                        // n 3 3
  std::vector<float> point;                          // C 3
  std::vector<float> jt3;                            // C 3: tangential impulse vectors (written when non-empty)
  std::vector<float> point_b;                        // C 3: each row's point on B (written when non-empty)
  std::vector<std::string> collision_shape;          // n: /bodies/collision_shape (written when non-empty)
  std::vector<float> friction, restitution;          // n
  std::map<std::string, std::string> string_attrs;   // root attributes
  std::map<std::string, double> number_attrs;
  std::map<std::string, std::vector<hsize_t>> dims;  // a dataset's shape, to write a wrong one

  Trace() {
    const float x[kBodies][3] = {{0, -1, 0}, {0, 0, 0}, {0.199f, 0, 0}};
    for (int i = 0; i < kBodies; ++i)
      for (int k = 0; k < 3; ++k) {
        local_min.push_back(-0.1f);
        local_max.push_back(0.1f);
      }
    for (int f = 0; f <= kFrames; ++f)
      for (int i = 0; i < kBodies; ++i)
        for (int k = 0; k < 3; ++k) {
          position.push_back(x[i][k]);
          velocity.push_back(0.0f);
          if (f > 0) {
            aabb_min.push_back(x[i][k] - 0.1f);
            aabb_max.push_back(x[i][k] + 0.1f);
          }
        }
  }

  /// The same bodies as a version 2 trace of a rotating engine: body 2 spins about +y at
  /// 0.5 rad/s (orientation row r: 0.05 r rad about y), body 1 is turned 0.3 rad about z;
  /// an inertia tensor per body (body 2's with products of inertia); the pair (1, 2) has a
  /// two-row manifold with points in frames 1 and 3 and one row in frame 2; materials as
  /// attributes and per body; no /aabbs (version 2 does not need them).
  static Trace make_v2() {
    Trace t;
    t.version = 2;
    t.skip = {"/aabbs/min", "/aabbs/max"};
    for (int r = 0; r <= kFrames; ++r)
      for (int i = 0; i < kBodies; ++i) {
        float q[4] = {1, 0, 0, 0}, w[3] = {0, 0, 0};
        if (i == 1) {
          q[0] = std::cos(0.15f);
          q[3] = std::sin(0.15f);
        } else if (i == 2) {
          q[0] = std::cos(0.025f * static_cast<float>(r));
          q[2] = std::sin(0.025f * static_cast<float>(r));
          w[1] = 0.5f;
        }
        t.orientation.insert(t.orientation.end(), q, q + 4);
        t.angular_velocity.insert(t.angular_velocity.end(), w, w + 3);
      }
    const float d = 0.2f * 0.2f / 6.0f;                // 1 kg box of side 0.2: m/12 (b^2 + c^2)
    t.inertia = {0, 0,      0, 0,      0, 0, 0, 0, 0,  //
                 d, 0,      0, 0,      d, 0, 0, 0, d,  //
                 d, 0.001f, 0, 0.001f, d, 0, 0, 0, 1.5f * d};
    t.contact_offsets = {0, 2, 3, 5};
    t.contact_pair = {1, 2, 1, 2, 1, 2, 1, 2, 1, 2};
    t.normal = {-1, 0, 0, -1, 0, 0, -1, 0, 0, -1, 0, 0, -1, 0, 0};
    t.depth = {0.001f, 0.0005f, 0.001f, 0.001f, 0.0f};
    t.jn = {0.01f, 0.02f, 0.03f, 0.04f, 0.05f};
    t.jt = {0.001f, -0.002f, 0.003f, 0.0f, 0.005f};
    t.point = {0.1f, 0.05f, 0.05f, 0.1f, -0.05f, -0.05f, 0.1f, 0, 0, 0.1f, 0.05f, 0, 0.1f, -0.05f, 0};
    t.friction = {0.5f, 0.7f, 0.9f};
    t.restitution = {0.1f, 0.2f, 0.3f};
    t.string_attrs = {{"detection", "pre-step"},
                      {"friction_combine", "min"},
                      {"restitution_combine", "max"},
                      {"contact_geometry", "aabb"}};
    t.number_attrs = {{"mu", 0.4}, {"restitution", 0.2}, {"contact_margin", 0.01}, {"broadphase_exact", 1}};
    return t;
  }

  void write(const std::string& path) const {
    const hid_t file = H5Fcreate(path.c_str(), H5F_ACC_TRUNC, H5P_DEFAULT, H5P_DEFAULT);
    ASSERT_GE(file, 0);
    const hid_t lcpl = H5Pcreate(H5P_LINK_CREATE);
    H5Pset_create_intermediate_group(lcpl, 1);
    auto put = [&](const char* name, hid_t mem, hid_t type, std::vector<hsize_t> shape, const void* data) {
      for (const std::string& s : skip)
        if (s == name) return;
      if (dims.count(name)) shape = dims.at(name);
      const hid_t space = H5Screate_simple(static_cast<int>(shape.size()), shape.data(), nullptr);
      const hid_t d = H5Dcreate2(file, name, type, space, lcpl, H5P_DEFAULT, H5P_DEFAULT);
      ASSERT_GE(d, 0) << name;
      ASSERT_GE(H5Dwrite(d, mem, H5S_ALL, H5S_ALL, H5P_DEFAULT, data), 0) << name;
      H5Dclose(d);
      H5Sclose(space);
    };
    auto str_attr = [&](const char* name, const char* value) {
      const hid_t t = H5Tcopy(H5T_C_S1);
      H5Tset_size(t, H5T_VARIABLE);
      const hid_t space = H5Screate(H5S_SCALAR);
      const hid_t a = H5Acreate2(file, name, t, space, H5P_DEFAULT, H5P_DEFAULT);
      H5Awrite(a, t, &value);
      H5Aclose(a);
      H5Sclose(space);
      H5Tclose(t);
    };
    auto num_attr = [&](const char* name, double value) {
      const hid_t space = H5Screate(H5S_SCALAR);
      const hid_t a = H5Acreate2(file, name, H5T_IEEE_F64LE, space, H5P_DEFAULT, H5P_DEFAULT);
      H5Awrite(a, H5T_NATIVE_DOUBLE, &value);
      H5Aclose(a);
      H5Sclose(space);
    };
    str_attr("format", "octocd-trace");
    if (!string_attrs.count("engine")) str_attr("engine", "test-engine");
    for (const auto& [name, value] : string_attrs) str_attr(name.c_str(), value.c_str());
    for (const auto& [name, value] : number_attrs) num_attr(name.c_str(), value);
    {
      const hid_t space = H5Screate(H5S_SCALAR);
      const hid_t a = H5Acreate2(file, "version", H5T_STD_I32LE, space, H5P_DEFAULT, H5P_DEFAULT);
      H5Awrite(a, H5T_NATIVE_INT, &version);
      H5Aclose(a);
      H5Sclose(space);
      const double gravity[3] = {0, 0, 0};
      const hsize_t three = 3;
      const hid_t gs = H5Screate_simple(1, &three, nullptr);
      const hid_t g = H5Acreate2(file, "gravity", H5T_IEEE_F64LE, gs, H5P_DEFAULT, H5P_DEFAULT);
      H5Awrite(g, H5T_NATIVE_DOUBLE, gravity);
      H5Aclose(g);
      H5Sclose(gs);
    }
    const hsize_t n = kBodies, f = kFrames;
    const hid_t F = H5T_NATIVE_FLOAT, FT = H5T_IEEE_F32LE;
    put("/bodies/local_aabb_min", F, FT, {n, 3}, local_min.data());
    put("/bodies/local_aabb_max", F, FT, {n, 3}, local_max.data());
    put("/bodies/inverse_mass", F, FT, {inverse_mass.size()}, inverse_mass.data());
    put("/states/position", F, FT, {f + 1, n, 3}, position.data());
    put("/states/velocity", F, FT, {velocity.size() / (3 * n), n, 3}, velocity.data());
    put("/aabbs/min", F, FT, {f, aabb_bodies, 3}, aabb_min.data());
    put("/aabbs/max", F, FT, {f, aabb_bodies, 3}, aabb_max.data());
    put("/pairs/offsets", H5T_NATIVE_INT64, H5T_STD_I64LE, {pair_offsets.size()}, pair_offsets.data());
    put("/pairs/pair", H5T_NATIVE_UINT32, H5T_STD_U32LE, {pairs.size() / 2, 2}, pairs.data());
    put("/contacts/offsets", H5T_NATIVE_INT64, H5T_STD_I64LE, {contact_offsets.size()}, contact_offsets.data());
    const hsize_t c = contact_pair.size() / 2;
    put("/contacts/pair", H5T_NATIVE_UINT32, H5T_STD_U32LE, {c, 2}, contact_pair.data());
    put("/contacts/normal", F, FT, {c, 3}, normal.data());
    put("/contacts/depth", F, FT, {c}, depth.data());
    put("/contacts/jn", F, FT, {c}, jn.data());
    put("/contacts/jt", F, FT, {c}, jt.data());
    if (!orientation.empty())
      put("/states/orientation", F, FT, {orientation.size() / (4 * n), n, 4}, orientation.data());
    if (!angular_velocity.empty())
      put("/states/angular_velocity", F, FT, {angular_velocity.size() / (3 * n), n, 3}, angular_velocity.data());
    if (!inertia.empty()) put("/bodies/inertia", F, FT, {inertia.size() / 9, 3, 3}, inertia.data());
    if (!point.empty()) put("/contacts/point", F, FT, {point.size() / 3, 3}, point.data());
    if (!jt3.empty()) put("/contacts/jt3", F, FT, {jt3.size() / 3, 3}, jt3.data());
    if (!point_b.empty()) put("/contacts/point_b", F, FT, {point_b.size() / 3, 3}, point_b.data());
    if (!collision_shape.empty()) {
      std::vector<const char*> ptrs;
      for (const std::string& shape : collision_shape) ptrs.push_back(shape.c_str());
      const hid_t st = H5Tcopy(H5T_C_S1);
      H5Tset_size(st, H5T_VARIABLE);
      put("/bodies/collision_shape", st, st, {ptrs.size()}, ptrs.data());
      H5Tclose(st);
    }
    if (!friction.empty()) put("/bodies/friction", F, FT, {friction.size()}, friction.data());
    if (!restitution.empty()) put("/bodies/restitution", F, FT, {restitution.size()}, restitution.data());
    H5Pclose(lcpl);
    H5Fclose(file);
  }
};

}  // namespace octocd::test
