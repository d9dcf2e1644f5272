#!/usr/bin/env bash
# Sanitizer stage of the test suite: only what needs it, to stay inside CI's budget.
#   ASan + UBSan: core, proto and server tests (Debug, no benchmarks, no CLI tests).
#   TSan: the job pool, job manager, memory budget, idle reaper and upload digest tests, which
#   have no gRPC in them (Debian's gRPC is not instrumented, so TSan would report noise inside it).
set -euo pipefail
cd "$(dirname "${BASH_SOURCE[0]}")/.."
jobs="${TEMPOKEY_JOBS:-$(nproc)}"
asan_dir="${TEMPOKEY_ASAN_BUILD_DIR:-build-asan}"
tsan_dir="${TEMPOKEY_TSAN_BUILD_DIR:-build-tsan}"
tsan_targets=(job_pool_test job_manager_test memory_budget_test idle_reaper_test
              background_digest_test)

printf '\n== ASan + UBSan build (core and server tests)\n'
cmake -S . -B "$asan_dir" -G Ninja -DCMAKE_BUILD_TYPE=Debug -DTEMPOKEY_BUILD_BENCH=OFF \
  -DTEMPOKEY_SANITIZE=address,undefined >/dev/null
asan_targets=$(cd "$asan_dir" && ninja -t targets all | sed -n 's/^\([a-z0-9_]*_test\): .*/\1/p' | sort -u)
server_and_core=()
for t in $asan_targets; do
  # Core tests live in subject folders (tests/core/io/, tests/core/reduce/, ...).
  if [[ -n "$(find tests/core tests/proto tests/server -name "$t.cc" -print -quit)" ]]; then
    server_and_core+=("$t")
  fi
done
ninja -C "$asan_dir" -j "$jobs" "${server_and_core[@]}"
export ASAN_OPTIONS="detect_leaks=1:abort_on_error=1"
export UBSAN_OPTIONS="print_stacktrace=1:halt_on_error=1"
ctest --test-dir "$asan_dir" --output-on-failure -j "$jobs" -L 'core|proto|server' --timeout 900

printf '\n== TSan build (job pool)\n'
cmake -S . -B "$tsan_dir" -G Ninja -DCMAKE_BUILD_TYPE=RelWithDebInfo -DTEMPOKEY_BUILD_BENCH=OFF \
  -DTEMPOKEY_SANITIZE=thread >/dev/null
present=()
for t in "${tsan_targets[@]}"; do [[ -f "tests/server/$t.cc" ]] && present+=("$t"); done
if [[ ${#present[@]} -gt 0 ]]; then
  ninja -C "$tsan_dir" -j "$jobs" "${present[@]}"
  export TSAN_OPTIONS="halt_on_error=1:second_deadlock_stack=1"
  for t in "${present[@]}"; do
    echo "-- $t (TSan)"
    "$tsan_dir/tests/$t"
  done
fi
