// The names and rules of octocd/physics_bodies.hpp: what a trace or an engine declares of
// its bodies.
#include "octocd/physics_bodies.hpp"

#include <cmath>

namespace octocd {

const char* material_combine_name(MaterialCombine c) {
  switch (c) {
    case MaterialCombine::Product: return "product";
    case MaterialCombine::Min: return "min";
    case MaterialCombine::Max: return "max";
    case MaterialCombine::Average: return "average";
    case MaterialCombine::Geometric: return "geometric";
  }
  return "product";
}

double combine_material(MaterialCombine c, double a, double b) {
  switch (c) {
    case MaterialCombine::Product: return a * b;
    case MaterialCombine::Min: return a < b ? a : b;
    case MaterialCombine::Max: return a > b ? a : b;
    case MaterialCombine::Average: return 0.5 * (a + b);
    case MaterialCombine::Geometric: return std::sqrt(a * b);
  }
  return a * b;
}

const char* collision_shape_name(CollisionShape c) {
  switch (c) {
    case CollisionShape::Mesh: return "mesh";
    case CollisionShape::ConvexHull: return "convex_hull";
    case CollisionShape::Box: return "box";
    case CollisionShape::Sphere: return "sphere";
  }
  return "mesh";
}

}  // namespace octocd
