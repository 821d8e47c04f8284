#!/bin/bash
# Resident memory of `isobar slide` after a list of isovalue changes, by part.
# usage: bench/slider/rss.sh STORE ISOVALUES [ISOBAR]   (ISOBAR: target/release/isobar)
# Feeds the isovalues through a FIFO held open, so the process is still alive after the
# last update; prints VmHWM (peak), VmRSS, RssAnon and RssFile from /proc/PID/status and
# the resident kilobytes of each mapping (the store's pages, the heap, anonymous maps).
set -euo pipefail
store=$1 isovalues=$2 isobar=${3:-target/release/isobar}
dir=$(mktemp -d)
trap 'rm -rf "$dir"' EXIT
mkfifo "$dir/in"
"$isobar" slide "$store" < "$dir/in" > "$dir/out" 2>&1 &
pid=$!
exec 3> "$dir/in"
cat "$isovalues" >&3
# The last update is done when its line is out.
want=$(grep -cv '^\s*\(#\|$\)' "$isovalues")
while [ "$(wc -l < "$dir/out")" -lt "$want" ] && kill -0 "$pid" 2> /dev/null; do sleep 0.1; done
grep -E "VmHWM|VmRSS|RssAnon|RssFile" "/proc/$pid/status"
awk '/^[0-9a-f]+-/ {name = ($6 == "" ? "[anonymous]" : $6)} /^Rss:/ {kb[name] += $2}
     END {for (n in kb) if (kb[n] >= 1024) printf "%8d kB  %s\n", kb[n], n}' "/proc/$pid/smaps"
tail -n 1 "$dir/out"
exec 3>&-
wait "$pid"
