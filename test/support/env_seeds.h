// Seeds (or other settings) a test runs: its own fixed list, or (a development aid for sweeping
// other worlds by hand) a comma-separated list from an environment variable.
#pragma once

#include <cstdlib>
#include <sstream>
#include <string>
#include <vector>

namespace board_calib {
namespace test_support {

// The non-empty comma-separated items of an environment variable (none when it is unset).
inline std::vector<std::string> envList(const char* variable) {
  std::vector<std::string> items;
  const char* list = std::getenv(variable);
  if (!list) return items;
  std::stringstream in(list);
  for (std::string item; std::getline(in, item, ',');)
    if (!item.empty()) items.push_back(item);
  return items;
}

inline std::vector<unsigned> seedsFromEnv(const char* variable, std::vector<unsigned> defaults) {
  std::vector<unsigned> seeds;
  for (const std::string& item : envList(variable))
    seeds.push_back(static_cast<unsigned>(std::strtoul(item.c_str(), nullptr, 10)));
  return seeds.empty() ? defaults : seeds;
}

}  // namespace test_support
}  // namespace board_calib
