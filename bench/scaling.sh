#!/usr/bin/env bash
# How far one coordinator goes (docs/scaling.md): a real `coordinator serve` pinned to core 0,
# `coordinator loadgen` (and relays, if any) pinned to core 1, one configuration per line of
# RUNS below. Prints each run's figures. Needs `cargo build --release -p coordinator` and 2
# cores; takes about 15 minutes.
#
#   bench/scaling.sh [TARGET_DIR]
set -euo pipefail
bin=${1:-target}/release/coordinator
work=$(mktemp -d)
trap 'kill $(jobs -p) 2>/dev/null; rm -rf "$work"' EXIT

# run NAME "SERVE FLAGS" "LOADGEN FLAGS" [RELAYS]
run() {
    local name=$1 serve_flags=$2 load_flags=$3 relays=${4:-0}
    rm -rf "$work/data"
    taskset -c 0 "$bin" serve --bind 127.0.0.1:0 --data "$work/data" $serve_flags >"$work/serve.out" 2>/dev/null &
    local pid=$!
    until grep -q listening "$work/serve.out" 2>/dev/null; do sleep 0.1; done
    local url; url=$(sed -n 's/listening on //p' "$work/serve.out")
    local via="" rpids=()
    for i in $(seq 1 "$relays"); do
        taskset -c 1 "$bin" relay --upstream "$url" --bind 127.0.0.1:0 --name "relay-$i" >"$work/relay$i.out" 2>/dev/null &
        rpids+=($!)
        until grep -q listening "$work/relay$i.out" 2>/dev/null; do sleep 0.1; done
        via="$via${via:+,}$(sed -n 's/listening on //p' "$work/relay$i.out")"
    done
    echo "== $name (serve $serve_flags; relays $relays)"
    timeout 900 taskset -c 1 "$bin" loadgen --coordinator "$url" ${via:+--via "$via"} --coordinator-pid "$pid" $load_flags 2>/dev/null
    kill "$pid" "${rpids[@]}" 2>/dev/null || true
    wait "$pid" "${rpids[@]}" 2>/dev/null || true
}

sat="--batch-seconds 0.001 --absorb-mpx-per-second 0"
for size in "--width 512 --height 512" "--width 1920 --height 1080"; do
    # Capacity: workers that render instantly, uploading as fast as the coordinator takes them.
    run "capacity, plain" "$sat" "$size --workers 16 --pass-seconds 0 --warmup 5 --duration 20 --identity"
    run "capacity, zstd" "$sat" "$size --workers 16 --pass-seconds 0 --warmup 5 --duration 20"
done
fixed="--absorb-mpx-per-second 0"
# Before: plain results, fixed 5 s batches.
run "before, 512x512" "$fixed" "--width 512 --height 512 --workers ${N512:-400} --identity --warmup 20 --duration 40"
run "before, 1920x1080" "$fixed" "--width 1920 --height 1080 --workers ${N1080:-40} --identity --warmup 20 --duration 40"
# After: zstd and batches that lengthen with the workers.
run "after, 1000 workers, 1920x1080" "" "--workers 1000 --warmup 60 --duration 60"
# After, with relays of 50 workers (simulated: the coordinator sees 20 clients, each 50x faster).
run "after, 1000 workers behind 20 relays of 50, 1920x1080" "" "--workers 1000 --fanout 50 --warmup 30 --duration 60"
# Real relays (on core 1 with the load generator): 2 relays, 60 workers, 1920x1080.
run "real relays, 60 workers behind 2 relays, 1920x1080" "" "--workers 60 --warmup 30 --duration 40" 2
