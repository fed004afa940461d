#!/usr/bin/env bash
# Speed of `filtrace view` while the camera moves, in a real window under Xvfb:
# a mouse drag held for SECONDS while the viewer renders the 1-spp filtered frames, then
# Escape; prints the viewer's summary line (moving frames, their mean render time and
# pixel count, and the longest UI-thread frame while a render ran) and, from the
# --log-frames lines, the mean milliseconds of each stage of the moving frames at the
# full resolution and the rate at which moving frames were shown (wall clock).
#
#   scripts/viewer_speed.sh [FILTRACE_BINARY] [SCENE] [RES] [TARGET_FPS] [SECONDS]
#
# TARGET_FPS 1 keeps the moving frames at full resolution (the adaptive scale stays at 1);
# the default 12 lets the resolution adapt. Needs Xvfb and xdotool.
set -euo pipefail
bin=${1:-target/debug/filtrace}
scene=${2:-cornell}
res=${3:-512x512}
fps=${4:-1}
seconds=${5:-10}
num=$((300 + RANDOM % 300))
display=":$num"
Xvfb "$display" -screen 0 1280x1024x24 -nolisten tcp >/dev/null 2>&1 &
xvfb=$!
trap 'kill $xvfb 2>/dev/null || true' EXIT
for _ in $(seq 100); do [ -S /tmp/.X11-unix/X$num ] && break; sleep 0.1; done
export DISPLAY=$display WINIT_X11_SCALE_FACTOR=1
log=$(mktemp)
"$bin" view "$scene" --res "$res" --target-fps "$fps" --log-frames 2>"$log" &
viewer=$!
for _ in $(seq 600); do grep -q "kind=still" "$log" && break; sleep 0.2; done
win=$(xdotool search --sync --onlyvisible --pid "$viewer" --name "filtrace view" | head -1)
xdotool mousemove --window "$win" 400 200 mousedown 1
end=$((SECONDS + seconds))
step=0
while [ $SECONDS -lt $end ]; do
    step=$((step + 1))
    xdotool mousemove --window "$win" $((400 + (step % 40) * 3)) 200
    sleep 0.02
done
xdotool mouseup 1 windowfocus --sync "$win" key Escape
wait $viewer
grep "closed;" "$log"
# Per-stage means over the moving frames at full resolution (--log-frames lines carry
# `kind=moving scale=S size=WxH layer=L ms=T stage=ms ...`), and the shown rate from the
# stderr timestamps the viewer does not print: frames over the drag's seconds.
awk -v res="$res" -v secs="$seconds" '
/kind=moving/ {
    moving++
    if (index($0, "size=" res " ") == 0) next
    full++
    for (i = 1; i <= NF; i++) {
        split($i, kv, "=")
        if (kv[1] ~ /^(kind|scale|size|layer|image|camera|anim_frame)$/ || kv[2] == "") continue
        if (kv[1] == "ms") kv[1] = "frame"
        if (!(kv[1] in sum)) order[++n] = kv[1]
        sum[kv[1]] += kv[2]
    }
}
END {
    printf "moving frames: %d (%.1f per second of drag), %d at %s; mean ms per stage at %s:", moving, moving / secs, full, res, res
    for (i = 1; i <= n; i++) printf " %s %.1f", order[i], sum[order[i]] / (full ? full : 1)
    printf "\n"
}' "$log"
rm -f "$log"
