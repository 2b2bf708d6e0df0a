// The CUDA engine's entry points in a build without CUDA (OCTOCD_CUDA=OFF or no nvcc):
// callers (the CLI's --engine cuda) link and get a clear error instead.
#include "octocd/cuda_world.hpp"

#include "octocd/error.hpp"

namespace octocd {

namespace {
const char* const kNotBuilt = "this octocd was built without CUDA (OCTOCD_CUDA=OFF)";
}  // namespace

std::unique_ptr<Engine> make_cuda_engine(std::shared_ptr<const Model> /*model*/, const std::string& /*broadphase*/,
                                         const CudaSettings& /*settings*/) {
  throw RuntimeError(std::string(kNotBuilt) +
                     ": the cuda engine is not available; rebuild on a machine with the CUDA toolkit (nvcc) "
                     "with -DOCTOCD_CUDA=ON, or use --engine cpu");
}

std::string cuda_device_status() { return std::string("no CUDA device: ") + kNotBuilt; }

bool cuda_device_available() { return false; }

}  // namespace octocd
