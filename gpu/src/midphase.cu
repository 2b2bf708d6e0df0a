// Midphase + narrow phase on the device (design.md sections 5.2-5.3): the kernels over the per-item
// device code of midphase.cuh (see there for the work lists, the counts and the order).
#include "kernels.hpp"
#include "midphase.cuh"

namespace octocd {
namespace gpu {
namespace {

// The grid is 4 blocks per SM (cuda_world.cpp, warp_grid): at 64 registers all 4 are
// resident (66 without the bound: 3, and the 4th ran as a second wave; 28 bytes spilled).
__global__ void __launch_bounds__(kBlockSize, 4) mid_start_kernel(MidListDesc d) { mid::mid_start_items<true>(d); }

__global__ void mid_witness_kernel(MidListDesc d) { mid::mid_witness_items(d); }

__global__ void mid_decide_kernel(MidListDesc d) {
  const std::uint32_t stride = gridDim.x * blockDim.x;
  const std::uint32_t np = *d.pair_count < d.pair_capacity ? *d.pair_count : d.pair_capacity;
  for (std::uint32_t k0 = (blockIdx.x * blockDim.x + threadIdx.x) & ~31u; k0 < np; k0 += stride)
    mid::mid_decide_warp(d, k0);
}

__global__ void mid_expand_kernel(MidListDesc d, int step) { mid::mid_expand_items(d, step); }

// The last expand step when it does not run its leaves itself (mid::fuse_leaves false):
// it appends them to the leaf list (mid_leaf_kernel runs them); launched beside
// mid_expand_last_kernel, exactly one of the two does the step.
__global__ void mid_expand_append_kernel(MidListDesc d, int step) {
  const std::uint32_t count = *d.in_count < d.in_capacity ? *d.in_count : d.in_capacity;
  if (mid::fuse_leaves(d, count)) return;
  mid::mid_expand_items(d, step);
}

// The last expand step, which may run its items' leaves itself (mid::fuse_leaves); 128
// registers: 2 of the grid's 4 blocks per SM at a time (bounding it to 3 spills > 200 bytes).
__global__ void __launch_bounds__(kBlockSize, 2) mid_expand_last_kernel(MidListDesc d, int step) {
  __shared__ mid::LeafTiles tiles;
  const std::uint32_t count = *d.in_count < d.in_capacity ? *d.in_count : d.in_capacity;
  if (!mid::fuse_leaves(d, count)) return;  // mid_expand_append_kernel does the step
  mid::mid_expand_items(d, step, &tiles);
}

// Four blocks per SM (64 registers; ptxas spills 20 bytes for it; 68 without the bound).
__global__ void __launch_bounds__(kBlockSize, 4) mid_leaf_kernel(MidListDesc d) {
  __shared__ mid::LeafTiles tiles;
  mid::mid_leaf_items<true>(d, tiles);
}

// The witness cache's copy of this step's keys and witnesses (grid-stride, a thread per pair),
// and this step's leaf items moved to the last step's (fuse_leaves).
__global__ void mid_keep_kernel(MidListDesc d) {
  const std::uint32_t np = *d.pair_count < d.pair_capacity ? *d.pair_count : d.pair_capacity;
  const std::uint32_t tid = blockIdx.x * blockDim.x + threadIdx.x;
  if (d.wit.witness != nullptr) {
    for (std::uint32_t k = tid; k < np; k += gridDim.x * blockDim.x) mid::keep_witness(d, k);
    if (tid == 0) mid::keep_witness_count(d);
  }
  if (tid == 0 && d.leaf_items != nullptr) {  // this step's leaf items become the last step's
    d.leaf_items[0] = d.leaf_items[1];
    d.leaf_items[1] = 0;
  }
}

}  // namespace

cudaError_t launch_mid_keep(const MidListDesc& d, unsigned grid, cudaStream_t stream) {
  return launch_when((d.wit.witness != nullptr || d.leaf_items != nullptr) && d.pair_capacity != 0, mid_keep_kernel,
                     d, grid, stream);
}

cudaError_t launch_mid_decide(const MidListDesc& d, unsigned grid, cudaStream_t stream) {
  return launch_when(d.pair_capacity != 0, mid_decide_kernel, d, grid, stream);
}

cudaError_t launch_mid_witness(const MidListDesc& d, unsigned grid, cudaStream_t stream) {
  return launch_when(d.wit.witness != nullptr, mid_witness_kernel, d, grid, stream);
}

cudaError_t launch_mid_start(const MidListDesc& d, unsigned grid, cudaStream_t stream) {
  mid_start_kernel<<<grid, kBlockSize, 0, stream>>>(d);
  return cudaGetLastError();
}

cudaError_t launch_mid_expand(const MidListDesc& d, int step, unsigned grid, cudaStream_t stream) {
  if (step + 2 == d.steps) {
    mid_expand_append_kernel<<<grid, kBlockSize, 0, stream>>>(d, step);
    mid_expand_last_kernel<<<grid, kBlockSize, 0, stream>>>(d, step);
  } else {
    mid_expand_kernel<<<grid, kBlockSize, 0, stream>>>(d, step);
  }
  return cudaGetLastError();
}

cudaError_t launch_mid_leaf(const MidListDesc& d, unsigned grid, cudaStream_t stream) {
  mid_leaf_kernel<<<grid, kBlockSize, 0, stream>>>(d);
  return cudaGetLastError();
}

}  // namespace gpu
}  // namespace octocd
