#!/usr/bin/env bash
# Builds isobar, sets up the benchmark's Python environment and runs bench_sph.py on the
# frames at hand; each table goes to bench/results/<frame>.md (and to stdout).
#
#   bash bench/run.sh                      # demo, shared splashsurf frames, 1M-particle frame
#   BENCH_SKIP_1M=1 bash bench/run.sh      # without the 1M-particle frame
#   BENCH_FRAME_1M=big.npz BENCH_RADIUS_1M=0.025 bash bench/run.sh   # another large frame
set -euo pipefail
cd "$(dirname "$0")/.."

VENV=.venv-bench
PY="$VENV/bin/python"
RESULTS=bench/results
SPLASHSURF_DATA=${SPLASHSURF_DATA:-../shared/data/splashsurf}
DEMO=rust-core/data/demo_dam_break.npz
FRAME_1M=${BENCH_FRAME_1M:-target/bench/frame_1m.npz}

log() { printf '\n== %s\n' "$*" >&2; }

if [ ! -x "$PY" ]; then
    log "venv $VENV"
    python3 -m venv "$VENV"
fi
log "pip install -r bench/requirements.txt"
"$PY" -m pip install -q -r bench/requirements.txt

log "cargo build --release"
cargo build --release

mkdir -p "$RESULTS"
bench() {  # bench NAME INPUT [bench_sph.py options]; r defaults to h/2 of an .npz
    local name=$1 input=$2
    shift 2
    log "bench $name: $input $*"
    "$PY" bench/bench_sph.py "$input" --out "$RESULTS/$name.md" "$@"
}

# (a) The demo frame (r = h/2 from its 'h' array).
if [ -f "$DEMO" ]; then
    bench demo "$DEMO" --repeat 3
fi
if [ -d "$SPLASHSURF_DATA" ]; then
    # A real SPlisHSPlasH frame at splashsurf's own settings.
    bench dam_break_24k "$SPLASHSURF_DATA/dam_break_frame_23_24389_particles.bgeo" \
        --radius 0.025 --repeat 3
    # (c) A particle-sampled shape: splashsurf's tests expect 360k-400k triangles.
    bench hilbert_47k "$SPLASHSURF_DATA/hilbert_46843_particles.bgeo" --radius 0.025 --repeat 2
fi

# (b) A frame of at least 1,000,000 particles (tiled copies of the demo frame), made once
# and kept under target/ (ignored by git).
if [ -z "${BENCH_SKIP_1M:-}" ]; then
    if [ ! -f "$FRAME_1M" ] && [ -f scripts/make_bench_frame.py ]; then
        log "scripts/make_bench_frame.py --out $FRAME_1M"
        "$PY" scripts/make_bench_frame.py --out "$FRAME_1M"
    fi
    if [ -f "$FRAME_1M" ]; then
        # One run per method, at most 300 s each: a method too slow is a result, not a hang.
        bench frame_1m "$FRAME_1M" ${BENCH_RADIUS_1M:+--radius "$BENCH_RADIUS_1M"} --timeout 300
    else
        log "no 1M-particle frame: set BENCH_FRAME_1M=FILE (and BENCH_RADIUS_1M if it has no 'h')"
    fi
fi
