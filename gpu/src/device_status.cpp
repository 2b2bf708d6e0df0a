// The CUDA device as the engine sees it: whether one is usable, its description, and the
// free-memory check the constructor makes before its first allocation.
#include <cstddef>

#include <fmt/format.h>

#include "cuda_impl.hpp"
#include "octocd/error.hpp"

namespace octocd {
namespace gpu {

namespace {

/// "1.23 GiB", "4.5 MiB" or "12.0 KiB": a byte count for a message.
std::string human_bytes(std::uint64_t bytes) {
  const double b = static_cast<double>(bytes);
  if (b >= 1024.0 * 1024.0 * 1024.0) return fmt::format("{:.2f} GiB", b / (1024.0 * 1024.0 * 1024.0));
  if (b >= 1024.0 * 1024.0) return fmt::format("{:.1f} MiB", b / (1024.0 * 1024.0));
  return fmt::format("{:.1f} KiB", b / 1024.0);
}

}  // namespace

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

void check_free_memory(const Model& m, const std::string& broadphase, std::uint64_t needed, std::uint64_t limit,
                       const std::function<std::uint64_t(std::uint64_t)>& free_bytes) {
  std::size_t device_free = 0, total_bytes = 0;
  check(cudaMemGetInfo(&device_free, &total_bytes), "cudaMemGetInfo");
  std::uint64_t free = free_bytes ? free_bytes(device_free) : device_free;
  std::string why;
  if (limit > 0 && limit < free) {
    free = limit;
    why = fmt::format(" (memory_limit_bytes={})", limit);
  }
  if (needed <= free) return;
  throw RuntimeError(fmt::format(
      "scene '{}': the cuda engine needs about {} bytes ({}) of device memory for {} bodies before its first step "
      "(broadphase '{}'), but the device has {} bytes ({}) free{} of {} bytes ({}); run fewer bodies, or use "
      "--engine cpu",
      m.scene.name, needed, human_bytes(needed), m.initial.size(), broadphase, free, human_bytes(free), why,
      total_bytes, human_bytes(total_bytes)));
}

}  // namespace gpu

std::string cuda_device_status() {
  try {
    const std::string reason = gpu::no_device_reason();
    if (!reason.empty()) return "no CUDA device: " + reason;
    return gpu::describe_current_device();
  } catch (const std::exception& e) {
    return std::string("no CUDA device: ") + e.what();
  }
}

bool cuda_device_available() { return gpu::no_device_reason().empty(); }

}  // namespace octocd
