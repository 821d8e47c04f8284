#!/usr/bin/env bash
# Installs what the tests need (apt, pip, cargo) and runs every test: the Rust core, the C
# ABI from C, the Python package with pyvista, the USD writer, the VTK module and ParaView
# plugin, the Blender add-on. On a fresh Debian 12 machine with the Rust
# toolchain (rustup) and CPython 3.11; run as root so apt can install.
set -euo pipefail
cd "$(dirname "$0")/.."
root=$(pwd)

log() { printf '\n== %s\n' "$*"; }

if ! command -v cargo >/dev/null; then
    echo "cargo not found: isobar needs a Rust toolchain (rustup, Rust >= 1.82)" >&2
    exit 1
fi

# Debian packages: a C compiler for the C ABI test; EGL/Mesa for pyvista's offscreen
# screenshots; lavapipe (mesa-vulkan-drivers) so the wgpu kernels run without a GPU. Each
# host suite's script installs its own libraries (gmsh's: tests/python/run.sh; bpy's:
# tests/blender/run.sh), through scripts/debian-packages.sh.
need=()
for pkg in gcc libegl1 libegl-mesa0 libgl1-mesa-dri libglx-mesa0 mesa-vulkan-drivers; do
    dpkg -s "$pkg" >/dev/null 2>&1 || need+=("$pkg")
done
if [ ${#need[@]} -gt 0 ]; then
    log "apt: ${need[*]}"
    apt-get update -qq
    DEBIAN_FRONTEND=noninteractive apt-get install -y -qq --no-install-recommends "${need[@]}"
fi

# wgpu: Vulkan only (lavapipe on CPU-only machines); skips the GL probe. GPU tests fail
# without an adapter unless ISOBAR_GPU_TESTS=skip.
export WGPU_BACKEND="${WGPU_BACKEND:-vulkan}"

rustup component add rustfmt clippy >/dev/null 2>&1 || true

log "format"
cargo fmt --all -- --check

log "clippy"
cargo clippy --workspace --all-targets --release -- -D warnings

log "build"
# The C ABI test links the cdylib that `cargo build` produces.
cargo build --workspace --release

mkdir -p target
results="$root/target/test-output.txt"
: > "$results"

log "rust tests"
cargo test --workspace --release --no-fail-fast 2>&1 | tee -a "$results"

log "rust tests of the CPU-only build (--no-default-features: no wgpu)"
cargo test -p isobar --release --no-default-features --lib no_gpu 2>&1 | tee -a "$results"

log "python tests"
bash tests/python/run.sh 2>&1 | tee -a "$results"

log "USD writer tests (usd-core from PyPI, in the Python tests' venv)"
ISOBAR_USD_SKIP_CORE=1 bash tests/usd/run.sh 2>&1 | tee -a "$results"

log "VTK module and ParaView plugin tests (installs Debian VTK 9.1 / ParaView 5.11)"
bash tests/vtk/run.sh 2>&1 | tee -a "$results"

log "Blender add-on tests (bpy 5.0.1 from PyPI, headless)"
bash tests/blender/run.sh 2>&1 | tee -a "$results"

# One closing line for the whole suite (cargo's and pytest's summaries added up).
passed=$(grep -Eo '[0-9]+ passed' "$results" | awk '{s+=$1} END {print s+0}')
failed=$(grep -Eo '[0-9]+ failed' "$results" | awk '{s+=$1} END {print s+0}')
echo
echo "all: $passed passed, $failed failed"
[ "$failed" -eq 0 ]
