#!/usr/bin/env bash
# The README's two commands. Each does its own set-up on a fresh Debian 12 machine (as root):
#
#   deploy/quickstart.sh demo   install, build, start tempokey-server on loopback, run the main jobs
#                               (retime, key reduction) with the CLI on a real clip from
#                               ../shared/data, write the results to build/demo, stop the server
#   deploy/quickstart.sh test   install, build, run the whole test suite (what .ci/run calls)
#   deploy/quickstart.sh studio install, build, serve the studio page on http://127.0.0.1:8080/
#                               (TEMPOKEY_STUDIO_PORT) until Ctrl-C, then drain the server
#
# Environment: TEMPOKEY_BUILD_DIR (default: build), TEMPOKEY_JOBS (default: nproc),
# TEMPOKEY_SANITIZER_TESTS=0 skips the sanitizer stage of `test`, TEMPOKEY_FUZZ_SECONDS (seconds
# per fuzz target, default 12; 0 skips the fuzz stage, deploy/fuzz.sh).
set -euo pipefail

here="$(cd "$(dirname "${BASH_SOURCE[0]}")/.." && pwd)"
cd "$here"
build_dir="${TEMPOKEY_BUILD_DIR:-build}"
jobs="${TEMPOKEY_JOBS:-$(nproc)}"
shared_dir="$(cd "$here/.." && pwd)/shared"

log() { printf '\n== %s\n' "$*"; }

build() {
  log "installing dependencies (Debian packages)"
  deploy/install-deps.sh
  log "building (Release) in $build_dir"
  cmake -S . -B "$build_dir" -G Ninja -DCMAKE_BUILD_TYPE=Release "$@" >/dev/null
  ninja -C "$build_dir" -j "$jobs"
}

demo() {
  build -DTEMPOKEY_BUILD_BENCH=OFF
  local clip="${1:-$shared_dir/data/bvh/cmu/131_01.bvh}"
  local out="$build_dir/demo"
  local work
  work="$(mktemp -d)"
  rm -rf "$out"
  mkdir -p "$out"
  log "starting tempokey-server on 127.0.0.1 (free port)"
  "$build_dir/server/tempokey-server" --address 127.0.0.1:0 --port_file "$work/port" \
    >"$work/server.log" 2>&1 &
  local server_pid=$!
  trap 'kill -TERM "$server_pid" 2>/dev/null || true; rm -rf "$work"' EXIT
  for _ in $(seq 1 100); do [[ -s "$work/port" ]] && break; sleep 0.1; done
  [[ -s "$work/port" ]] || { cat "$work/server.log"; echo "error: server did not start" >&2; exit 1; }
  local target="127.0.0.1:$(cat "$work/port")"
  local cli=("$build_dir/client/tempokey" --server "$target")
  local stem
  stem="$(basename "${clip%.*}")"

  log "tempokey health"
  "${cli[@]}" health
  log "tempokey info $clip"
  "${cli[@]}" info "$clip"
  log "retime: half speed from 2 s to 4 s (slow motion in the middle of the clip)"
  "${cli[@]}" retime "$clip" -o "$out/$stem-slow.bvh" --speed "0s:1,2s:1,2s:0.5,4s:0.5,4s:1"
  log "reduce: fewest keys within 0.5 degrees / 0.3 % of the figure's height, as Maya .anim, as JSON, baked to BVH"
  "${cli[@]}" reduce "$clip" -o "$out/$stem-keys.anim"
  "${cli[@]}" reduce "$clip" -o "$out/$stem-keys.json" >/dev/null
  "${cli[@]}" reduce "$clip" -o "$out/$stem-reduced.bvh" >/dev/null
  log "reduce: every joint within 0.5 % of the figure's height of its source position"
  "${cli[@]}" reduce "$clip" -o "$out/$stem-joints.json" --joint-tolerance 0.5%
  log "reduce: the paper's Hermite DP fit, for comparison"
  "${cli[@]}" reduce "$clip" -o "$out/$stem-paper.anim" --method paper
  log "outputs in $out"
  ls -l "$out"

  log "stopping the server (SIGTERM drain)"
  kill -TERM "$server_pid"
  local status=0
  wait "$server_pid" || status=$?
  trap - EXIT
  rm -rf "$work"
  echo "tempokey-server exited with status $status"
  return "$status"
}

test_suite() {
  build -DTEMPOKEY_BUILD_BENCH=ON  # benchmarks are built (so they keep compiling), not run
  log "test suite (CTest, Release)"
  ctest --test-dir "$build_dir" --output-on-failure -j "$jobs" --timeout 900
  deploy/unoptimized-kernel-tests.sh
  if [[ "${TEMPOKEY_SANITIZER_TESTS:-1}" != "0" ]]; then
    deploy/sanitizer-tests.sh
  fi
  deploy/fuzz.sh  # bounded: TEMPOKEY_FUZZ_SECONDS per target, 0 skips
}

studio() {
  build -DTEMPOKEY_BUILD_BENCH=OFF
  local port="${TEMPOKEY_STUDIO_PORT:-8080}"
  log "tempokey studio: open http://127.0.0.1:$port/ in a browser (Ctrl-C stops the server)"
  # exec: Ctrl-C reaches the server itself, which drains and exits 0.
  exec "$build_dir/server/tempokey-server" --address 127.0.0.1:0 --http_address "127.0.0.1:$port"
}

case "${1:-}" in
  demo) shift; demo "$@" ;;
  test) shift; test_suite "$@" ;;
  studio) shift; studio "$@" ;;
  *) echo "usage: deploy/quickstart.sh demo [CLIP.bvh] | test | studio" >&2; exit 2 ;;
esac
