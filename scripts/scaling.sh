#!/usr/bin/env bash
# Parallel scaling of the filters, the filtered pipeline and the path tracer (issue 13):
# two release binaries (A = before, B = after) run interleaved at each thread count, one
# markdown report on stdout (raw JSON kept in $OUT_DIR).
#
#   scripts/scaling.sh A_BIN B_BIN [THREADS]      THREADS default: "1 2 4 8 16"
#   e.g. scripts/scaling.sh /tmp/main-filtrace target/release/filtrace > scaling.md
#
# Built-in scenes (cornell, grass; bunny-room and engine too when the bunny and the engine
# glTF are found under $FILTRACE_SHARED or ../shared) and the VPL frame on cornell. About
# 4 minutes on 16 idle cores; needs python3 for the tables. Run on an idle machine: the
# numbers are wall-clock times. REPORT_ONLY=1 with OUT_DIR set prints the tables of an
# earlier run's JSON without running anything.
set -euo pipefail

if [ $# -lt 2 ]; then
    sed -n '2,14p' "$0" >&2
    exit 2
fi
A=$1
B=$2
THREADS=${3:-"1 2 4 8 16"}
for bin in "$A" "$B"; do
    [ -x "$bin" ] || { echo "scaling.sh: $bin is not an executable" >&2; exit 2; }
done
command -v python3 > /dev/null || { echo "scaling.sh: python3 is needed for the tables" >&2; exit 2; }
OUT_DIR=${OUT_DIR:-$(mktemp -d /tmp/scaling.XXXXXX)}
mkdir -p "$OUT_DIR"

SHARED=${FILTRACE_SHARED:-../shared}
SCENES=cornell,grass
if [ -f "$SHARED/scenes/bunny/bunny.obj" ]; then
    SCENES=$SCENES,bunny-room
fi
if [ -f "$SHARED/scenes/gltf/2CylinderEngine.glb" ]; then
    SCENES=$SCENES,engine
fi

# One run: $1 = label (A/B), $2 = binary, $3 = threads, $4 = benchmark name, rest: arguments.
run() {
    local label=$1 bin=$2 t=$3 name=$4
    shift 4
    local f="$OUT_DIR/$name-$label-$t.json"
    if ! RAYON_NUM_THREADS=$t "$bin" "$@" --json > "$f" 2> "$f.err"; then
        echo "scaling.sh: $label $name at $t threads failed (see $f.err)" >&2
        rm -f "$f"
    fi
}

start=$(date +%s)
[ -n "${REPORT_ONLY:-}" ] && THREADS_RUN="" || THREADS_RUN=$THREADS
for t in $THREADS_RUN; do
    for label in A B; do
        bin=$A
        [ $label = B ] && bin=$B
        run $label "$bin" "$t" guided bench filters --res 1920x1080 --only guided --repeats 5
        run $label "$bin" "$t" atrous bench filters --res 1920x1080 --only a-trous --repeats 3
        run $label "$bin" "$t" pipeline bench pipeline --threads "$t" --filter guided --frames 10 --warmup 2
        run $label "$bin" "$t" vpl bench vpl cornell --res 512x512 --repeat 3 --samplers balance,optimized
        run $label "$bin" "$t" suite bench suite --scenes "$SCENES" --no-rays --threads "$t" --spp 8 --repeats 3
    done
    echo "scaling.sh: $t threads done after $(($(date +%s) - start)) s" >&2
done

python3 - "$OUT_DIR" "$A" "$B" "$THREADS" <<'PY'
import json, os, sys

out_dir, bin_a, bin_b, threads = sys.argv[1], sys.argv[2], sys.argv[3], [int(t) for t in sys.argv[4].split()]


def load(name, label, t):
    try:
        with open(os.path.join(out_dir, f"{name}-{label}-{t}.json")) as f:
            return json.load(f)
    except (OSError, ValueError):
        return None


def bauszat_ms(name, setting):
    def get(label, t):
        j = load(name, label, t)
        rows = j["bauszat2011_table2"]["rows"] if j else []
        return next((r["ms"] for r in rows if r["setting"] == setting), None)
    return get


def pipeline(key):
    def get(label, t):
        j = load("pipeline", label, t)
        if not j:
            return None
        row = j["rows"][0]
        if key == "fps":
            return row["fps_median"]
        return next((s["median_ms"] for s in row["stages"] if s["stage"] == key), None)
    return get


def suite(scene):
    def get(label, t):
        j = load("suite", label, t)
        for s in (j or {}).get("scenes", []):
            if s["scene"] == scene and s.get("render"):
                return s["render"][0]["samples_per_s_median"] / 1e6
        return None
    return get


def table(title, unit, get, faster_is_lower):
    print(f"\n### {title}\n")
    print(f"| threads | A {unit} | B {unit} | A scaling | B scaling | B vs A |")
    print("|---:|---:|---:|---:|---:|---:|")
    base = {label: get(label, threads[0]) for label in "AB"}
    for t in threads:
        v = {label: get(label, t) for label in "AB"}
        def fmt(x):
            return "-" if x is None else f"{x:.2f}"
        def scaling(label):
            b, x = base[label], v[label]
            if b is None or x is None or x == 0 or b == 0:
                return "-"
            return f"{(b / x if faster_is_lower else x / b):.2f}x"
        ratio = "-"
        if v["A"] and v["B"]:
            ratio = f"{(v['A'] / v['B'] if faster_is_lower else v['B'] / v['A']):.2f}x"
        print(f"| {t} | {fmt(v['A'])} | {fmt(v['B'])} | {scaling('A')} | {scaling('B')} | {ratio} |")


print(f"## Parallel scaling: A = `{bin_a}`, B = `{bin_b}`\n")
print("Interleaved runs (A then B at each thread count, RAYON_NUM_THREADS / --threads). Scaling is")
print(f"against {threads[0]} thread(s) of the same binary; 'B vs A' > 1 means B is faster.")
table("Guided filter, 1920x1080, 4 channels (normal + depth), r 32: median wall ms", "ms",
      bauszat_ms("guided", "4 dimension, radius 32"), True)
table("Guided filter, 1920x1080, 1 channel (grey normal), r 24: median wall ms", "ms",
      bauszat_ms("guided", "1 dimension, radius 24"), True)
table("À-Trous, 1920x1080, 5 iterations, 3 weights: median wall ms", "ms",
      bauszat_ms("atrous", "5 iterations"), True)
table("À-Trous, 1920x1080, 10 iterations, 3 weights: median wall ms", "ms",
      lambda label, t: next((r["ms"] for r in (load("atrous", label, t) or {}).get("dammertz2010_table2", [])
                             if r["iterations"] == 10 and r["weights"] == 3), None), True)
table("Pipeline, Cornell 512², 1 spp, guided: median frames/s", "fps", pipeline("fps"), False)
table("Pipeline, Cornell 512², 1 spp, guided: filter stage median ms", "ms", pipeline("filter"), True)
table("Pipeline, Cornell 512², 1 spp, guided: guide stage median ms", "ms", pipeline("guide"), True)
def vpl(sampler, stage):
    def get(label, t):
        j = load("vpl", label, t)
        row = next((r for r in (j or {}).get("rows", []) if r.get("sampler") == sampler), None)
        return None if row is None else row.get(stage)
    return get


for sampler in ("balance", "optimized"):
    table(f"VPL frame, cornell 512², 1 spp, 2048 VPLs, 1024 cache points, {sampler}: median total ms", "ms",
          vpl(sampler, "total_ms"), True)
scenes = []
for t in threads:
    for s in (load("suite", "A", t) or {}).get("scenes", []):
        if s["scene"] not in scenes:
            scenes.append(s["scene"])
for scene in scenes:
    table(f"Path tracer, {scene} 512², 8 spp, depth 8: M samples/s (median of 3)", "M/s", suite(scene), False)
print(f"\nRaw JSON: {out_dir}")
PY
