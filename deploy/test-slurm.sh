#!/bin/bash
# The worker job array (deploy/slurm-workers.sbatch) under a real Slurm, on this machine:
#
#   deploy/test-slurm.sh            (as root; after `cargo build --release`)
#
# 1. Installs Debian's slurm-wlm and munge if they are missing, then starts munged, slurmctld and
#    slurmd itself (there is no systemd), each with its own key, socket, ports and folders under
#    a temporary directory, so nothing of an existing Slurm or munge is touched.
# 2. Starts a coordinator, submits a 4-frame SPPM sequence, and renders it on a 2-task array
#    submitted with sbatch: each frame must have the bytes of `coordinator render --frames`.
# 3. Submits a longer job, and `scancel`s the array while it renders. Slurm sends SIGTERM: each
#    worker must deliver (or release) the batch under way, so no lease is left to expire (the
#    lease timeout is 120 s; the check is made within 20 s). A second array then finishes the
#    job, whose image must again have the local render's bytes: no pass lost, none counted twice.
# 4. Tears everything down (also on failure).
#
# Prints each step; exits 0 only if every check passed. About a minute on 2 cores.
set -euo pipefail

ROOT=$(cd "$(dirname "$0")/.." && pwd)
BIN=${PHOTONFARM_BIN:-$ROOT/target/release}
for b in coordinator worker; do
    [ -x "$BIN/$b" ] || { echo "test-slurm: $BIN/$b is missing: run cargo build --release" >&2; exit 1; }
done
if ! command -v slurmctld >/dev/null || ! command -v slurmd >/dev/null || ! command -v munged >/dev/null; then
    echo "== installing slurm-wlm and munge"
    DEBIAN_FRONTEND=noninteractive apt-get install -y --no-install-recommends slurm-wlm munge >/dev/null
fi

WORK=$(mktemp -d /tmp/photonfarm-slurm.XXXXXX)
PIDS=()
cleanup() {
    local status=$?
    if [ -n "${SLURM_CONF:-}" ]; then
        scancel --quiet --user root 2>/dev/null || true
    fi
    for pidfile in "$WORK"/run/*.pid; do
        [ -f "$pidfile" ] && kill "$(cat "$pidfile")" 2>/dev/null || true
    done
    for p in "${PIDS[@]}"; do kill "$p" 2>/dev/null || true; done
    sleep 1
    rm -rf "$WORK"
    [ $status -eq 0 ] && echo "test-slurm: passed" || echo "test-slurm: FAILED (status $status)" >&2
}
trap cleanup EXIT
fail() { echo "test-slurm: $*" >&2; exit 1; }
mkdir -p "$WORK"/{munge,run,log,state,spool,jobs}

echo "== munged"
mungekey --create --keyfile "$WORK/munge/munge.key" >/dev/null 2>&1 \
    || { dd if=/dev/urandom of="$WORK/munge/munge.key" bs=1 count=1024 2>/dev/null; chmod 600 "$WORK/munge/munge.key"; }
MUNGE_SOCKET=$WORK/munge/munge.socket
munged --force --socket="$MUNGE_SOCKET" --key-file="$WORK/munge/munge.key" \
    --pid-file="$WORK/run/munged.pid" --log-file="$WORK/log/munged.log" --seed-file="$WORK/munge/seed"
munge --socket="$MUNGE_SOCKET" -n | unmunge --socket="$MUNGE_SOCKET" >/dev/null || fail "munge does not work"

echo "== slurmctld and slurmd"
NODE=$(hostname -s)
PORT=$((20000 + $$ % 20000))
export SLURM_CONF=$WORK/slurm.conf
cat > "$SLURM_CONF" <<EOF
ClusterName=photonfarm-test
SlurmctldHost=$NODE
SlurmUser=root
SlurmdUser=root
AuthType=auth/munge
AuthInfo=socket=$MUNGE_SOCKET
CredType=cred/munge
StateSaveLocation=$WORK/state
SlurmdSpoolDir=$WORK/spool
SlurmctldPidFile=$WORK/run/slurmctld.pid
SlurmdPidFile=$WORK/run/slurmd.pid
SlurmctldLogFile=$WORK/log/slurmctld.log
SlurmdLogFile=$WORK/log/slurmd.log
SlurmctldPort=$PORT
SlurmdPort=$((PORT + 1))
ProctrackType=proctrack/linuxproc
TaskPlugin=task/none
JobAcctGatherType=jobacct_gather/none
AccountingStorageType=accounting_storage/none
SelectType=select/cons_tres
SelectTypeParameters=CR_Core
MpiDefault=none
ReturnToService=2
KillWait=30
NodeName=$NODE CPUs=$(nproc) RealMemory=2000 State=UNKNOWN
PartitionName=test Nodes=ALL Default=YES MaxTime=INFINITE State=UP
EOF
slurmctld -f "$SLURM_CONF"
slurmd -f "$SLURM_CONF"
for _ in $(seq 60); do
    [ "$(sinfo -h -o %t 2>/dev/null)" = idle ] && break
    sleep 0.5
done
[ "$(sinfo -h -o %t)" = idle ] || fail "the node did not come up: $(tail -5 "$WORK/log/slurmctld.log")"
sinfo

echo "== coordinator"
export PHOTONFARM_TOKEN=client-$$
export PHOTONFARM_WORKER_TOKEN=worker-$$
"$BIN/coordinator" serve --bind 127.0.0.1:0 --data "$WORK/data" --lease-timeout 120 \
    --batch-seconds 1 > "$WORK/log/serve.out" 2> "$WORK/log/serve.log" &
PIDS+=($!)
for _ in $(seq 100); do
    URL=$(sed -n 's/^listening on //p' "$WORK/log/serve.out")
    [ -n "$URL" ] && break
    sleep 0.1
done
[ -n "$URL" ] || fail "the coordinator did not start: $(cat "$WORK/log/serve.log")"
echo "coordinator at $URL"

# Submits the array of $1 tasks; prints its Slurm job id.
array() {
    PHOTONFARM_COORDINATOR=$URL PHOTONFARM_WORKER=$BIN/worker PHOTONFARM_TOKEN=$PHOTONFARM_WORKER_TOKEN \
        sbatch --parsable --export=ALL --array=0-$(($1 - 1)) --cpus-per-task=1 --mem-per-cpu=500M \
        --time=00:10:00 --chdir="$WORK/jobs" --output="$WORK/jobs/worker-%A_%a.log" \
        "$ROOT/deploy/slurm-workers.sbatch"
}
status() { curl -sf -H "Authorization: Bearer $PHOTONFARM_TOKEN" "$URL/api/jobs/$1"; }
field() { python3 -c "import json,sys; print(json.load(sys.stdin)[\"$1\"])"; }
SCENE=$ROOT/tests/refs/cbox-spheres.xml

echo "== an SPPM sequence of 4 frames on a 2-task array"
SEQ=(--frames 1-4 -D angle=-20:20 -D roll=-0.5:0.4 --integrator sppm --iterations 12
     --photons 20000 -D res=48 --seed 3 --checkpoint-every 12)
JOB=$("$BIN/coordinator" submit --to "$URL" "$ROOT/scenes/turntable.xml" "${SEQ[@]}")
ARRAY=$(array 2)
echo "job $JOB, array $ARRAY"
"$BIN/coordinator" wait --to "$URL" "$JOB" --out "$WORK/farm-#.exr"
squeue -h -j "$ARRAY" -o "%i %T" | sed 's/^/  task /'
"$BIN/coordinator" render "$ROOT/scenes/turntable.xml" "${SEQ[@]}" --out "$WORK/local-#.exr" 2>/dev/null
for f in 1 2 3 4; do
    cmp "$WORK/farm-$f.exr" "$WORK/local-$f.exr" || fail "frame $f differs from coordinator render --frames"
done
echo "every frame has the bytes of coordinator render --frames"
scancel --quiet "$ARRAY"

echo "== scancel while the array renders"
PATH_JOB=(--integrator path --spp 3000 -D res=64 --seed 4)
JOB=$("$BIN/coordinator" submit --to "$URL" "$SCENE" "${PATH_JOB[@]}" --checkpoint-every 3000)
ARRAY=$(array 2)
for _ in $(seq 300); do
    DONE=$(status "$JOB" | field iterations_done)
    [ "$DONE" -ge 300 ] && break
    sleep 0.2
done
[ "$DONE" -ge 300 ] || fail "the array rendered nothing in 60 s"
echo "$DONE of 3000 passes in; scancel $ARRAY"
scancel "$ARRAY"
for _ in $(seq 100); do
    HELD=$(status "$JOB" | python3 -c "import json,sys; print(len(json.load(sys.stdin)['workers']))")
    [ "$HELD" = 0 ] && break
    sleep 0.2
done
[ "$HELD" = 0 ] || fail "a lease is still held 20 s after scancel: its batch was neither delivered nor released"
grep -l "shutting down after the batch under way" "$WORK"/jobs/worker-"$ARRAY"_*.log >/dev/null \
    || fail "no worker logged Slurm's SIGTERM: $(cat "$WORK"/jobs/worker-"$ARRAY"_*.log)"
AFTER=$(status "$JOB" | field iterations_done)
echo "every batch delivered or released within seconds; $AFTER passes in"
[ "$AFTER" -lt 3000 ] || fail "the job finished before scancel: make it longer"
ARRAY=$(array 2)
"$BIN/coordinator" wait --to "$URL" "$JOB" --out "$WORK/farm2.exr"
"$BIN/coordinator" render "$SCENE" "${PATH_JOB[@]}" --checkpoint-every 3000 --out "$WORK/local2.exr" 2>/dev/null
cmp "$WORK/farm2.exr" "$WORK/local2.exr" || fail "after scancel, the image differs from coordinator render's"
echo "a second array finished the job: same bytes as coordinator render"
