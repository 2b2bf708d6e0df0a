// The CUDA engine's orchestration (SPEC 11): device buffers, the shapes' packed octrees,
// the step's stages in World::step's order, stage timing with CUDA events, recording and
// errors. The kernels are in the stage files (*.cu, through kernels.hpp); this file holds
// no float formula of the step.
#include "octocd/cuda_world.hpp"

#include <algorithm>
#include <chrono>
#include <cstdlib>
#include <cstring>
#include <initializer_list>
#include <utility>

#include <cuda_runtime_api.h>
#include <fmt/format.h>

#include "kernels.hpp"
#include "octocd/error.hpp"

namespace octocd {

namespace {

using Clock = std::chrono::steady_clock;

double ms_since(Clock::time_point t0) {
  return std::chrono::duration<double, std::milli>(Clock::now() - t0).count();
}

std::string cuda_text(cudaError_t e) { return fmt::format("{} ({})", cudaGetErrorString(e), cudaGetErrorName(e)); }

/// Throws RuntimeError naming `what` when a CUDA runtime call failed.
void check(cudaError_t e, const char* what) {
  if (e != cudaSuccess) {
    (void)cudaGetLastError();  // clear a non-sticky error
    throw RuntimeError(fmt::format("CUDA error in {}: {}", what, cuda_text(e)));
  }
}

/// The reason no device is usable, or "" when one is.
std::string no_device_reason() {
  int count = 0;
  const cudaError_t e = cudaGetDeviceCount(&count);
  if (e != cudaSuccess) {
    (void)cudaGetLastError();
    return fmt::format("cudaGetDeviceCount failed: {}", cuda_text(e));
  }
  if (count == 0) return "cudaGetDeviceCount found 0 devices";
  return "";
}

std::string describe_current_device() {
  int dev = 0;
  check(cudaGetDevice(&dev), "cudaGetDevice");
  cudaDeviceProp p{};
  check(cudaGetDeviceProperties(&p, dev), "cudaGetDeviceProperties");
  return fmt::format("{} (device {}, sm_{}{}, {:.1f} GiB)", p.name, dev, p.major, p.minor,
                     static_cast<double>(p.totalGlobalMem) / (1024.0 * 1024.0 * 1024.0));
}

/// An untyped device allocation with a name (for errors) and a capacity in elements.
class BufferBase {
 public:
  BufferBase(const char* name, std::size_t elem_size) : name_(name), elem_size_(elem_size) {}
  virtual ~BufferBase() { release(); }
  BufferBase(const BufferBase&) = delete;
  BufferBase& operator=(const BufferBase&) = delete;

  /// Makes room for `count` elements (contents are lost when it grows): grows to
  /// max(count, 2 x capacity) so a growing scene reallocates rarely.
  void ensure(std::size_t count) {
    if (count <= cap_ && ptr_) return;
    allocate(std::max(count, 2 * cap_));
  }
  /// Frees the buffer and allocates exactly `count` elements (>= 1).
  void reset(std::size_t count) { allocate(std::max<std::size_t>(count, 1)); }
  std::size_t capacity() const { return cap_; }
  std::uint64_t bytes() const { return static_cast<std::uint64_t>(cap_) * elem_size_; }
  const char* name() const { return name_; }

 protected:
  void* ptr_ = nullptr;

 private:
  void allocate(std::size_t count) {
    release();
    count = std::max<std::size_t>(count, 1);
    const std::size_t bytes = count * elem_size_;
    void* p = nullptr;
    const cudaError_t e = cudaMalloc(&p, bytes);
    if (e != cudaSuccess) {
      (void)cudaGetLastError();
      throw RuntimeError(fmt::format("out of device memory: cudaMalloc of {} bytes ({:.1f} MiB) for the "
                                     "buffer '{}' failed: {}",
                                     bytes, static_cast<double>(bytes) / (1024.0 * 1024.0), name_, cuda_text(e)));
    }
    ptr_ = p;
    cap_ = count;
  }
  void release() {
    if (ptr_) (void)cudaFree(ptr_);
    ptr_ = nullptr;
    cap_ = 0;
  }

  const char* name_;
  std::size_t elem_size_;
  std::size_t cap_ = 0;
};

template <class T>
class DeviceBuffer : public BufferBase {
 public:
  explicit DeviceBuffer(const char* name) : BufferBase(name, sizeof(T)) {}
  T* get() const { return static_cast<T*>(ptr_); }
};

/// Copies a host vector into a device buffer on `stream` and waits for it. With
/// `allocate`, the buffer is first reallocated to the vector's size.
template <class T>
void upload(DeviceBuffer<T>& buf, const std::vector<T>& host, cudaStream_t stream, bool allocate = true) {
  if (allocate) buf.reset(host.size());
  if (host.empty()) return;
  check(cudaMemcpyAsync(buf.get(), host.data(), host.size() * sizeof(T), cudaMemcpyHostToDevice, stream),
        fmt::format("cudaMemcpy to '{}'", buf.name()).c_str());
  check(cudaStreamSynchronize(stream), "cudaStreamSynchronize");
}

template <class T>
void download(std::vector<T>& host, const DeviceBuffer<T>& buf, std::size_t count, cudaStream_t stream) {
  host.resize(count);
  if (count == 0) return;
  check(cudaMemcpyAsync(host.data(), buf.get(), count * sizeof(T), cudaMemcpyDeviceToHost, stream),
        fmt::format("cudaMemcpy from '{}'", buf.name()).c_str());
  check(cudaStreamSynchronize(stream), "cudaStreamSynchronize");
}

/// Bits needed to hold every key in [0, n] (the sort's end_bit), at least 1.
int key_bits(std::uint32_t n) {
  int bits = 1;
  while (bits < 32 && (n >> bits) != 0) ++bits;
  return bits;
}

constexpr int kEvents = static_cast<int>(Stage::Count) + 1;

/// Most bytes the per-pair narrow-phase scratch may take.
constexpr std::size_t kLeafScratchBudget = std::size_t{512} << 20;

}  // namespace

// ---- device state ----------------------------------------------------------------------

struct CudaWorld::Impl {
  cudaStream_t stream = nullptr;
  cudaEvent_t events[kEvents] = {};
  bool sync_each_launch = false;  // OCTOCD_CUDA_SYNC=1
  std::string device;
  std::string broadphase;
  std::uint32_t n = 0;
  std::uint32_t shape_count = 0;
  hd::LevelList levels;
  std::uint32_t leaf_max = 0;  // most vertices in a narrow-phase cell of any mesh
  std::uint64_t static_static = 0;  // static_static_pairs(model): constant over the run

  // Bodies (fixed size n).
  DeviceBuffer<Vec3> x{"body positions"};
  DeviceBuffer<Vec3> v{"body velocities"};
  DeviceBuffer<float> w{"body inverse masses"};
  DeviceBuffer<Aabb> local{"body local boxes"};
  DeviceBuffer<std::uint32_t> shape{"body shapes"};
  DeviceBuffer<Aabb> aabb{"world AABBs"};
  // Shapes, packed once.
  DeviceBuffer<gpu::DeviceShape> shapes{"shapes"};
  DeviceBuffer<Vec3> vertices{"octree vertices"};
  DeviceBuffer<MeshOctreeCell> cells{"octree cells"};
  DeviceBuffer<std::uint32_t> level_offsets{"octree level offsets"};
  DeviceBuffer<float> theta{"theta table"};
  /// box tests, box pairs, vertex tests (midphase), exact AABB tests (octree broadphase)
  DeviceBuffer<unsigned long long> counters{"counters"};
  DeviceBuffer<gpu::MetricsResult> metrics{"metrics"};
  // Scratch, grown on demand (reset_capacities shrinks these).
  DeviceBuffer<std::uint32_t> bp_count{"broadphase counts"};
  DeviceBuffer<std::uint32_t> bp_offset{"broadphase offsets"};
  DeviceBuffer<Pair> pairs{"candidate pairs"};
  DeviceBuffer<std::uint8_t> confirmed{"confirmed flags"};
  DeviceBuffer<Vec3> leaf_scratch{"narrow-phase scratch"};
  DeviceBuffer<std::uint8_t> hit{"contact hit flags"};
  DeviceBuffer<Vec3> dx_a{"contact dx_a"};
  DeviceBuffer<Vec3> dx_b{"contact dx_b"};
  DeviceBuffer<Vec3> dv_a{"contact dv_a"};
  DeviceBuffer<Vec3> dv_b{"contact dv_b"};
  DeviceBuffer<float> depth0{"contact depths"};
  DeviceBuffer<gpu::DeviceContact> records{"contact records"};
  DeviceBuffer<std::uint32_t> keys_in{"contact index keys"};
  DeviceBuffer<std::uint32_t> keys_out{"sorted contact index keys"};
  DeviceBuffer<std::uint32_t> vals_in{"contact index entries"};
  DeviceBuffer<std::uint32_t> vals_out{"sorted contact index entries"};
  DeviceBuffer<std::uint32_t> body_begin{"body contact segments"};
  DeviceBuffer<unsigned char> temp{"CUB temporary storage"};
  // Loose octree broadphase (broadphase_octree.cu).
  DeviceBuffer<float> loose_extent{"octree body extents"};
  DeviceBuffer<float> loose_min{"octree smallest extent"};
  DeviceBuffer<std::uint32_t> loose_key{"octree body keys"};
  DeviceBuffer<std::uint32_t> loose_body{"octree body indices"};
  DeviceBuffer<gpu::LooseQBox> loose_q{"octree body unit boxes"};
  DeviceBuffer<std::uint32_t> loose_sorted_key{"octree sorted keys"};
  DeviceBuffer<std::uint32_t> loose_slot_body{"octree slot bodies"};
  DeviceBuffer<Aabb> loose_slot_box{"octree slot boxes"};
  DeviceBuffer<gpu::LooseQBox> loose_slot_q{"octree slot unit boxes"};
  DeviceBuffer<unsigned long long> pair_keys{"octree pair keys"};
  DeviceBuffer<unsigned long long> pair_keys_sorted{"octree sorted pair keys"};

  std::uint32_t pair_count = 0;  // candidate pairs of the last step

  ~Impl() {
    for (cudaEvent_t& e : events)
      if (e) (void)cudaEventDestroy(e);
    if (stream) (void)cudaStreamDestroy(stream);
  }

  std::vector<BufferBase*> all_buffers() {
    return {&x, &v, &w, &local, &shape, &aabb, &shapes, &vertices, &cells, &level_offsets, &theta, &counters,
            &metrics, &bp_count, &bp_offset, &pairs, &confirmed, &leaf_scratch, &hit, &dx_a, &dx_b, &dv_a, &dv_b, &depth0,
            &records, &keys_in, &keys_out, &vals_in, &vals_out, &body_begin, &temp, &loose_extent, &loose_min,
            &loose_key, &loose_body, &loose_q, &loose_sorted_key, &loose_slot_body, &loose_slot_box,
            &loose_slot_q, &pair_keys, &pair_keys_sorted};
  }
  std::vector<BufferBase*> scratch_buffers() {
    return {&bp_count, &bp_offset, &pairs,   &confirmed, &leaf_scratch, &hit,     &dx_a,     &dx_b,       &dv_a,
            &dv_b,     &depth0,    &records, &keys_in,   &keys_out,     &vals_in, &vals_out, &body_begin, &temp,
            &loose_extent, &loose_min, &loose_key, &loose_body, &loose_q, &loose_sorted_key, &loose_slot_body,
            &loose_slot_box, &loose_slot_q, &pair_keys, &pair_keys_sorted};
  }

  /// Checks a launch; with OCTOCD_CUDA_SYNC=1 also waits for it and checks its execution.
  void launched(cudaError_t e, const char* kernel) {
    if (e != cudaSuccess) {
      (void)cudaGetLastError();
      throw RuntimeError(fmt::format("CUDA kernel '{}' failed to launch: {}", kernel, cuda_text(e)));
    }
    if (sync_each_launch) {
      e = cudaStreamSynchronize(stream);
      if (e != cudaSuccess) throw RuntimeError(fmt::format("CUDA kernel '{}' failed: {}", kernel, cuda_text(e)));
    }
  }

  void record_event(int i) { check(cudaEventRecord(events[i], stream), "cudaEventRecord"); }

  gpu::BodiesDesc bodies() {
    gpu::BodiesDesc b;
    b.x = x.get();
    b.v = v.get();
    b.w = w.get();
    b.local = local.get();
    b.shape = shape.get();
    b.aabb = aabb.get();
    b.n = n;
    return b;
  }

  gpu::ShapesDesc shapes_desc() {
    gpu::ShapesDesc s;
    s.shapes = shapes.get();
    s.vertices = vertices.get();
    s.cells = cells.get();
    s.level_offsets = level_offsets.get();
    s.theta = theta.get();
    s.count = shape_count;
    return s;
  }

  /// Exclusive scan through CUB, growing the temporary storage as asked.
  void scan(const std::uint32_t* in, std::uint32_t* out, std::uint32_t count) {
    std::size_t bytes = 0;
    check(gpu::exclusive_scan_u32(nullptr, bytes, in, out, count, stream), "cub::DeviceScan::ExclusiveSum (size)");
    temp.ensure(bytes);
    bytes = temp.capacity();
    launched(gpu::exclusive_scan_u32(temp.get(), bytes, in, out, count, stream), "cub::DeviceScan::ExclusiveSum");
  }

  /// Stable radix sort of (key, value) pairs through CUB.
  void sort(const std::uint32_t* kin, std::uint32_t* kout, const std::uint32_t* vin, std::uint32_t* vout,
            std::uint32_t count, int end_bit) {
    std::size_t bytes = 0;
    check(gpu::sort_pairs_u32(nullptr, bytes, kin, kout, vin, vout, count, end_bit, stream),
          "cub::DeviceRadixSort::SortPairs (size)");
    temp.ensure(bytes);
    bytes = temp.capacity();
    launched(gpu::sort_pairs_u32(temp.get(), bytes, kin, kout, vin, vout, count, end_bit, stream),
             "cub::DeviceRadixSort::SortPairs");
  }

  void sort_keys(const unsigned long long* kin, unsigned long long* kout, std::uint32_t count, int end_bit) {
    std::size_t bytes = 0;
    check(gpu::sort_keys_u64(nullptr, bytes, kin, kout, count, end_bit, stream),
          "cub::DeviceRadixSort::SortKeys (size)");
    temp.ensure(bytes);
    bytes = temp.capacity();
    launched(gpu::sort_keys_u64(temp.get(), bytes, kin, kout, count, end_bit, stream),
             "cub::DeviceRadixSort::SortKeys");
  }

  void min(const float* in, float* out, std::uint32_t count) {
    std::size_t bytes = 0;
    check(gpu::min_f32(nullptr, bytes, in, out, count, stream), "cub::DeviceReduce::Min (size)");
    temp.ensure(bytes);
    bytes = temp.capacity();
    launched(gpu::min_f32(temp.get(), bytes, in, out, count, stream), "cub::DeviceReduce::Min");
  }

  /// Reads the scanned total at offset[count] (one synchronisation) and returns it.
  std::uint32_t read_total(const std::uint32_t* offset, std::uint32_t count, const char* what) {
    std::uint32_t total = 0;
    check(cudaMemcpyAsync(&total, offset + count, sizeof(total), cudaMemcpyDeviceToHost, stream), what);
    check(cudaStreamSynchronize(stream), what);
    return total;
  }

  /// Broadphase `flat` (SPEC 5.1): count, exclusive scan over n + 1 (the last count is 0,
  /// so offset[n] is the total), size the output, fill. The output is sorted by (a, b).
  std::uint32_t flat_broadphase() {
    const std::size_t n1 = static_cast<std::size_t>(n) + 1;
    bp_count.ensure(n1);
    bp_offset.ensure(n1);
    check(cudaMemsetAsync(bp_count.get(), 0, n1 * sizeof(std::uint32_t), stream), "cudaMemset broadphase counts");
    launched(gpu::launch_flat_count(aabb.get(), n, bp_count.get(), stream), "flat_count");
    scan(bp_count.get(), bp_offset.get(), n + 1);
    const std::uint32_t np = read_total(bp_offset.get(), n, "pair count");
    pairs.ensure(np);
    launched(gpu::launch_flat_fill(aabb.get(), n, bp_offset.get(), pairs.get(), stream), "flat_fill");
    return np;
  }

  /// Broadphase `octree` (SPEC 5.1, loose; broadphase_octree.cu): keys, stable sort by
  /// key, per-slot query counted, scanned, sized and filled, then the pair keys sorted.
  std::uint32_t octree_broadphase(const Aabb& domain, int depth) {
    const std::size_t n1 = static_cast<std::size_t>(n) + 1;
    for (BufferBase* b : std::initializer_list<BufferBase*>{&loose_extent, &loose_key, &loose_body, &loose_q,
                                                             &loose_sorted_key, &loose_slot_body, &loose_slot_box,
                                                             &loose_slot_q})
      b->ensure(n);
    loose_min.ensure(1);
    bp_count.ensure(n1);
    bp_offset.ensure(n1);
    gpu::LooseDesc ld;
    ld.aabb = aabb.get();
    ld.n = n;
    ld.grid = loose_grid(domain);
    ld.depth = depth;
    ld.extent = loose_extent.get();
    ld.min_extent = loose_min.get();
    ld.key = loose_key.get();
    ld.body = loose_body.get();
    ld.q = loose_q.get();
    ld.sorted_key = loose_sorted_key.get();
    ld.slot_body = loose_slot_body.get();
    ld.slot_box = loose_slot_box.get();
    ld.slot_q = loose_slot_q.get();
    ld.count = bp_count.get();
    ld.offset = bp_offset.get();
    ld.candidates = counters.get() + 3;
    if (n == 0) return 0;
    if (depth < 0) {
      launched(gpu::launch_loose_extent(ld, stream), "loose_extent");
      min(loose_extent.get(), loose_min.get(), n);
    }
    launched(gpu::launch_loose_keys(ld, stream), "loose_keys");
    sort(loose_key.get(), loose_sorted_key.get(), loose_body.get(), loose_slot_body.get(), n, 32);
    launched(gpu::launch_loose_gather(ld, stream), "loose_gather");
    check(cudaMemsetAsync(bp_count.get(), 0, n1 * sizeof(std::uint32_t), stream), "cudaMemset broadphase counts");
    launched(gpu::launch_loose_query(ld, false, stream), "loose_query (count)");
    scan(bp_count.get(), bp_offset.get(), n + 1);
    const std::uint32_t np = read_total(bp_offset.get(), n, "pair count");
    pair_keys.ensure(np);
    pair_keys_sorted.ensure(np);
    pairs.ensure(np);
    ld.pair_keys = pair_keys.get();
    launched(gpu::launch_loose_query(ld, true, stream), "loose_query (fill)");
    if (np > 0) {
      sort_keys(pair_keys.get(), pair_keys_sorted.get(), np, 32 + key_bits(n));
      launched(gpu::launch_unpack_pairs(pair_keys_sorted.get(), np, pairs.get(), stream), "unpack_pairs");
    }
    return np;
  }
};

// ---- free functions ----------------------------------------------------------------------

std::string cuda_device_status() {
  try {
    const std::string reason = no_device_reason();
    if (!reason.empty()) return "no CUDA device: " + reason;
    return describe_current_device();
  } catch (const std::exception& e) {
    return std::string("no CUDA device: ") + e.what();
  }
}

bool cuda_device_available() { return no_device_reason().empty(); }

std::unique_ptr<Engine> make_cuda_engine(std::shared_ptr<const Model> model, const std::string& broadphase) {
  return std::make_unique<CudaWorld>(std::move(model), broadphase);
}

// ---- CudaWorld ---------------------------------------------------------------------------

CudaWorld::CudaWorld(std::shared_ptr<const Model> model, const std::string& broadphase)
    : model_(std::move(model)), impl_(std::make_unique<Impl>()) {
  if (!model_) throw InputError("CudaWorld: no model given");
  if (broadphase != "flat" && broadphase != "octree")
    throw InputError(fmt::format("broadphase.name: '{}' is not available on the cuda engine yet (available "
                                 "there: flat, octree)",
                                 broadphase));
  const std::string reason = no_device_reason();
  if (!reason.empty()) throw RuntimeError("no CUDA device: " + reason + "; the cuda engine needs one");

  Impl& d = *impl_;
  d.broadphase = broadphase;
  d.device = describe_current_device();
  const char* sync = std::getenv("OCTOCD_CUDA_SYNC");
  d.sync_each_launch = sync != nullptr && std::strcmp(sync, "1") == 0;
  check(cudaStreamCreateWithFlags(&d.stream, cudaStreamNonBlocking), "cudaStreamCreate");
  for (cudaEvent_t& e : d.events) check(cudaEventCreate(&e), "cudaEventCreate");

  const Model& m = *model_;
  const std::size_t n = m.initial.size();
  if (n > 0x7fffffffu) throw InputError("the cuda engine takes at most 2^31 - 1 bodies");
  d.n = static_cast<std::uint32_t>(n);

  // Midphase level list (SPEC 5.2), as the CPU's confirm_contact converts it.
  const MidphaseConfig& mc = m.scene.midphase;
  d.levels.aabb_only = mc.aabb_only;
  d.levels.count = static_cast<int>(std::min<std::size_t>(mc.levels.size(), hd::kMidphaseMaxLevels));
  for (int i = 0; i < d.levels.count; ++i) d.levels.levels[i] = mc.levels[static_cast<std::size_t>(i)];

  // Shapes: every octree packed once.
  std::vector<gpu::DeviceShape> shapes;
  std::vector<Vec3> vertices;
  std::vector<MeshOctreeCell> cells;
  std::vector<std::uint32_t> level_offsets;
  for (const Shape& s : m.shapes) {
    gpu::DeviceShape ds;
    ds.bounds = s.local;
    if (s.octree) {
      const MeshOctree& t = *s.octree;
      ds.is_mesh = 1;
      ds.depth = t.depth;
      ds.bounds = t.bounds;
      ds.vertex_offset = static_cast<std::uint32_t>(vertices.size());
      ds.vertex_count = static_cast<std::uint32_t>(t.vertices.size());
      ds.cell_offset = static_cast<std::uint32_t>(cells.size());
      ds.level_offset_offset = static_cast<std::uint32_t>(level_offsets.size());
      vertices.insert(vertices.end(), t.vertices.begin(), t.vertices.end());
      cells.insert(cells.end(), t.cells.begin(), t.cells.end());
      level_offsets.insert(level_offsets.end(), t.level_offset.begin(), t.level_offset.end());
      // Largest cell at the level the narrow phase runs on (the last level, clamped).
      if (!mc.aabb_only && !mc.levels.empty()) {
        const int leaf = std::min(mc.levels.back(), t.depth);
        for (std::uint32_t c = t.level_begin(leaf); c < t.level_end(leaf); ++c)
          d.leaf_max = std::max(d.leaf_max, t.cells[c].vertex_count);
      }
    }
    shapes.push_back(ds);
  }
  d.shape_count = static_cast<std::uint32_t>(shapes.size());
  upload(d.shapes, shapes, d.stream);
  upload(d.vertices, vertices, d.stream);
  upload(d.cells, cells, d.stream);
  upload(d.level_offsets, level_offsets, d.stream);
  upload(d.theta, m.theta_table, d.stream);

  // Bodies.
  std::vector<Aabb> local(n);
  std::vector<std::uint32_t> shape(n);
  for (std::size_t i = 0; i < n; ++i) {
    local[i] = m.local_box(i);
    shape[i] = m.bodies[i].shape;
  }
  upload(d.local, local, d.stream);
  upload(d.shape, shape, d.stream);
  upload(d.x, m.initial.x, d.stream);
  upload(d.v, m.initial.v, d.stream);
  upload(d.w, m.initial.w, d.stream);
  d.aabb.reset(n);
  d.counters.reset(4);
  d.metrics.reset(1);
  d.static_static = static_static_pairs(m);
  reset_capacities(1);
  d.launched(gpu::launch_aabbs(d.bodies(), d.stream), "aabbs");
  check(cudaStreamSynchronize(d.stream), "cudaStreamSynchronize");
  state_ = m.initial;
  state_frame_ = 0;
}

CudaWorld::~CudaWorld() = default;

std::string CudaWorld::device() const { return impl_->device; }

std::string CudaWorld::broadphase_name() const { return impl_->broadphase; }

std::uint64_t CudaWorld::device_bytes() const {
  std::uint64_t total = 0;
  for (const BufferBase* b : impl_->all_buffers()) total += b->bytes();
  return total;
}

void CudaWorld::reset_capacities(std::size_t capacity) {
  if (capacity < 1) capacity = 1;
  for (BufferBase* b : impl_->scratch_buffers()) b->reset(capacity);
}

void CudaWorld::set_state(const BodyState& s) {
  Impl& d = *impl_;
  if (s.x.size() != d.n || s.v.size() != d.n || s.w.size() != d.n)
    throw InputError(fmt::format("CudaWorld::set_state: expected {} bodies, got x {}, v {}, w {}", d.n, s.x.size(),
                                 s.v.size(), s.w.size()));
  upload(d.x, s.x, d.stream, false);
  upload(d.v, s.v, d.stream, false);
  upload(d.w, s.w, d.stream, false);
  state_ = s;
  state_frame_ = frame_;
}

const BodyState& CudaWorld::state() const {
  if (state_frame_ != frame_) {
    Impl& d = *impl_;
    download(state_.x, d.x, d.n, d.stream);
    download(state_.v, d.v, d.n, d.stream);
    download(state_.w, d.w, d.n, d.stream);
    state_frame_ = frame_;
  }
  return state_;
}

const std::vector<ContactRecord>& CudaWorld::contacts() const {
  static const std::vector<ContactRecord> kNone;
  return recording_ ? record_.contacts : kNone;
}

const FrameMetrics& CudaWorld::step() {
  const auto t_step = Clock::now();
  Impl& d = *impl_;
  const Scene& scene = model_->scene;
  const ContactParams& params = scene.response;
  const std::uint32_t n = d.n;
  FrameMetrics m;
  m.frame = frame_ + 1;
  m.time = static_cast<double>(m.frame) * static_cast<double>(scene.dt);
  if (recording_) {
    const BodyState& s = state();
    record_.frame = m.frame;
    record_.x_pre = s.x;
    record_.v_pre = s.v;
  }
  const gpu::BodiesDesc bodies = d.bodies();
  d.record_event(0);

  // 1. Integrate (Eq. 1-3).
  d.launched(gpu::launch_integrate(bodies, scene.gravity, scene.dt, d.stream), "integrate");
  d.record_event(1);

  // 2. World AABBs.
  d.launched(gpu::launch_aabbs(bodies, d.stream), "aabbs");
  d.record_event(2);

  // 3. Broadphase (SPEC 5.1): the sorted unique pairs with overlapping AABBs.
  check(cudaMemsetAsync(d.counters.get(), 0, 4 * sizeof(unsigned long long), d.stream), "cudaMemset counters");
  const bool flat = d.broadphase == "flat";
  const std::uint32_t np =
      flat ? d.flat_broadphase() : d.octree_broadphase(scene.domain, scene.broadphase.octree_depth);
  d.pair_count = np;
  if (flat) m.cell_candidates = static_cast<std::uint64_t>(n) * (n == 0 ? 0 : n - 1) / 2;
  m.aabb_pairs = np;
  // Static bodies never move, so the static-static overlaps are the constant counted at
  // construction (World::step counts the same pairs one by one).
  m.dynamic_pairs = np >= d.static_static ? np - d.static_static : 0;
  d.record_event(3);

  // 4. Midphase + narrow phase (SPEC 5.2-5.3), one thread per pair.
  d.confirmed.ensure(np);
  gpu::MidphaseDesc md;
  md.x = d.x.get();
  md.w = d.w.get();
  md.aabb = d.aabb.get();
  md.shape = d.shape.get();
  md.shapes = d.shapes_desc();
  md.levels = d.levels;
  md.pairs = d.pairs.get();
  md.pair_count = np;
  md.confirmed = d.confirmed.get();
  md.counters = d.counters.get();
  // Per-pair narrow-phase scratch when it fits a modest budget; else the leaf test
  // recomputes the filtered vertices (identical tests, only slower).
  const std::size_t scratch_elems = static_cast<std::size_t>(np) * d.leaf_max;
  if (d.leaf_max > 0 && np > 0 && scratch_elems * sizeof(Vec3) <= kLeafScratchBudget) {
    d.leaf_scratch.ensure(scratch_elems);
    md.scratch = d.leaf_scratch.get();
    md.scratch_per_pair = d.leaf_max;
  }
  d.launched(gpu::launch_midphase(md, d.stream), "midphase");
  d.record_event(4);

  // 5. Response (SPEC 6): body-major index of the confirmed contacts (stable sort by
  // body keeps (a, b) order per body), then `iterations` passes of per-contact terms and
  // per-body sums, then the clamp (Eq. 23).
  const std::size_t entries = 2 * static_cast<std::size_t>(np);
  d.keys_in.ensure(entries);
  d.keys_out.ensure(entries);
  d.vals_in.ensure(entries);
  d.vals_out.ensure(entries);
  d.hit.ensure(np);
  d.dx_a.ensure(np);
  d.dx_b.ensure(np);
  d.dv_a.ensure(np);
  d.dv_b.ensure(np);
  d.depth0.ensure(np);
  if (recording_) d.records.ensure(np);
  d.body_begin.ensure(static_cast<std::size_t>(n) + 1);
  if (np > 0) {
    d.launched(gpu::launch_contact_entries(d.pairs.get(), d.confirmed.get(), np, n, d.keys_in.get(),
                                           d.vals_in.get(), d.stream),
               "contact_entries");
    d.sort(d.keys_in.get(), d.keys_out.get(), d.vals_in.get(), d.vals_out.get(),
           static_cast<std::uint32_t>(entries), key_bits(n));
  }
  d.launched(gpu::launch_body_segments(d.keys_out.get(), static_cast<std::uint32_t>(np > 0 ? entries : 0), n,
                                       d.body_begin.get(), d.stream),
             "body_segments");
  gpu::TermsDesc td;
  td.pairs = d.pairs.get();
  td.confirmed = d.confirmed.get();
  td.pair_count = np;
  td.x = d.x.get();
  td.v = d.v.get();
  td.w = d.w.get();
  td.local = d.local.get();
  td.params = params;
  td.hit = d.hit.get();
  td.dx_a = d.dx_a.get();
  td.dx_b = d.dx_b.get();
  td.dv_a = d.dv_a.get();
  td.dv_b = d.dv_b.get();
  gpu::ApplyDesc ad;
  ad.x = d.x.get();
  ad.v = d.v.get();
  ad.w = d.w.get();
  ad.n = n;
  ad.body_begin = d.body_begin.get();
  ad.entries = d.vals_out.get();
  ad.hit = d.hit.get();
  ad.dx_a = d.dx_a.get();
  ad.dx_b = d.dx_b.get();
  ad.dv_a = d.dv_a.get();
  ad.dv_b = d.dv_b.get();
  for (int pass = 0; pass < params.iterations; ++pass) {
    td.depth0 = pass == 0 ? d.depth0.get() : nullptr;
    td.records = pass == 0 && recording_ ? d.records.get() : nullptr;
    d.launched(gpu::launch_contact_terms(td, d.stream), "contact_terms");
    d.launched(gpu::launch_apply_sums(ad, d.stream), "apply_sums");
  }
  d.launched(gpu::launch_clamp(bodies, params.max_velocity, d.stream), "clamp");
  d.record_event(5);

  // 6. Metrics and the non-finite guard.
  gpu::MetricsDesc xd;
  xd.x = d.x.get();
  xd.v = d.v.get();
  xd.w = d.w.get();
  xd.n = n;
  xd.depth0 = d.depth0.get();
  xd.pair_count = np;
  xd.slop = params.slop;
  xd.out = d.metrics.get();
  d.launched(gpu::launch_metrics(xd, d.stream), "metrics");
  gpu::MetricsResult r;
  unsigned long long counters[4] = {0, 0, 0, 0};
  check(cudaMemcpyAsync(&r, d.metrics.get(), sizeof(r), cudaMemcpyDeviceToHost, d.stream), "cudaMemcpy metrics");
  check(cudaMemcpyAsync(counters, d.counters.get(), sizeof(counters), cudaMemcpyDeviceToHost, d.stream),
        "cudaMemcpy counters");
  d.record_event(6);
  check(cudaStreamSynchronize(d.stream), "cudaStreamSynchronize (metrics)");

  // The state on the device is now this frame's; the host copy is stale.
  state_frame_ = -1;
  if (r.first_non_finite < n) {
    const std::uint32_t i = r.first_non_finite;
    Vec3 x, v;
    check(cudaMemcpy(&x, d.x.get() + i, sizeof(Vec3), cudaMemcpyDeviceToHost), "cudaMemcpy x");
    check(cudaMemcpy(&v, d.v.get() + i, sizeof(Vec3), cudaMemcpyDeviceToHost), "cudaMemcpy v");
    // The message World::step gives.
    throw RuntimeError(fmt::format(
        "frame {}: body {} (group '{}') has a non-finite {} ({}, {}, {}); the run stops here", m.frame, i,
        model_->bodies[i].group, is_finite(x) ? "velocity" : "position", is_finite(x) ? v.x : x.x,
        is_finite(x) ? v.y : x.y, is_finite(x) ? v.z : x.z));
  }
  m.box_tests = counters[0];
  m.box_pairs = counters[1];
  m.vertex_tests = counters[2];
  if (!flat) m.cell_candidates = counters[3];
  m.contacts = r.contacts;
  if (r.contacts > 0) {
    m.penetration_mean = r.pen_sum / static_cast<double>(r.contacts);
    m.penetration_max = r.pen_max;
    m.penetration_share_above_slop = static_cast<double>(r.pen_above) / static_cast<double>(r.contacts);
  }
  m.kinetic_energy = r.kinetic_energy;
  m.momentum = {r.momentum[0], r.momentum[1], r.momentum[2]};
  for (int s = 0; s < static_cast<int>(Stage::Count); ++s) {
    float ms = 0.0f;
    check(cudaEventElapsedTime(&ms, d.events[s], d.events[s + 1]), "cudaEventElapsedTime");
    m.stage_ms[static_cast<std::size_t>(s)] = static_cast<double>(ms);
  }
  m.memory_bytes = device_bytes();

  frame_ = m.frame;
  if (recording_) {
    download(record_.aabbs, d.aabb, n, d.stream);
    download(record_.pairs, d.pairs, np, d.stream);
    std::vector<std::uint8_t> confirmed;
    download(confirmed, d.confirmed, np, d.stream);
    std::vector<gpu::DeviceContact> recs;
    download(recs, d.records, np, d.stream);
    record_.confirmed.clear();
    record_.contacts.clear();
    for (std::size_t k = 0; k < np; ++k) {
      if (!confirmed[k]) continue;
      const Pair p = record_.pairs[k];
      record_.confirmed.push_back(p);
      const gpu::DeviceContact& c = recs[k];
      if (!c.hit) continue;
      ContactRecord rec;
      rec.pair = p;
      rec.normal = c.normal;
      rec.depth = c.depth;
      rec.axis = c.axis;
      rec.v_a = c.v_a;
      rec.v_b = c.v_b;
      rec.dx_a = c.dx_a;
      rec.dx_b = c.dx_b;
      rec.jn = c.jn;
      rec.jt = c.jt;
      rec.dv_a = c.dv_a;
      rec.dv_b = c.dv_b;
      record_.contacts.push_back(rec);
    }
    const BodyState& s = state();
    record_.x_post = s.x;
    record_.v_post = s.v;
  }
  m.step_ms = ms_since(t_step);
  metrics_ = m;
  return metrics_;
}

}  // namespace octocd
