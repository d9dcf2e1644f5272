#!/usr/bin/env bash
# Builds the tempokey image and smoke-tests it with no container registry (SPEC 7), as root:
#   1. installs podman and debootstrap (deploy/install-deps.sh --image),
#   2. debootstraps a minimal bookworm once into a cache dir and imports it as a local base image,
#   3. builds the Dockerfile on it (--build-arg BASE=...),
#   4. runs the image as Kubernetes would (read-only root, no capabilities, uid 10001), checks with
#      the image's own `tempokey` CLI that health is SERVING and that a real clip from
#      ../shared/data round-trips through a server job, reads the metrics port,
#   5. stops it with `podman stop` (the image's STOPSIGNAL, SIGTERM) and checks it drained and
#      exited 0, then prints the image size.
#
#   deploy/image-smoke.sh
#
# Environment (defaults in brackets):
#   TEMPOKEY_IMAGE          the image built and tested [localhost/tempokey:latest]
#   TEMPOKEY_BASE_IMAGE     the local base image [localhost/bookworm-base:latest]
#   TEMPOKEY_ROOTFS_CACHE   the debootstrapped tree, reused when present [/var/cache/tempokey/bookworm]
#   TEMPOKEY_DEBIAN_MIRROR  where debootstrap and the build's apt fetch from [http://deb.debian.org/debian]
#   TEMPOKEY_SHARED_DIR     the shared folder whose data/ holds the clips [../shared]
#   TEMPOKEY_SMOKE_CLIP     the clip, relative to ../shared/data [bvh/cmu/131_01.bvh]
#   TEMPOKEY_PODMAN_STORAGE_DRIVER  e.g. vfs where overlay mounts are refused [podman's default]
#
# The image is built from the working tree as it is (uncommitted edits included; .dockerignore
# keeps build trees, tests, benchmarks and manifests out). On the 2-core machine a cold run takes
# about 9 minutes, most of it compiling; podman's layer cache makes a rerun with no source change
# take seconds. Superseded build layers stay in podman's store (about 1 GB per source change):
# `podman image prune` reclaims them, and the next build then starts from apt again.
set -euo pipefail

usage() { echo "usage: deploy/image-smoke.sh   (as root; see the header for the environment)" >&2; }
if [[ $# -gt 0 ]]; then
  usage
  [[ "$1" == "-h" || "$1" == "--help" ]] && exit 0
  exit 2
fi
if [[ $(id -u) -ne 0 ]]; then
  echo "error: run as root (debootstrap and rootful podman)" >&2
  exit 2
fi

here="$(cd "$(dirname "${BASH_SOURCE[0]}")/.." && pwd)"
shared_dir="${TEMPOKEY_SHARED_DIR:-$(cd "$here/.." && pwd)/shared}"
image="${TEMPOKEY_IMAGE:-localhost/tempokey:latest}"
base_image="${TEMPOKEY_BASE_IMAGE:-localhost/bookworm-base:latest}"
rootfs="${TEMPOKEY_ROOTFS_CACHE:-/var/cache/tempokey/bookworm}"
mirror="${TEMPOKEY_DEBIAN_MIRROR:-http://deb.debian.org/debian}"
clip="${TEMPOKEY_SMOKE_CLIP:-bvh/cmu/131_01.bvh}"

# Bounds on every step that waits on something else.
readonly kDebootstrapTimeout=1800  # downloads about 100 packages
readonly kBuildTimeout=5400        # apt + compiling the project on 2 cores, cold
readonly kStartTimeout=30          # server start to "listening"
readonly kCliTimeout=120           # one CLI container, server calls included
readonly kStopTimeout=45           # podman stop: SIGTERM, then SIGKILL after this; the drain
                                   # grace is 25 s (+ 12 s worst-case settle and shutdown)

log() { printf '\n== %s\n' "$*"; }
die() { echo "error: $*" >&2; exit 1; }

[[ -f "$shared_dir/data/$clip" ]] || die "no clip at $shared_dir/data/$clip (../shared beside the checkout?)"

log "installing podman, runc and debootstrap (deploy/install-deps.sh --image)"
"$here/deploy/install-deps.sh" --image

# What podman needs on these machines:
#   --runtime runc             required (found by trying): the hosts mount cgroups "hybrid" (v1
#                              controllers, plus a v2 hierarchy holding hugetlb), which crun 1.8
#                              refuses outright ("cgroups in hybrid mode not supported", even with
#                              --cgroups disabled);
#   --cgroup-manager cgroupfs  no systemd runs as PID 1 (nor in CI): no systemd to ask for cgroups;
#   --events-backend file      no journald either; events go to a file under /run.
# podman 4.3 falls back to the last two by itself here; they are explicit so that a machine with
# systemd installed but not running does not send podman looking for it.
# Storage stays podman's default (overlay on the host's ext4 works natively as root); set
# TEMPOKEY_PODMAN_STORAGE_DRIVER=vfs on a kernel that refuses overlay mounts.
podman=(podman --runtime runc --cgroup-manager cgroupfs --events-backend file)
if [[ -n "${TEMPOKEY_PODMAN_STORAGE_DRIVER:-}" ]]; then
  podman+=(--storage-driver "$TEMPOKEY_PODMAN_STORAGE_DRIVER")
fi
# Rootful podman asks for open files and processes limits far above the host's (1048576 and
# more), and root here lacks CAP_SYS_RESOURCE, so raising a hard limit fails at container start
# ("error setting rlimit type 7: operation not permitted"). Ask for what the host has instead:
# its hard open-files limit, and its process limit capped at pid_max (podman caps its own, and
# so the runtime's, there).
max_processes="$(ulimit -Hu)"
pid_max="$(cat /proc/sys/kernel/pid_max)"
if [[ "$max_processes" == unlimited ]] || ((max_processes > pid_max)); then
  max_processes="$pid_max"
fi
max_files="$(ulimit -Hn)"
ulimits=(--ulimit "nofile=$max_files:$max_files" --ulimit "nproc=$max_processes:$max_processes")

# --- base image -------------------------------------------------------------------------------
if [[ ! -d "$rootfs" ]]; then
  log "debootstrapping bookworm (minbase) into $rootfs"
  # Into a side directory renamed at the end, so an interrupted run is never taken for a cache.
  rm -rf "$rootfs.partial"
  mkdir -p "$(dirname "$rootfs")"
  timeout "$kDebootstrapTimeout" debootstrap --variant=minbase bookworm "$rootfs.partial" "$mirror"
  # Downloaded .debs and package lists are build-time only; the image starts without them, as the
  # registry's debian:bookworm does. The host's resolver and name are podman's to provide.
  rm -rf "$rootfs.partial"/var/cache/apt/archives/*.deb "$rootfs.partial"/var/lib/apt/lists/*
  rm -f "$rootfs.partial/etc/hostname" "$rootfs.partial/etc/resolv.conf"
  mv "$rootfs.partial" "$rootfs"
else
  echo "reusing $rootfs"
fi

if ! "${podman[@]}" image exists "$base_image"; then
  log "importing $rootfs as $base_image"
  # PATH as the registry's debian images set it: an imported tarball has no environment, and the
  # Dockerfile's RUN and exec-form ENTRYPOINT rely on it.
  tar --numeric-owner -C "$rootfs" -c . |
    "${podman[@]}" import \
      --change 'ENV PATH=/usr/local/sbin:/usr/local/bin:/usr/sbin:/usr/bin:/sbin:/bin' \
      --change 'CMD ["bash"]' - "$base_image" >/dev/null
else
  echo "reusing $base_image (podman rmi it to re-import $rootfs)"
fi

# --- image ------------------------------------------------------------------------------------
log "building $image from $here/Dockerfile (BASE=$base_image)"
# --network host: the build's apt-get reaches the Debian mirror through the host's own routes and
# resolver, with no container network (netavark/CNI, iptables) to set up. Layers are cached, so a
# rerun with no source change takes seconds.
build_start=$SECONDS
timeout "$kBuildTimeout" "${podman[@]}" build --network host "${ulimits[@]}" \
  --build-arg "BASE=$base_image" --tag "$image" --file "$here/Dockerfile" "$here"
build_seconds=$((SECONDS - build_start))
echo "image build: ${build_seconds} s"

# --- smoke test -------------------------------------------------------------------------------
work="$(mktemp -d)"
name="tempokey-smoke-$$"
cleanup() {
  "${podman[@]}" rm --force --ignore "$name" >/dev/null 2>&1 || true
  rm -rf "$work"
}
trap cleanup EXIT
mkdir "$work/out"
chown 10001 "$work/out"  # the CLI container runs as the image's user, uid 10001

# Locked down as deploy/k8s/deployment.yaml runs it: read-only root with no tmpfs added, no
# capabilities, no privilege escalation, the image's own user. --network none gives the server a
# network namespace of its own with only loopback: it listens on its ENTRYPOINT's 0.0.0.0:50051
# and 0.0.0.0:9464, unchanged, and nothing on the host can clash with those ports.
lockdown=(--read-only --read-only-tmpfs=false --cap-drop ALL --security-opt no-new-privileges
  "${ulimits[@]}")
log "starting $image as $name"
"${podman[@]}" run --detach --name "$name" --network none "${lockdown[@]}" "$image" >/dev/null

# Logs are read into a variable before grep: `podman logs | grep -q` fails under pipefail when
# grep exits at the first match and podman gets SIGPIPE.
server_logs() { "${podman[@]}" logs "$name" 2>&1; }
deadline=$((SECONDS + kStartTimeout))
until logs="$(server_logs)" && grep -q '^tempokey-server listening on' <<<"$logs"; do
  if [[ "$("${podman[@]}" inspect --format '{{.State.Running}}' "$name")" != "true" ]]; then
    "${podman[@]}" logs "$name" >&2 || true
    die "the server exited before listening"
  fi
  if ((SECONDS >= deadline)); then
    "${podman[@]}" logs "$name" >&2 || true
    die "the server did not listen within ${kStartTimeout} s"
  fi
  sleep 0.2
done
grep -m1 '^tempokey-server listening on' <<<"$logs"

# The image's own CLI, in a second container that joins the server's network namespace, so
# 127.0.0.1:50051 is the server. ../shared/data is mounted read-only; outputs go to $work/out.
cli() {
  timeout "$kCliTimeout" "${podman[@]}" run --rm --network "container:$name" "${lockdown[@]}" \
    --volume "$shared_dir/data:/data:ro" --volume "$work/out:/out" \
    --entrypoint /usr/local/bin/tempokey "$image" --server 127.0.0.1:50051 --timeout 60 "$@"
}

log "tempokey health"
health_status=0
health="$(cli health)" || health_status=$?
echo "$health"
[[ $health_status -eq 0 ]] || die "tempokey health exited $health_status (want 0: live and ready)"
[[ "$(grep -c ': *SERVING$' <<<"$health")" -eq 2 ]] || die "expected live and ready SERVING"

log "tempokey run /data/$clip (upload, job, watch, result)"
cli run "/data/$clip" -o /out/roundtrip.bvh
# The clip came back with the same shape (frames, rate, joints, channels, rotation orders)...
diff <(cli info "/data/$clip" | grep -v '^name:') <(cli info /out/roundtrip.bvh | grep -v '^name:') ||
  die "the round-tripped clip differs from the input (summaries above)"
# ...and the same samples: a second trip through the server writes the same bytes (BVH numbers
# are written in the shortest form that reads back to the same double).
cli run /out/roundtrip.bvh -o /out/roundtrip2.bvh >/dev/null
cmp "$work/out/roundtrip.bvh" "$work/out/roundtrip2.bvh" || die "a second round trip changed the clip"
echo "round trip: same summary, second trip byte-identical ($(wc -c <"$work/out/roundtrip.bvh") bytes)"

log "metrics on 9464 (from inside the server's network namespace)"
# The runtime image has no HTTP client: the host's curl enters the container's network namespace.
server_pid="$("${podman[@]}" inspect --format '{{.State.Pid}}' "$name")"
metrics="$(timeout 10 nsenter --target "$server_pid" --net curl --silent --show-error --fail \
  http://127.0.0.1:9464/metrics)" || die "no metrics on 9464"
grep -E '^tempokey_jobs_total\{' <<<"$metrics" || die "metrics have no tempokey_jobs_total"

log "podman stop (SIGTERM, drain)"
timeout $((kStopTimeout + 15)) "${podman[@]}" stop --time "$kStopTimeout" "$name" >/dev/null
exit_code="$("${podman[@]}" inspect --format '{{.State.ExitCode}}' "$name")"
logs="$(server_logs)"
tail -n 4 <<<"$logs"
[[ "$exit_code" == "0" ]] || die "tempokey-server exited with $exit_code after SIGTERM (want 0)"
grep -q 'received SIGTERM, draining' <<<"$logs" ||
  die "the server did not log a SIGTERM drain (was it stopped by another signal?)"
echo "tempokey-server exited 0 after a SIGTERM drain"

log "image"
size_bytes="$("${podman[@]}" image inspect --format '{{.Size}}' "$image")"
base_bytes="$("${podman[@]}" image inspect --format '{{.Size}}' "$base_image")"
echo "$image: $(numfmt --to=iec-i --suffix=B "$size_bytes") ($size_bytes bytes; base $(numfmt --to=iec-i --suffix=B "$base_bytes")), built in ${build_seconds} s"
echo "image smoke test passed"
