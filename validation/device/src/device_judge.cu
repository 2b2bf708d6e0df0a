// The CUDA judge of octocd/device_judge.hpp: candidates by a uniform grid and the box
// pairs' separating-axis test, in double precision. Shares no code with gpu/ (the engine).
#include "octocd/device_judge.hpp"

#include "octocd/box_sat.hpp"

#include <cuda_runtime.h>
#include <thrust/binary_search.h>
#include <thrust/device_ptr.h>
#include <thrust/execution_policy.h>
#include <thrust/system/cuda/execution_policy.h>
#include <thrust/functional.h>
#include <thrust/reduce.h>
#include <thrust/sort.h>
#include <thrust/iterator/counting_iterator.h>
#include <thrust/transform_reduce.h>
#include <thrust/unique.h>

#include <chrono>
#include <cmath>
#include <cstdint>
#include <map>
#include <stdexcept>
#include <string>
#include <vector>

namespace octocd {

namespace {

static_assert(sizeof(Pose) == 7 * sizeof(float), "Pose: 3 + 4 floats, copied as such");
static_assert(sizeof(Aabb) == 6 * sizeof(float), "Aabb: 6 floats, copied as such");

void check(cudaError_t e, const char* what) {
  if (e != cudaSuccess) throw std::runtime_error(std::string("device judge: ") + what + ": " + cudaGetErrorString(e));
}

/// A device buffer of T that grows (never shrinks) to the size asked.
template <class T>
struct Buffer {
  T* p = nullptr;
  std::size_t cap = 0;
  ~Buffer() { cudaFree(p); }
  T* reserve(std::size_t n, const char* what) {
    if (n <= cap) return p;
    cudaFree(p);
    p = nullptr;
    cap = 0;
    check(cudaMalloc(&p, std::max<std::size_t>(n, 1) * sizeof(T)), what);
    cap = std::max<std::size_t>(n, 1);
    return p;
  }
};

/// Thrust's temporary storage, kept from call to call: once warm a frame allocates and frees
/// nothing (cudaFree waits for the whole device, a resident kernel of the judged engine too).
struct CachedAllocator {
  using value_type = char;
  std::multimap<std::size_t, char*> spare;  // size -> block
  std::map<char*, std::size_t> lent;
  char* allocate(std::ptrdiff_t n) {
    char* p = nullptr;
    const auto it = spare.lower_bound(std::size_t(n));
    if (it != spare.end()) {
      p = it->second;
      lent[p] = it->first;
      spare.erase(it);
      return p;
    }
    check(cudaMalloc(&p, std::max<std::size_t>(std::size_t(n), 1)), "cudaMalloc(sort and reduce storage)");
    lent[p] = std::size_t(n);
    return p;
  }
  void deallocate(char* p, std::size_t) {
    const auto it = lent.find(p);
    spare.emplace(it->second, p);
    lent.erase(it);
  }
  ~CachedAllocator() {
    for (const auto& [n, p] : spare) cudaFree(p);
    for (const auto& [p, n] : lent) cudaFree(p);
  }
};

struct Body {
  double lo[3], hi[3], grow;
  int box, dynamic;
};

/// The body-to-world rotation of a float quaternion, normalised in double (dmath::rotation).
__device__ void rotation(const float* q, double r[9]) {
  double w = q[0], x = q[1], y = q[2], z = q[3];
  const double n = sqrt(w * w + x * x + y * y + z * z);
  if (n > 0) {
    w /= n;
    x /= n;
    y /= n;
    z /= n;
  }
  r[0] = 1 - 2 * (y * y + z * z), r[1] = 2 * (x * y - w * z), r[2] = 2 * (x * z + w * y);
  r[3] = 2 * (x * y + w * z), r[4] = 1 - 2 * (x * x + z * z), r[5] = 2 * (y * z - w * x);
  r[6] = 2 * (x * z - w * y), r[7] = 2 * (y * z + w * x), r[8] = 1 - 2 * (x * x + y * y);
}

/// Box i's 8 corners in the world (m) at pose `pose` (7 floats: position, then w, x, y, z).
__device__ void corners(const Body& b, const float* pose, double c[8][3]) {
  double r[9];
  rotation(pose + 3, r);
  for (int k = 0; k < 8; ++k) {
    const double v[3] = {(k & 1) ? b.hi[0] : b.lo[0], (k & 2) ? b.hi[1] : b.lo[1], (k & 4) ? b.hi[2] : b.lo[2]};
    for (int d = 0; d < 3; ++d) c[k][d] = double(pose[d]) + (r[3 * d] * v[0] + r[3 * d + 1] * v[1] + r[3 * d + 2] * v[2]);
  }
}

/// World AABBs (grown by each body's `grow`): boxes posed here, other bodies from `world`.
__global__ void world_boxes(int n, const Body* bodies, const float* poses, const float* world, double* lo, double* hi) {
  const int i = blockIdx.x * blockDim.x + threadIdx.x;
  if (i >= n) return;
  const Body b = bodies[i];
  double l[3], h[3];
  if (b.box) {
    double c[8][3];
    corners(b, poses + 7 * std::size_t(i), c);
    for (int d = 0; d < 3; ++d) {
      l[d] = h[d] = c[0][d];
      for (int k = 1; k < 8; ++k) l[d] = fmin(l[d], c[k][d]), h[d] = fmax(h[d], c[k][d]);
    }
  } else {
    for (int d = 0; d < 3; ++d) l[d] = world[6 * std::size_t(i) + d], h[d] = world[6 * std::size_t(i) + 3 + d];
  }
  for (int d = 0; d < 3; ++d) {
    lo[3 * std::size_t(i) + d] = l[d] - b.grow;
    hi[3 * std::size_t(i) + d] = h[d] + b.grow;
  }
}

/// Given float AABBs as they are (an engine's own), widened to double exactly.
__global__ void given_boxes(int n, const float* boxes, double* lo, double* hi) {
  const int i = blockIdx.x * blockDim.x + threadIdx.x;
  if (i >= n) return;
  for (int d = 0; d < 3; ++d) {
    lo[3 * std::size_t(i) + d] = boxes[6 * std::size_t(i) + d];
    hi[3 * std::size_t(i) + d] = boxes[6 * std::size_t(i) + 3 + d];
  }
}

__device__ double extent(const double* lo, const double* hi, int i) {
  const double* l = lo + 3 * std::size_t(i);
  const double* h = hi + 3 * std::size_t(i);
  return fmax(h[0] - l[0], fmax(h[1] - l[1], h[2] - l[2]));
}

constexpr std::uint64_t kBig = ~std::uint64_t(0);  // the key of a body wider than a cell
constexpr int kAxisBits = 21;

/// Per body its cell key (lower corner's cell; kBig for wide bodies) and its index.
__global__ void cell_keys(int n, const double* lo, const double* hi, double cell, double ox, double oy, double oz,
                          std::uint64_t* keys, std::uint32_t* ids) {
  const int i = blockIdx.x * blockDim.x + threadIdx.x;
  if (i >= n) return;
  ids[i] = std::uint32_t(i);
  if (extent(lo, hi, i) > cell) {
    keys[i] = kBig;
    return;
  }
  const double o[3] = {ox, oy, oz};
  std::uint64_t key = 0;
  for (int d = 0; d < 3; ++d) {
    double c = floor((lo[3 * std::size_t(i) + d] - o[d]) / cell);
    c = fmin(fmax(c, 0.0), double((1 << kAxisBits) - 3));
    key = (key << kAxisBits) | std::uint64_t(c + 1);  // +1: a neighbour at -1 stays >= 0
  }
  keys[i] = key;
}

__device__ bool boxes_overlap(const double* lo, const double* hi, std::uint32_t i, std::uint32_t j) {
  for (int d = 0; d < 3; ++d)
    if (lo[3 * std::size_t(i) + d] > hi[3 * std::size_t(j) + d] || lo[3 * std::size_t(j) + d] > hi[3 * std::size_t(i) + d])
      return false;
  return true;
}

__device__ void emit(std::uint32_t i, std::uint32_t j, unsigned long long* count, std::uint64_t* out,
                     unsigned long long cap) {
  const unsigned long long k = atomicAdd(count, 1ull);
  if (k < cap) out[k] = (std::uint64_t(min(i, j)) << 32) | std::uint64_t(max(i, j));
}

/// Grid pairs: body s of the sorted small bodies against the 27 cells around its own; a
/// pair is emitted by its lower-indexed body (each pair is seen from both sides).
__global__ void grid_pairs(int small, const std::uint64_t* keys, const std::uint32_t* ids, const double* lo,
                           const double* hi, const Body* bodies, unsigned long long* count, std::uint64_t* out,
                           unsigned long long cap) {
  const int s = blockIdx.x * blockDim.x + threadIdx.x;
  if (s >= small) return;
  const std::uint32_t i = ids[s];
  const std::uint64_t key = keys[s];
  const std::uint64_t mask = (std::uint64_t(1) << kAxisBits) - 1;
  const std::uint64_t c[3] = {(key >> (2 * kAxisBits)) & mask, (key >> kAxisBits) & mask, key & mask};
  const bool dyn_i = bodies[i].dynamic;
  for (int dx = -1; dx <= 1; ++dx)
    for (int dy = -1; dy <= 1; ++dy)
      for (int dz = -1; dz <= 1; ++dz) {
        const std::uint64_t want = ((c[0] + dx) << (2 * kAxisBits)) | ((c[1] + dy) << kAxisBits) | (c[2] + dz);
        int a = 0, b = small;  // lower bound of `want`
        while (a < b) {
          const int m = (a + b) / 2;
          if (keys[m] < want) a = m + 1; else b = m;
        }
        for (int t = a; t < small && keys[t] == want; ++t) {
          const std::uint32_t j = ids[t];
          if (j <= i) continue;
          if (!dyn_i && !bodies[j].dynamic) continue;
          if (boxes_overlap(lo, hi, i, j)) emit(i, j, count, out, cap);
        }
      }
}

/// Wide bodies (ids[small..n)) against every body: a pair with a small body is emitted
/// here, a pair of two wide bodies by the lower-indexed one.
__global__ void wide_pairs(int n, int small, const std::uint32_t* ids, const double* lo, const double* hi,
                           const Body* bodies, unsigned long long* count, std::uint64_t* out,
                           unsigned long long cap) {
  const std::size_t t = std::size_t(blockIdx.x) * blockDim.x + threadIdx.x;
  const std::size_t wide = std::size_t(n - small);
  if (t >= wide * std::size_t(n)) return;
  const std::uint32_t w = ids[small + t / std::size_t(n)];
  const std::uint32_t j = std::uint32_t(t % std::size_t(n));
  if (j == w) return;
  if (!bodies[w].dynamic && !bodies[j].dynamic) return;
  if (!boxes_overlap(lo, hi, w, j)) return;
  emit(w, j, count, out, cap);
}

/// The separating-axis test of two posed boxes: octocd/box_sat.hpp's closed form, the
/// formula the CPU tier's reference takes for two boxes (sat.hpp sat_boxes).
__device__ double box_box_overlap(const Body& A, const float* pa, const Body& B, const float* pb) {
  auto place = [](const Body& b, const float* pose) {
    double r[9];
    rotation(pose + 3, r);
    const double x[3] = {double(pose[0]), double(pose[1]), double(pose[2])};
    return sat_box(b.lo, b.hi, r, x);
  };
  return box_sat_least_overlap(place(A, pa), place(B, pb));
}

/// Per pair (key a << 32 | b): the box-box test when both are boxes.
__global__ void pair_sat(std::size_t m, const std::uint64_t* pairs, const Body* bodies, const float* poses,
                         DeviceBoxSat* out) {
  const std::size_t k = std::size_t(blockIdx.x) * blockDim.x + threadIdx.x;
  if (k >= m) return;
  const std::uint32_t a = std::uint32_t(pairs[k] >> 32), b = std::uint32_t(pairs[k] & 0xffffffffu);
  DeviceBoxSat r;
  r.box = bodies[a].box && bodies[b].box;
  r.overlap = r.box ? box_box_overlap(bodies[a], poses + 7 * std::size_t(a), bodies[b], poses + 7 * std::size_t(b)) : 0.0;
  out[k] = r;
}

struct ExtentOf {
  const double* lo;
  const double* hi;
  __device__ double operator()(int i) const { return extent(lo, hi, i); }
};
struct SmallExtent {
  const double* lo;
  const double* hi;
  double limit;
  __device__ double operator()(int i) const {
    const double e = extent(lo, hi, i);
    return e <= limit ? e : 0.0;
  }
};
struct SmallLow {
  const double* lo;
  const double* hi;
  double limit;
  int axis;
  __device__ double operator()(int i) const { return extent(lo, hi, i) <= limit ? lo[3 * std::size_t(i) + axis] : INFINITY; }
};

struct SmallHigh {
  const double* lo;
  const double* hi;
  double limit;
  int axis;
  __device__ double operator()(int i) const { return extent(lo, hi, i) <= limit ? lo[3 * std::size_t(i) + axis] : -INFINITY; }
};

unsigned blocks(std::size_t n, unsigned threads) { return unsigned((n + threads - 1) / threads); }

class CudaJudge final : public DeviceJudge {
 public:
  CudaJudge() {
    int count = 0;
    if (cudaGetDeviceCount(&count) != cudaSuccess || count == 0)
      throw std::runtime_error("--judge-device cuda: no CUDA device is usable here (cudaGetDeviceCount found none)");
    cudaDeviceProp prop{};
    check(cudaGetDeviceProperties(&prop, 0), "cudaGetDeviceProperties");
    name_ = std::string("cuda: ") + prop.name;
    check(cudaMalloc(&count_, sizeof(unsigned long long)), "cudaMalloc(count)");
  }
  ~CudaJudge() override { cudaFree(count_); }

  std::string device_name() const override { return name_; }

  void set_bodies(const std::vector<DeviceJudgeBody>& bodies) override {
    n_ = bodies.size();
    std::vector<Body> host(n_);
    for (std::size_t i = 0; i < n_; ++i) {
      for (int d = 0; d < 3; ++d) host[i].lo[d] = bodies[i].lo[d], host[i].hi[d] = bodies[i].hi[d];
      host[i].grow = bodies[i].grow;
      host[i].box = bodies[i].box;
      host[i].dynamic = bodies[i].dynamic;
    }
    check(cudaMemcpy(bodies_.reserve(n_, "cudaMalloc(bodies)"), host.data(), n_ * sizeof(Body), cudaMemcpyHostToDevice),
          "upload bodies");
  }

  void judge_frame(const std::vector<Pose>& poses, const std::vector<Aabb>& world, DeviceFrameAnswer& out) override {
    const auto t0 = std::chrono::steady_clock::now();
    if (poses.size() != n_ || (!world.empty() && world.size() != n_))
      throw std::invalid_argument("device judge: poses or world AABBs not one per body");
    const int n = int(n_);
    check(cudaMemcpy(poses_.reserve(7 * n_, "cudaMalloc(poses)"), poses.data(), n_ * sizeof(Pose),
                     cudaMemcpyHostToDevice),
          "upload poses");
    const float* w = nullptr;
    if (!world.empty()) {
      check(cudaMemcpy(world_.reserve(6 * n_, "cudaMalloc(world)"), world.data(), n_ * sizeof(Aabb),
                       cudaMemcpyHostToDevice),
            "upload world AABBs");
      w = world_.p;
    }
    double* lo = lo_.reserve(3 * n_, "cudaMalloc(lo)");
    double* hi = hi_.reserve(3 * n_, "cudaMalloc(hi)");
    if (n > 0) world_boxes<<<blocks(n_, 256), 256>>>(n, bodies_.p, poses_.p, w, lo, hi);
    check(cudaGetLastError(), "world_boxes");
    pairs_of_boxes(out.candidates);
    const std::size_t m = out.candidates.size();
    out.sat.resize(m);
    if (m > 0) {
      pair_sat<<<blocks(m, 128), 128>>>(m, pairs_.p, bodies_.p, poses_.p, sat_.reserve(m, "cudaMalloc(sat)"));
      check(cudaGetLastError(), "pair_sat");
      check(cudaMemcpy(out.sat.data(), sat_.p, m * sizeof(DeviceBoxSat), cudaMemcpyDeviceToHost), "download sat");
    }
    out.device_seconds = std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count();
  }

  void box_sat(const std::vector<Pair>& pairs, std::vector<DeviceBoxSat>& out) override {
    const std::size_t m = pairs.size();
    out.resize(m);
    if (m == 0) return;
    std::vector<std::uint64_t> keys(m);
    for (std::size_t k = 0; k < m; ++k) {
      if (pairs[k].a >= n_ || pairs[k].b >= n_) throw std::invalid_argument("device judge: a pair's body out of range");
      keys[k] = (std::uint64_t(pairs[k].a) << 32) | pairs[k].b;
    }
    check(cudaMemcpy(extra_.reserve(m, "cudaMalloc(pairs)"), keys.data(), m * sizeof(std::uint64_t),
                     cudaMemcpyHostToDevice),
          "upload pairs");
    pair_sat<<<blocks(m, 128), 128>>>(m, extra_.p, bodies_.p, poses_.p, sat_.reserve(m, "cudaMalloc(sat)"));
    check(cudaGetLastError(), "pair_sat");
    check(cudaMemcpy(out.data(), sat_.p, m * sizeof(DeviceBoxSat), cudaMemcpyDeviceToHost), "download sat");
  }

  void overlapping_pairs(const std::vector<Aabb>& boxes, std::vector<Pair>& out) override {
    if (boxes.size() != n_) throw std::invalid_argument("device judge: AABBs not one per body");
    check(cudaMemcpy(world_.reserve(6 * n_, "cudaMalloc(world)"), boxes.data(), n_ * sizeof(Aabb),
                     cudaMemcpyHostToDevice),
          "upload AABBs");
    double* lo = lo_.reserve(3 * n_, "cudaMalloc(lo)");
    double* hi = hi_.reserve(3 * n_, "cudaMalloc(hi)");
    if (n_ > 0) given_boxes<<<blocks(n_, 256), 256>>>(int(n_), world_.p, lo, hi);
    check(cudaGetLastError(), "given_boxes");
    pairs_of_boxes(out);
  }

 private:
  /// Every overlapping pair of the boxes in lo_/hi_ with a dynamic body, sorted, into
  /// `out` (and pairs_ on the device).
  void pairs_of_boxes(std::vector<Pair>& out) {
    const int n = int(n_);
    out.clear();
    if (n < 2) return;
    const double* lo = lo_.p;
    const double* hi = hi_.p;
    auto index = thrust::counting_iterator<int>(0);
    // Cell side: the largest extent among the bodies at most twice the mean extent.
    const double mean =
        thrust::transform_reduce(thrust::cuda::par(alloc_), index, index + n, ExtentOf{lo, hi}, 0.0, thrust::plus<double>()) /
        double(n);
    const double limit = 2 * mean;
    double cell = thrust::transform_reduce(thrust::cuda::par(alloc_), index, index + n, SmallExtent{lo, hi, limit}, 0.0,
                                           thrust::maximum<double>());
    double origin[3], top[3];
    for (int d = 0; d < 3; ++d) {
      origin[d] = thrust::transform_reduce(thrust::cuda::par(alloc_), index, index + n, SmallLow{lo, hi, limit, d}, INFINITY,
                                           thrust::minimum<double>());
      top[d] = thrust::transform_reduce(thrust::cuda::par(alloc_), index, index + n, SmallHigh{lo, hi, limit, d}, -INFINITY,
                                        thrust::maximum<double>());
    }
    // Keep every axis within 2^21 - 3 cells, and the cell a hair wider than the widest
    // small body so that two overlapping bodies' lower corners are at most a cell apart.
    for (int d = 0; d < 3; ++d)
      if (std::isfinite(origin[d])) cell = std::max(cell, (top[d] - origin[d]) / double((1 << kAxisBits) - 4));
    cell = cell * (1 + 1e-9) + 1e-12;
    if (!std::isfinite(origin[0])) origin[0] = origin[1] = origin[2] = 0;
    std::uint64_t* keys = keys_.reserve(n_, "cudaMalloc(keys)");
    std::uint32_t* ids = ids_.reserve(n_, "cudaMalloc(ids)");
    cell_keys<<<blocks(n_, 256), 256>>>(n, lo, hi, cell, origin[0], origin[1], origin[2], keys, ids);
    check(cudaGetLastError(), "cell_keys");
    thrust::sort_by_key(thrust::cuda::par(alloc_), keys, keys + n, ids);
    const int small = int(thrust::lower_bound(thrust::cuda::par(alloc_), keys, keys + n, kBig) - keys);
    unsigned long long cap = std::max<unsigned long long>(pairs_.cap, 4 * n_);
    for (;;) {
      std::uint64_t* pairs = pairs_.reserve(cap, "cudaMalloc(candidate pairs)");
      check(cudaMemset(count_, 0, sizeof(unsigned long long)), "cudaMemset(count)");
      if (small > 0)
        grid_pairs<<<blocks(std::size_t(small), 128), 128>>>(small, keys, ids, lo, hi, bodies_.p, count_, pairs, cap);
      check(cudaGetLastError(), "grid_pairs");
      const std::size_t wide_work = std::size_t(n - small) * n_;
      if (wide_work > 0)
        wide_pairs<<<blocks(wide_work, 256), 256>>>(n, small, ids, lo, hi, bodies_.p, count_, pairs, cap);
      check(cudaGetLastError(), "wide_pairs");
      unsigned long long found = 0;
      check(cudaMemcpy(&found, count_, sizeof(found), cudaMemcpyDeviceToHost), "download pair count");
      if (found <= cap) {
        // A wide body against another wide body is emitted from both sides: sort, then drop repeats.
        thrust::sort(thrust::cuda::par(alloc_), pairs, pairs + found);
        const std::size_t m = std::size_t(thrust::unique(thrust::cuda::par(alloc_), pairs, pairs + found) - pairs);
        std::vector<std::uint64_t> host(m);
        check(cudaMemcpy(host.data(), pairs, m * sizeof(std::uint64_t), cudaMemcpyDeviceToHost),
              "download candidate pairs");
        out.resize(m);
        for (std::size_t k = 0; k < m; ++k) out[k] = Pair{std::uint32_t(host[k] >> 32), std::uint32_t(host[k])};
        return;
      }
      cap = found + found / 4;
    }
  }

  std::string name_;
  CachedAllocator alloc_;  // before the buffers: destroyed after every use of them
  std::size_t n_ = 0;
  unsigned long long* count_ = nullptr;
  Buffer<Body> bodies_;
  Buffer<float> poses_, world_;
  Buffer<double> lo_, hi_;
  Buffer<std::uint64_t> keys_, pairs_, extra_;
  Buffer<std::uint32_t> ids_;
  Buffer<DeviceBoxSat> sat_;
};

}  // namespace

std::unique_ptr<DeviceJudge> make_cuda_judge() { return std::make_unique<CudaJudge>(); }

bool cuda_judge_built() { return true; }

}  // namespace octocd
