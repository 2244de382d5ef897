// Seeds a test runs: its own fixed list, or (a development aid for sweeping other worlds by
// hand) a comma-separated list from an environment variable.
#pragma once

#include <cstdlib>
#include <sstream>
#include <string>
#include <vector>

namespace board_calib {
namespace test_support {

inline std::vector<unsigned> seedsFromEnv(const char* variable, std::vector<unsigned> defaults) {
  const char* list = std::getenv(variable);
  if (!list) return defaults;
  std::vector<unsigned> seeds;
  std::stringstream in(list);
  std::string item;
  while (std::getline(in, item, ','))
    if (!item.empty())
      seeds.push_back(static_cast<unsigned>(std::strtoul(item.c_str(), nullptr, 10)));
  return seeds.empty() ? defaults : seeds;
}

}  // namespace test_support
}  // namespace board_calib
