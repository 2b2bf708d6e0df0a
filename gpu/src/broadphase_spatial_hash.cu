// Broadphase `spatial-hash` on the device (paper section 4.2; design.md section 5.1): the uniform grid
// of cell size h of the CPU's core/src/broadphase_spatial_hash.cpp, with every cell
// decision from octocd/spatial_hash.hpp (the header the CPU uses): a body's cells
// (hash_span), cell keys packing the integer cell coordinates (hash_cell_key), sorted
// (key, body) entries, de-duplication by the cell of the intersection's min corner
// (hash_pair_cell_key), an oversize list tested against every body, NaN bodies left out.
//
// Oversize policy of the device (which bodies skip the grid). The device cannot size the
// entry array from the bodies without a host synchronisation (the DeviceBroadPhase
// contract, device_broadphase.hpp, forbids one in find()), so the entries have a fixed
// budget of E = kEntriesPerBody * n slots, allocated by reserve(n):
// - a body covering at most kSmallCells cells (any body no larger than h on every axis)
//   always gets its entries: those bodies need at most E entries in all;
// - a body covering kSmallCells + 1 .. kMaxCells cells gets its entries while they fit in
//   what the small bodies left of the budget, in body order (a prefix scan decides);
// - every other grid-able body (more than kMaxCells cells, or not admitted by the budget),
//   and every body out of cell-coordinate range or with an infinite coordinate
//   (hash_span's kHashOversize), goes to the oversize list: one warp per oversize body
//   tests it against every non-NaN body (oversize pairs once, by the smaller index).
// Each rule only moves bodies between the grid and the oversize list, and both find every
// overlapping pair a body of theirs has, so the pair set is exact whatever the policy: a
// grid pair is reported from the one cell both boxes cover at the min corner of their
// intersection, a pair with an oversize body by that body's warp. Cost: n_oversize x n
// tests; with h much smaller than the bodies most bodies become oversize and the cost
// tends to `flat`'s (as the CPU's kMaxCells policy does past 4096 cells).
//
// Steps, on one stream, no host synchronisation, no allocation:
// 1. span per body: kind (grid / oversize / NaN), its min cell (for the de-duplication),
//    its cell count into the small or the large count array (n + 1 entries each);
// 2. two exclusive scans: entry offsets of the small bodies ([0, S)) and of the large ones
//    (after S, admitted while they end within E);
// 3. entries: unused slots keep the key ~0 (sorted last); per body its (cell key, body)
//    entries at its offset; a large body that does not fit becomes oversize;
// 4. a stable radix sort of the E entries by key: every occupied cell is a run of slots;
// 5. count pass: per entry slot (one thread) the later slots of its cell (the pairs
//    sharing a cell), the de-duplication rule, then Eq. 6; per oversize body (one warp)
//    every other non-NaN body; counts at [0, E) and [E, E + n), count[E + n] = 0;
// 6. exclusive scan of the E + n + 1 counts; the total offset[E + n] is copied
//    device-to-device to *out.total; fill pass at the scanned offsets (below capacity).
// *out.candidates gets the pairs sharing a cell (before the de-duplication) plus the
// oversize tests, the quantity the CPU reports as cell_candidates (the numbers differ
// from the CPU's where the oversize lists differ).
#include "broadphase_common.cuh"
#include "broadphase_key_sort.cuh"
#include "scanned_counts.hpp"
#include "device_footprint.hpp"
#include "octocd/broadphase.hpp"
#include "octocd/spatial_hash.hpp"

namespace octocd {
namespace gpu {
namespace {

/// Bodies covering at most this many cells always get grid entries.
constexpr std::uint32_t kSmallCells = 8;
/// Entry budget per body: E = kEntriesPerBody * n (>= kSmallCells, so small bodies fit);
/// from device_footprint.hpp, which the host memory estimate reads too.
constexpr std::uint32_t kEntriesPerBody = footprint::kHashEntriesPerBody;
static_assert(kEntriesPerBody >= kSmallCells, "small bodies always get their entries");
/// Bodies covering more cells than this are oversize (the CPU's kMaxCells is 4096; one
/// device thread writes a body's entries, so the device keeps this small).
constexpr std::int64_t kMaxCells = 64;
/// Key of an unused entry slot: after every cell key (those have 63 bits).
constexpr unsigned long long kUnusedKey = ~0ull;

static_assert(kEntriesPerBody >= kSmallCells, "the budget must hold every small body");

/// What the spatial-hash kernels read and write (device pointers): FindDesc's boxes, bodies
/// and pair output (keys, capacity, candidates), and:
struct HashDesc : bp::FindDesc {
  double inv_h = 0.0;                     ///< 1 / h (1/m), hash_inv_cell_size
  std::uint32_t entries = 0;              ///< E, the entry budget
  std::uint8_t* kind = nullptr;           ///< per body: HashKind (after step 3: final)
  std::int32_t* cell0 = nullptr;          ///< per body, 3 ints: min cell (grid bodies)
  std::uint32_t* small_cells = nullptr;   ///< n + 1: cells of bodies with <= kSmallCells, else 0
  std::uint32_t* large_cells = nullptr;   ///< n + 1: cells of bodies with > kSmallCells (grid), else 0
  const std::uint32_t* small_off = nullptr;  ///< n + 1: exclusive scan of small_cells
  const std::uint32_t* large_off = nullptr;  ///< n + 1: exclusive scan of large_cells
  unsigned long long* key = nullptr;      ///< E: entry cell keys (kUnusedKey: unused)
  std::uint32_t* body = nullptr;          ///< E: entry bodies
  const unsigned long long* sorted_key = nullptr;  ///< E: keys, ascending
  const std::uint32_t* slot_body = nullptr;        ///< E: bodies, in the sorted order
  std::uint32_t* count = nullptr;         ///< E + n + 1: pairs per entry slot, per oversize body, 0
  const std::uint32_t* offset = nullptr;  ///< E + n + 1: exclusive scan of count
};

__global__ void hash_span_kernel(HashDesc d) {
  const std::uint32_t i = blockIdx.x * blockDim.x + threadIdx.x;
  if (i == 0) {
    d.small_cells[d.n] = 0;
    d.large_cells[d.n] = 0;
  }
  if (i >= d.n) return;
  const HashSpan s = hash_span(d.aabb[i], d.inv_h, kMaxCells);
  d.kind[i] = s.kind;
  d.cell0[3 * i + 0] = s.c0[0];
  d.cell0[3 * i + 1] = s.c0[1];
  d.cell0[3 * i + 2] = s.c0[2];
  const bool grid = s.kind == kHashGrid;
  d.small_cells[i] = grid && s.cells <= kSmallCells ? s.cells : 0u;
  d.large_cells[i] = grid && s.cells > kSmallCells ? s.cells : 0u;
}

__global__ void hash_entries_kernel(HashDesc d) {
  const std::uint32_t i = blockIdx.x * blockDim.x + threadIdx.x;
  if (i >= d.n || d.kind[i] != kHashGrid) return;
  const HashSpan s = hash_span(d.aabb[i], d.inv_h, kMaxCells);  // the same span as step 1
  std::uint64_t at;
  if (s.cells <= kSmallCells) {
    at = d.small_off[i];
  } else {
    at = static_cast<std::uint64_t>(d.small_off[d.n]) + d.large_off[i];
    if (at + s.cells > d.entries) {  // out of budget: oversize
      d.kind[i] = kHashOversize;
      return;
    }
  }
  for (std::int64_t x = s.c0[0]; x <= s.c1[0]; ++x) {
    for (std::int64_t y = s.c0[1]; y <= s.c1[1]; ++y) {
      for (std::int64_t z = s.c0[2]; z <= s.c1[2]; ++z) {
        d.key[at] = hash_cell_key(x, y, z);
        d.body[at] = i;
        ++at;
      }
    }
  }
}

/// One thread per entry slot: the later slots of its cell; a pair is reported from the
/// cell of its intersection's min corner only, after Eq. 6.
template <bool kFill>
__global__ void hash_cell_query_kernel(HashDesc d) {
  const std::uint32_t e = blockIdx.x * blockDim.x + threadIdx.x;
  unsigned long long tests = 0;
  if (e < d.entries) {
    const unsigned long long key = d.sorted_key[e];
    std::uint32_t found = 0;
    if (key != kUnusedKey) {
      const std::uint32_t p = d.slot_body[e];
      const Aabb bp = d.aabb[p];
      const std::int32_t* cp = d.cell0 + 3 * static_cast<std::size_t>(p);
      const std::uint32_t base = kFill ? d.offset[e] : 0u;
      for (std::uint32_t j = e + 1; j < d.entries && d.sorted_key[j] == key; ++j) {
        ++tests;
        const std::uint32_t q = d.slot_body[j];
        if (hash_pair_cell_key(cp, d.cell0 + 3 * static_cast<std::size_t>(q)) != key) continue;
        if (!overlaps(bp, d.aabb[q])) continue;
        if (kFill) {
          const unsigned long long pos = static_cast<unsigned long long>(base) + found;
          if (pos < d.out.capacity) d.out.keys[pos] = bp::pair_key(p, q, d.out.shift);
        }
        ++found;
      }
    }
    if (!kFill) d.count[e] = found;
  }
  if (!kFill) bp::block_add(d.out.candidates, tests);
}

/// One warp per body: an oversize body against every other non-NaN body (two oversize
/// bodies: by the smaller index).
template <bool kFill>
__global__ void hash_oversize_query_kernel(HashDesc d) {
  bp::warp_query<kFill>(d.n, d.entries, d.out, d.offset, d.count,
                        [&](std::uint32_t p, unsigned lane, bp::WarpWriter& w, unsigned long long& tests) {
    if (d.kind[p] == kHashOversize) {
      const Aabb bp_box = d.aabb[p];
      for (std::uint32_t q0 = 0; q0 < d.n; q0 += bp::kWarpSize) {
        const std::uint32_t q = q0 + lane;
        bool hit = false;
        if (q < d.n && q != p) {
          const std::uint8_t kq = d.kind[q];
          if (kq != kHashSkip && !(kq == kHashOversize && q < p)) {
            ++tests;
            hit = overlaps(bp_box, d.aabb[q]);
          }
        }
        w.round(hit, hit ? bp::pair_key(p, q, d.out.shift) : 0ull);
      }
    }
  });
}

class SpatialHashDevice final : public DeviceBroadPhase {
 public:
  explicit SpatialHashDevice(float cell_size) : inv_h_(hash_inv_cell_size(cell_size)) {}

  std::string name() const override { return broadphase_name(BroadPhaseId::spatial_hash); }

  void reserve(std::uint32_t n, cudaStream_t stream) override {
    const std::size_t entries = static_cast<std::size_t>(kEntriesPerBody) * n;
    const std::size_t counts = entries + n + 1;
    // 32-bit offsets: the counts (E + n + 1) and the large bodies' cells (<= kMaxCells n).
    if (counts > 0xffffffffu || static_cast<std::uint64_t>(kMaxCells) * n > 0xffffffffu)
      throw RuntimeError(fmt::format("device broadphase '{}': {} bodies are more than its 32-bit "
                                     "entry offsets hold (at most {})",
                                     name(), n, 0xffffffffu / static_cast<std::uint32_t>(kMaxCells)));
    const std::size_t n1 = static_cast<std::size_t>(n) + 1;
    kind_.ensure(n);
    cell0_.ensure(3 * static_cast<std::size_t>(n));
    small_.ensure(n1);
    large_.ensure(n1);
    sort_.ensure(entries, false);
    pairs_.ensure(counts);
    std::size_t bytes = 0;
    sort_.need_temp(bytes, static_cast<std::uint32_t>(entries), 64, stream);
    pairs_.need_temp(bytes, static_cast<std::uint32_t>(counts), stream);
    small_.need_temp(bytes, static_cast<std::uint32_t>(n1), stream);  // large_ scans as many
    temp_.ensure(bytes);
    reserved_ = true;
    reserved_n_ = n;
  }

  void find(const Aabb* aabb, std::uint32_t n, const PairOutput& out, cudaStream_t stream) override {
    if (!bp::start_find(reserved_, reserved_n_, n, broadphase_name(BroadPhaseId::spatial_hash), out, stream)) return;
    const std::uint32_t entries = kEntriesPerBody * n;
    const std::uint32_t counts = entries + n + 1;
    HashDesc d;
    d.set_find(aabb, n, out);
    d.inv_h = inv_h_;
    d.entries = entries;
    d.kind = kind_.get();
    d.cell0 = cell0_.get();
    d.small_cells = small_.count.get();
    d.large_cells = large_.count.get();
    d.small_off = small_.offset.get();
    d.large_off = large_.offset.get();
    sort_.set(d);
    d.count = pairs_.count.get();
    d.offset = pairs_.offset.get();

    hash_span_kernel<<<grid_for(n), kBlockSize, 0, stream>>>(d);
    bp::launched(cudaGetLastError(), "hash_span");
    std::size_t bytes = temp_.capacity();
    bp::launched(small_.scan(temp_.get(), bytes, n + 1, stream), "cub::DeviceScan::ExclusiveSum");
    bytes = temp_.capacity();
    bp::launched(large_.scan(temp_.get(), bytes, n + 1, stream), "cub::DeviceScan::ExclusiveSum");
    // Unused slots: key ~0 (sorted last, skipped), body ~0 (never read).
    check(cudaMemsetAsync(sort_.key.get(), 0xff, entries * sizeof(unsigned long long), stream), "cudaMemset hash keys");
    check(cudaMemsetAsync(sort_.body.get(), 0xff, entries * sizeof(std::uint32_t), stream), "cudaMemset hash bodies");
    hash_entries_kernel<<<grid_for(n), kBlockSize, 0, stream>>>(d);
    bp::launched(cudaGetLastError(), "hash_entries");
    bytes = temp_.capacity();
    bp::launched(sort_.sort(temp_.get(), bytes, entries, 64, stream), "cub::DeviceRadixSort::SortPairs");
    check(cudaMemsetAsync(pairs_.count.get() + entries + n, 0, sizeof(std::uint32_t), stream),
          "cudaMemset hash counts");
    hash_cell_query_kernel<false><<<grid_for(entries), kBlockSize, 0, stream>>>(d);
    bp::launched(cudaGetLastError(), "hash_cell_query (count)");
    hash_oversize_query_kernel<false><<<bp::warp_grid_for(n), kBlockSize, 0, stream>>>(d);
    bp::launched(cudaGetLastError(), "hash_oversize_query (count)");
    bytes = temp_.capacity();
    bp::launched(pairs_.scan(temp_.get(), bytes, counts, stream), "cub::DeviceScan::ExclusiveSum");
    check(pairs_.copy_total(out.total, entries + n, stream), "cudaMemcpy pair total");
    hash_cell_query_kernel<true><<<grid_for(entries), kBlockSize, 0, stream>>>(d);
    bp::launched(cudaGetLastError(), "hash_cell_query (fill)");
    hash_oversize_query_kernel<true><<<bp::warp_grid_for(n), kBlockSize, 0, stream>>>(d);
    bp::launched(cudaGetLastError(), "hash_oversize_query (fill)");
  }

  std::uint64_t device_bytes() const override {
    return sort_.bytes() + small_.bytes() + large_.bytes() + pairs_.bytes() + total_bytes({&kind_, &cell0_, &temp_});
  }

 private:
  double inv_h_;
  bool reserved_ = false;
  std::uint32_t reserved_n_ = 0;
  DeviceBuffer<std::uint8_t> kind_{"spatial-hash body kinds"};
  DeviceBuffer<std::int32_t> cell0_{"spatial-hash body min cells"};
  ScannedCounts small_{"spatial-hash small-body cell counts", "spatial-hash small-body entry offsets"};
  ScannedCounts large_{"spatial-hash large-body cell counts", "spatial-hash large-body entry offsets"};
  bp::KeySortBuffers<unsigned long long> sort_{"spatial-hash entry keys", "spatial-hash entry bodies",
                                               "spatial-hash sorted entry keys", "spatial-hash sorted entry bodies",
                                               "spatial-hash slot boxes (unused)"};
  ScannedCounts pairs_{"spatial-hash pair counts", "spatial-hash pair offsets"};
  DeviceBuffer<unsigned char> temp_{"spatial-hash CUB temporary storage"};
};

}  // namespace

std::unique_ptr<DeviceBroadPhase> make_device_spatial_hash(const BroadPhaseConfig& config) {
  check_broadphase_parameters(config);  // the checks of make_broadphase (same errors)
  return std::make_unique<SpatialHashDevice>(config.cell_size);
}

std::unique_ptr<DeviceBroadPhase> make_device_broadphase_spatial_hash(const BroadPhaseConfig& config, const Aabb&,
                                                                      DeviceUse) {
  return make_device_spatial_hash(config);
}

}  // namespace gpu
}  // namespace octocd
