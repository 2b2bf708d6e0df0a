// The places the device rows can be judged (octocd/device_judge.hpp), in both builds.
#include <cstring>
#include <stdexcept>

#include "octocd/device_judge.hpp"

namespace octocd {

const std::vector<JudgeDeviceKind>& judge_device_kinds() {
  static const std::vector<JudgeDeviceKind> kinds{{"cpu", nullptr}, {"cuda", &make_cuda_judge}};
  return kinds;
}

const JudgeDeviceKind& judge_device_kind(const std::string& name, const char* option) {
  std::string allowed;
  for (const JudgeDeviceKind& k : judge_device_kinds()) {
    if (std::strcmp(k.name, name.c_str()) == 0) return k;
    allowed += (allowed.empty() ? "" : ", ") + std::string(k.name);
  }
  throw std::invalid_argument(std::string(option) + ": '" + name + "'; allowed: " + allowed);
}

}  // namespace octocd
