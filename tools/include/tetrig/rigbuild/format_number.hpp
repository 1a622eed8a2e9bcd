// One number through a printf format ("%.3g mm"), for the rig builder's messages. Load time only.
#pragma once

#include <cstdio>
#include <string>

namespace tetrig::rigbuild {

inline std::string formatNumber(const char* format, double value) {
  char buf[64];
  std::snprintf(buf, sizeof buf, format, value);
  return buf;
}

}  // namespace tetrig::rigbuild
