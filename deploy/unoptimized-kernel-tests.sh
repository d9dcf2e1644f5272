#!/usr/bin/env bash
# The vector kernels' tests built without optimization (Debug, -O0) and without sanitizers, so the
# AVX and AVX2 clones are in (sanitizer builds keep the portable clone only). At -O0 nothing is
# inlined unless it is marked always_inline: a helper or lambda that passes a 32-byte vector by
# value between a clone and code built for the baseline would disagree on how the vector is
# passed and crash, which an optimized build hides by inlining it anyway.
set -euo pipefail
cd "$(dirname "${BASH_SOURCE[0]}")/.."
jobs="${TEMPOKEY_JOBS:-$(nproc)}"
dir="${TEMPOKEY_O0_BUILD_DIR:-build-O0}"
targets=(vector_trig_test rotation_batch_test resample_rotation_test noise_fit_test
         tolerance_fit_test hermite_dp_test kinematics_test world_points_test keyed_clip_test
         rotation_test)

printf '\n== unoptimized vector kernels (Debug, -O0, AVX clones in)\n'
cmake -S . -B "$dir" -G Ninja -DCMAKE_BUILD_TYPE=Debug -DTEMPOKEY_BUILD_BENCH=OFF >/dev/null
ninja -C "$dir" -j "$jobs" "${targets[@]}"
for t in "${targets[@]}"; do
  echo "-- $t (-O0)"
  "$dir/tests/$t" --gtest_brief=1
  # The run-time kernels capped at AVX2 as well (core/src/simd/instruction_set.h).
  TEMPOKEY_MAX_ISA=avx2 "$dir/tests/$t" --gtest_brief=1
done
# The error-bounded fit has a baseline build beside its AVX2 one (core/CMakeLists.txt), and only
# the baseline build holds AVX clones: run it too.
echo "-- tolerance_fit_test (-O0, baseline)"
TEMPOKEY_MAX_ISA=baseline "$dir/tests/tolerance_fit_test" --gtest_brief=1
