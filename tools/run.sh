#!/usr/bin/env bash
# The README's run command: install what is missing, build the release preset, and run the main
# job on the project's own default data (assets/). Extra arguments go to `tetrig demo`.
set -euo pipefail
cd "$(dirname "$0")/.."
bash tools/setup.sh
cmake --preset release >/dev/null
cmake --build --preset release
exec build/release/tetrig demo "$@"
