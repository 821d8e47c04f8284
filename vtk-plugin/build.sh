#!/usr/bin/env bash
# Builds the isobar VTK module (Debian VTK 9.1, Python-wrapped) and the ParaView plugin
# (Debian ParaView 5.11 with its own VTK 9.2) from the same C++ sources, in two trees:
#
#   vtk-plugin/build-vtk/python/isobar_vtk/        PYTHONPATH for /usr/bin/python3
#   vtk-plugin/build-pv/lib/paraview-5.11/plugins/IsobarSPH/IsobarSPH.so   LoadPlugin
#
# Installs the Debian packages it needs when they are missing (run as root), and builds
# the private prefix that ParaView's CMake config and pvbatch's Python need (Debian's
# python3-paraview conflicts with python3-vtk9, so it is unpacked, not installed).
# Idempotent; a second run only asks cargo and ninja whether anything changed.
#
# Environment: ISOBAR_PV_PREFIX (default /opt/isobar/paraview-5.11) for the prefix,
# ISOBAR_BUILD_ONLY=vtk|pv to build one tree, ISOBAR_VERBOSE=1 for full output.
set -euo pipefail
here=$(cd "$(dirname "$0")" && pwd)
pv_prefix=${ISOBAR_PV_PREFIX:-/opt/isobar/paraview-5.11}
only=${ISOBAR_BUILD_ONLY:-}
quiet() { if [ "${ISOBAR_VERBOSE:-0}" = 1 ]; then "$@"; else "$@" >/dev/null; fi; }
log() { printf '[build.sh] %s\n' "$*" >&2; }

# --- Debian packages -------------------------------------------------------------------
packages=(libvtk9-dev python3-vtk9 paraview paraview-dev cmake ninja-build g++
          xvfb xauth libgl1-mesa-dri)
missing=()
for p in "${packages[@]}"; do
    dpkg-query -W -f='${Status}' "$p" 2>/dev/null | grep -q "install ok installed" \
        || missing+=("$p")
done
if [ ${#missing[@]} -gt 0 ]; then
    if [ "$(id -u)" != 0 ]; then
        log "missing Debian packages (${missing[*]}); run as root or install them"
        exit 1
    fi
    log "apt-get install ${missing[*]}"
    export DEBIAN_FRONTEND=noninteractive
    apt-get update -qq
    apt-get install -y -qq --no-install-recommends "${missing[@]}" >/dev/null
fi

if ! command -v cargo >/dev/null; then
    export PATH="$HOME/.cargo/bin:$PATH"
fi
command -v cargo >/dev/null || { log "cargo not found: install a Rust toolchain (rustup)"; exit 1; }

# --- ParaView's private prefix ---------------------------------------------------------
# paraview-dev's CMake config locates ParaView relative to itself and refers to files
# that only python3-paraview ships (pvpython, the Python modules). The prefix mirrors
# /usr (links), adds python3-paraview's files (unpacked) and a COPY of the CMake config,
# so that the config's computed prefix is this one.
build_pv_prefix() {
    local version stamp
    version=$(dpkg-query -W -f='${Version}' paraview-dev)
    stamp="$pv_prefix/.isobar-prefix-$version"
    [ -f "$stamp" ] && return 0
    log "building ParaView prefix $pv_prefix (python3-paraview $version, unpacked)"
    rm -rf "$pv_prefix"
    mkdir -p "$pv_prefix"
    local dl
    dl=$(mktemp -d)
    (cd "$dl" && apt-get download -qq "python3-paraview=$version" 2>/dev/null \
        || apt-get download -qq python3-paraview)
    dpkg -x "$dl"/python3-paraview_*.deb "$pv_prefix"
    rm -rf "$dl"
    local arch=x86_64-linux-gnu
    ln -s /usr/include "$pv_prefix/include"
    ln -s /usr/share "$pv_prefix/share"
    ln -s "$pv_prefix/usr/lib/python3" "$pv_prefix/lib-python3.tmp"
    mkdir -p "$pv_prefix/bin" "$pv_prefix/lib/$arch/cmake" "$pv_prefix/lib/$arch/vtk/hierarchy"
    mv "$pv_prefix/lib-python3.tmp" "$pv_prefix/lib/python3"
    local f
    for f in /usr/bin/*; do
        case "$(basename "$f")" in
            pv*|paraview*|smTestDriver*|vtk*-pv5.11*) ln -s "$f" "$pv_prefix/bin/" ;;
        esac
    done
    for f in "$pv_prefix"/usr/bin/*; do ln -sf "$f" "$pv_prefix/bin/"; done
    for f in /usr/lib/$arch/*; do
        case "$(basename "$f")" in
            cmake|vtk) ;;
            *) ln -s "$f" "$pv_prefix/lib/$arch/" ;;
        esac
    done
    for f in /usr/lib/$arch/vtk/hierarchy/* "$pv_prefix"/usr/lib/$arch/vtk/hierarchy/*; do
        [ -e "$f" ] && ln -sfn "$f" "$pv_prefix/lib/$arch/vtk/hierarchy/"
    done
    cp -r /usr/lib/$arch/cmake/paraview-5.11 "$pv_prefix/lib/$arch/cmake/"
    touch "$stamp"
}

# --- the two build trees ---------------------------------------------------------------
configure_and_build() {
    local tree=$1; shift
    local dir="$here/$tree"
    if [ ! -f "$dir/build.ninja" ]; then
        log "configure $tree"
        quiet cmake -S "$here" -B "$dir" -G Ninja -DCMAKE_BUILD_TYPE=Release "$@"
    fi
    log "build $tree"
    # Re-configures by itself when a CMakeLists.txt changed.
    if ! cmake --build "$dir" >"$dir/build.log" 2>&1; then
        cat "$dir/build.log" >&2
        log "build of $tree failed (log: $dir/build.log)"
        return 1
    fi
    [ "${ISOBAR_VERBOSE:-0}" = 1 ] && cat "$dir/build.log"
    return 0
}

start=$(date +%s)
if [ "$only" != pv ]; then
    configure_and_build build-vtk -DISOBAR_PARAVIEW=OFF -DVTK_DIR=/usr/lib/x86_64-linux-gnu/cmake/vtk-9.1
fi
if [ "$only" != vtk ]; then
    build_pv_prefix
    configure_and_build build-pv -DISOBAR_PARAVIEW=ON \
        -DParaView_DIR="$pv_prefix/lib/x86_64-linux-gnu/cmake/paraview-5.11"
fi
log "done in $(( $(date +%s) - start )) s"
