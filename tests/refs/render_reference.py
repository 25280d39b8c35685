#!/usr/bin/env python3
"""Renders a reference image for an accuracy test with Mitsuba 3, an independent renderer.

Not run by CI: references are rendered once and checked in beside their scene. Mitsuba comes from
PyPI into a local virtual environment:

    python3 -m venv .mitsuba && .mitsuba/bin/pip install mitsuba numpy
    DRJIT_LIBLLVM_PATH=/usr/lib/x86_64-linux-gnu/libLLVM-19.so \
        .mitsuba/bin/python tests/refs/render_reference.py tests/refs/SCENE.xml --spp 8192

Writes SCENE.exr (linear RGB float) and SCENE.json beside the scene (or at --out). The JSON
records how the image was made, its channel means, its noise floor (the variance of its mean,
from two independent halves: an error measured below it cannot be trusted), and Mitsuba's own
MSE against it at the spp the test renders (`--test-spp`, several seeds): the bar a test holds
our renderer to.
"""

import argparse
import json
import os
import time

import numpy as np


def integrator_type(path):
    """The scene's declared <integrator> type (Mitsuba's default is path)."""
    import xml.etree.ElementTree as ET

    el = ET.parse(path).getroot().find("integrator")
    return "path" if el is None else el.get("type")


def main():
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("scene")
    ap.add_argument("--spp", type=int, default=8192, help="samples per pixel of the reference")
    ap.add_argument("--chunk", type=int, default=256, help="spp per Mitsuba call (memory)")
    ap.add_argument("--test-spp", type=int, default=256, help="spp at which Mitsuba's own MSE is measured")
    ap.add_argument("--seeds", type=int, default=15, help="seeds for Mitsuba's own MSE (0: skip)")
    ap.add_argument("--variant", default="llvm_ad_rgb")
    ap.add_argument("-D", action="append", default=[], metavar="NAME=VALUE", help="scene parameter")
    ap.add_argument("--out", help="output name without extension (default: beside the scene)")
    ap.add_argument(
        "--mse-only",
        action="store_true",
        help="keep the existing reference; only measure Mitsuba's own MSE against it again",
    )
    args = ap.parse_args()

    import mitsuba as mi

    mi.set_variant(args.variant)
    params = dict(d.split("=", 1) for d in args.D)
    scene = mi.load_file(args.scene, **params)

    def render(spp, seed):
        return np.array(mi.render(scene, spp=spp, seed=seed), dtype=np.float64)[:, :, :3]

    def render_long(spp, first_seed):
        chunks = max(1, spp // args.chunk)
        acc = None
        for i in range(chunks):
            img = render(spp // chunks, first_seed + i)
            acc = img if acc is None else acc + img
        return acc / chunks

    out = args.out or os.path.splitext(args.scene)[0]
    if args.mse_only:
        ref = np.array(mi.Bitmap(out + ".exr"), dtype=np.float64)[:, :, :3]
        with open(out + ".json") as f:
            meta = json.load(f)
    else:
        t0 = time.time()
        half_a = render_long(args.spp // 2, 100000)
        half_b = render_long(args.spp // 2, 200000)
        seconds = time.time() - t0
        ref = 0.5 * (half_a + half_b)
        # Var(mean of the whole) = Var(half) / 2 and E|a - b|^2 = 2 Var(half).
        noise_floor = float(np.mean((half_a - half_b) ** 2) / 4.0)
        mi.Bitmap(ref.astype(np.float32)).write(out + ".exr")
        meta = {
            "scene": os.path.basename(args.scene),
            "defines": params,
            "integrator": integrator_type(args.scene),
            "spp": args.spp,
            "seconds": round(seconds, 1),
            "mean_rgb": [float(ref[:, :, c].mean()) for c in range(3)],
            "noise_floor_mse": noise_floor,
            "renderer": f"Mitsuba {mi.__version__} {args.variant}",
        }
    if args.seeds > 0:
        mses = [float(np.mean((render(args.test_spp, s) - ref) ** 2)) for s in range(1, args.seeds + 1)]
        meta["mitsuba_mse_at_test_spp"] = {
            "spp": args.test_spp,
            "seeds": list(range(1, args.seeds + 1)),
            "mse": mses,
            "median": float(np.median(mses)),
        }
    with open(out + ".json", "w") as f:
        json.dump(meta, f, indent=1)
    print(json.dumps(meta))


if __name__ == "__main__":
    main()
