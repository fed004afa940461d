#!/usr/bin/env bash
# The benchmark suite of issue 13, with its peers, in interleaved runs (docs/performance.md,
# "The suite"). Run from the project root on an idle machine, after
#   cargo build --release -p filtrace
#   pip install mitsuba embreex trimesh; apt-get install -y libllvm19
#
#   scripts/bench_suite.sh [--filtrace PATH] [--scenes a,b,...] [--spp N] [--res N]
#       [--max-depth N] [--threads T] [--rays N] [--repeats K] [--rounds R]
#       [--scaling "1 2 4 ..."] [--scaling-scenes a,b] [--filter-res WxH] [--frames N]
#       [--embree native|embreex|both] [--skip-peers] [--skip-rays] [--skip-scaling] [--out DIR]
#       [--report-only]
#
# Part 1, per scene and round (A B A B ...): filtrace path tracing, Mitsuba 3 on the same
# scene (dumped by `filtrace bench suite --dump-scene-json`), filtrace rays on 1 thread,
# Embree on the same world-space triangles and ray distributions on 1 thread: --embree native
# (the default) calls Embree 3 from C (scripts/embree_native.c through `embree_bench.py
# --native`: needs cc and libembree3), embreex calls Embree 4 through embreex (its per-call
# Python overhead flatters filtrace), both runs both (the table adds embreex's columns).
# Part 2, per thread count: the path tracer (`bench suite --threads T`), À-Trous and the
# guided filter at --filter-res (`RAYON_NUM_THREADS=T bench filters`) and the filtered
# pipeline (`bench pipeline --threads T`).
# Writes OUT/commands.log (every command, exactly as run), OUT/raw/*.json, OUT/suite.md and
# OUT/scaling.md; prints both tables at the end. --report-only --out DIR rebuilds the tables
# from DIR/raw (after an interrupted run, say) without measuring anything.
set -euo pipefail

FILTRACE=target/release/filtrace
SCENES=cornell,bunny-room,grass,grass-1m,engine,bunny,teapot
SPP=64 RES=512 MAX_DEPTH=8 THREADS=$(nproc) RAYS=1048576 REPEATS=3 ROUNDS=2
SCALING="" SCALING_SCENES=cornell,bunny-room FILTER_RES=1920x1080 FRAMES=20
PEERS=1 RAYS_ON=1 SCALING_ON=1 OUT="" REPORT_ONLY=0 EMBREE=native
while [ $# -gt 0 ]; do
    case "$1" in
        --filtrace) FILTRACE=$2 ;;
        --scenes) SCENES=$2 ;;
        --spp) SPP=$2 ;;
        --res) RES=$2 ;;
        --max-depth) MAX_DEPTH=$2 ;;
        --threads) THREADS=$2 ;;
        --rays) RAYS=$2 ;;
        --repeats) REPEATS=$2 ;;
        --rounds) ROUNDS=$2 ;;
        --scaling) SCALING=$2 ;;
        --scaling-scenes) SCALING_SCENES=$2 ;;
        --filter-res) FILTER_RES=$2 ;;
        --frames) FRAMES=$2 ;;
        --embree) EMBREE=$2 ;;
        --out) OUT=$2 ;;
        --skip-peers) PEERS=0; shift; continue ;;
        --skip-rays) RAYS_ON=0; shift; continue ;;
        --skip-scaling) SCALING_ON=0; shift; continue ;;
        --report-only) REPORT_ONLY=1; shift; continue ;;
        -h|--help) sed -n '2,24p' "$0"; exit 0 ;;
        *) echo "bench_suite.sh: unknown option $1 (see --help)" >&2; exit 2 ;;
    esac
    [ $# -ge 2 ] || { echo "bench_suite.sh: $1 needs a value" >&2; exit 2; }
    shift 2
done
if [ "$REPORT_ONLY" = 1 ]; then
    [ -n "$OUT" ] && [ -d "$OUT/raw" ] || { echo "bench_suite.sh: --report-only needs --out DIR with DIR/raw" >&2; exit 2; }
    PEERS=0 RAYS_ON=0 SCALING_ON=0 ROUNDS=0
else
    [ -x "$FILTRACE" ] || { echo "bench_suite.sh: no filtrace binary at $FILTRACE (cargo build --release -p filtrace, or --filtrace PATH)" >&2; exit 2; }
fi
case "$EMBREE" in
    native|embreex|both) ;;
    *) echo "bench_suite.sh: --embree is native, embreex or both, not $EMBREE" >&2; exit 2 ;;
esac
EMBREEX_MOD=""
[ "$EMBREE" = native ] || EMBREEX_MOD=", embreex"
if [ "$PEERS" = 1 ] && ! python3 -c "import mitsuba, drjit, numpy$EMBREEX_MOD" 2>/dev/null; then
    echo "bench_suite.sh: the peers need: pip install mitsuba embreex trimesh; apt-get install -y libllvm19 (or --skip-peers)" >&2
    exit 2
fi
if [ "$PEERS" = 1 ] && [ "$RAYS_ON" = 1 ] && [ "$EMBREE" != embreex ] && ! command -v "${CC:-cc}" >/dev/null; then
    echo "bench_suite.sh: --embree $EMBREE needs a C compiler (apt-get install gcc libembree3-3), or --embree embreex" >&2
    exit 2
fi
if [ -z "$SCALING" ]; then
    t=1; SCALING=""
    while [ "$t" -lt "$(nproc)" ]; do SCALING="$SCALING $t"; t=$((t * 2)); done
    SCALING="$SCALING $(nproc)"
fi
OUT=${OUT:-bench-suite-$(date -u +%Y%m%dT%H%M%SZ)}
HERE=$(cd "$(dirname "$0")" && pwd)
mkdir -p "$OUT/raw" "$OUT/scenes"
LOG="$OUT/commands.log"
[ "$REPORT_ONLY" = 1 ] || : > "$LOG"
echo "# $(date -u +%FT%TZ) $(uname -n), $(nproc) cores, load $(cut -d' ' -f1-3 /proc/loadavg), filtrace $(git -C "$HERE/.." rev-parse --short HEAD 2>/dev/null || echo '?')" >> "$LOG"

# run OUTFILE CMD...: logs the command, runs it with stdout to OUTFILE (stderr to the terminal).
run() {
    local out=$1; shift
    echo "$(date -u +%T) $* > $out" >> "$LOG"
    echo "[bench_suite] $*" >&2
    "$@" > "$out"
}

SUITE_START=$(date +%s)
if [ "$PEERS" = 1 ]; then
    run "$OUT/raw/dump.txt" "$FILTRACE" bench suite --scenes "$SCENES" --dump-scene-json "$OUT/scenes"
fi
for round in $(seq 1 "$ROUNDS"); do
    for scene in ${SCENES//,/ }; do
        dir=$(echo "$scene" | sed 's/[^A-Za-z0-9._-]/_/g')
        run "$OUT/raw/filtrace_render_${dir}_$round.json" "$FILTRACE" bench suite --scenes "$scene" --no-rays \
            --res "${RES}x$RES" --spp "$SPP" --max-depth "$MAX_DEPTH" --threads "$THREADS" --repeats "$REPEATS" --json
        if [ "$PEERS" = 1 ]; then
            run "$OUT/raw/mitsuba_${dir}_$round.json" python3 "$HERE/mitsuba_bench.py" --scene-dir "$OUT/scenes/$dir" \
                --res "$RES" --spp "$SPP" --max-depth "$MAX_DEPTH" --threads "$THREADS" --repeats "$REPEATS" --json
        fi
        if [ "$RAYS_ON" = 1 ]; then
            run "$OUT/raw/filtrace_rays_${dir}_$round.json" "$FILTRACE" bench suite --scenes "$scene" --no-render \
                --res "${RES}x$RES" --rays "$RAYS" --ray-threads 1 --repeats "$REPEATS" --json
            if [ "$PEERS" = 1 ] && [ "$EMBREE" != embreex ]; then
                run "$OUT/raw/embree_native_${dir}_$round.json" python3 "$HERE/embree_bench.py" --native \
                    --scene-dir "$OUT/scenes/$dir" --rays "$RAYS" --repeats "$REPEATS" --json
            fi
            if [ "$PEERS" = 1 ] && [ "$EMBREE" != native ]; then
                run "$OUT/raw/embree_${dir}_$round.json" python3 "$HERE/embree_bench.py" --scene-dir "$OUT/scenes/$dir" \
                    --res "${RES}x$RES" --rays "$RAYS" --threads 1 --repeats "$REPEATS" --json
            fi
        fi
    done
done
SUITE_END=$(date +%s)

if [ "$SCALING_ON" = 1 ]; then
    for t in $SCALING; do
        run "$OUT/raw/scaling_render_$t.json" "$FILTRACE" bench suite --scenes "$SCALING_SCENES" --no-rays \
            --res "${RES}x$RES" --spp "$SPP" --max-depth "$MAX_DEPTH" --threads "$t" --repeats "$REPEATS" --json
        run "$OUT/raw/scaling_atrous_$t.json" env RAYON_NUM_THREADS="$t" "$FILTRACE" bench filters \
            --res "$FILTER_RES" --no-bilateral --only a-trous --repeats 5 --json
        run "$OUT/raw/scaling_guided_$t.json" env RAYON_NUM_THREADS="$t" "$FILTRACE" bench filters \
            --res "$FILTER_RES" --no-bilateral --only guided --repeats 5 --json
        run "$OUT/raw/scaling_pipeline_$t.json" "$FILTRACE" bench pipeline --threads "$t" --filter guided \
            --frames "$FRAMES" --json
    done
fi
SCALING_END=$(date +%s)
echo "# suite $((SUITE_END - SUITE_START)) s, scaling $((SCALING_END - SUITE_END)) s" >> "$LOG"

python3 - "$OUT" "$SCENES" <<'PY'
import glob, json, os, re, statistics, sys

# The thread counts are those of the scaling files present (so --report-only needs no list).
out, scenes = sys.argv[1], sys.argv[2].split(",")
raw = os.path.join(out, "raw")
scaling = sorted({int(m.group(1)) for p in glob.glob(os.path.join(raw, "scaling_*_*.json"))
                  if (m := re.search(r"_(\d+)\.json$", p))})


def load(pattern):
    docs = []
    for p in sorted(glob.glob(os.path.join(raw, pattern))):
        with open(p) as f:
            docs.append(json.load(f))
    return docs


def fmt(x, digits=2):
    return "-" if x is None else f"{x:.{digits}f}"


def ratio_cell(ours, theirs):
    """Median of ours / median of theirs, and the range of the per-round ratios."""
    pairs = [(a, b) for a, b in zip(ours, theirs) if a and b]
    if not pairs:
        return "-"
    r = statistics.median(ours) / statistics.median(theirs)
    per = [a / b for a, b in pairs]
    return f"**{r:.2f}x** ({min(per):.2f}-{max(per):.2f})"


def lum(c):
    return 0.2126 * c[0] + 0.7152 * c[1] + 0.0722 * c[2]


def ray_rate(report, query):
    """filtrace: Mrays per CPU-s of the 1-thread run, else wall Mrays/s."""
    cpu = report.get(f"{query}_mrays_per_cpu_s")
    return cpu if cpu else report[f"{query}_mrays"]


def embree_rate(report, query):
    m = report[query]
    return m.get("mrays_per_cpu_s") or m["mrays"]


# Embree native (embree_native.c) when measured, else embreex; with both, embreex's columns too.
have_native = bool(glob.glob(os.path.join(raw, "embree_native_*.json")))
have_embreex = bool(glob.glob(os.path.join(raw, "embree_*.json"))) and any(
    not os.path.basename(p).startswith("embree_native_") for p in glob.glob(os.path.join(raw, "embree_*.json")))
embree_name = "Embree native" if have_native else "Embree (embreex)"
extra = have_native and have_embreex
lines = ["| scene | triangles | filtrace M samples/s | Mitsuba M samples/s | ratio (rounds) | mean luminance filtrace / Mitsuba "
         f"| closest: filtrace / {embree_name} Mrays per CPU-s | ratio (rounds) | any: filtrace / {embree_name} | ratio (rounds) |"
         + (" closest: filtrace / embreex | ratio (rounds) | any: filtrace / embreex | ratio (rounds) |" if extra else ""),
         "|---|---:|---:|---:|---:|---:|---:|---:|---:|---:|" + ("---:|" * 4 if extra else "")]
for scene in scenes:
    d = "".join(c if (c.isascii() and c.isalnum()) or c in "._-" else "_" for c in scene)
    if not glob.glob(os.path.join(raw, f"*_{d}_*.json")):
        continue
    fr = [doc["scenes"][0] for doc in load(f"filtrace_render_{d}_*.json")]
    mi = load(f"mitsuba_{d}_*.json")
    frays = [doc["scenes"][0]["rays"] for doc in load(f"filtrace_rays_{d}_*.json")]
    em = load(f"embree_native_{d}_*.json") if have_native else load(f"embree_{d}_*.json")
    peers = [em] + ([load(f"embree_{d}_*.json")] if extra else [])
    ft_sps = [s["render"][0]["samples_per_s_best"] / 1e6 for s in fr]
    mi_sps = [m["samples_per_s_best"] / 1e6 for m in mi]
    tris = fr[0]["triangles"] if fr else (frays[0]["triangles"] if frays else "-")
    lum_ratio = "-"
    if fr and mi:
        lum_ratio = fmt(lum(fr[-1]["render"][0]["mean_rgb"]) / max(lum(mi[-1]["mean_rgb"]), 1e-12), 3)
    cells = []
    for docs in peers:
        for q in ("incoherent_closest", "incoherent_any"):
            a = [ray_rate(r, q) for r in frays]
            b = [embree_rate(e, q) for e in docs]
            cells.append(f"{fmt(statistics.median(a)) if a else '-'} / {fmt(statistics.median(b)) if b else '-'}")
            cells.append(ratio_cell(a, b))
    lines.append(f"| {scene} | {tris} | {fmt(statistics.median(ft_sps)) if ft_sps else '-'} "
                 f"| {fmt(statistics.median(mi_sps)) if mi_sps else '-'} | {ratio_cell(ft_sps, mi_sps)} | {lum_ratio} "
                 f"| {' | '.join(cells)} |")
with open(os.path.join(out, "suite.md"), "w") as f:
    f.write("\n".join(lines) + "\n")
print("\n".join(lines))

rows = []
base = {}
names = None
for t in scaling:
    pt = load(f"scaling_render_{t}.json")
    at = load(f"scaling_atrous_{t}.json")
    gu = load(f"scaling_guided_{t}.json")
    pl = load(f"scaling_pipeline_{t}.json")
    if not (pt or at or gu or pl):
        continue
    cols = {}
    for s in (pt[0]["scenes"] if pt else []):
        cols[f"path tracer {s['scene']}, M samples/s"] = (s["render"][0]["samples_per_s_best"] / 1e6, True)
    for r in (at[0]["dammertz2010_table2"] if at else []):
        if (r["iterations"], r["weights"]) == (5, 3):
            cols[f"À-Trous {r['width']}x{r['height']} 5 it, ms"] = (r["ms"], False)
    if gu:
        size = f"{gu[0]['bauszat2011_table2']['width']}x{gu[0]['bauszat2011_table2']['height']}"
        for r in gu[0]["bauszat2011_table2"]["rows"]:
            if r["setting"] == "4 dimension, radius 32":
                cols[f"guided {size} 4 ch r 32, ms"] = (r["ms"], False)
    for r in (pl[0]["rows"] if pl else []):
        cols[f"pipeline {r['filter']}, fps"] = (r["fps_median"], True)
    names = names or list(cols)
    cells = []
    for n in names:
        v, higher_better = cols.get(n, (None, True))
        if v is not None and n not in base:
            base[n] = v
        speed = None if v is None else (v / base[n] if higher_better else base[n] / v)
        eff = None if speed is None else speed * scaling[0] / t
        cells.append("-" if v is None else f"{v:.2f} ({speed:.2f}x, {eff:.0%})")
    rows.append(f"| {t} | " + " | ".join(cells) + " |")
if rows:
    table = ["| threads | " + " | ".join(names) + " |", "|---:|" + "---:|" * len(names)] + rows
    with open(os.path.join(out, "scaling.md"), "w") as f:
        f.write("Each cell: value (speed-up over the first thread count, efficiency = speed-up / threads)\n\n")
        f.write("\n".join(table) + "\n")
    print()
    print("\n".join(table))
PY
echo "[bench_suite] wrote $OUT/suite.md, $OUT/scaling.md, commands in $LOG" >&2
