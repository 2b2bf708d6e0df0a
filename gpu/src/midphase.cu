// Midphase + narrow phase on the device (SPEC 5.2-5.3): one thread per candidate pair runs
// hd::confirm_contact, the function the CPU's confirm_contact runs, on views of the packed
// octrees, with the same positions, world AABBs and theta. Static-static pairs are skipped
// as in World::step. Test counts are summed with integer atomics (order-free).
#include "kernels.hpp"

namespace octocd {
namespace gpu {
namespace {

__device__ hd::PlacedView place(const ShapesDesc& s, std::uint32_t shape, Vec3 x, const Aabb& box) {
  hd::PlacedView p;
  const DeviceShape& d = s.shapes[shape];
  p.is_mesh = d.is_mesh != 0;
  if (p.is_mesh) {
    p.octree.depth = d.depth;
    p.octree.bounds = d.bounds;
    p.octree.vertices = s.vertices + d.vertex_offset;
    p.octree.vertex_count = d.vertex_count;
    p.octree.cells = s.cells + d.cell_offset;
    p.octree.level_offset = s.level_offsets + d.level_offset_offset;
  }
  p.position = x;
  p.box = box;
  return p;
}

__global__ void midphase_kernel(MidphaseDesc d) {
  const std::uint32_t k = blockIdx.x * blockDim.x + threadIdx.x;
  if (k >= d.pair_count) return;
  const Pair p = d.pairs[k];
  if (d.w[p.a] == 0.0f && d.w[p.b] == 0.0f) {  // static-static
    d.confirmed[k] = 0;
    return;
  }
  const std::uint32_t sa = d.shape[p.a];
  const std::uint32_t sb = d.shape[p.b];
  const hd::PlacedView a = place(d.shapes, sa, d.x[p.a], d.aabb[p.a]);
  const hd::PlacedView b = place(d.shapes, sb, d.x[p.b], d.aabb[p.b]);
  hd::MidphaseCounters c;
  Vec3* scratch = d.scratch ? d.scratch + static_cast<std::size_t>(k) * d.scratch_per_pair : nullptr;
  const bool hit = hd::confirm_contact(a, b, d.shapes.theta[sa * d.shapes.count + sb], d.levels, c, scratch,
                                       scratch ? d.scratch_per_pair : 0u);
  d.confirmed[k] = hit ? 1 : 0;
  if (c.box_tests) atomicAdd(&d.counters[0], static_cast<unsigned long long>(c.box_tests));
  if (c.box_pairs) atomicAdd(&d.counters[1], static_cast<unsigned long long>(c.box_pairs));
  if (c.vertex_tests) atomicAdd(&d.counters[2], static_cast<unsigned long long>(c.vertex_tests));
}

}  // namespace

cudaError_t launch_midphase(const MidphaseDesc& d, cudaStream_t stream) {
  if (d.pair_count == 0) return cudaSuccess;
  midphase_kernel<<<grid_for(d.pair_count), kBlockSize, 0, stream>>>(d);
  return cudaGetLastError();
}

}  // namespace gpu
}  // namespace octocd
