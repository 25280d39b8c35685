#!/usr/bin/env bash
# End-to-end test of the Dockerfile and docker-compose.yml on one Debian 12 host (as root):
#   1. a Docker engine (installs docker.io / docker-compose / debootstrap and starts dockerd
#      if `docker info` fails);
#   2. the Dockerfile's base images: Docker Hub's if the Hub answers, else local stand-ins
#      (a debootstrap'ed bookworm for debian:bookworm-slim; that plus gcc and a Rust 1.95
#      toolchain, the host's or rustup's, for rust:1.95-bookworm);
#   3. `compose build`; `render --denoise` in the image (OIDN loads); a coordinator and two
#      workers with PHOTONFARM_TOKEN set, /healthz;
#   4. a small SPPM job submitted from the host: its PNG must equal, byte for byte, a local
#      `coordinator render` of the same scene and settings;
#   5. a longer job while the workers are scaled to 3 (at 10%) and then to 1 (at 35%): same check;
#   6. `compose down -v`.
# Exits non-zero, saying which step failed, on any failure; prints each step's time.
#
# Settings (environment):
#   COMPOSE="docker compose" | "docker-compose"  compose command [whichever is installed, v2 first]
#   PHOTONFARM_BASES=auto|hub|local   base images [auto: local if Docker Hub does not answer]
#   PHOTONFARM_REBUILD_BASES=1        remake the local base images even if present
#   PHOTONFARM_PORT=8080              the coordinator's published port
#   PHOTONFARM_TOKEN                  the farm's token [random]
#   PHOTONFARM_TEST_DIR               where images and logs go [a new /tmp/photonfarm-compose.*]
#   KEEP=1                            leave the farm running at the end (no `down -v`)
set -Eeuo pipefail

REPO=$(cd "$(dirname "${BASH_SOURCE[0]}")/.." && pwd)
cd "$REPO"
WORK=${PHOTONFARM_TEST_DIR:-$(mktemp -d /tmp/photonfarm-compose.XXXXXX)}
mkdir -p "$WORK"
export COMPOSE_PROJECT_NAME=${COMPOSE_PROJECT_NAME:-photonfarm-test}
export PHOTONFARM_PORT=${PHOTONFARM_PORT:-8080}
export PHOTONFARM_TOKEN=${PHOTONFARM_TOKEN:-$(head -c 16 /dev/urandom | od -An -tx1 | tr -d ' \n')}
BASES=${PHOTONFARM_BASES:-auto}
LOCAL_DEBIAN=photonfarm-local/debian:bookworm
LOCAL_RUST=photonfarm-local/rust:1.95-bookworm
RUST_VERSION=1.95
URL=http://127.0.0.1:$PHOTONFARM_PORT
SCENE=scenes/cbox-spheres.xml
SMALL=(--integrator sppm --iterations 24 --photons 50000 -D res=64)
LONG=(--integrator sppm --iterations 300 --photons 200000 -D res=64)

# ---- reporting -----------------------------------------------------------------------------
T0=$(date +%s)
STEP="" STEP_T=0 FARM_UP=0
TIMINGS=() RESULTS=()
log() { printf '[%s] %s\n' "$(date -u +%H:%M:%S)" "$*"; }
step() {
    end_step
    STEP=$1 STEP_T=$(date +%s)
    echo
    log "=== $STEP"
}
end_step() {
    if [[ -n $STEP ]]; then
        TIMINGS+=("$(printf '%5ss  %s' $(($(date +%s) - STEP_T)) "$STEP")")
        STEP=""
    fi
}
die() {
    echo >&2
    echo "FAILED in step \"${STEP:-?}\": $*" >&2
    exit 1
}
summary() {
    echo
    echo "==== summary ($WORK)"
    echo "docker:  $(docker version --format 'client {{.Client.Version}}, engine {{.Server.Version}} (API {{.Server.APIVersion}})' 2>/dev/null || echo '?')"
    echo "compose: ${DC[*]:-?}: $("${DC[@]}" version --short 2>/dev/null || "${DC[@]}" version 2>/dev/null | head -1 || echo '?')"
    echo "bases:   build ${PHOTONFARM_BUILD_IMAGE:-?}, runtime ${PHOTONFARM_RUNTIME_IMAGE:-?}"
    echo "timings:"
    printf '  %s\n' "${TIMINGS[@]}"
    printf '  %5ss  total\n' $(($(date +%s) - T0))
    if ((${#RESULTS[@]})); then
        echo "checks:"
        printf '  %s\n' "${RESULTS[@]}"
    fi
}
on_exit() {
    local rc=$?
    trap - EXIT ERR
    set +e
    if ((rc != 0)); then
        end_step
        if ((FARM_UP)); then
            echo "---- last compose logs" >&2
            "${DC[@]}" logs --no-color --tail 30 >&2 2>&1
        fi
    fi
    if ((FARM_UP)) && [[ ${KEEP:-0} != 1 ]]; then
        log "tearing down (down -v)"
        "${DC[@]}" down -v --remove-orphans >"$WORK/down.log" 2>&1
    fi
    summary
    if ((rc == 0)); then echo "PASS"; else echo "FAIL (exit $rc): see above and $WORK" >&2; fi
    exit $rc
}
trap on_exit EXIT
trap 'die "command failed (line $LINENO): $BASH_COMMAND"' ERR
DC=()

APT_UPDATED=0
apt_install() {
    if ((!APT_UPDATED)); then
        apt-get update -qq >"$WORK/apt.log" 2>&1 || die "apt-get update failed (see $WORK/apt.log)"
        APT_UPDATED=1
    fi
    log "apt-get install -y $*"
    DEBIAN_FRONTEND=noninteractive apt-get install -y -qq "$@" >>"$WORK/apt.log" 2>&1 ||
        die "apt-get install $* failed (see $WORK/apt.log)"
}

# Answers an HTTP request with the farm's token: prints the body, fails on an HTTP error.
api() { curl -fsS -m 10 -H "Authorization: Bearer $PHOTONFARM_TOKEN" "$URL$1"; }
json_field() { sed -nE "s/.*\"$1\":\"?([^\",}]*).*/\1/p"; }

# ---- 1. Docker engine ----------------------------------------------------------------------
step "1. Docker engine"
((EUID == 0)) || die "run as root (installs packages and starts dockerd)"
command -v curl >/dev/null || apt_install curl ca-certificates
if ! docker info >/dev/null 2>&1; then
    command -v dockerd >/dev/null && command -v docker >/dev/null || apt_install docker.io
    if ! docker info >/dev/null 2>&1; then
        log "starting dockerd in the background (log: $WORK/dockerd.log)"
        setsid nohup dockerd >"$WORK/dockerd.log" 2>&1 </dev/null &
        for _ in $(seq 60); do
            docker info >/dev/null 2>&1 && break
            sleep 1
        done
        docker info >/dev/null 2>&1 || die "dockerd did not answer within 60 s (see $WORK/dockerd.log)"
    fi
fi
if [[ -n ${COMPOSE:-} ]]; then
    read -ra DC <<<"$COMPOSE"
elif docker compose version >/dev/null 2>&1; then
    DC=(docker compose)
else
    command -v docker-compose >/dev/null || apt_install docker-compose
    DC=(docker-compose)
fi
"${DC[@]}" version >/dev/null 2>&1 || die "compose command '${DC[*]}' does not work"
log "docker $(docker version --format '{{.Client.Version}} / engine {{.Server.Version}}'); compose: ${DC[*]}"
"${DC[@]}" ps -q 2>/dev/null | grep -q . &&
    die "compose project $COMPOSE_PROJECT_NAME is already running: '${DC[*]} -p $COMPOSE_PROJECT_NAME down -v' first"
if (echo >"/dev/tcp/127.0.0.1/$PHOTONFARM_PORT") 2>/dev/null; then
    die "port $PHOTONFARM_PORT is in use: set PHOTONFARM_PORT to a free one"
fi

# ---- 2. base images ------------------------------------------------------------------------
step "2. base images"
if [[ $BASES == auto ]]; then
    # Any HTTP answer (401 included) means the registry is reachable.
    if curl -sS -m 10 -o /dev/null https://registry-1.docker.io/v2/ 2>/dev/null; then BASES=hub; else BASES=local; fi
    log "Docker Hub $([[ $BASES == hub ]] && echo answers: using its images || echo 'is out of reach: making local base images')"
fi
if [[ $BASES == hub ]]; then
    export PHOTONFARM_BUILD_IMAGE=rust:1.95-bookworm PHOTONFARM_RUNTIME_IMAGE=debian:bookworm-slim
else
    export PHOTONFARM_BUILD_IMAGE=$LOCAL_RUST PHOTONFARM_RUNTIME_IMAGE=$LOCAL_DEBIAN
    have_image() { docker image inspect "$1" >/dev/null 2>&1 && [[ ${PHOTONFARM_REBUILD_BASES:-0} != 1 ]]; }

    if have_image "$LOCAL_DEBIAN"; then
        log "$LOCAL_DEBIAN exists (PHOTONFARM_REBUILD_BASES=1 remakes it)"
    else
        command -v debootstrap >/dev/null || apt_install debootstrap
        # The Debian mirror this machine's apt uses (uncommented lines only), else deb.debian.org.
        MIRROR=$(cat /etc/apt/sources.list /etc/apt/sources.list.d/*.list /etc/apt/sources.list.d/*.sources 2>/dev/null |
            grep -v '^[[:space:]]*#' | grep -oE 'https?://[^[:space:]]+' | grep -E '/debian/?$' | head -1 || true)
        MIRROR=${MIRROR:-http://deb.debian.org/debian}
        ROOTFS=$WORK/rootfs
        rm -rf "$ROOTFS"
        log "debootstrap --variant=minbase bookworm $ROOTFS $MIRROR (log: $WORK/debootstrap.log)"
        debootstrap --variant=minbase bookworm "$ROOTFS" "$MIRROR" >"$WORK/debootstrap.log" 2>&1 ||
            die "debootstrap failed (see $WORK/debootstrap.log)"
        rm -rf "$ROOTFS"/var/cache/apt/archives/*.deb "$ROOTFS"/var/lib/apt/lists/*
        log "docker import -> $LOCAL_DEBIAN"
        tar -C "$ROOTFS" -c . | docker import \
            -c 'ENV PATH=/usr/local/sbin:/usr/local/bin:/usr/sbin:/usr/bin:/sbin:/bin' \
            -c 'CMD ["bash"]' - "$LOCAL_DEBIAN" >/dev/null
        rm -rf "$ROOTFS"
    fi

    if have_image "$LOCAL_RUST"; then
        log "$LOCAL_RUST exists (PHOTONFARM_REBUILD_BASES=1 remakes it)"
    else
        CTX=$WORK/rust-image
        rm -rf "$CTX"
        mkdir -p "$CTX"
        # The host's trust store: where TLS is intercepted, cargo in the build stage needs its CA.
        if [[ -f /etc/ssl/certs/ca-certificates.crt ]]; then
            cp /etc/ssl/certs/ca-certificates.crt "$CTX/ca-certificates.crt"
            CA_COPY='COPY ca-certificates.crt /etc/ssl/certs/ca-certificates.crt'
        else
            CA_COPY=''
        fi
        # The toolchain: the host's Rust 1.95 if it has one, else rustup from static.rust-lang.org.
        SYSROOT=""
        for v in "" "+$RUST_VERSION" "+$RUST_VERSION.0"; do
            if ver=$(rustc $v --version 2>/dev/null) && [[ $ver == "rustc $RUST_VERSION."* ]]; then
                SYSROOT=$(rustc $v --print sysroot)
                break
            fi
        done
        if [[ -n $SYSROOT ]]; then
            log "toolchain: the host's $ver ($SYSROOT, without its docs)"
            mkdir -p "$CTX/rust"
            for d in bin lib libexec; do
                [[ -d $SYSROOT/$d ]] || continue
                cp -al "$SYSROOT/$d" "$CTX/rust/" 2>/dev/null || cp -a "$SYSROOT/$d" "$CTX/rust/"
            done
            TOOLCHAIN='COPY rust /usr/local/rust
ENV PATH=/usr/local/cargo/bin:/usr/local/rust/bin:$PATH'
        else
            curl -fsS -m 20 -o /dev/null -I https://static.rust-lang.org/rustup/dist/x86_64-unknown-linux-gnu/rustup-init ||
                die "no Rust $RUST_VERSION on the host and static.rust-lang.org is out of reach: install it with rustup on the host"
            log "toolchain: rustup $RUST_VERSION (minimal profile) from static.rust-lang.org"
            TOOLCHAIN="ENV RUSTUP_HOME=/usr/local/rustup PATH=/usr/local/cargo/bin:\$PATH
RUN apt-get update && apt-get install -y --no-install-recommends curl && rm -rf /var/lib/apt/lists/* \\
    && curl -fsSL -o /tmp/rustup-init https://static.rust-lang.org/rustup/dist/x86_64-unknown-linux-gnu/rustup-init \\
    && chmod +x /tmp/rustup-init \\
    && /tmp/rustup-init -y --no-modify-path --profile minimal --default-toolchain $RUST_VERSION \\
    && rm /tmp/rustup-init"
        fi
        cat >"$CTX/Dockerfile" <<EOF
# A stand-in for rust:$RUST_VERSION-bookworm, made by deploy/test-compose.sh.
FROM $LOCAL_DEBIAN
RUN apt-get update \\
    && apt-get install -y --no-install-recommends gcc libc6-dev pkg-config make ca-certificates \\
    && rm -rf /var/lib/apt/lists/*
$CA_COPY
ENV CARGO_HOME=/usr/local/cargo CARGO_HTTP_CAINFO=/etc/ssl/certs/ca-certificates.crt
$TOOLCHAIN
RUN rustc --version && cargo --version
EOF
        log "docker build -> $LOCAL_RUST (log: $WORK/rust-image.log)"
        DOCKER_BUILDKIT=0 docker build -t "$LOCAL_RUST" "$CTX" >"$WORK/rust-image.log" 2>&1 ||
            die "building $LOCAL_RUST failed (see $WORK/rust-image.log)"
        grep -m1 '^rustc ' "$WORK/rust-image.log" | sed 's/^/  image: /' || true
        rm -rf "$CTX"
    fi
fi
log "build image $PHOTONFARM_BUILD_IMAGE, runtime image $PHOTONFARM_RUNTIME_IMAGE"

# The host's coordinator, copied so that a concurrent `cargo build` cannot swap it mid-test.
step "host coordinator binary"
if [[ ! -x target/release/coordinator ]]; then
    log "cargo build --release -p coordinator"
    cargo build --release -p coordinator || die "cargo build --release -p coordinator failed"
fi
cp target/release/coordinator "$WORK/coordinator"
CO=$WORK/coordinator
log "$("$CO" --version)"

# ---- 3. build and start --------------------------------------------------------------------
step "3a. compose build"
log "${DC[*]} build (log: $WORK/build.log)"
"${DC[@]}" build >"$WORK/build.log" 2>&1 || { tail -30 "$WORK/build.log" >&2; die "compose build failed (see $WORK/build.log)"; }
tail -3 "$WORK/build.log"

step "3a'. denoising in the image (Open Image Denoise at the coordinator's run path)"
docker run --rm photonfarm sh -c 'coordinator render /usr/share/photonfarm/scenes/cbox-spheres.xml \
    -D res=32 --spp 4 --denoise --out /tmp/d.exr && test -s /tmp/d.denoised.exr' >"$WORK/denoise.log" 2>&1 ||
    { tail -5 "$WORK/denoise.log" >&2; die "render --denoise failed in the image (see $WORK/denoise.log)"; }
log "$(grep -m1 'denoised in' "$WORK/denoise.log")"

step "3b. compose up: coordinator and 2 workers"
FARM_UP=1
"${DC[@]}" up -d --no-build >"$WORK/up.log" 2>&1 || { cat "$WORK/up.log" >&2; die "compose up failed"; }
for _ in $(seq 60); do
    api /healthz >/dev/null 2>&1 && break
    sleep 1
done
api /healthz >/dev/null || die "$URL/healthz did not answer within 60 s"
log "/healthz: $(api /healthz)"
curl -fsS -o /dev/null "$URL/api/jobs" 2>/dev/null && die "/api/jobs answered without the token"
running_workers() { "${DC[@]}" ps -q worker 2>/dev/null | xargs -r docker inspect -f '{{.State.Running}}' | grep -c true || true; }
n=$(running_workers)
[[ $n == 2 ]] || die "expected 2 running workers, found $n"
log "workers running: $n"

# ---- 4. small job: farm vs local -----------------------------------------------------------
step "4. small job (${SMALL[*]})"
OUT=$WORK/out
mkdir -p "$OUT"
log "submit --wait --out $OUT/small-farm.png"
"$CO" submit --to "$URL" --token "$PHOTONFARM_TOKEN" "$SCENE" "${SMALL[@]}" --checkpoint-every 8 \
    --wait --out "$OUT/small-farm.png" >"$OUT/small-submit.log" 2>&1 ||
    { tail -5 "$OUT/small-submit.log" >&2; die "submit of the small job failed"; }
log "local render"
"$CO" render "$SCENE" "${SMALL[@]}" --out "$OUT/small-local.png" >"$OUT/small-local.log" 2>&1 ||
    { tail -5 "$OUT/small-local.log" >&2; die "local render failed"; }
cmp "$OUT/small-farm.png" "$OUT/small-local.png" ||
    die "the farm's image differs from the local render ($OUT/small-farm.png vs small-local.png)"
RESULTS+=("small job: cmp small-farm.png small-local.png: identical ($(stat -c %s "$OUT/small-farm.png") bytes, sha256 $(sha256sum <"$OUT/small-farm.png" | cut -c1-16))")
log "${RESULTS[-1]}"

# ---- 5. longer job while scaling -----------------------------------------------------------
step "5. long job (${LONG[*]}), workers 2 -> 3 -> 1"
ID=$("$CO" submit --to "$URL" --token "$PHOTONFARM_TOKEN" "$SCENE" "${LONG[@]}" --checkpoint-every 50 2>"$OUT/long-submit.log") ||
    { cat "$OUT/long-submit.log" >&2; die "submit of the long job failed"; }
log "job $ID submitted"
"$CO" wait --to "$URL" --token "$PHOTONFARM_TOKEN" "$ID" --out "$OUT/long-farm.png" >"$OUT/long-wait.log" 2>&1 &
WAIT_PID=$!
TOTAL=${LONG[*]}
TOTAL=${TOTAL#*--iterations }
TOTAL=${TOTAL%% *}
job() { api "/api/jobs/$ID"; }
done_passes() { job | json_field iterations_done; }
wait_passes() { # until the job has at least $1 passes (and is not over), at most $2 s
    local t=$(($(date +%s) + $2)) d s
    while (($(date +%s) < t)); do
        s=$(job) || die "GET /api/jobs/$ID failed"
        d=$(json_field iterations_done <<<"$s")
        [[ $(json_field state <<<"$s") == @(done|failed|cancelled) ]] &&
            die "job $ID ended ($(json_field state <<<"$s") at $d/$TOTAL) before the scaling was done: make it longer"
        ((d >= $1)) && return 0
        sleep 1
    done
    die "job $ID did not reach $1 passes within $2 s (at ${d:-?})"
}
wait_passes $((TOTAL / 10)) 300
log "at $(done_passes)/$TOTAL passes: --scale worker=3"
"${DC[@]}" up -d --no-build --no-recreate --scale worker=3 >>"$WORK/up.log" 2>&1 || die "scaling to 3 workers failed"
n=$(running_workers)
[[ $n == 3 ]] || die "expected 3 running workers, found $n"
wait_passes $((TOTAL * 35 / 100)) 300
present=$(job | json_field workers_present)
log "at $(done_passes)/$TOTAL passes, $n workers running ($present present at the coordinator): --scale worker=1"
RESULTS+=("long job: scaled to 3 workers (coordinator saw $present) and back to 1 mid-job")
"${DC[@]}" up -d --no-build --no-recreate --scale worker=1 >>"$WORK/up.log" 2>&1 || die "scaling to 1 worker failed"
n=$(running_workers)
[[ $n == 1 ]] || die "expected 1 running worker, found $n"
d=$(done_passes)
log "at $d/$TOTAL passes with 1 worker"
((d < TOTAL)) || die "job $ID finished while scaling down: make it longer"
wait "$WAIT_PID" || { tail -5 "$OUT/long-wait.log" >&2; die "waiting for job $ID failed"; }
s=$(job)
[[ $(json_field state <<<"$s") == done ]] || die "job $ID ended as $(json_field state <<<"$s")"
log "job $ID done: $(json_field iterations_done <<<"$s") passes in $(json_field elapsed_seconds <<<"$s") s, $(json_field batches_received <<<"$s") batches"
log "local render"
"$CO" render "$SCENE" "${LONG[@]}" --out "$OUT/long-local.png" >"$OUT/long-local.log" 2>&1 ||
    { tail -5 "$OUT/long-local.log" >&2; die "local render failed"; }
cmp "$OUT/long-farm.png" "$OUT/long-local.png" ||
    die "the farm's image differs from the local render ($OUT/long-farm.png vs long-local.png)"
RESULTS+=("long job: cmp long-farm.png long-local.png: identical ($(stat -c %s "$OUT/long-farm.png") bytes, sha256 $(sha256sum <"$OUT/long-farm.png" | cut -c1-16))")
log "${RESULTS[-1]}"

# ---- 6. tear down --------------------------------------------------------------------------
step "6. down -v"
if [[ ${KEEP:-0} == 1 ]]; then
    log "KEEP=1: leaving the farm running at $URL"
else
    "${DC[@]}" down -v --remove-orphans >"$WORK/down.log" 2>&1 || { cat "$WORK/down.log" >&2; die "compose down -v failed"; }
    FARM_UP=0
    left=$(docker ps -aq --filter "label=com.docker.compose.project=$COMPOSE_PROJECT_NAME")
    [[ -z $left ]] || die "containers left after down -v: $left"
    docker volume ls -q | grep -q "^${COMPOSE_PROJECT_NAME}_farm-data$" && die "volume ${COMPOSE_PROJECT_NAME}_farm-data left after down -v"
    log "no containers or volumes left"
fi
end_step
