#include "octocd/version.hpp"

#include "octocd_build_id.h"  // OCTOCD_BUILD_ID, generated at build time (cmake/build_id.cmake)

#include <fstream>
#include <string>
#include <thread>

namespace octocd {

const char* build_id() { return OCTOCD_BUILD_ID; }

std::string cpu_description() {
  std::ifstream in("/proc/cpuinfo");
  std::string line;
  std::string model = "unknown CPU";
  while (std::getline(in, line)) {
    if (line.rfind("model name", 0) == 0) {
      const auto colon = line.find(':');
      if (colon != std::string::npos) model = line.substr(colon + 2);
      break;
    }
  }
  return model + " (" + std::to_string(std::thread::hardware_concurrency()) + " threads)";
}

}  // namespace octocd
