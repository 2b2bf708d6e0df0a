// The per-stage path of the cuda engine (design.md section 11): the step's stages in World::step's
// order as separate kernels (integrate.cu, the broadphases, midphase.cu, response.cu,
// metrics.cu), enqueued on one stream with no host synchronisation inside a step, replayed
// from a CUDA graph while the buffer capacities do not change; the buffers' sizes, the
// kernels' descriptors, and the regrow and rerun of a step whose lists overflowed.
#include <algorithm>
#include <cstddef>
#include <initializer_list>

#include <fmt/format.h>

#include "cuda_impl.hpp"
#include "device_footprint.hpp"
#include "octocd/error.hpp"

namespace octocd {

using gpu::BufferBase;
using gpu::check;
using gpu::cuda_text;

namespace {

// The host estimate (device_footprint.cpp) counts these structs by the sizes of
// device_footprint.hpp.
static_assert(sizeof(gpu::DeviceShape) == gpu::footprint::kDeviceShapeBytes, "device_footprint.hpp: DeviceShape");
static_assert(sizeof(gpu::MidItem) == gpu::footprint::kMidItemBytes, "device_footprint.hpp: MidItem");
static_assert(sizeof(gpu::DeviceContact) == gpu::footprint::kDeviceContactBytes, "device_footprint.hpp: DeviceContact");
static_assert(gpu::kIndexShortSegment == gpu::footprint::kIndexShortSegment, "device_footprint.hpp: kIndexShortSegment");
static_assert(gpu::kSmallFrontBodies == gpu::footprint::kSmallBlockPairBodies,
              "device_footprint.hpp: kSmallBlockPairBodies");
static_assert(gpu::kBlockPairSegments == gpu::footprint::kBlockPairSegments, "device_footprint.hpp: kBlockPairSegments");
static_assert(sizeof(gpu::StepStats) == gpu::footprint::kStepStatsBytes, "device_footprint.hpp: StepStats");
static_assert(sizeof(gpu::MetricsResult) == gpu::footprint::kMetricsResultBytes, "device_footprint.hpp: MetricsResult");
static_assert(gpu::kMetricsBlocks == gpu::footprint::kMetricsPartials, "device_footprint.hpp: kMetricsBlocks");

/// The capacity to grow to when `needed` entries did not fit into `capacity`.
std::size_t grown(std::size_t needed, std::size_t capacity) {
  return std::max(needed + needed / 4 + 64, 2 * capacity);
}

/// Destroys a captured graph and its executable (either may be null) and nulls both.
void destroy_graph(cudaGraph_t& graph, cudaGraphExec_t& exec) {
  if (exec) (void)cudaGraphExecDestroy(exec);
  if (graph) (void)cudaGraphDestroy(graph);
  exec = nullptr;
  graph = nullptr;
}

}  // namespace

void CudaWorld::Impl::drop_graph() {
  for (int p = 0; p < gpu::kBroadPhasePlans; ++p) {
    destroy_graph(graph[p], graph_exec[p]);
    destroy_graph(timed_graph[p], timed_graph_exec[p]);
  }
}

std::vector<BufferBase*> CudaWorld::Impl::all_buffers() {
  std::vector<BufferBase*> all{&x, &v, &x_saved, &v_saved, &w, &local, &shape, &aabb, &x_pre, &v_pre, &shapes, &vertices, &cells,
                               &level_offsets, &blocks, &theta, &stats, &metric_partials};
  for (BufferBase* b : scratch_buffers()) all.push_back(b);
  return all;
}

std::vector<BufferBase*> CudaWorld::Impl::scratch_buffers() {
  return {&bp_counts.count, &bp_counts.offset, &pair_keys, &pair_keys_sorted, &pairs, &confirmed, &items_a, &items_b,
          &corrections.hit, &corrections.dx_a, &corrections.dx_b, &corrections.dv_a, &corrections.dv_b, &depth0,
          &records, &in_list, &in_counts.offset, &in_counts.count, &index_offsets, &index_rank, &index_entries,
          &index_long, &witness, &prev_keys, &prev_witness, &prev_begin, &prev_count, &leaf_items, &temp};
}

void CudaWorld::Impl::launched(cudaError_t e, const char* kernel) {
  if (e != cudaSuccess) {
    (void)cudaGetLastError();
    throw RuntimeError(fmt::format("CUDA kernel '{}' failed to launch: {}", kernel, cuda_text(e)));
  }
  if (sync_each_launch && !capturing) {
    e = cudaStreamSynchronize(stream);
    if (e != cudaSuccess) throw RuntimeError(fmt::format("CUDA kernel '{}' failed: {}", kernel, cuda_text(e)));
  }
}

namespace {

/// A stage descriptor's body state: positions, velocities, inverse masses.
template <class Desc>
void set_body_state(Desc& d, CudaWorld::Impl& w) {
  d.x = w.x.get();
  d.v = w.v.get();
  d.w = w.w.get();
}

/// A stage descriptor's pair list: the pairs, which the midphase confirmed, the count.
template <class Desc>
void set_pair_list(Desc& d, CudaWorld::Impl& w) {
  d.pairs = w.pairs.get();
  d.confirmed = w.confirmed.get();
  d.pair_count = w.counts();
}

/// A stage descriptor's per-pair corrections (the contact terms' outputs, the apply's inputs).
template <class Desc>
void set_corrections(Desc& d, CudaWorld::Impl& w) {
  d.hit = w.corrections.hit.get();
  d.dx_a = w.corrections.dx_a.get();
  d.dx_b = w.corrections.dx_b.get();
  d.dv_a = w.corrections.dv_a.get();
  d.dv_b = w.corrections.dv_b.get();
}

}  // namespace

gpu::BodiesDesc CudaWorld::Impl::bodies() {
  gpu::BodiesDesc b;
  set_body_state(b, *this);
  b.local = local.get();
  b.shape = shape.get();
  b.aabb = aabb.get();
  b.n = n;
  return b;
}

gpu::ShapesDesc CudaWorld::Impl::shapes_desc() {
  gpu::ShapesDesc s;
  s.shapes = shapes.get();
  s.vertices = vertices.get();
  s.cells = cells.get();
  s.level_offsets = level_offsets.get();
  s.blocks = blocks.get();
  s.theta = theta.get();
  s.count = shape_count;
  return s;
}

gpu::MidListDesc CudaWorld::Impl::mid_desc(const unsigned long long* keys) {
  gpu::MidListDesc md;
  md.x = x.get();
  md.w = w.get();
  md.aabb = aabb.get();
  md.shape = shape.get();
  md.shapes = shapes_desc();
  md.levels = levels;
  set_pair_list(md, *this);
  md.pair_keys = keys;
  md.pair_shift = gpu::key_bits(n);
  md.pair_capacity = pcap();
  md.counters = counters();
  md.steps = level_steps;
  md.early_exit = mid_early_exit;
  md.fuse_min_items = mid_fuse_min_items;
  md.leaf_items = leaf_items.get();
  md.witness_pass_pairs = mid_witness_pass_min_pairs > 0
                              ? mid_witness_pass_min_pairs
                              : gpu::kWitnessPassPairsPerWarp * warp_grid * (gpu::kBlockSize / 32u);
  if (witnesses()) {
    md.wit.witness = witness.get();
    md.wit.prev_keys = prev_keys.get();
    md.wit.prev_witness = prev_witness.get();
    md.wit.prev_begin = prev_begin.get();
    md.wit.prev_count = prev_count.get();
  }
  return md;
}

gpu::TermsDesc CudaWorld::Impl::terms_desc(const ContactParams& params) {
  gpu::TermsDesc td;
  set_pair_list(td, *this);
  td.pair_capacity = pcap();
  set_body_state(td, *this);
  td.local = local.get();
  td.params = params;
  set_corrections(td, *this);
  return td;
}

gpu::ApplyDesc CudaWorld::Impl::apply_desc() {
  gpu::ApplyDesc ad;
  set_body_state(ad, *this);
  ad.n = n;
  ad.offsets = index_offsets.get();
  ad.entries = index_entries.get();
  set_corrections(ad, *this);
  return ad;
}

gpu::IndexDesc CudaWorld::Impl::index_desc() {
  gpu::IndexDesc id;
  set_pair_list(id, *this);
  id.capacity = icap();
  id.n = n;
  id.w = w.get();
  id.offsets = index_offsets.get();
  id.rank = index_rank.get();
  id.entries = index_entries.get();
  id.long_list = index_long.get();
  id.long_count = &stats.get()->index_long;
  return id;
}

gpu::MetricsDesc CudaWorld::Impl::metrics_desc(const ContactParams& params) {
  gpu::MetricsDesc xd;
  set_body_state(xd, *this);
  xd.n = n;
  xd.depth0 = depth0.get();
  xd.pair_count = counts();
  xd.pair_capacity = pcap();
  xd.slop = params.slop;
  xd.out = &stats.get()->metrics;
  xd.partials = metric_partials.get();
  return xd;
}

void CudaWorld::Impl::prepare() {
  if (prepared) return;
  drop_graph();
  if (pair_cap > 0x7fffffffu || list_cap > 0x7fffffffu)
    throw RuntimeError(fmt::format("the step needs more than 2^31 - 1 pairs ({}) or midphase items ({})",
                                   pair_cap, list_cap));
  const std::size_t n1 = static_cast<std::size_t>(n) + 1;
  bp_counts.ensure(n1);
  for (BufferBase* b :
       std::initializer_list<BufferBase*>{&pair_keys, &pair_keys_sorted, &pairs, &confirmed, &corrections.hit,
                                          &corrections.dx_a, &corrections.dx_b, &corrections.dv_a, &corrections.dv_b,
                                          &depth0, &records})
    b->ensure(pair_cap);
  if (witnesses()) {
    for (BufferBase* b : std::initializer_list<BufferBase*>{&witness, &prev_keys, &prev_witness}) b->ensure(pair_cap);
    prev_begin.ensure(n1);
    prev_count.ensure(1);
    // The cache starts empty whenever the buffers may have moved (its entries are hints,
    // tested before use: an old one is harmless, a garbage count is not).
    check(cudaMemsetAsync(prev_count.get(), 0, sizeof(std::uint32_t), stream), "cudaMemset witness count");
  }
  items_a.ensure(list_cap);
  items_b.ensure(list_cap);
  if (!leaf_items.get()) {  // the fuse decision's words (MidListDesc::leaf_items), kept across regrows
    leaf_items.ensure(2);
    check(cudaMemsetAsync(leaf_items.get(), 0, 2 * sizeof(unsigned long long), stream), "cudaMemset leaf items");
  }
  if (small) {
    in_list.ensure(pair_cap);
    in_counts.ensure(n1);
  } else {
    index_offsets.ensure(n1);
    index_rank.ensure(pair_cap);
    index_entries.ensure(pair_cap);
    index_long.ensure(long_cap());
  }
  std::size_t a = 0, b = 0, c = 0;
  check(gpu::sort_keys_u64(nullptr, a, pair_keys.get(), pair_keys_sorted.get(), pcap(), 2 * gpu::key_bits(n),
                           stream),
        "cub::DeviceRadixSort::SortKeys (size)");
  check(gpu::exclusive_scan_u64(nullptr, b, index_offsets.get(), index_offsets.get(), n + 1, stream),
        "cub::DeviceScan::ExclusiveSum (size)");
  bp_counts.need_temp(c, n + 1, stream);
  temp.ensure(std::max({a, b, c, std::size_t{1}}));
  if (bp) bp->reserve(n, stream);
  prepared = true;
}

void CudaWorld::Impl::flat_broadphase() {
  const std::size_t n1 = static_cast<std::size_t>(n) + 1;
  check(cudaMemsetAsync(bp_counts.count.get(), 0, n1 * sizeof(std::uint32_t), stream),
        "cudaMemset broadphase counts");
  launched(gpu::launch_flat_count(aabb.get(), n, bp_counts.count.get(), stream), "flat_count");
  std::size_t bytes = temp.capacity();
  launched(bp_counts.scan(temp.get(), bytes, n + 1, stream), "cub::DeviceScan::ExclusiveSum");
  check(bp_counts.copy_total(counts(), n, stream), "cudaMemcpy pair total");
  launched(gpu::launch_flat_fill(aabb.get(), n, bp_counts.offset.get(), pair_keys.get(), pcap(), gpu::key_bits(n),
                                 stream),
           "flat_fill");
}

void CudaWorld::Impl::enqueue_step(const Scene& scene, bool recording, bool with_events) {
  const ContactParams& params = scene.response;
  const gpu::BodiesDesc b = bodies();
  record_event(0, with_events);
  // 1. Integrate (Eq. 1-3), keeping the state before the step for a rerun.
  gpu::BodiesDesc bi = b;
  bi.x_saved = x_saved.get();
  bi.v_saved = v_saved.get();
  launched(gpu::launch_integrate(bi, scene.gravity, scene.dt, stream), "integrate");
  record_event(1, with_events);
  // 2. World AABBs.
  launched(gpu::launch_aabbs(b, stream), "aabbs");
  record_event(2, with_events);
  // 3. Broadphase (design.md section 5.1): pair keys (padding sorts last), sorted, unpacked.
  static_assert(offsetof(gpu::StepStats, counts) ==
                        offsetof(gpu::StepStats, counters) + sizeof(gpu::StepStats::counters) &&
                    offsetof(gpu::StepStats, index_long) ==
                        offsetof(gpu::StepStats, counts) + sizeof(gpu::StepStats::counts),
                "counters, counts and index_long are contiguous");
  check(cudaMemsetAsync(counters(), 0,
                        sizeof(gpu::StepStats::counters) + sizeof(gpu::StepStats::counts) +
                            sizeof(gpu::StepStats::index_long),
                        stream),
        "cudaMemset step counts");
  // A broadphase that sorts its own keys (`octree`) writes them straight into the sorted
  // buffer (pair_keys as its scratch); nothing reads past the pairs found. Any other
  // broadphase's keys are sorted here over the whole buffer: its padding is all ones.
  const bool self_sorts = bp && bp->sorts_pairs();
  if (!self_sorts)
    check(cudaMemsetAsync(pair_keys.get(), 0xff, pair_cap * sizeof(unsigned long long), stream),
          "cudaMemset pair keys");
  if (bp) {
    gpu::PairOutput out;
    out.keys = self_sorts ? pair_keys_sorted.get() : pair_keys.get();
    out.scratch = self_sorts ? pair_keys.get() : nullptr;
    out.capacity = pcap();
    out.total = counts();
    out.candidates = counters() + 3;
    out.shift = gpu::key_bits(n);
    bp->find(aabb.get(), n, out, stream);
  } else {
    flat_broadphase();
  }
  std::size_t bytes = temp.capacity();
  // Keys are (a << key_bits(n)) | b: the sort covers 2 key_bits(n) bits (padding keys,
  // all ones, still sort after every real key: a < b < 2^key_bits(n)).
  if (!self_sorts)
    launched(gpu::sort_keys_u64(temp.get(), bytes, pair_keys.get(), pair_keys_sorted.get(), pcap(),
                                2 * gpu::key_bits(n), stream),
             "cub::DeviceRadixSort::SortKeys");
  record_event(3, with_events);  // the pairs are unpacked from the sorted keys by mid_start / mid_decide
  // 4. Midphase + narrow phase (design.md sections 5.2-5.3) as per-level work lists, or, when no pair
  // can need a level step (no mesh shape, or no level), decide: a thread per pair.
  gpu::MidListDesc md = mid_desc(pair_keys_sorted.get());
  const bool lists_needed = any_mesh && level_steps > 0;
  gpu::MidItem* lists[2] = {items_a.get(), items_b.get()};
  md.out = lists[0];
  md.out_count = counts() + 1;
  md.out_capacity = lcap();
  if (lists_needed) {
    launched(gpu::launch_mid_witness(md, pair_grid(), stream), "mid_witness");
    launched(gpu::launch_mid_start(md, warp_grid, stream), "mid_start");
  } else {
    launched(gpu::launch_mid_decide(md, pair_grid(), stream), "mid_decide");
  }
  for (int i = 0; lists_needed && i + 1 < level_steps; ++i) {
    md.in = lists[i % 2];
    md.in_count = counts() + 1 + i;
    md.in_capacity = lcap();
    md.out = lists[(i + 1) % 2];
    md.out_count = counts() + 2 + i;
    launched(gpu::launch_mid_expand(md, i, warp_grid, stream), "mid_expand");
  }
  if (lists_needed) {
    md.in = lists[(level_steps - 1) % 2];
    md.in_count = counts() + level_steps;
    md.in_capacity = lcap();
    md.out = nullptr;
    md.out_count = nullptr;
    md.out_capacity = 0;
    launched(gpu::launch_mid_leaf(md, warp_grid, stream), "mid_leaf");
    launched(gpu::launch_mid_keep(md, pair_grid(), stream), "mid_keep");
  }
  record_event(4, with_events);
  // 5. Response (design.md section 6): the contact index (response.cu) of the first icap() pairs (a
  // step with more runs again: grow_if_needed), `iterations` passes, the clamp (Eq. 23)
  // fused into the last.
  const gpu::IndexDesc id = index_desc();
  check(cudaMemsetAsync(index_offsets.get(), 0, (static_cast<std::size_t>(n) + 1) * sizeof(unsigned long long), stream),
        "cudaMemset contact index counts");
  launched(gpu::launch_index_count(id, pair_grid(), stream), "index_count");
  bytes = temp.capacity();
  launched(gpu::exclusive_scan_u64(temp.get(), bytes, index_offsets.get(), index_offsets.get(), n + 1, stream),
           "cub::DeviceScan::ExclusiveSum (contact index)");
  launched(gpu::launch_index_fill(id, pair_grid(), stream), "index_fill");
  launched(gpu::launch_index_long(id, std::max(1u, warp_grid / 4), stream), "index_long");
  gpu::TermsDesc td = terms_desc(params);
  gpu::ApplyDesc ad = apply_desc();
  for (int pass = 0; pass < params.iterations; ++pass) {
    td.depth0 = pass == 0 ? depth0.get() : nullptr;
    td.records = pass == 0 && recording ? records.get() : nullptr;
    launched(gpu::launch_contact_terms(td, pair_grid(), stream), "contact_terms");
    ad.sort_entries = pass == 0 ? 1 : 0;
    ad.clamp = pass + 1 == params.iterations ? 1 : 0;
    ad.max_velocity = params.max_velocity;
    launched(gpu::launch_apply_sums(ad, stream), "apply_sums");
  }
  if (params.iterations <= 0) launched(gpu::launch_clamp(b, params.max_velocity, stream), "clamp");
  record_event(5, with_events);
  // 6. Metrics, and everything the host reads, in one place.
  launched(gpu::launch_metrics(metrics_desc(params), stream), "metrics");
  check(cudaMemcpyAsync(host, stats.get(), sizeof(gpu::StepStats), cudaMemcpyDeviceToHost, stream),
        "cudaMemcpy step statistics");
  record_event(6, with_events);
}

void CudaWorld::Impl::run_stages(const Scene& scene, bool recording) {
  if (use_graph && !sync_each_launch && !recording) {
    // Per broadphase plan, two graphs of the same step: without events (untimed steps) and
    // with them.
    const int plan = bp ? bp->plan() : 0;
    cudaGraph_t& g = timed ? timed_graph[plan] : graph[plan];
    cudaGraphExec_t& exec = timed ? timed_graph_exec[plan] : graph_exec[plan];
    if (!exec) {
      capturing = true;
      check(cudaStreamBeginCapture(stream, cudaStreamCaptureModeThreadLocal), "cudaStreamBeginCapture");
      try {
        enqueue_step(scene, false, timed);
      } catch (...) {
        cudaGraph_t partial = nullptr;
        (void)cudaStreamEndCapture(stream, &partial);
        if (partial) (void)cudaGraphDestroy(partial);
        capturing = false;
        throw;
      }
      capturing = false;
      check(cudaStreamEndCapture(stream, &g), "cudaStreamEndCapture");
      check(cudaGraphInstantiate(&exec, g, 0), "cudaGraphInstantiate");
    }
    check(cudaGraphLaunch(exec, stream), "cudaGraphLaunch");
  } else {
    enqueue_step(scene, recording, timed);
  }
  check(cudaStreamSynchronize(stream), "cudaStreamSynchronize (step)");
}

bool CudaWorld::Impl::grow_if_needed() {
  bool grow = false;
  const std::size_t pairs_found = host->counts[0];
  if (pairs_found > pair_cap) {
    pair_cap = grown(pairs_found, pair_cap);
    grow = true;
  }
  std::size_t items = 0;
  for (int i = 0; i < level_steps; ++i) items = std::max<std::size_t>(items, host->counts[1 + i]);
  if (items > list_cap) {
    list_cap = grown(items, list_cap);
    grow = true;
  }
  // The contact index left pairs out: a larger sort, captured anew (no buffer changes).
  bool index_grown = false;
  if (!small && pairs_found > index_cap && index_cap < pair_cap) {
    index_cap = grown(pairs_found, index_cap);
    drop_graph();
    index_grown = true;
  }
  if (grow) {
    prepared = false;
    stop_resident();  // before restore_state and prepare()
  }
  return grow || index_grown;
}

bool CudaWorld::Impl::rerun_needed() {
  if (bp && !small) {
    switch (bp->settle()) {
      case gpu::Settled::Valid:
        break;
      case gpu::Settled::Rerun:
        return true;
      case gpu::Settled::Regrow:
        prepared = false;  // prepare() drops the graphs and calls bp->reserve(n)
        stop_resident();
        return true;
    }
  }
  return grow_if_needed();
}

void CudaWorld::Impl::restore_state() {
  const std::size_t vec_bytes = static_cast<std::size_t>(n) * sizeof(Vec3);
  if (n == 0) return;
  check(cudaMemcpyAsync(x.get(), x_saved.get(), vec_bytes, cudaMemcpyDeviceToDevice, stream), "cudaMemcpy restore x");
  check(cudaMemcpyAsync(v.get(), v_saved.get(), vec_bytes, cudaMemcpyDeviceToDevice, stream), "cudaMemcpy restore v");
  check(cudaStreamSynchronize(stream), "cudaStreamSynchronize (restore)");
}

}  // namespace octocd
