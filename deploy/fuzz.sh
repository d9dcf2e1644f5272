#!/usr/bin/env bash
# Fuzzing stage: builds the libFuzzer targets of fuzz/ with clang (libFuzzer + ASan + UBSan, every
# library of the tree instrumented), writes their seed corpora into the build tree (from
# ../shared/data and the test tables; nothing is committed), then runs every target for a bounded
# time. A crash, a sanitizer report, a leak, a timeout or a broken invariant fails the stage and
# leaves the input that caused it in <build>/fuzz/findings/<target>/.
#
#   deploy/fuzz.sh              every target for TEMPOKEY_FUZZ_SECONDS seconds (default 12)
#   deploy/fuzz.sh bvh_fuzz     one target
#
# Environment: TEMPOKEY_FUZZ_SECONDS (per target; 0 skips the stage), TEMPOKEY_FUZZ_BUILD_DIR
# (default build-fuzz), TEMPOKEY_JOBS (default nproc). The corpus grows across runs in the build
# tree, so later runs start from what earlier ones found.
set -euo pipefail
cd "$(dirname "${BASH_SOURCE[0]}")/.."
seconds="${TEMPOKEY_FUZZ_SECONDS:-12}"
if [[ "$seconds" == "0" ]]; then
  echo "fuzz stage skipped (TEMPOKEY_FUZZ_SECONDS=0)"
  exit 0
fi
dir="${TEMPOKEY_FUZZ_BUILD_DIR:-build-fuzz}"
jobs="${TEMPOKEY_JOBS:-$(nproc)}"

printf '\n== libFuzzer build (clang, ASan + UBSan) in %s\n' "$dir"
CC=clang-14 CXX=clang++-14 cmake -S . -B "$dir" -G Ninja -DCMAKE_BUILD_TYPE=RelWithDebInfo \
  -DTEMPOKEY_FUZZ=ON -DTEMPOKEY_BUILD_TESTS=OFF -DTEMPOKEY_BUILD_BENCH=OFF >/dev/null
ninja -C "$dir" -j "$jobs" fuzz

targets=("$@")
if [[ ${#targets[@]} -eq 0 ]]; then
  for src in fuzz/*_fuzz.cc; do targets+=("$(basename "${src%.cc}")"); done
fi
"$dir/fuzz/seed_corpus" "$dir/fuzz/corpus" >/dev/null

dictionary() {
  case "$1" in
    bvh_fuzz | csv_fuzz) echo "-dict=fuzz/dicts/bvh.dict" ;;
    keyed_json_fuzz | pipeline_file_fuzz) echo "-dict=fuzz/dicts/json.dict" ;;
    speed_knots_fuzz) echo "-dict=fuzz/dicts/speed.dict" ;;
  esac
}

export ASAN_OPTIONS="detect_leaks=1:abort_on_error=1"
export UBSAN_OPTIONS="print_stacktrace=1:halt_on_error=1"
for target in "${targets[@]}"; do
  printf '\n== %s (%s s)\n' "$target" "$seconds"
  mkdir -p "$dir/fuzz/corpus/$target" "$dir/fuzz/findings/$target"
  # -timeout: one input over 10 s is a finding (inputs are held to small limits); -rss_limit_mb:
  # so is one that needs 2 GiB.
  log="$dir/fuzz/findings/$target/last-run.log"
  status=0
  # shellcheck disable=SC2046
  "$dir/fuzz/$target" -max_total_time="$seconds" -timeout=10 -rss_limit_mb=2048 \
    -print_final_stats=1 -artifact_prefix="$dir/fuzz/findings/$target/" \
    $(dictionary "$target") "$dir/fuzz/corpus/$target" >"$log" 2>&1 || status=$?
  grep -E '^(#[0-9]+ +DONE|stat::number_of_executed_units|stat::peak_rss_mb|==[0-9]+==ERROR|SUMMARY|fuzz invariant|artifact_prefix|Test unit written)' "$log" || true
  if [[ $status -ne 0 ]]; then
    tail -40 "$log" >&2
    echo "error: $target found a failing input (exit $status); see $dir/fuzz/findings/$target/" >&2
    exit 1
  fi
done
