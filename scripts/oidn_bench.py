#!/usr/bin/env python3
"""Time Intel Open Image Denoise (OIDN) on this CPU, to compare with `filtrace bench filters`.

Issue 3 asks for our filters to be at least 10x faster than OIDN's "fast" quality at
1920x1080 on the same CPU. This script runs OIDN's `RT` filter on a synthetic 1920x1080
colour + albedo + normal image (float32, HDR, shaped like `bench filters`' input: noisy
colour with fireflies over a box room), with a fixed thread count, one warm-up run, then
`--repeats` timed runs; it prints the median wall-clock ms and the median process CPU ms
divided by the thread count (the same two columns as `bench filters`).

Setup (not a project dependency; OIDN 2.x ships inside the wheel):

    pip install pyoidn
    python3 scripts/oidn_bench.py --res 1920x1080 --threads 2 --repeats 5 --quality fast

`--quality` is OIDN 2's `quality` filter parameter (fast / balanced / high). OIDN's CPU
device may create its own thread pool; `numThreads` caps it (checked with `--verbose`).
"""

import argparse
import json
import statistics
import sys
import time

import numpy as np
from importlib.metadata import version as _version


def synthetic_input(w, h, seed=0x2545F491):
    """Noisy colour (exponential noise, 0.1% fireflies x50), albedo and unit normals of a
    room with a box, float32 arrays of shape (h, w, 3)."""
    rng = np.random.default_rng(seed)
    u = (np.arange(w, dtype=np.float32) + 0.5) / w
    v = (np.arange(h, dtype=np.float32) + 0.5) / h
    uu, vv = np.meshgrid(u, v)
    in_box = (uu >= 0.2) & (uu < 0.45) & (vv >= 0.4) & (vv < 0.9)
    normal = np.zeros((h, w, 3), np.float32)
    normal[..., 2] = -1.0
    left = (uu < 0.1) & ~in_box
    floor = (vv > 0.9) & ~in_box & ~left
    normal[left] = (1.0, 0.0, 0.0)
    normal[floor] = (0.0, 1.0, 0.0)
    albedo = np.full((h, w, 3), 0.7, np.float32)
    albedo[in_box] = (0.8, 0.6, 0.3)
    albedo[left] = (0.7, 0.1, 0.1)
    base = (0.3 + 0.5 * uu)[..., None] * albedo
    noise = rng.exponential(1.0, (h, w, 3)).astype(np.float32)
    fire = np.where(rng.random((h, w, 3)) < 1e-3, 50.0, 1.0).astype(np.float32)
    color = np.ascontiguousarray(base * noise * fire, dtype=np.float32)
    return color, albedo, normal


def cpu_seconds():
    return time.process_time()


def main():
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--res", default="1920x1080")
    ap.add_argument("--threads", type=int, default=2)
    ap.add_argument("--repeats", type=int, default=5)
    ap.add_argument("--quality", default="fast", choices=["fast", "balanced", "high", "default"])
    ap.add_argument("--no-aux", action="store_true", help="colour only (no albedo/normal)")
    ap.add_argument("--json", action="store_true")
    ap.add_argument("--verbose", action="store_true")
    a = ap.parse_args()
    try:
        import pyoidn
    except ImportError:
        sys.exit("pyoidn is not installed: pip install pyoidn")
    w, h = (int(s) for s in a.res.lower().split("x"))
    color, albedo, normal = synthetic_input(w, h)
    output = np.zeros_like(color)

    device = pyoidn.Device(pyoidn.OIDN_DEVICE_TYPE_CPU)
    device.set_int("numThreads", a.threads)
    device.set_bool("setAffinity", False)
    if a.verbose:
        device.set_int("verbose", 2)
    device.commit()
    err = device.get_error()
    if err:
        sys.exit(f"OIDN device: {err}")
    flt = pyoidn.Filter(device, pyoidn.OIDN_FILTER_TYPE_RT)
    f3 = pyoidn.OIDN_FORMAT_FLOAT3
    flt.set_image(pyoidn.OIDN_IMAGE_COLOR, color, f3)
    if not a.no_aux:
        flt.set_image(pyoidn.OIDN_IMAGE_ALBEDO, albedo, f3)
        flt.set_image(pyoidn.OIDN_IMAGE_NORMAL, normal, f3)
    flt.set_image(pyoidn.OIDN_IMAGE_OUTPUT, output, f3)
    flt.set_bool("hdr", True)
    quality = {
        "fast": pyoidn.OIDN_QUALITY_FAST,
        "balanced": pyoidn.OIDN_QUALITY_BALANCED,
        "high": pyoidn.OIDN_QUALITY_HIGH,
        "default": pyoidn.OIDN_QUALITY_DEFAULT,
    }[a.quality]
    flt.set_quality(quality)
    flt.commit()
    err = device.get_error()
    if err:
        sys.exit(f"OIDN filter: {err}")
    threads_used = device.get_int("numThreads")

    flt.execute()  # warm-up (first run also tunes/allocates)
    err = device.get_error()
    if err:
        sys.exit(f"OIDN execute: {err}")
    wall, cpu = [], []
    for _ in range(a.repeats):
        c0, t0 = cpu_seconds(), time.perf_counter()
        flt.execute()
        wall.append((time.perf_counter() - t0) * 1e3)
        cpu.append((cpu_seconds() - c0) * 1e3)
    if not np.isfinite(output).all():
        sys.exit("OIDN output has non-finite values")
    res = {
        "pyoidn_version": _version("pyoidn"),
        "res": [w, h],
        "quality": a.quality,
        "aux": not a.no_aux,
        "threads": threads_used,
        "repeats": a.repeats,
        "wall_ms_median": statistics.median(wall),
        "cpu_ms_per_thread_median": statistics.median(cpu) / max(threads_used, 1),
        "wall_ms": wall,
    }
    if a.json:
        print(json.dumps(res))
    else:
        print(
            f"OIDN RT, quality {a.quality}, {w}x{h}, colour{'' if a.no_aux else ' + albedo + normal'}, "
            f"{threads_used} threads: median {res['wall_ms_median']:.1f} ms wall, "
            f"{res['cpu_ms_per_thread_median']:.1f} CPU-ms / {threads_used}"
        )
    flt.release()
    device.release()


if __name__ == "__main__":
    main()
