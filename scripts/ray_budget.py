#!/usr/bin/env python3
"""What ">= 2x Mitsuba 3 on every suite scene" (issue 13) asks of the rays, per scene
(docs/performance.md, "What 2x Mitsuba would take, per scene").

1. Which library traces the rays of the PyPI `mitsuba` wheel's llvm variants: the shared
   libraries it links (libembree3.so, its version string) and the Embree entry points
   libmitsuba.so imports (the LLVM kernels call rtcIntersect4/8/16 and rtcOccluded4/8/16).
2. Per scene and round (interleaved: Mitsuba closest, Embree closest, Mitsuba any, Embree
   any): Mitsuba's `scene.ray_intersect_preliminary` and `scene.ray_test` on N incoherent
   rays (origins uniform in the bounds, directions uniform: `embree_bench.incoherent_rays`,
   the same arrays) against embreex's rtcIntersect1/rtcOccluded1 loop. Mitsuba runs with
   `dr.set_thread_count(1)` and is timed in CPU seconds of the whole process (its kernel
   runs on Dr.Jit's worker), embreex in CPU seconds of the calling thread; JIT compilation
   is left out by a warm-up call on the same arrays.
3. The budget: with filtrace's rays per sample and the coherence factor of its path rays
   (instructions per ray in the render over instructions per ray on the uniform rays, from
   callgrind: PROFILE below, or --profile FILE), a lower bound of Mitsuba's ray time per
   sample (its per-ray cost on the uniform rays x the same coherence factor x filtrace's
   rays per sample) against its measured CPU time per sample (the suite's Mitsuba
   samples/s, --suite-raw), and the speed-up of filtrace's rays that 2x Mitsuba needs with
   today's non-ray cost and with none.

4. With --perf: Mitsuba's own time in Embree, measured: `perf record` of
   scripts/mitsuba_bench.py on one thread, samples in libembree3.so over the render's
   (the estimate of 3. disagrees with it, see the docs; the table uses this one).
5. With --callgrind FILTRACE: filtrace's side (PROFILE) measured again.

Scenes come from `filtrace bench suite --dump-scene-json DIR` (--scene-root DIR; the
suite's OUT/scenes). Needs `pip install mitsuba embreex` and libllvm19 (as
scripts/mitsuba_bench.py), perf for --perf, valgrind for --callgrind; measuring only, not a
dependency of filtrace. Prints markdown tables; --json writes everything.

    python3 scripts/ray_budget.py --scene-root OUT/scenes --suite-raw OUT/raw [--perf]
        [--scenes a,b] [--rays N] [--rounds R] [--json FILE]
    python3 scripts/ray_budget.py --skip-timing --callgrind target/debug/filtrace [--scenes a,b] [--cg-dir DIR]
    python3 scripts/ray_budget.py --rays-json FILE --suite-raw OUT/raw [--profile DIR/profile.json]
"""
import argparse
import glob
import json
import os
import statistics
import sys
import time

HERE = os.path.dirname(os.path.abspath(__file__))
sys.path.insert(0, HERE)

SCENES = ["cornell", "bunny-room", "grass", "grass-1m", "engine", "bunny", "teapot"]

# filtrace per sample, from callgrind on the dev binary (filtrace-accel and -render at
# opt-level 3) of main 8b135fd, 1 thread, 128x128 at 2 spp and 32,768 uniform rays: the
# output of `--callgrind` (docs/performance.md, "What 2x Mitsuba would take, per scene").
# grass-1m has no scalar render, so no ray counts of its own. Per scene:
#   sample_ir: instructions of the render loop per sample (the lockstep tile loop);
#   closest_ir / any_ir: of it, inclusive instructions of the closest-hit / any-hit queries;
#   closest_rays / shadow_rays: queries per sample (the scalar tracer's calls of
#     SceneAccel::intersect / occluded, whose film is bit-identical to the lockstep one);
#   uniform_closest_ir / uniform_any_ir: instructions per ray of the same queries on the
#     suite's uniform incoherent rays (`bench suite --no-render --ray-threads 1`).
PROFILE = {
    "cornell": {
        "sample_ir": 3365.294, "closest_ir": 1334.236, "any_ir": 678.249,
        "uniform_closest_ir": 676.504, "uniform_any_and_shadow_ir": 383.179, "closest_rays": 3.887,
        "shadow_rays": 1.974,
    },
    "bunny-room": {
        "sample_ir": 7163.611, "closest_ir": 4180.675, "any_ir": 1559.906,
        "uniform_closest_ir": 1081.792, "uniform_any_and_shadow_ir": 671.727,
        "closest_rays": 3.904, "shadow_rays": 2.171,
    },
    "grass": {
        "sample_ir": 11353.479, "closest_ir": 7626.089, "any_ir": 2355.594,
        "uniform_closest_ir": 654.736, "uniform_any_and_shadow_ir": 446.003, "closest_rays": 3.264,
        "shadow_rays": 1.205,
    },
    "grass-1m": {
        "sample_ir": 18266.666, "closest_ir": 13612.466, "any_ir": 3205.11,
        "uniform_closest_ir": 726.427, "uniform_any_and_shadow_ir": 444.148,
    },
    "engine": {
        "sample_ir": 4441.864, "closest_ir": 2701.499, "any_ir": 770.743,
        "uniform_closest_ir": 1720.621, "uniform_any_and_shadow_ir": 1105.787,
        "closest_rays": 2.308, "shadow_rays": 0.58,
    },
    "bunny": {
        "sample_ir": 1781.129, "closest_ir": 1127.218, "any_ir": 275.275,
        "uniform_closest_ir": 1146.294, "uniform_any_and_shadow_ir": 942.686, "closest_rays": 1.71,
        "shadow_rays": 0.316,
    },
    "teapot": {
        "sample_ir": 1381.615, "closest_ir": 908.337, "any_ir": 158.183,
        "uniform_closest_ir": 990.633, "uniform_any_and_shadow_ir": 780.584, "closest_rays": 1.671,
        "shadow_rays": 0.251,
    },
}

SHARED = os.path.join(HERE, "..", "..", "shared")
# `filtrace render` names of the suite scenes (bench suite builds grass-1m itself).
SCALAR_SCENE = {
    "engine": os.path.join(SHARED, "scenes", "gltf", "2CylinderEngine.glb"),
    "bunny": os.path.join(SHARED, "scenes", "bunny", "bunny.obj"),
    "teapot": os.path.join(SHARED, "scenes", "teapot", "teapot.obj"),
}


def callgrind_edges(path):
    """(caller, callee) -> [calls, inclusive Ir] of a callgrind output file (names as
    written, so run valgrind with --demangle=no: closures keep their distinct hashes)."""
    names, edges, fn, callee, calls = {}, {}, None, None, None

    def name(text):
        text = text.strip()
        if text.startswith("("):
            k, _, rest = text.partition(")")
            if rest.strip():
                names[k] = rest.strip()
            return names[k]
        return text

    with open(path, errors="replace") as f:
        for line in f:
            if line.startswith("fn="):
                fn = name(line[3:])
            elif line.startswith("cfn="):
                callee = name(line[4:])
            elif line.startswith("calls="):
                calls = int(line[6:].split()[0])
            elif calls is not None and line[:1] in "0123456789+-*":
                e = edges.setdefault((fn, callee), [0, 0])
                e[0] += calls
                e[1] += int(line.split()[1])
                calls = None
    return edges


def is_query(sym):
    return "filtrace_accel" in sym and ("intersect" in sym or "occluded" in sym)


def query_cost(edges, kind):
    """Calls and inclusive Ir of the BVH queries (`kind`: "intersect" or "occluded") entered
    from outside the accel crate: the ray queries, each counted once at its entry point."""
    calls = ir = 0
    for (caller, callee), (n, c) in edges.items():
        if is_query(callee) and kind in callee and "filtrace_accel" not in (caller or ""):
            calls, ir = calls + n, ir + c
    return calls, ir


def entered_cost(edges, needle):
    """Calls and inclusive Ir of the functions whose symbol contains `needle`, entered from
    functions that do not."""
    calls = ir = 0
    for (caller, callee), (n, c) in edges.items():
        if needle in (callee or "") and needle not in (caller or ""):
            calls, ir = calls + n, ir + c
    return calls, ir


def callgrind(binary, cmd, out):
    import subprocess

    full = ["valgrind", "--tool=callgrind", "--demangle=no", f"--callgrind-out-file={out}", binary, *cmd]
    print("[ray_budget] RAYON_NUM_THREADS=1 " + " ".join(full), file=sys.stderr)
    subprocess.run(full, check=True, stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL,
                   env={**os.environ, "RAYON_NUM_THREADS": "1"})
    return callgrind_edges(out)


def profile_scene(binary, name, res, spp, rays, workdir):
    """PROFILE's entries for one scene from three callgrind runs of the (dev) binary."""
    tag = os.path.join(workdir, name.replace("/", "_"))
    samples = res * res * spp
    lock = callgrind(binary, ["bench", "suite", "--scenes", name, "--no-rays", "--res", f"{res}x{res}", "--spp",
                              str(spp), "--threads", "1", "--repeats", "1"], tag + ".lockstep.cg")
    _, sample_ir = entered_cost(lock, "lockstep_tile")
    _, closest_ir = query_cost(lock, "intersect")
    _, any_ir = query_cost(lock, "occluded")
    uni = callgrind(binary, ["bench", "suite", "--scenes", name, "--no-render", "--rays", str(rays), "--res", "8x8",
                             "--ray-threads", "1", "--repeats", "1"], tag + ".uniform.cg")
    out = {"sample_ir": sample_ir / samples, "closest_ir": closest_ir / samples, "any_ir": any_ir / samples,
           "uniform_closest_ir": uniform_per_ray(uni, "intersect"),
           "uniform_any_and_shadow_ir": uniform_per_ray(uni, "occluded")}
    if name != "grass-1m":  # `filtrace render` cannot load it (GrassParams in bench suite only)
        scalar = callgrind(binary, ["render", SCALAR_SCENE.get(name, name), "--trace", "scalar", "--res",
                                    f"{res}x{res}", "--spp", str(spp), "--threads", "1", "--out",
                                    tag + ".exr"], tag + ".scalar.cg")
        out["closest_rays"] = query_cost(scalar, "intersect")[0] / samples
        out["shadow_rays"] = query_cost(scalar, "occluded")[0] / samples
    return out


def uniform_per_ray(edges, kind):
    """Ir per call of the single-ray queries of `ray_bench` (entered from outside the accel
    crate, packets left out). Closest hits: the incoherent rays (the warm-up's 16,384 of
    them and the timed set) and the 64 primary rays of `--res 8x8`. Any hits: the
    incoherent and the shadow sets, whose identical closures the profile does not tell
    apart, so it is their mean (budget() uses a timing ratio instead)."""
    total = calls = 0
    for (caller, callee), (n, c) in edges.items():
        if is_query(callee) and kind in callee and "packet" not in callee and "filtrace_accel" not in (caller or ""):
            total, calls = total + c, calls + n
    return total / calls if calls else None


def mitsuba_tracer():
    """What the installed wheel traces with: linked libraries and imported Embree calls."""
    import mitsuba

    pkg = os.path.dirname(mitsuba.__file__)
    out = {"mitsuba_dir": pkg, "bundled_embree": None, "embree_version": None, "llvm_kernels_call": []}
    libs = sorted(glob.glob(os.path.join(pkg, "libembree*.so*")))
    if libs:
        out["bundled_embree"] = os.path.basename(libs[0])
        with open(libs[0], "rb") as f:
            data = f.read()
        k = data.find(b"Embree Ray Tracing Kernels")
        if k >= 0:
            for tok in data[k:k + 4096].split(b"\0"):
                tok = tok.strip()
                if tok[:1].isdigit() and tok.count(b".") == 2:
                    out["embree_version"] = tok.decode()
                    break
    core = os.path.join(pkg, "libmitsuba.so")
    if os.path.exists(core):
        with open(core, "rb") as f:
            data = f.read()
        for name in (b"rtcIntersect1", b"rtcIntersect4", b"rtcIntersect8", b"rtcIntersect16",
                     b"rtcOccluded1", b"rtcOccluded4", b"rtcOccluded8", b"rtcOccluded16"):
            if name + b"E" in data:  # the mangled imports: ..13rtcIntersect16EPK...
                out["llvm_kernels_call"].append(name.decode())
        out["embree_accel_class"] = b"EmbreeAccel" in data
        out["kdtree_class"] = b"ShapeKDTree" in data
    return out


def load_scene_pair(mi, scene_dir):
    """Mitsuba's scene (as mitsuba_bench.py builds it) and embreex's flat world mesh."""
    import numpy as np
    from embree_bench import scene_triangles
    from embreex import rtcore_scene
    from embreex.mesh_construction import TriangleMesh
    from mitsuba_bench import dumped_scene_dict

    _, desc = dumped_scene_dict(mi, scene_dir, 1, 16, 8)
    mscene = mi.load_dict(desc)
    tris, _ = scene_triangles(scene_dir)
    escene = rtcore_scene.EmbreeScene()
    TriangleMesh(escene, tris)
    flat = tris.reshape(-1, 3)
    return mscene, escene, flat.min(0).astype(np.float64), flat.max(0).astype(np.float64)


def timed(fn):
    """(CPU seconds of the process, CPU seconds of this thread, wall seconds, result)."""
    p0, t0, w0 = time.process_time(), time.thread_time(), time.perf_counter()
    r = fn()
    return time.process_time() - p0, time.thread_time() - t0, time.perf_counter() - w0, r


def mitsuba_query(mi, dr, mscene, ray, query):
    import numpy as np

    def run():
        if query == "closest":
            pi = mscene.ray_intersect_preliminary(ray, coherent=False)
            dr.eval(pi.t, pi.prim_index, pi.shape_index)
            dr.sync_thread()
            return pi.t
        m = mscene.ray_test(ray, coherent=False)
        dr.eval(m)
        dr.sync_thread()
        return m

    cpu, _, wall, r = timed(run)
    a = np.asarray(r)
    hits = np.isfinite(a).mean() if query == "closest" else a.mean()
    return {"cpu_s": cpu, "wall_s": wall, "hit_fraction": float(hits)}


def embree_query(escene, o, d, query):
    import numpy as np

    q = "INTERSECT" if query == "closest" else "OCCLUDED"
    _, cpu, wall, r = timed(lambda: escene.run(o, d, query=q))
    return {"cpu_s": cpu, "wall_s": wall, "hit_fraction": float((np.asarray(r) >= 0).mean())}


def miss_rays(lo, hi, n):
    """Rays that start beyond the bounds' upper corner and point away from them: every
    query ends at the root box, so its time is the per-call overhead (loads, stores, setup)
    of each tracer's interface."""
    import numpy as np

    rng = np.random.default_rng(1)
    o = hi + (hi - lo + 1.0) * (1.0 + rng.random((n, 3)))
    d = 0.5 + rng.random((n, 3))
    d /= np.linalg.norm(d, axis=1, keepdims=True)
    return o.astype(np.float32), d.astype(np.float32)


def measure_rays(args):
    """Per scene: Mitsuba and embreex CPU ns per ray, closest and any, each round."""
    import mitsuba as mi

    mi.set_variant(args.variant)
    import drjit as dr
    from embree_bench import incoherent_rays

    dr.set_thread_count(args.threads)
    loaded = {}
    for name in args.scenes:
        mscene, escene, lo, hi = load_scene_pair(mi, os.path.join(args.scene_root, name))
        o, d = incoherent_rays(lo, hi, args.rays, args.seed)
        mo, md = miss_rays(lo, hi, args.rays)
        sets = {"": (o, d), "miss_": (mo, md)}
        mrays = {k: mi.Ray3f(o=mi.Point3f(a[:, 0], a[:, 1], a[:, 2]), d=mi.Vector3f(b[:, 0], b[:, 1], b[:, 2]))
                 for k, (a, b) in sets.items()}
        dr.eval(mrays)
        for q in ("closest", "any"):  # JIT compilation and Embree's lazy commit, untimed
            mitsuba_query(mi, dr, mscene, mrays[""], q)
            embree_query(escene, o[:1024], d[:1024], q)
        loaded[name] = (mscene, escene, mrays, sets)
    keys = [f"{p}_{s}{q}" for s, q in (("", "closest"), ("", "any"), ("miss_", "closest")) for p in ("mitsuba", "embree")]
    rows = {n: {k: [] for k in keys} for n in args.scenes}
    hits = {}
    for r in range(args.rounds):
        for name in args.scenes:
            mscene, escene, mrays, sets = loaded[name]
            for s, q in (("", "closest"), ("", "any"), ("miss_", "closest")):
                m = mitsuba_query(mi, dr, mscene, mrays[s], q)
                e = embree_query(escene, *sets[s], q)
                rows[name][f"mitsuba_{s}{q}"].append(1e9 * m["cpu_s"] / args.rays)
                rows[name][f"embree_{s}{q}"].append(1e9 * e["cpu_s"] / args.rays)
                hits[(name, s + q)] = (m["hit_fraction"], e["hit_fraction"])
            print(f"[ray_budget] round {r + 1}/{args.rounds} {name}: " + ", ".join(
                f"{k} {v[-1]:.0f}" for k, v in rows[name].items()) + " CPU ns/ray", file=sys.stderr)
    out = {}
    for name in args.scenes:
        med = {k: statistics.median(v) for k, v in rows[name].items()}
        out[name] = {"cpu_ns_per_ray_median": med, "cpu_ns_per_ray_rounds": rows[name],
                     "hit_fraction_mitsuba_embree": {q: hits[(name, q)] for q in ("closest", "any", "miss_closest")}}
    return out


RENDER_DSOS = ("libembree", "[JIT]", "libdrjit", "libmitsuba", "libc.so", "libm.so", "libstdc++", "libnanothread")


def perf_embree_share(scene_dir, res, spp, workdir):
    """Mitsuba's own share of render time inside Embree: `perf record` (cpu-clock samples)
    of scripts/mitsuba_bench.py on one thread, samples in libembree3.so over the samples of
    the render's code (Embree, the JIT kernels, Dr.Jit, Mitsuba, libc/libm; scene loading in
    Python and LLVM's compilation are left out)."""
    import subprocess

    name = os.path.basename(os.path.normpath(scene_dir))
    data = os.path.join(workdir, f"{name}.perf.data")
    cmd = ["perf", "record", "-e", "cpu-clock", "-F", "499", "-o", data, "--", sys.executable,
           os.path.join(HERE, "mitsuba_bench.py"), "--scene-dir", scene_dir, "--res", str(res), "--spp", str(spp),
           "--threads", "1", "--repeats", "3"]
    print("[ray_budget] " + " ".join(cmd), file=sys.stderr)
    subprocess.run(cmd, check=True, stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)
    rep = subprocess.run(["perf", "report", "-i", data, "--sort", "dso", "--stdio"], check=True,
                         capture_output=True, text=True).stdout
    shares = {}
    for line in rep.splitlines():
        parts = line.split(None, 1)
        if len(parts) == 2 and parts[0].endswith("%") and not line.startswith("#"):
            shares[parts[1].strip()] = float(parts[0][:-1])
    render = sum(v for k, v in shares.items() if any(d in k for d in RENDER_DSOS))
    embree = sum(v for k, v in shares.items() if "libembree" in k)
    kernels = embree + sum(v for k, v in shares.items() if "[JIT]" in k)
    # Lower bound: Dr.Jit's tracing and code generation of the first render (not its LLVM
    # part) count as render time; upper bound: only the compiled kernels and Embree do.
    return {"embree_share_of_render": embree / render if render else None,
            "embree_share_of_kernels": embree / kernels if kernels else None, "dso_percent": shares}


def suite_rates(raw):
    """Median filtrace samples per CPU-s and Mitsuba samples/s (x its threads = CPU-s, an
    upper bound of its CPU time) per scene from a bench_suite.sh raw folder."""
    out = {}
    for name in SCENES:
        ft = [json.load(open(p))["scenes"][0]["render"][0] for p in sorted(glob.glob(os.path.join(raw, f"filtrace_render_{name}_*.json")))]
        mi = [json.load(open(p)) for p in sorted(glob.glob(os.path.join(raw, f"mitsuba_{name}_*.json")))]
        rays = [json.load(open(p))["scenes"][0]["rays"] for p in sorted(glob.glob(os.path.join(raw, f"filtrace_rays_{name}_*.json")))]
        if not ft or not mi:
            continue
        em = [json.load(open(p)) for p in sorted(glob.glob(os.path.join(raw, f"embree_{name}_*.json")))]
        for q in ("closest", "any"):
            if em:
                out.setdefault(name, {})[f"embree_{q}_ns"] = 1e3 / statistics.median(
                    e[f"incoherent_{q}"]["mrays_per_cpu_s"] for e in em)
        ratio = None
        if rays:
            ratio = statistics.median(r["incoherent_closest_mrays_per_cpu_s"] / r["incoherent_any_mrays_per_cpu_s"] for r in rays)
        out[name] = {
            **out.get(name, {}),
            "filtrace_any_over_closest_time": ratio,
            "filtrace_cpu_ns_per_sample": 1e9 / statistics.median(r["samples_per_cpu_s"] for r in ft),
            "mitsuba_cpu_ns_per_sample": 1e9 * statistics.median(m["threads"] / m["samples_per_s_best"] for m in mi),
            "ratio_samples_per_s": statistics.median(r["samples_per_s_best"] for r in ft)
            / statistics.median(m["samples_per_s_best"] for m in mi),
        }
    return out


def borrow_ray_counts(profile):
    """grass-1m has no scalar render (`filtrace render` cannot build it): it takes grass's
    rays per sample, marked as such (the denser field likely hits more, so this is low)."""
    g, d = profile.get("grass"), profile.get("grass-1m")
    if g and d and not d.get("closest_rays") and g.get("closest_rays"):
        d.update(closest_rays=g["closest_rays"], shadow_rays=g["shadow_rays"], rays_from="grass")


def uniform_any_ir(prof, rates):
    """Ir per uniform incoherent any-hit ray: measured where the profile has it, else the
    closest-hit figure scaled by filtrace's own closest/any CPU time per ray on those rays
    (the suite's `bench suite --no-render` runs, --suite-raw)."""
    if prof.get("uniform_any_ir"):
        return prof["uniform_any_ir"]
    if rates and rates.get("filtrace_any_over_closest_time"):
        return prof["uniform_closest_ir"] * rates["filtrace_any_over_closest_time"]
    return None


def budget(name, prof, rates, rays):
    """The per-scene arithmetic of the docs section (all times CPU ns per sample)."""
    kc = prof["closest_ir"] / prof["closest_rays"] / prof["uniform_closest_ir"]
    u_any = uniform_any_ir(prof, rates)
    ka = prof["any_ir"] / prof["shadow_rays"] / u_any if prof["shadow_rays"] and u_any else None
    ray_share = (prof["closest_ir"] + prof["any_ir"]) / prof["sample_ir"]
    row = {"scene": name, "closest_rays": prof["closest_rays"], "shadow_rays": prof["shadow_rays"],
           "coherence_closest": kc, "coherence_any": ka, "filtrace_ray_share": ray_share,
           "rays_from": prof.get("rays_from")}
    if rates:
        t_ft = rates["filtrace_cpu_ns_per_sample"]
        t_mi = rates["mitsuba_cpu_ns_per_sample"]
        target = t_mi / 2.0
        rays_ft, other_ft = ray_share * t_ft, (1.0 - ray_share) * t_ft
        row.update({"filtrace_ns": t_ft, "mitsuba_ns": t_mi, "ratio": rates["ratio_samples_per_s"],
                    "filtrace_ray_ns": rays_ft, "filtrace_other_ns": other_ft, "target_ns": target,
                    "ray_speedup_needed": rays_ft / (target - other_ft) if target > other_ft else None,
                    "ray_speedup_needed_no_other": rays_ft / target})
    if rays:
        m = rays["cpu_ns_per_ray_median"]
        # Mitsuba's cost per ray: its ratio to embreex in the same run, times embreex's cost
        # in the suite's run (--suite-raw), so that a run on a loaded machine is not read
        # against the suite's idle samples/s; without the suite, this run's own cost.
        per_ray = {}
        for q in ("closest", "any"):
            e = (rates or {}).get(f"embree_{q}_ns")
            per_ray[q] = m[f"mitsuba_{q}"] / m[f"embree_{q}"] * e if e else m[f"mitsuba_{q}"]
        lb = prof["closest_rays"] * kc * per_ray["closest"] + prof["shadow_rays"] * (ka or 0.0) * per_ray["any"]
        row.update({"mitsuba_ray_ns_lower_bound": lb, "mitsuba_ns_per_uniform_ray": per_ray,
                    "mitsuba_ray_ns_at_uniform_cost": prof["closest_rays"] * per_ray["closest"]
                    + prof["shadow_rays"] * per_ray["any"],
                    "mitsuba_vs_embree_closest": m["mitsuba_closest"] / m["embree_closest"],
                    "mitsuba_vs_embree_any": m["mitsuba_any"] / m["embree_any"]})
        if rates:
            row["mitsuba_ray_share_lower_bound"] = lb / row["mitsuba_ns"]
            # How much faster than Mitsuba's rays filtrace's would have to be at 2x.
            room = row["target_ns"] - row["filtrace_other_ns"]
            row["vs_mitsuba_rays_needed"] = lb / room if room > 0 else None
            row["vs_mitsuba_rays_needed_no_other"] = lb / row["target_ns"]
    return row


def fmt(x, spec=".2f"):
    return "-" if x is None else format(x, spec)


def span(row, key):
    """'low-high x' of a figure from perf's lower and upper bound of Mitsuba's Embree share."""
    lo, hi = row.get(f"{key}_render_perf"), row.get(f"{key}_kernels_perf")
    if lo is None or hi is None:
        return "-"
    return f"{lo:.2f}x" if abs(hi - lo) < 0.005 else f"{lo:.2f}-{hi:.2f}x"


def print_tables(tracer, rays, rows):
    print(f"Mitsuba's tracer: {tracer.get('bundled_embree')} (Embree {tracer.get('embree_version')}), "
          f"LLVM kernels call {', '.join(tracer.get('llvm_kernels_call', []))}; "
          f"kd-tree class present: {tracer.get('kdtree_class')}\n")
    if rays:
        print("| scene | Mitsuba closest | Embree closest | ratio | Mitsuba any | Embree any | ratio "
              "| missing rays (overhead) Mitsuba / Embree |")
        print("|---|---:|---:|---:|---:|---:|---:|---:|")
        for name, r in rays.items():
            m = r["cpu_ns_per_ray_median"]
            print(f"| {name} | {m['mitsuba_closest']:.0f} | {m['embree_closest']:.0f} | "
                  f"{m['mitsuba_closest'] / m['embree_closest']:.2f} | {m['mitsuba_any']:.0f} | "
                  f"{m['embree_any']:.0f} | {m['mitsuba_any'] / m['embree_any']:.2f} | "
                  f"{m['mitsuba_miss_closest']:.0f} / {m['embree_miss_closest']:.0f} |")
        print("\n(CPU ns per uniform incoherent ray, 1 thread, median of the rounds)\n")
    print("| scene | rays/sample closest + shadow | coherence closest / any | filtrace ns/sample (rays) "
          "| Mitsuba ns/sample | Mitsuba rays, ns (share) [at uniform cost] | 2x target ns | filtrace ray speed-up needed "
          "(no other cost) | needed: filtrace rays / Mitsuba rays (no other cost) | Mitsuba in Embree (perf: render / kernels) "
          "| needed, from perf (no other cost) |")
    print("|---|---:|---:|---:|---:|---:|---:|---:|---:|---:|---:|")
    for r in rows:
        lb = r.get("mitsuba_ray_ns_lower_bound")
        share = r.get("mitsuba_ray_share_lower_bound")
        mark = f" ({r['rays_from']}'s)" if r.get("rays_from") else ""
        print(f"| {r['scene']} | {r['closest_rays']:.2f} + {r['shadow_rays']:.2f}{mark} | "
              f"{r['coherence_closest']:.2f} / {fmt(r['coherence_any'])} | "
              f"{fmt(r.get('filtrace_ns'), '.0f')} ({r['filtrace_ray_share']:.0%}) | {fmt(r.get('mitsuba_ns'), '.0f')} | "
              f"{fmt(lb, '.0f')} ({fmt(share, '.0%')}) [{fmt(r.get('mitsuba_ray_ns_at_uniform_cost'), '.0f')}] | "
              f"{fmt(r.get('target_ns'), '.0f')} | "
              f"{fmt(r.get('ray_speedup_needed'))}x ({fmt(r.get('ray_speedup_needed_no_other'))}x) | "
              f"{fmt(r.get('vs_mitsuba_rays_needed'))}x ({fmt(r.get('vs_mitsuba_rays_needed_no_other'))}x) | "
              f"{fmt(r.get('mitsuba_embree_share_of_render_perf'), '.0%')} / "
              f"{fmt(r.get('mitsuba_embree_share_of_kernels_perf'), '.0%')} | {span(r, 'vs_mitsuba_rays_needed')} "
              f"({span(r, 'vs_mitsuba_rays_needed_no_other')}) |")
    print("\n(CPU ns per sample; '-': not measured, or in a speed-up column: the non-ray cost alone exceeds the target)")


def main():
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--scene-root", help="OUT of `filtrace bench suite --dump-scene-json OUT`")
    ap.add_argument("--scenes", default=",".join(SCENES))
    ap.add_argument("--rays", type=int, default=1 << 20)
    ap.add_argument("--rounds", type=int, default=3, help="interleaved rounds (Mitsuba, Embree, ...)")
    ap.add_argument("--threads", type=int, default=1, help="Dr.Jit worker threads (embreex: always 1)")
    ap.add_argument("--variant", default="llvm_ad_rgb")
    ap.add_argument("--seed", type=int, default=7)
    ap.add_argument("--suite-raw", help="OUT/raw of scripts/bench_suite.sh (samples/s of both renderers)")
    ap.add_argument("--profile", help="JSON {scene: {...}} replacing the built-in PROFILE's scenes (same keys)")
    ap.add_argument("--callgrind", metavar="FILTRACE", help="measure PROFILE with callgrind on this (dev) binary")
    ap.add_argument("--cg-res", type=int, default=128, help="callgrind renders: RES x RES pixels")
    ap.add_argument("--cg-spp", type=int, default=2)
    ap.add_argument("--cg-rays", type=int, default=32768, help="callgrind: uniform rays per query")
    ap.add_argument("--cg-dir", default="ray-budget-callgrind", help="callgrind output files")
    ap.add_argument("--perf", action="store_true", help="perf-profile Mitsuba's renders (needs --scene-root)")
    ap.add_argument("--perf-res", type=int, default=256)
    ap.add_argument("--perf-spp", type=int, default=32)
    ap.add_argument("--rays-json", help="reuse the ray timings of an earlier --json output (implies --skip-timing)")
    ap.add_argument("--skip-timing", action="store_true", help="only the budget from --profile/--suite-raw")
    ap.add_argument("--json", help="also write everything as JSON to this file")
    args = ap.parse_args()
    args.scenes = [s for s in args.scenes.split(",") if s]
    if args.rounds < 1 or args.rays < 1:
        ap.error("--rounds and --rays must be at least 1")
    args.skip_timing = args.skip_timing or bool(args.rays_json)
    if not args.skip_timing and not args.scene_root:
        ap.error("--scene-root is needed for the timing (or --skip-timing)")
    profile = PROFILE
    if args.profile:
        with open(args.profile) as f:
            profile = {**PROFILE, **json.load(f)}
    if args.callgrind:
        os.makedirs(args.cg_dir, exist_ok=True)
        profile = dict(profile)
        for name in args.scenes:
            profile[name] = profile_scene(args.callgrind, name, args.cg_res, args.cg_spp, args.cg_rays, args.cg_dir)
            with open(os.path.join(args.cg_dir, "profile.json"), "w") as f:
                json.dump(profile, f, indent=2)
        print(f"[ray_budget] profile written to {args.cg_dir}/profile.json", file=sys.stderr)
    tracer = mitsuba_tracer()
    rays = {} if args.skip_timing else measure_rays(args)
    if args.rays_json:
        with open(args.rays_json) as f:
            rays = json.load(f)["rays"]
    rates = suite_rates(args.suite_raw) if args.suite_raw else {}
    perf = {}
    if args.perf:
        os.makedirs(args.cg_dir, exist_ok=True)
        for n in args.scenes:
            perf[n] = perf_embree_share(os.path.join(args.scene_root, n), args.perf_res, args.perf_spp, args.cg_dir)
            print(f"[ray_budget] {n}: Mitsuba in Embree {perf[n]['embree_share_of_render']:.0%} of its render, "
                  f"{perf[n]['embree_share_of_kernels']:.0%} of its kernels",
                  file=sys.stderr)
    elif args.rays_json:
        with open(args.rays_json) as f:
            perf = json.load(f).get("mitsuba_perf", {})
    borrow_ray_counts(profile)
    rows = [budget(n, profile[n], rates.get(n), rays.get(n)) for n in args.scenes
            if n in profile and profile[n].get("closest_rays")]
    for r in rows:
        got = perf.get(r["scene"]) or {}
        if got.get("embree_share_of_render") is None or not r.get("mitsuba_ns"):
            continue
        # Measured: Mitsuba's time in Embree (lower and upper bound), which replaces the
        # estimate of the coherence transfer.
        for key in ("render", "kernels"):
            ray_ns = got[f"embree_share_of_{key}"] * r["mitsuba_ns"]
            room = r["target_ns"] - r["filtrace_other_ns"]
            r[f"mitsuba_embree_share_of_{key}_perf"] = got[f"embree_share_of_{key}"]
            r[f"vs_mitsuba_rays_needed_{key}_perf"] = ray_ns / room if room > 0 else None
            r[f"vs_mitsuba_rays_needed_no_other_{key}_perf"] = ray_ns / r["target_ns"]
    print_tables(tracer, rays, rows)
    if args.json:
        with open(args.json, "w") as f:
            json.dump({"tracer": tracer, "rays": rays, "rounds": args.rounds, "ray_count": args.rays,
                       "threads": args.threads, "load": os.getloadavg(), "profile": profile,
                       "suite": rates, "mitsuba_perf": perf, "budget": rows}, f, indent=2)
    return 0


if __name__ == "__main__":
    sys.exit(main())
