#!/usr/bin/env bash
# Instructions per slider update, counted by callgrind (load-independent, unlike timings
# on a shared machine). Builds a store of bench_slider.py's synthetic volume (12
# Gaussians plus noise) at SIZE^3, writes an isovalue list starting at 30 % of the value
# range and stepping STEP_PCT % of the range up N times, then runs `isobar slide` under
# callgrind once with the starting isovalue only and once with all N+1; the difference
# over N is the cost of one update (the walk, the edge/cell/triangle changes; the scripted
# `slide` builds neither V, N nor I, which hosts compute on first read).
#
#   bench/slider/callgrind.sh [SIZE=128] [N=8] [STEP_PCT=0.1]
# Needs: valgrind, cargo build --release, a Python with numpy ($PYTHON, default
# .venv-bench/bin/python, else .venv-test/bin/python). Output in $OUT (default
# out/slider-callgrind); the store is kept there and reused when present.
set -euo pipefail
REPO=$(cd "$(dirname "$0")/../.." && pwd)
SIZE=${1:-128}
N=${2:-8}
STEP_PCT=${3:-0.1}
OUT=${OUT:-$REPO/out/slider-callgrind}
CLI=${ISOBAR_CLI:-$REPO/target/release/isobar}
if [[ -z ${PYTHON:-} ]]; then
  for p in "$REPO/.venv-bench/bin/python" "$REPO/.venv-test/bin/python"; do
    [[ -x $p ]] && PYTHON=$p && break
  done
fi
: "${PYTHON:?set PYTHON to a Python with numpy}"
mkdir -p "$OUT"
store=$OUT/gaussians$SIZE.isoslider
npy=$OUT/gaussians$SIZE.npy
if [[ ! -f $store ]]; then
  # bench_slider.py imports the isobar package, which loads the library.
  ISOBAR_LIBRARY=${ISOBAR_LIBRARY:-$REPO/target/release/libisobar.so} "$PYTHON" - "$REPO" "$SIZE" "$npy" <<'EOF'
import sys
import numpy as np
sys.path.insert(0, sys.argv[1] + "/bench/slider")
from bench_slider import synthetic
np.save(sys.argv[3], synthetic(int(sys.argv[2])))
EOF
  "$CLI" slide-build --quiet "$npy" -o "$store" >/dev/null
fi
"$PYTHON" - "$npy" "$N" "$STEP_PCT" "$OUT" <<'EOF'
import sys
import numpy as np
vol = np.load(sys.argv[1], mmap_mode="r")
lo, hi = float(vol.min()), float(vol.max())
n, step = int(sys.argv[2]), float(sys.argv[3]) / 100 * (hi - lo)
isos = [lo + 0.3 * (hi - lo) + k * step for k in range(n + 1)]
open(sys.argv[4] + "/one.txt", "w").write(f"{isos[0]!r}\n")
open(sys.argv[4] + "/all.txt", "w").write("".join(f"{v!r}\n" for v in isos))
EOF
count() {  # total instructions of `isobar slide` over the isovalues in $1
  valgrind --tool=callgrind --callgrind-out-file="$OUT/callgrind.$2" "$CLI" slide "$store" \
    <"$1" >"$OUT/slide.$2.txt" 2>"$OUT/valgrind.$2.txt"
  awk '/^summary:/ {print $2}' "$OUT/callgrind.$2"
}
one=$(count "$OUT/one.txt" one)
all=$(count "$OUT/all.txt" all)
echo "store $store ($(stat -L -c %s "$store") bytes), $N steps of $STEP_PCT % from 30 % of the range"
echo "open + first surface: $one instructions"
echo "$N updates: $((all - one)) instructions, $(((all - one) / N)) per update"
awk 'NR > 1 {a += $10; r += $12} END {printf "triangles added + removed per update: %d\n", (a + r) / (NR - 1)}' \
  "$OUT/slide.all.txt"
echo "profile of all updates: callgrind_annotate $OUT/callgrind.all"
