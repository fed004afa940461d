#!/usr/bin/env python3
"""Mitsuba 3 path-tracing throughput, the baseline of the path tracer's speed goals.

Without --scene-dir: the Cornell box, ../shared/scenes/cornell_box/cornell_box_lit.obj, with
the settings of ../shared/reference/README.md (512x512, max_depth 8, RR from depth 5, box
filter, independent sampler).

With --scene-dir DIR: a scene of `filtrace bench suite` as filtrace renders it, from the dump
`filtrace bench suite --scenes NAME --dump-scene-json OUT` writes to OUT/NAME (scene.json and
one binary PLY per mesh and material, object space, with the instance transforms). Same
camera, depth, spp and sampler settings; every BSDF two-sided (filtrace shades both faces);
meshes placed more than once become Mitsuba shapegroups and instances, as filtrace instances
them; the sky (linear in cos(theta) from horizon to zenith, ground below) becomes an envmap
bitmap. Conductor and plastic map to Mitsuba's roughconductor / roughplastic (GGX,
alpha = roughness^2), close but not identical models: compare mean colours only as a check
that the same scene was rendered.

The first render of each run includes LLVM JIT compilation, so it is reported separately and
the rate is taken from the following renders (best and median).

Needs `pip install mitsuba` and, for the llvm variants, Debian's libllvm19
(`apt-get install libllvm19`). Measuring only; not a dependency of filtrace.

    python3 scripts/mitsuba_bench.py [--scene-dir DIR] [--spp 64] [--max-depth 8] [--res 512]
                                     [--threads 2] [--repeats 3] [--json]
"""
import argparse
import json
import math
import os
import statistics
import sys
import time

HERE = os.path.dirname(os.path.abspath(__file__))
OBJ = os.path.join(HERE, "..", "..", "shared", "scenes", "cornell_box", "cornell_box_lit.obj")

# Kd/Ke of ../shared/scenes/SOURCES.md (Mitsuba's built-in Cornell box values).
MATERIALS = {
    "white": (0.885809, 0.698859, 0.666422),
    "red": (0.570068, 0.0430135, 0.0443706),
    "green": (0.105421, 0.37798, 0.076425),
}
LIGHT_RADIANCE = (18.387, 13.9873, 6.75357)


def split_obj_by_material(path, out_dir):
    """One OBJ per usemtl group, so each gets its own Mitsuba BSDF."""
    verts, groups, current = [], {}, None
    with open(path) as f:
        for line in f:
            parts = line.split()
            if not parts:
                continue
            if parts[0] == "v":
                verts.append(line)
            elif parts[0] == "usemtl":
                current = parts[1]
            elif parts[0] == "f":
                idx = []
                for p in parts[1:]:
                    i = int(p.split("/")[0])
                    idx.append(i if i > 0 else len(verts) + 1 + i)
                groups.setdefault(current, []).append(idx)
    files = {}
    for name, faces in groups.items():
        out = os.path.join(out_dir, f"{name}.obj")
        with open(out, "w") as f:
            f.writelines(verts)
            for face in faces:
                f.write("f " + " ".join(str(i) for i in face) + "\n")
        files[name] = out
    return files


def sensor_dict(mi, camera, spp, res, clip):
    """Filtrace's pinhole camera: eye, target, up, vertical field of view, square pixels."""
    return {
        "type": "perspective",
        "fov": camera["vfov_deg"],
        "fov_axis": "y",
        "near_clip": clip[0],
        "far_clip": clip[1],
        "to_world": mi.ScalarTransform4f().look_at(origin=camera["eye"], target=camera["target"], up=camera["up"]),
        "sampler": {"type": "independent", "sample_count": spp},
        "film": {"type": "hdrfilm", "width": res, "height": res, "rfilter": {"type": "box"}},
    }


def cornell_dict(mi, files, spp, res, max_depth):
    shapes = {}
    for name, path in files.items():
        shape = {"type": "obj", "filename": path, "face_normals": True}
        if name in MATERIALS:
            shape["bsdf"] = {"type": "diffuse", "reflectance": {"type": "rgb", "value": MATERIALS[name]}}
        else:  # the light quad: Kd 0 as in cornell_box_lit.mtl
            shape["bsdf"] = {"type": "diffuse", "reflectance": {"type": "rgb", "value": (0.0, 0.0, 0.0)}}
            shape["emitter"] = {"type": "area", "radiance": {"type": "rgb", "value": LIGHT_RADIANCE}}
        shapes[name] = shape
    camera = {"eye": [278, 273, -800], "target": [278, 273, -799], "up": [0, 1, 0], "vfov_deg": 39.3077}
    return {
        "type": "scene",
        "integrator": {"type": "path", "max_depth": max_depth, "rr_depth": 5},
        "sensor": sensor_dict(mi, camera, spp, res, (0.01, 1e4)),
        **shapes,
    }


def rgb(value):
    return {"type": "rgb", "value": [float(x) for x in value]}


def texture(mi, spec, textures):
    """A filtrace colour: constant, or a texture times a factor (raw f32 RGB, rows top first)."""
    import numpy as np

    if "rgb" in spec:
        return rgb(spec["rgb"])
    t = textures[spec["texture"]]
    texels = np.fromfile(t["path"], dtype="<f4").reshape(t["height"], t["width"], 3)
    texels = texels * np.asarray(spec["factor"], dtype=np.float32)
    return {"type": "bitmap", "bitmap": mi.Bitmap(np.ascontiguousarray(texels)), "raw": True, "filter_type": "bilinear"}


def bsdf_dict(mi, material, textures):
    b = material["bsdf"]
    if b["type"] == "diffuse":
        inner = {"type": "diffuse", "reflectance": texture(mi, b["reflectance"], textures)}
    elif b["type"] == "conductor":
        inner = {"type": "roughconductor", "distribution": "ggx", "alpha": max(b["roughness"] ** 2, 1e-4),
                 "eta": rgb(b["eta"]), "k": rgb(b["k"])}
    elif b["type"] == "plastic":
        inner = {"type": "roughplastic", "distribution": "ggx", "alpha": max(b["roughness"] ** 2, 1e-4),
                 "int_ior": b["ior"], "diffuse_reflectance": texture(mi, b["diffuse"], textures)}
    else:
        raise SystemExit(f"unknown BSDF type {b['type']!r} in the scene dump")
    return {"type": "twosided", "bsdf": inner}


def sky_bitmap(mi, lights):
    """filtrace's environment (constant + sky, summed) as a lat-long envmap: Mitsuba's row r
    looks along theta = (r + 0.5) / H * pi from +y, and filtrace's sky depends on y only."""
    import numpy as np

    h, w = 256, 8
    y = np.cos((np.arange(h) + 0.5) / h * np.pi)[:, None]
    img = np.zeros((h, 3), dtype=np.float64)
    for l in lights:
        if l["type"] == "constant":
            img += np.asarray(l["radiance"])
        elif l["type"] == "sky":
            z, hz, g = (np.asarray(l[k]) for k in ("zenith", "horizon", "ground"))
            img += np.where(y >= 0.0, hz + (z - hz) * np.clip(y, 0.0, 1.0), g)
    img = np.repeat(img[:, None, :], w, axis=1).astype(np.float32)
    return mi.Bitmap(np.ascontiguousarray(img))


def light_dicts(mi, lights):
    out = {}
    envs = [l for l in lights if l["type"] in ("constant", "sky")]
    if envs and all(l["type"] == "constant" for l in envs):
        out["env"] = {"type": "constant", "radiance": rgb([sum(l["radiance"][c] for l in envs) for c in range(3)])}
    elif envs:
        out["env"] = {"type": "envmap", "bitmap": sky_bitmap(mi, envs)}
    for i, l in enumerate(lights):
        if l["type"] == "point":
            out[f"light{i}"] = {"type": "point", "position": l["position"], "intensity": rgb(l["intensity"])}
        elif l["type"] == "directional":
            out[f"light{i}"] = {"type": "directional", "direction": [-x for x in l["direction"]],
                                "irradiance": rgb(l["irradiance"])}
        elif l["type"] == "spot":
            p, d = l["position"], l["direction"]
            target = [p[k] + d[k] for k in range(3)]
            up = [0, 1, 0] if abs(d[1]) < 0.9 else [1, 0, 0]
            out[f"light{i}"] = {
                "type": "spot", "intensity": rgb(l["intensity"]),
                "cutoff_angle": math.degrees(math.acos(l["cos_total_width"])),
                "beam_width": math.degrees(math.acos(l["cos_falloff_start"])),
                "to_world": mi.ScalarTransform4f().look_at(origin=p, target=target, up=up),
            }
    return out


def shape_dicts(mi, doc, scene_dir, textures):
    """Plain shapes for meshes placed once and for emitters (Mitsuba instances cannot emit),
    shapegroups with instances for the rest."""
    out = {}
    for k, s in enumerate(doc["shapes"]):
        material = doc["materials"][s["material"]]
        shape = {"type": "ply", "filename": os.path.join(scene_dir, s["file"]), "face_normals": not s["normals"],
                 "bsdf": bsdf_dict(mi, material, textures)}
        emitter = any(c > 0 for c in material["emission"])
        transforms = [mi.ScalarTransform4f([m[0:4], m[4:8], m[8:12], m[12:16]]) for m in s["instances"]]
        if emitter:
            for j, t in enumerate(transforms):
                faces = [False, True] if material["two_sided_emission"] else [False]
                for flip in faces:
                    out[f"s{k}_{j}_{int(flip)}"] = {**shape, "to_world": t, "flip_normals": flip,
                                                    "emitter": {"type": "area", "radiance": rgb(material["emission"])}}
        elif len(transforms) == 1:
            out[f"s{k}"] = {**shape, "to_world": transforms[0]}
        else:
            out[f"group{k}"] = {"type": "shapegroup", "mesh": shape}
            for j, t in enumerate(transforms):
                out[f"s{k}_{j}"] = {"type": "instance", "shapegroup": {"type": "ref", "id": f"group{k}"}, "to_world": t}
    return out


def dumped_scene_dict(mi, scene_dir, spp, res, max_depth):
    with open(os.path.join(scene_dir, "scene.json")) as f:
        doc = json.load(f)
    textures = [{**t, "path": os.path.join(scene_dir, t["file"])} for t in doc["textures"]]
    lo, hi = doc["bounds"]
    radius = max(0.5 * math.dist(lo, hi), 1e-6)
    eye_to_centre = math.dist(doc["camera"]["eye"], [(a + b) / 2 for a, b in zip(lo, hi)])
    clip = (1e-5 * radius, 10.0 * (eye_to_centre + radius))  # filtrace has no clip planes
    return doc, {
        "type": "scene",
        "integrator": {"type": "path", "max_depth": max_depth, "rr_depth": 5},
        "sensor": sensor_dict(mi, doc["camera"], spp, res, clip),
        **light_dicts(mi, doc["lights"]),
        **shape_dicts(mi, doc, scene_dir, textures),
    }


def main():
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--scene-dir", help="a scene dumped by `filtrace bench suite --dump-scene-json`")
    ap.add_argument("--variant", default="llvm_ad_rgb")
    ap.add_argument("--spp", type=int, default=64)
    ap.add_argument("--res", type=int, default=512)
    ap.add_argument("--max-depth", type=int, default=8)
    ap.add_argument("--threads", type=int, default=os.cpu_count())
    ap.add_argument("--repeats", type=int, default=3)
    ap.add_argument("--json", action="store_true")
    args = ap.parse_args()
    if args.repeats < 1:
        raise SystemExit("--repeats must be at least 1")

    import tempfile

    import mitsuba as mi

    mi.set_variant(args.variant)
    import drjit as dr

    if hasattr(dr, "set_thread_count"):
        dr.set_thread_count(args.threads)
    with tempfile.TemporaryDirectory() as tmp:
        if args.scene_dir:
            doc, desc = dumped_scene_dict(mi, args.scene_dir, args.spp, args.res, args.max_depth)
            name, triangles = doc["name"], doc["triangles"]
        else:
            desc = cornell_dict(mi, split_obj_by_material(OBJ, tmp), args.spp, args.res, args.max_depth)
            name, triangles = "cornell", 36
        t0 = time.perf_counter()
        scene = mi.load_dict(desc)
        load_s = time.perf_counter() - t0
        times = []
        for i in range(args.repeats + 1):
            t0 = time.perf_counter()
            img = mi.render(scene, spp=args.spp, seed=i)
            dr.eval(img)
            dr.sync_thread()
            times.append(time.perf_counter() - t0)
        import numpy as np

        mean_rgb = [float(x) for x in np.asarray(img)[..., :3].reshape(-1, 3).mean(axis=0)]
    samples = args.res * args.res * args.spp
    steady = times[1:]
    result = {
        "scene": name,
        "triangles": triangles,
        "variant": args.variant,
        "mitsuba": mi.__version__,
        "res": args.res,
        "spp": args.spp,
        "max_depth": args.max_depth,
        "threads": args.threads,
        "load_s": load_s,
        "first_render_s": times[0],
        "render_s": steady,
        "samples_per_s_best": samples / min(steady),
        "samples_per_s_median": samples / statistics.median(steady),
        "mean_rgb": mean_rgb,
    }
    if args.json:
        print(json.dumps(result))
    else:
        print(f"Mitsuba {mi.__version__} {args.variant}, {name} ({triangles} triangles) {args.res}^2, "
              f"{args.spp} spp, depth {args.max_depth}, {args.threads} threads")
        print(f"scene load: {load_s:.3f} s; first render (with JIT): {times[0]:.3f} s")
        print("steady renders: " + ", ".join(f"{t:.3f} s" for t in steady))
        print(f"samples/s: best {result['samples_per_s_best'] / 1e6:.2f} M, median {result['samples_per_s_median'] / 1e6:.2f} M")
        print("mean RGB: " + " ".join(f"{c:.4f}" for c in mean_rgb))
    return 0


if __name__ == "__main__":
    sys.exit(main())
