#!/usr/bin/env bash
# Adaptive 3-level surfaces, CPU (rayon) against GPU (wgpu), on the same particles: builds
# the release binary, runs `isobar adaptive --compare --backend gpu` on two real frames
# (which also times the CPU back end and uniform finest-level marching cubes) and prints
# one table. Meant for a machine with a GPU; on lavapipe (mesa-vulkan-drivers) the GPU
# figures only show correctness. Usage: bash bench/gpu/run.sh [DATA_DIR]
set -euo pipefail
cd "$(dirname "$0")/../.."
data=${1:-../shared/data/splashsurf}
out=$(mktemp -d)
trap 'rm -rf "$out"' EXIT

cargo build --release --bin isobar >&2
bin=target/release/isobar
"$bin" info >/dev/null 2>&1 || true

frames=(
    "$data/dam_break_frame_23_24389_particles.bgeo"
    "$data/double_dam_break_frame_26_4732_particles.vtk"
)
keys=(
    backend
    cpu_adaptive_time_s gpu_adaptive_time_s
    cpu_adaptive_triangles gpu_adaptive_triangles
    cpu_adaptive_array_bytes gpu_adaptive_array_bytes
    gpu_cpu_triangles gpu_cpu_max_position_difference
    uniform_L3_time_s uniform_L3_triangles
    Hausdorff_to_uniform_L3_finest_cell
)
printf '| frame |'; printf ' %s |' "${keys[@]}"; printf '\n|---|'
printf -- '---|%.0s' "${keys[@]}"; printf '\n'
for f in "${frames[@]}"; do
    json="$out/$(basename "$f").json"
    "$bin" adaptive "$f" --h 0.05 --iso 0.6 --grid-factor 0.375 --compare --backend gpu \
        --quiet --stats-json "$json" -o "$out/surface.ply"
    printf '| %s |' "$(basename "$f")"
    for k in "${keys[@]}"; do
        v=$(python3 -c "import json,sys; d=json.load(open(sys.argv[1])); print(d.get(sys.argv[2], '-'))" "$json" "$k")
        printf ' %s |' "$v"
    done
    printf '\n'
done
