// Text mutations shared by the YAML fuzzers: byte flips, deletions, hostile tokens, truncation,
// hostile numbers, duplicated and swapped lines.
#pragma once

#include <algorithm>
#include <cstdlib>
#include <random>
#include <sstream>
#include <string>
#include <vector>

namespace fuzz {

// The suite's seeds are fixed (a failure reproduces). BOARD_CALIB_FUZZ_ROUND=N (N > 0) shifts
// every seed by N * 100 for a longer search by hand (rerun a failure with the same round).
inline std::mt19937::result_type seed(std::mt19937::result_type base) {
  const char* round = std::getenv("BOARD_CALIB_FUZZ_ROUND");
  const long n = round ? std::clamp(std::strtol(round, nullptr, 10), 0L, 1000000L) : 0L;
  return base + static_cast<std::mt19937::result_type>(n * 100);
}

inline std::string mutateText(std::mt19937& rng, std::string text) {
  static const char* kTokens[] = {
      "nan",   ".nan",       "inf",         "-.inf", "-1", "0",        "1e300",
      "65536", "2147483648", "-2147483649", "1e20",  "[]", "{}",       "~",
      "\"\"",  "[1e20, -5]", "[nan, 0, 1]", "&a",    "*a", "!!binary", "'",
      "\"",    ":",          "- ",          "\t",    "{",  "[",        "#"};
  const int mutations = 1 + static_cast<int>(rng() % 4);
  for (int k = 0; k < mutations && !text.empty(); ++k) {
    const size_t at = rng() % text.size();
    switch (rng() % 7) {
      case 0: text[at] = static_cast<char>(rng() % 128); break;  // byte flip
      case 1: text.erase(at, 1 + rng() % 8); break;
      case 2: text.insert(at, kTokens[rng() % (sizeof(kTokens) / sizeof(kTokens[0]))]); break;
      case 3: text.resize(at); break;  // truncated file
      case 4: {                        // replace a number by a hostile token
        const size_t digit = text.find_first_of("0123456789", at);
        if (digit == std::string::npos) break;
        const size_t end = text.find_first_not_of("0123456789.e-", digit);
        text.replace(digit, (end == std::string::npos ? text.size() : end) - digit,
                     kTokens[rng() % 11]);
        break;
      }
      case 5: {  // duplicate a line (duplicate keys)
        const size_t begin = text.rfind('\n', at);
        const size_t b = begin == std::string::npos ? 0 : begin + 1;
        const size_t e = text.find('\n', at);
        const std::string line = text.substr(b, (e == std::string::npos ? text.size() : e) - b);
        text.insert(b, line + "\n");
        break;
      }
      default: {  // swap two lines
        std::vector<std::string> lines;
        std::stringstream s(text);
        for (std::string l; std::getline(s, l);) lines.push_back(l);
        if (lines.size() > 1) std::swap(lines[rng() % lines.size()], lines[rng() % lines.size()]);
        text.clear();
        for (const auto& l : lines) text += l + "\n";
        break;
      }
    }
  }
  return text;
}

}  // namespace fuzz
