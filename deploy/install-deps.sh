#!/usr/bin/env bash
# Installs every build, test and runtime dependency of tempokey from Debian 12 packages.
# This is the only place packages are listed; README, .ci/run and the Dockerfile all call it.
# Idempotent: packages already present are skipped, apt is not touched when nothing is missing.
#
#   deploy/install-deps.sh            build + test dependencies (default)
#   deploy/install-deps.sh --runtime  only the shared libraries tempokey-server and tempokey need
set -euo pipefail

build_packages=(
  build-essential cmake ninja-build pkg-config git ca-certificates
  libabsl-dev libprotobuf-dev protobuf-compiler
  libgrpc++-dev libgrpc-dev protobuf-compiler-grpc
  libspdlog-dev libfmt-dev
  prometheus-cpp-dev
  libgtest-dev libgmock-dev googletest libbenchmark-dev
  libssl-dev openssl procps curl ccache
  python3 python3-grpcio python3-protobuf
)
runtime_packages=(
  libgrpc++1.51 libgrpc29 libprotobuf32 libspdlog1.10 libfmt9
  libabsl20220623 libprometheus-cpp-core1.0 libprometheus-cpp-pull1.0
  ca-certificates
)

packages=("${build_packages[@]}")
if [[ "${1:-}" == "--runtime" ]]; then
  packages=("${runtime_packages[@]}")
fi

missing=()
for p in "${packages[@]}"; do
  if ! dpkg-query -W -f='${Status}' "$p" 2>/dev/null | grep -q "install ok installed"; then
    missing+=("$p")
  fi
done

if [[ ${#missing[@]} -eq 0 ]]; then
  echo "install-deps: all ${#packages[@]} packages present"
  exit 0
fi

echo "install-deps: installing ${missing[*]}"
export DEBIAN_FRONTEND=noninteractive
apt-get update -qq
apt-get install -y -qq --no-install-recommends "${missing[@]}" >/dev/null
echo "install-deps: done"
