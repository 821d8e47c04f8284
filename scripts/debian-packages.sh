# Sourced by the host test scripts (tests/python/run.sh, tests/blender/run.sh):
#
#   ensure_debian_packages PKG...
#
# installs those of the named Debian packages that dpkg does not list as installed
# (apt-get, through sudo when not root). Does nothing off Debian (no dpkg-query) or with
# ISOBAR_SKIP_APT=1. Expects the caller's `log` function.
ensure_debian_packages() {
    local missing=() p sudo=""
    command -v dpkg-query >/dev/null 2>&1 || return 0
    for p in "$@"; do
        dpkg-query -W -f='${Status}' "$p" 2>/dev/null | grep -q "install ok installed" || missing+=("$p")
    done
    if [ "${#missing[@]}" -eq 0 ] || [ "${ISOBAR_SKIP_APT:-0}" = 1 ]; then
        return 0
    fi
    log "apt-get install ${missing[*]}"
    [ "$(id -u)" -ne 0 ] && sudo="sudo"
    $sudo apt-get update -qq
    DEBIAN_FRONTEND=noninteractive $sudo apt-get install -y -qq --no-install-recommends "${missing[@]}"
}
