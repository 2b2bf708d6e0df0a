// The device judge in a build without CUDA (OCTOCD_CUDA=OFF or no nvcc): make_cuda_judge
// says so.
#include <stdexcept>

#include "octocd/device_judge.hpp"

namespace octocd {

std::unique_ptr<DeviceJudge> make_cuda_judge() {
  throw std::runtime_error(
      "--judge-device cuda: this build has no CUDA (configured with OCTOCD_CUDA=OFF or without nvcc); rebuild with a "
      "CUDA toolkit (docs/gpu.md) or judge on the CPU (the default)");
}

bool cuda_judge_built() { return false; }

}  // namespace octocd
