#pragma once
// The coherent-motion sequence of the GPU broadphase bench (bench_gpu_motion.cpp).
#include "bench_gpu_common.hpp"

namespace gpu_bench {

/// The bench's boxes moving at constant velocity (a random direction, speed uniform in
/// [0, --motion-speed)), reflected at the centres' cube; the oracle (CPU `flat` up to
/// --cpu-flat-max bodies, else the CPU `octree`, one instance over the sequence) every
/// --motion-oracle-every steps; the two device sets compared every step. Each broadphase
/// is replayed from CUDA graphs with --graph (the coherent one: a graph per plan).
MotionResult run_motion(std::uint32_t n, float fraction, const Options& o, cudaStream_t stream);

/// The coherent-motion sequences as a Markdown table.
void print_motion(std::ostream& os, const Options& o, const std::vector<MotionResult>& ms);

/// The coherent-motion sequences as JSON.
Json motion_json(const std::vector<MotionResult>& ms);

}  // namespace gpu_bench
