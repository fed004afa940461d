#!/usr/bin/env python3
"""Embree 4 (through embreex) on the ray sets of `filtrace_accel::bench::ray_bench`.

Same mesh (an OBJ: the file itself, or one written by
`cargo run --release -p filtrace-accel --example raybench -- SCENE --write-obj OUT.obj`; or
with --scene-dir DIR a scene of `filtrace bench suite` dumped by
`filtrace bench suite --scenes NAME --dump-scene-json OUT`, DIR = OUT/NAME: every instance's
world-space triangles in one Embree mesh), same ray distributions and counts:
  - primary: W x H pinhole camera, 45 degree vertical fov, eye at
    centre + normalize(0.5, 0.4, 1.0) * 2.4 * bounding radius, one ray per pixel;
  - incoherent: N rays, origins uniform in the bounding box, directions uniform on the
    sphere, t in [0, inf), closest hit (INTERSECT) and any hit (OCCLUDED).
(The generators differ - numpy vs SplitMix64 - so the rays are the same distribution,
not the same bits.)

With --native the incoherent sets are cast by scripts/embree_native.c instead: Embree 3
(the system's libembree3, Debian 3.13.5) called from C, one rtcIntersect1 / rtcOccluded1
per ray and rtcIntersect8 / rtcOccluded8 on groups of eight, on the same one-geometry
mesh, rays drawn by filtrace's own generator (SplitMix64, seed 7 as `filtrace bench suite`),
so the same rays bit for bit. It measures Embree without embreex's per-call overhead. The
binary is compiled at run time with `cc` into a temporary directory (a measurement tool, not
a dependency); headers from $EMBREE_INCLUDE, /usr/include or Mitsuba's bundled embree3,
library from $EMBREE_LIB or the system's libembree3.so.3.

Reports wall-clock Mrays/s and Mrays per CPU-second of the calling thread (embreex casts
rtcIntersect1 in a loop on that thread; the BVH build happens before timing). With
--threads T > 1 the rays are split over T Python threads: this only scales if embreex
releases the GIL, which the script reports rather than assumes.

    pip install embreex trimesh
    python3 scripts/embree_bench.py {MESH.obj | --scene-dir DIR} [--rays N] [--res WxH] [--threads T] [--repeats K] [--json]
        [--native [--quality medium|high] [--seed S]]
"""
import argparse
import json
import os
import time
from concurrent.futures import ThreadPoolExecutor

import numpy as np


def read_ply(path):
    """Positions and triangles of a binary little-endian PLY as the suite dump writes it
    (float x y z [nx ny nz] [u v], faces as uchar 3 + int32 x 3)."""
    with open(path, "rb") as f:
        props, counts, element = [], {}, None
        while True:
            line = f.readline().decode("ascii").strip()
            if line == "end_header":
                break
            parts = line.split()
            if parts[0] == "element":
                element, counts[parts[1]] = parts[1], int(parts[2])
            elif parts[0] == "property" and element == "vertex":
                props.append(parts[-1])
        data = f.read()
    vertex = np.dtype([(p, "<f4") for p in props])
    nv, nf = counts["vertex"], counts["face"]
    verts = np.frombuffer(data, dtype=vertex, count=nv)
    faces = np.frombuffer(data, dtype=np.dtype([("n", "u1"), ("i", "<i4", 3)]), count=nf, offset=nv * vertex.itemsize)
    if nf and not (faces["n"] == 3).all():
        raise SystemExit(f"{path}: only triangles are expected")
    pos = np.stack([verts["x"], verts["y"], verts["z"]], axis=1).astype(np.float64)
    return pos, faces["i"]


def scene_triangles(scene_dir):
    """World-space triangles (n, 3, 3) of every instance of every shape of a suite dump."""
    with open(os.path.join(scene_dir, "scene.json")) as f:
        doc = json.load(f)
    parts = []
    for s in doc["shapes"]:
        pos, idx = read_ply(os.path.join(scene_dir, s["file"]))
        for m in s["instances"]:
            m = np.asarray(m, dtype=np.float64).reshape(4, 4)
            world = pos @ m[:3, :3].T + m[:3, 3]
            parts.append(world[idx])
    return np.concatenate(parts).astype(np.float32), doc["name"]


def primary_rays(lo, hi, w, h):
    c = 0.5 * (lo + hi)
    r = max(0.5 * np.linalg.norm(hi - lo), 1e-6)
    d0 = np.array([0.5, 0.4, 1.0])
    eye = c + d0 / np.linalg.norm(d0) * 2.4 * r
    fw = (c - eye) / np.linalg.norm(c - eye)
    u = np.cross(fw, [0.0, 1.0, 0.0])
    u /= np.linalg.norm(u)
    v = np.cross(u, fw)
    tan_half = np.tan(np.radians(22.5))
    xs = (2.0 * (np.arange(w) + 0.5) / w - 1.0) * tan_half * (w / h)
    ys = (1.0 - 2.0 * (np.arange(h) + 0.5) / h) * tan_half
    sx, sy = np.meshgrid(xs, ys)
    d = fw + sx[..., None] * u + sy[..., None] * v
    d = d.reshape(-1, 3)
    o = np.broadcast_to(eye, d.shape)
    return o.astype(np.float32), d.astype(np.float32)


def incoherent_rays(lo, hi, n, seed):
    rng = np.random.default_rng(seed)
    o = lo + (hi - lo) * rng.random((n, 3))
    z = 1.0 - 2.0 * rng.random(n)
    r = np.sqrt(np.maximum(0.0, 1.0 - z * z))
    phi = 2.0 * np.pi * rng.random(n)
    d = np.stack([r * np.cos(phi), r * np.sin(phi), z], axis=1)
    return o.astype(np.float32), d.astype(np.float32)


def cast(scene, o, d, query, threads):
    if threads <= 1:
        return scene.run(o, d, query=query)
    parts = np.array_split(np.arange(len(o)), threads * 8)
    with ThreadPoolExecutor(threads) as ex:
        res = list(ex.map(lambda idx: scene.run(np.ascontiguousarray(o[idx]), np.ascontiguousarray(d[idx]), query=query), parts))
    return np.concatenate(res)


def measure(scene, o, d, query, threads, repeats):
    best_wall, best_cpu, hits = float("inf"), float("inf"), 0
    for _ in range(repeats):
        c0, t0 = time.thread_time(), time.perf_counter()
        r = cast(scene, o, d, query, threads)
        wall, cpu = time.perf_counter() - t0, time.thread_time() - c0
        best_wall, best_cpu = min(best_wall, wall), min(best_cpu, cpu)
        # INTERSECT returns primID, OCCLUDED 0 for a hit; both -1 for a miss.
        hits = int((np.asarray(r) >= 0).sum())
    n = len(o)
    out = {"mrays": n / best_wall / 1e6, "hit_fraction": hits / n}
    if threads <= 1:
        out["mrays_per_cpu_s"] = n / best_cpu / 1e6
    return out


def embree3_include(cache):
    """A directory holding embree3/rtcore.h usable from C. Mitsuba's bundled headers put the
    API in a C++ namespace (its own build); Debian's libembree3 has none, so a copy with the
    namespace switched off is made in `cache`."""
    import importlib.util
    import shutil

    candidates = [os.environ.get("EMBREE_INCLUDE", ""), "/usr/include", "/usr/local/include"]
    spec = importlib.util.find_spec("mitsuba")
    if spec and spec.submodule_search_locations:
        candidates += [os.path.join(p, "include") for p in spec.submodule_search_locations]
    for inc in candidates:
        config = os.path.join(inc, "embree3", "rtcore_config.h")
        if not inc or not os.path.isfile(config):
            continue
        with open(config) as f:
            text = f.read()
        if "\n#define EMBREE_API_NAMESPACE\n" not in text:
            return inc
        copy = os.path.join(cache, "include")
        shutil.rmtree(copy, ignore_errors=True)
        shutil.copytree(os.path.join(inc, "embree3"), os.path.join(copy, "embree3"))
        with open(os.path.join(copy, "embree3", "rtcore_config.h"), "w") as f:
            f.write(text.replace("\n#define EMBREE_API_NAMESPACE\n", "\n"))
        return copy
    raise SystemExit("embree_bench.py --native: no Embree 3 headers (embree3/rtcore_config.h) in "
                     f"{[c for c in candidates if c]}; set EMBREE_INCLUDE, or apt-get install libembree-dev")


def embree3_library():
    import glob

    env = os.environ.get("EMBREE_LIB")
    if env:
        if not os.path.isfile(env):
            raise SystemExit(f"embree_bench.py --native: EMBREE_LIB={env} is not a file")
        return env
    for d in ("/usr/lib/x86_64-linux-gnu", "/usr/lib/aarch64-linux-gnu", "/usr/lib", "/usr/local/lib"):
        found = sorted(glob.glob(os.path.join(d, "libembree3.so*")))
        if found:
            return found[0]
    raise SystemExit("embree_bench.py --native: no libembree3.so in the system library directories; "
                     "set EMBREE_LIB=/path/to/libembree3.so.3, or apt-get install libembree3-3")


def native_binary():
    """scripts/embree_native.c compiled with `cc -O2` into a temporary directory keyed by the
    source, the library and the compiler (reused while those stay the same)."""
    import hashlib
    import shutil
    import subprocess
    import tempfile

    src = os.path.join(os.path.dirname(os.path.abspath(__file__)), "embree_native.c")
    cc = shutil.which(os.environ.get("CC", "cc"))
    if cc is None:
        raise SystemExit("embree_bench.py --native: no C compiler (`cc`, or set CC); apt-get install gcc")
    lib = embree3_library()
    with open(src, "rb") as f:
        key = hashlib.sha1(f.read() + f"{cc}\0{lib}".encode()).hexdigest()[:12]
    cache = os.path.join(tempfile.gettempdir(), f"filtrace-embree-native-{key}")
    exe = os.path.join(cache, "embree_native")
    if os.access(exe, os.X_OK):
        return exe
    os.makedirs(cache, exist_ok=True)
    inc = embree3_include(cache)
    cmd = [cc, "-O2", "-std=c11", "-D_DEFAULT_SOURCE", "-I", inc, src, "-o", exe + ".tmp", lib, "-lm"]
    done = subprocess.run(cmd, capture_output=True, text=True)
    if done.returncode != 0:
        raise SystemExit(f"embree_bench.py --native: compiling failed: {' '.join(cmd)}\n{done.stderr}")
    os.replace(exe + ".tmp", exe)
    return exe


def run_native(tris, name, a):
    """The incoherent sets through scripts/embree_native.c (see the module docs)."""
    import subprocess
    import tempfile

    exe = native_binary()
    with tempfile.TemporaryDirectory(prefix="embree-native-") as tmp:
        path = os.path.join(tmp, "tris.bin")
        with open(path, "wb") as f:
            # A triangle soup, as embreex's TriangleMesh builds it: 3 vertices per triangle.
            n = len(tris)
            np.array([3 * n], "<u4").tofile(f)
            np.ascontiguousarray(tris, "<f4").tofile(f)
            np.array([n], "<u4").tofile(f)
            np.arange(3 * n, dtype="<u4").tofile(f)
        cmd = [exe, path, "--rays", str(a.rays), "--repeats", str(a.repeats), "--seed", str(a.seed),
               "--quality", a.quality]
        done = subprocess.run(cmd, capture_output=True, text=True)
    if done.returncode != 0:
        raise SystemExit(f"embree_bench.py: {exe} failed ({done.returncode}): {done.stderr.strip()}")
    rep = json.loads(done.stdout)
    rep["mesh"] = name
    return rep


def main():
    ap = argparse.ArgumentParser()
    ap.add_argument("mesh", nargs="?", help="an OBJ file (or use --scene-dir)")
    ap.add_argument("--scene-dir", help="a scene dumped by `filtrace bench suite --dump-scene-json`")
    ap.add_argument("--rays", type=int, default=1 << 20)
    ap.add_argument("--res", default="1024x1024")
    ap.add_argument("--threads", type=int, default=1)
    ap.add_argument("--repeats", type=int, default=3)
    ap.add_argument("--seed", type=int, default=7, help="filtrace's ray bench seed; numpy's generator for embreex")
    ap.add_argument("--native", action="store_true", help="Embree 3 from C on the incoherent sets (embree_native.c)")
    ap.add_argument("--quality", choices=("medium", "high"), default="medium", help="--native: BVH build quality")
    ap.add_argument("--json", action="store_true")
    a = ap.parse_args()
    if a.native and a.threads != 1:
        ap.error("--native measures one thread")
    w, h = (int(x) for x in a.res.split("x"))

    if (a.mesh is None) == (a.scene_dir is None):
        ap.error("give either MESH or --scene-dir")
    if a.scene_dir:
        tris, name = scene_triangles(a.scene_dir)
    else:
        import trimesh

        mesh = trimesh.load(a.mesh, process=False, force="mesh")
        tris, name = mesh.vertices[mesh.faces].astype(np.float32), a.mesh
    if a.native:
        return report_native(run_native(tris, name, a), a.json)
    from embreex import rtcore_scene
    from embreex.mesh_construction import TriangleMesh

    t0 = time.perf_counter()
    scene = rtcore_scene.EmbreeScene()
    TriangleMesh(scene, tris)
    lo, hi = tris.reshape(-1, 3).min(0).astype(np.float64), tris.reshape(-1, 3).max(0).astype(np.float64)
    po, pd = primary_rays(lo, hi, w, h)
    io, idr = incoherent_rays(lo, hi, a.rays, a.seed)
    scene.run(io[:1024], idr[:1024])  # commits the scene: the BVH build
    build_s = time.perf_counter() - t0
    rep = {
        "mesh": name,
        "triangles": len(tris),
        "threads": a.threads,
        "build_s_incl_ray_generation": build_s,
        "primary_closest": measure(scene, po, pd, "INTERSECT", a.threads, a.repeats),
        "incoherent_closest": measure(scene, io, idr, "INTERSECT", a.threads, a.repeats),
        "incoherent_any": measure(scene, io, idr, "OCCLUDED", a.threads, a.repeats),
    }
    if a.json:
        print(json.dumps(rep, indent=2))
        return
    print(f"embree (embreex) `{name}`: {len(tris)} triangles, {a.threads} thread(s)")
    print("| query | Mrays/s | Mrays per CPU-s | hit fraction |\n|---|---:|---:|---:|")
    for k in ("primary_closest", "incoherent_closest", "incoherent_any"):
        m = rep[k]
        cpu = f"{m['mrays_per_cpu_s']:.2f}" if "mrays_per_cpu_s" in m else "n/a"
        print(f"| {k.replace('_', ' ')} | {m['mrays']:.2f} | {cpu} | {m['hit_fraction']:.3f} |")


def report_native(rep, as_json):
    if as_json:
        print(json.dumps(rep, indent=2))
        return
    print(f"embree {rep['embree']} (native C) `{rep['mesh']}`: {rep['triangles']} triangles, 1 thread, "
          f"{rep['build_quality']} BVH")
    print("| query | Mrays per CPU-s (best) | median | wall Mrays/s | hit fraction |\n|---|---:|---:|---:|---:|")
    for k in ("incoherent_closest", "incoherent_any", "packet8_incoherent_closest", "packet8_incoherent_any"):
        m = rep[k]
        print(f"| {k.replace('_', ' ')} | {m['mrays_per_cpu_s']:.2f} | {m['mrays_per_cpu_s_median']:.2f} "
              f"| {m['mrays']:.2f} | {m['hit_fraction']:.3f} |")


if __name__ == "__main__":
    main()
