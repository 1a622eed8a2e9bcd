// Built instead of the transport tests when umockdev-1.0 was not found at configure time: the
// device tests must fail loudly in CI, never pass or skip silently.
#include <gtest/gtest.h>

TEST(DeviceTransports, UmockdevIsInstalled) {
  FAIL() << "umockdev-1.0 was not found when CMake configured the build: install the Debian packages "
            "'umockdev' and 'libumockdev-dev' (tools/setup.sh), re-run CMake, and run the device tests "
            "under umockdev-wrapper";
}
