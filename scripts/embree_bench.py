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

Reports wall-clock Mrays/s and Mrays per CPU-second of the calling thread (embreex casts
rtcIntersect1 in a loop on that thread; the BVH build happens before timing). With
--threads T > 1 the rays are split over T Python threads: this only scales if embreex
releases the GIL, which the script reports rather than assumes.

    pip install embreex trimesh
    python3 scripts/embree_bench.py {MESH.obj | --scene-dir DIR} [--rays N] [--res WxH] [--threads T] [--repeats K] [--json]
"""
import argparse
import json
import os
import time
from concurrent.futures import ThreadPoolExecutor

import numpy as np
from embreex import rtcore_scene
from embreex.mesh_construction import TriangleMesh


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


def main():
    ap = argparse.ArgumentParser()
    ap.add_argument("mesh", nargs="?", help="an OBJ file (or use --scene-dir)")
    ap.add_argument("--scene-dir", help="a scene dumped by `filtrace bench suite --dump-scene-json`")
    ap.add_argument("--rays", type=int, default=1 << 20)
    ap.add_argument("--res", default="1024x1024")
    ap.add_argument("--threads", type=int, default=1)
    ap.add_argument("--repeats", type=int, default=3)
    ap.add_argument("--seed", type=int, default=7)
    ap.add_argument("--json", action="store_true")
    a = ap.parse_args()
    w, h = (int(x) for x in a.res.split("x"))

    if (a.mesh is None) == (a.scene_dir is None):
        ap.error("give either MESH or --scene-dir")
    if a.scene_dir:
        tris, name = scene_triangles(a.scene_dir)
    else:
        import trimesh

        mesh = trimesh.load(a.mesh, process=False, force="mesh")
        tris, name = mesh.vertices[mesh.faces].astype(np.float32), a.mesh
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


if __name__ == "__main__":
    main()
