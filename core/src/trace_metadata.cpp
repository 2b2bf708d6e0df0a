// What a trace takes from an engine (octocd/trace.hpp): its metadata, the declarations of
// octocd's own conventions and the body tables.
#include "octocd/trace.hpp"

#include <fmt/format.h>
#include <nlohmann/json.hpp>

#include "octocd/version.hpp"
#include "trace_hdf5_out.hpp"

namespace octocd {

using trace_out::iso_utc_now;
using trace_out::vec_json;

TraceMetadata trace_metadata(const Engine& engine, int state_every) {
  const Scene& s = engine.scene();
  TraceMetadata meta;
  meta.scene_name = s.name;
  meta.scene_json = s.json;
  nlohmann::json p;
  const ContactParams& r = s.response;
  p["response"] = {{"slop", r.slop},
                   {"beta", r.beta},
                   {"alpha", r.alpha},
                   {"restitution", r.restitution},
                   {"restitution_threshold", r.restitution_threshold},
                   {"impulse_floor", r.impulse_floor},
                   {"mu_static", r.mu_static},
                   {"mu_kinetic", r.mu_kinetic},
                   {"max_velocity", r.max_velocity},
                   {"epsilon", r.epsilon},
                   {"overlap", r.overlap == OverlapMode::Paper ? "paper" : "separating"},
                   {"iterations", r.iterations}};
  p["theta"] = s.theta ? nlohmann::json(*s.theta) : nlohmann::json("auto");
  p["dt"] = s.dt;
  p["frames"] = s.frames;
  p["gravity"] = vec_json(s.gravity);
  p["domain"] = {{"min", vec_json(s.domain.min)}, {"max", vec_json(s.domain.max)}};
  p["wall_thickness"] = s.wall_thickness;
  p["broadphase"] = {{"name", engine.broadphase_name()},
                     {"octree_depth", s.broadphase.octree_depth},
                     {"cell_size", s.broadphase.cell_size}};
  p["midphase"] = engine.midphase_name();
  p["geometry"] = engine.collision_geometry();  // what the engine collided (design.md section 15)
  p["mesh_octree_depth"] = s.mesh_octree_depth;
  meta.parameters_json = p.dump();
  meta.engine = engine.name();
  meta.broadphase = engine.broadphase_name();
  meta.midphase = engine.midphase_name();
  meta.build_id = build_id();
  meta.device = engine.device();
  meta.start_time = iso_utc_now();
  meta.dt = s.dt;
  meta.state_every = state_every;
  // The engine says whether it follows octocd's contact conventions; the trace declares
  // them, so readers never judge by the engine's name.
  if (engine.octocd_contacts()) meta.declarations = octocd_trace_declarations(engine.model());
  return meta;
}

TraceDeclarations octocd_trace_declarations(const Model& model) {
  const ContactParams& r = model.scene.response;
  TraceDeclarations d;
  d.contact_geometry = "aabb";
  d.broadphase_exact = 1;
  d.contact_margin_rule = "theta";
  d.jt_direction = "along-sliding";
  d.velocity_clamp = r.max_velocity;
  d.impulses_complete = r.iterations <= 1 ? 1 : 0;
  d.response_scheme = "jacobi";
  d.integrator = "semi-implicit";
  d.contact_model = "rigid";
  d.deactivation = "off";
  d.friction_directions = 1;  // design.md section 6: J_t along t, one direction
  return d;
}

TraceBodies trace_bodies(const Engine& engine) {
  TraceBodies tb;
  const auto& info = engine.bodies();
  const auto& shapes = engine.shapes();
  const BodyState& st = engine.state();
  for (std::size_t i = 0; i < info.size(); ++i) {
    tb.shape_id.push_back(info[i].shape);
    tb.inverse_mass.push_back(i < st.w.size() ? st.w[i] : 0.0f);
    tb.local_aabb.push_back(info[i].shape < shapes.size() ? shapes[info[i].shape].local : Aabb{});
    tb.group.push_back(info[i].group);
  }
  for (const Shape& sh : shapes) tb.shape_names.push_back(sh.name);
  return tb;
}

}  // namespace octocd
