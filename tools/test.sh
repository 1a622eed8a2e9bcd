#!/usr/bin/env bash
# The README's test command: install what is missing, build the release preset, run every test
# that is not labelled soak or fuzz. Extra arguments go to ctest (e.g. -R Polar).
# With TETRIG_SANITIZERS=1 the hostile-input stage follows (tools/sanitize.sh: the runtime and
# drivers under ASan + UBSan, every fuzz target over its corpus).
set -euo pipefail
cd "$(dirname "$0")/.."
bash tools/setup.sh
cmake --preset release
cmake --build --preset release
ctest --preset release "$@"
if [ "${TETRIG_SANITIZERS:-}" = "1" ]; then
  bash tools/sanitize.sh
fi
