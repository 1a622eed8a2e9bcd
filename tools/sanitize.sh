#!/usr/bin/env bash
# The hostile-input checks (issue 37): the runtime's and drivers' tests under ASan + UBSan (the
# parsers and the frame path), then every libFuzzer target built and run once over its whole seed
# corpus. tools/test.sh runs this after the release suite with TETRIG_SANITIZERS=1 (as CI does:
# .ci/run). Longer fuzzing and the whole project under ASan: README.md, "Tests".
set -euo pipefail
cd "$(dirname "$0")/.."
bash tools/setup.sh

echo "sanitize: ASan + UBSan, runtime and drivers"
cmake --preset asan-core
cmake --build --preset asan-core
ctest --preset asan-core

echo "sanitize: fuzz targets over their seed corpora"
cmake --preset fuzz
cmake --build --preset fuzz
export LSAN_OPTIONS="suppressions=$PWD/tools/fuzz/lsan_suppressions.txt"
failed=0
ran=0
for corpus in runtime/fuzz/corpus/* drivers/fuzz/corpus/* tools/fuzz/corpus/*; do
  target=$(find build/fuzz -type f -name "fuzz_$(basename "$corpus")" -perm -u+x | head -n 1)
  if [ -z "$target" ]; then
    target="fuzz_$(basename "$corpus")"
    echo "sanitize: $target was not built" >&2
    failed=1
    continue
  fi
  # -runs=0: read and run every input of the corpus once, no mutation.
  ran=$((ran + 1))
  if "$target" -runs=0 "$corpus" > "build/fuzz/replay_$(basename "$corpus").log" 2>&1; then
    echo "sanitize: $(basename "$target"): $(ls "$corpus" | wc -l) inputs, no crash"
  else
    echo "sanitize: $(basename "$target") failed on its corpus; see build/fuzz/replay_$(basename "$corpus").log" >&2
    tail -n 30 "build/fuzz/replay_$(basename "$corpus").log" >&2
    failed=1
  fi
done
echo "sanitize: $ran fuzz targets replayed their corpora$([ "$failed" -eq 0 ] && echo ", none crashed" || echo "; FAILED")"
exit "$failed"
