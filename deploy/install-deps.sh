#!/usr/bin/env bash
# Installs every build, test and runtime dependency of tempokey from Debian 12 packages.
# This is the only place packages are listed; README, .ci/run and the Dockerfile all call it.
# Idempotent: packages already present are skipped, apt is not touched when nothing is missing.
#
#   deploy/install-deps.sh            build + test dependencies (default), npm ci in tests/export
#                                     and tests/deploy
#   deploy/install-deps.sh --build    build dependencies only (the image's build stage)
#   deploy/install-deps.sh --runtime  only the shared libraries tempokey-server and tempokey need
#   deploy/install-deps.sh --image    tools that build and smoke-test the container image with no
#                                     registry (deploy/image-smoke.sh: podman, debootstrap) and
#                                     run deploy/compose.yaml (podman-compose)
set -euo pipefail

build_packages=(
  build-essential cmake ninja-build pkg-config git ca-certificates
  libabsl-dev libprotobuf-dev protobuf-compiler
  libgrpc++-dev libgrpc-dev protobuf-compiler-grpc
  libspdlog-dev libfmt-dev
  prometheus-cpp-dev libcivetweb-dev
  libgtest-dev libgmock-dev googletest libbenchmark-dev
  libssl-dev openssl procps curl ccache
  python3 python3-grpcio python3-protobuf
  # `pip install client/python` into a virtual environment, offline (tests/python)
  python3-venv python3-pip python3-setuptools python3-wheel
  python3-yaml
  libcivetweb-dev libjs-three
  chromium chromium-driver python3-selenium
  # clang and its runtimes (libFuzzer, ASan, UBSan): the fuzz stage, deploy/fuzz.sh
  clang-14 libclang-rt-14-dev
)
# Export checks (ctest -L export): a real browser for the glTF page, and tools that are not ours
# under node: the Khronos glTF validator and three.js, pinned in tests/export/package-lock.json
# and installed with `npm ci`. Deploy checks (ctest -L deploy): the Kubernetes API's schemas
# (kubernetes-models), which Debian lacks (its kubectl 1.20 predates the Job fields the manifests
# use and needs a cluster), pinned in tests/deploy/package-lock.json, installed the same way.
# A machine without node gets Debian's nodejs and npm.
test_packages=(chromium)
node_packages=(nodejs npm)
runtime_packages=(
  libgrpc++1.51 libgrpc29 libprotobuf32 libspdlog1.10 libfmt9
  libabsl20220623 libprometheus-cpp-core1.0 libprometheus-cpp-pull1.0 libcivetweb1
  ca-certificates
  libcivetweb1 libjs-three
)
# podman builds (through its built-in buildah) and runs the image; runc is its OCI runtime
# (crun 1.8 refuses these machines' hybrid cgroup mounts; see image-smoke.sh).
# debootstrap makes the bookworm base image locally, checked against debian-archive-keyring.
# curl reads the container's metrics port from the host (the runtime image has no HTTP client).
# image-smoke.sh itself needs no container network (it builds on the host network and tests in
# the server's own namespace); podman-compose, the CNI plugins and iptables are for
# deploy/compose.yaml, whose three servers publish their ports through a bridge network.
image_packages=(
  podman runc conmon debootstrap debian-archive-keyring curl
  podman-compose containernetworking-plugins iptables
)

case "${1:-}" in
  "") packages=("${build_packages[@]}" "${test_packages[@]}") ;;
  --build) packages=("${build_packages[@]}") ;;
  --runtime) packages=("${runtime_packages[@]}") ;;
  --image) packages=("${image_packages[@]}") ;;
  *) echo "usage: deploy/install-deps.sh [--build | --runtime | --image]" >&2; exit 2 ;;
esac

# The machine's node is used when it has one (it may come from elsewhere than Debian).
if [[ -z "${1:-}" ]] && ! command -v node > /dev/null; then
  packages+=("${node_packages[@]}")
fi

# npm ci in each test folder with a lock file (tests/export, tests/deploy) when its packages are
# missing or older than the lock file.
install_npm_packages() {
  local root dir
  root="$(cd "$(dirname "${BASH_SOURCE[0]}")/.." && pwd)"
  for dir in tests/export tests/deploy; do
    if [[ ! -f "$root/$dir/node_modules/.package-lock.json" ||
          "$root/$dir/package-lock.json" -nt "$root/$dir/node_modules/.package-lock.json" ]]; then
      echo "install-deps: npm ci in $dir"
      (cd "$root/$dir" && npm ci --no-audit --no-fund --loglevel=error)
    fi
  done
}

# promtool, Prometheus's own checker of a metrics exposition (ctest -L server,
# MetricsEndpointTest), taken out of Debian's prometheus package into tests/server/tools/
# without installing that package, which would add the Prometheus daemon and its service.
install_promtool() {
  local root target work
  root="$(cd "$(dirname "${BASH_SOURCE[0]}")/.." && pwd)"
  target="$root/tests/server/tools/promtool"
  [[ -x "$target" ]] && return 0
  echo "install-deps: promtool from Debian's prometheus package into tests/server/tools"
  work="$(mktemp -d)"
  # apt-get download needs the package lists; a machine that had every package may never have
  # fetched them.
  if ! (cd "$work" && apt-get download -qq prometheus 2>/dev/null); then
    apt-get update -qq
    (cd "$work" && apt-get download -qq prometheus)
  fi
  dpkg-deb -x "$work"/prometheus_*.deb "$work/root"
  install -D -m 0755 "$work/root/usr/bin/promtool" "$target"
  rm -rf "$work"
}

missing=()
for p in "${packages[@]}"; do
  if ! dpkg-query -W -f='${Status}' "$p" 2>/dev/null | grep -q "install ok installed"; then
    missing+=("$p")
  fi
done

if [[ ${#missing[@]} -eq 0 ]]; then
  echo "install-deps: all ${#packages[@]} packages present"
else
  echo "install-deps: installing ${missing[*]}"
  export DEBIAN_FRONTEND=noninteractive
  apt-get update -qq
  apt-get install -y -qq --no-install-recommends "${missing[@]}" >/dev/null
  echo "install-deps: done"
fi
if [[ -z "${1:-}" ]]; then
  install_npm_packages
  install_promtool
fi
