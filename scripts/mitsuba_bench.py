#!/usr/bin/env python3
"""Mitsuba 3 path-tracing throughput on the Cornell box, the baseline of issue 2's speed goal.

Renders ../shared/scenes/cornell_box/cornell_box_lit.obj with the settings of
../shared/reference/README.md (512x512, max_depth 8, RR from depth 5, box filter,
independent sampler) and reports samples per second. The first render of each variant
includes LLVM JIT compilation, so it is reported separately and the rate is taken from
the following renders (best and median).

Needs `pip install mitsuba` and, for the llvm variants, Debian's libllvm19
(`apt-get install libllvm19`). Measuring only; not a dependency of filtrace.

    python3 scripts/mitsuba_bench.py [--spp 64] [--threads 2] [--repeats 3] [--json]
"""
import argparse
import json
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


def scene_dict(mi, files, spp, res):
    shapes = {}
    for name, path in files.items():
        shape = {"type": "obj", "filename": path, "face_normals": True}
        if name in MATERIALS:
            shape["bsdf"] = {"type": "diffuse", "reflectance": {"type": "rgb", "value": MATERIALS[name]}}
        else:  # the light quad: Kd 0 as in cornell_box_lit.mtl
            shape["bsdf"] = {"type": "diffuse", "reflectance": {"type": "rgb", "value": (0.0, 0.0, 0.0)}}
            shape["emitter"] = {"type": "area", "radiance": {"type": "rgb", "value": LIGHT_RADIANCE}}
        shapes[name] = shape
    return {
        "type": "scene",
        "integrator": {"type": "path", "max_depth": 8, "rr_depth": 5},
        "sensor": {
            "type": "perspective",
            "fov": 39.3077,
            "fov_axis": "y",
            "to_world": mi.ScalarTransform4f().look_at(
                origin=[278, 273, -800], target=[278, 273, -799], up=[0, 1, 0]
            ),
            "sampler": {"type": "independent", "sample_count": spp},
            "film": {"type": "hdrfilm", "width": res, "height": res, "rfilter": {"type": "box"}},
        },
        **shapes,
    }


def main():
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--variant", default="llvm_ad_rgb")
    ap.add_argument("--spp", type=int, default=64)
    ap.add_argument("--res", type=int, default=512)
    ap.add_argument("--threads", type=int, default=os.cpu_count())
    ap.add_argument("--repeats", type=int, default=3)
    ap.add_argument("--json", action="store_true")
    args = ap.parse_args()

    import tempfile

    import mitsuba as mi

    mi.set_variant(args.variant)
    import drjit as dr

    if hasattr(dr, "set_thread_count"):
        dr.set_thread_count(args.threads)
    with tempfile.TemporaryDirectory() as tmp:
        files = split_obj_by_material(OBJ, tmp)
        scene = mi.load_dict(scene_dict(mi, files, args.spp, args.res))
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
        "variant": args.variant,
        "res": args.res,
        "spp": args.spp,
        "max_depth": 8,
        "threads": args.threads,
        "first_render_s": times[0],
        "render_s": steady,
        "samples_per_s_best": samples / min(steady),
        "samples_per_s_median": samples / statistics.median(steady),
        "mean_rgb": mean_rgb,
    }
    if args.json:
        print(json.dumps(result))
    else:
        print(f"Mitsuba {mi.__version__} {args.variant}, Cornell {args.res}^2, {args.spp} spp, depth 8, {args.threads} threads")
        print(f"first render (with JIT): {times[0]:.3f} s")
        print("steady renders: " + ", ".join(f"{t:.3f} s" for t in steady))
        print(f"samples/s: best {result['samples_per_s_best'] / 1e6:.2f} M, median {result['samples_per_s_median'] / 1e6:.2f} M")
    return 0


if __name__ == "__main__":
    sys.exit(main())
