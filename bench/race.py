#!/usr/bin/env python3
"""Equal-time race against Mitsuba 3: renders each scene with our path tracer and SPPM and with
Mitsuba 3's path integrator (and, on the caustic scene, both renderers' particle tracers too; our
hybrid where the reference holds the caustics) for the same wall time, back to back, and prints
each one's RMSE against the scene's Mitsuba reference, the samples (or iterations) reached, and
the ratios. Mitsuba's column is its best method on the scene; the ratio is our best method's.

Mitsuba comes from PyPI into a local virtual environment that this script makes if it is missing
(never in CI):

    python3 bench/race.py                       # 60 s per renderer and scene
    python3 bench/race.py --seconds 20 --only cbox
    python3 bench/race.py --only living --scene living-room=/path/to/scene.xml,spp=64

Mitsuba renders with its low-discrepancy `ldsampler` in 64-spp calls, each with a new seed: the
best of the configurations measured (issue 27; the scenes' own `independent` sampler in 8-spp
calls flattered us). `--mitsuba-sampler scene --mitsuba-chunk 8` gives the old race.

It needs `target/release/coordinator` (`cargo build --release -p coordinator`) and, for
Mitsuba's LLVM variant, Debian's libllvm19 (DRJIT_LIBLLVM_PATH is set below if the library is
there). Wall time includes loading the scene and, for Mitsuba, its JIT compilation, as a user
would wait for them.
"""

import argparse
import json
import os
import re
import subprocess
import sys
import tempfile
import time

ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
SHARED = os.path.join(ROOT, "..", "shared", "scenes-ref")
REFS = os.path.join(ROOT, "tests", "refs")
LLVM = "/usr/lib/x86_64-linux-gnu/libLLVM-19.so"

# name, scene, reference, defines, Mitsuba's methods (None: the scene's own integrator), our
# methods beyond path and SPPM: every scene's reference is Mitsuba 3.9.1's. The hybrid races
# where the reference holds the scene's caustics (Mitsuba's path tracer finds an area light's;
# on `lights` it misses the spot light's, which the hybrid renders).
PATH = [None]
SCENES = [
    ("cbox", os.path.join(SHARED, "cbox.xml"), os.path.join(SHARED, "cbox.exr"), {"res": "256"}, PATH, []),
    ("cbox-spheres", os.path.join(SHARED, "cbox-spheres.xml"), os.path.join(SHARED, "cbox-spheres.exr"),
     {"res": "256"}, PATH, ["hybrid"]),
    ("fog", os.path.join(REFS, "fog.xml"), os.path.join(REFS, "fog.exr"), {"res": "64"}, PATH, []),
    ("lights (thin lens, spot, glass)", os.path.join(REFS, "lights.xml"), os.path.join(REFS, "lights.exr"),
     {"res": "128"}, PATH, []),
    # The glass ball is out of the camera's view, so the particle tracer renders all of it.
    ("caustic (spot through glass)", os.path.join(REFS, "caustic.xml"), os.path.join(REFS, "caustic.exr"),
     {"res": "128"}, ["path", "ptracer"], ["ptracer", "hybrid"]),
    ("textures", os.path.join(REFS, "textures.xml"), os.path.join(REFS, "textures.exr"), {}, PATH, []),
    ("environment", os.path.join(REFS, "environment.xml"), os.path.join(REFS, "environment.exr"), {}, PATH, []),
]


def ensure_mitsuba(venv):
    """The Python of a virtual environment with Mitsuba and NumPy, made on first use."""
    py = os.path.join(venv, "bin", "python")
    if not os.path.exists(py):
        print(f"making {venv} with Mitsuba 3 from PyPI ...", file=sys.stderr)
        subprocess.run([sys.executable, "-m", "venv", venv], check=True)
        subprocess.run([py, "-m", "pip", "install", "-q", "mitsuba", "numpy"], check=True)
    return py


MITSUBA_WORKER = r'''
import json, os, sys, time
import xml.etree.ElementTree as ET
import numpy as np
import mitsuba as mi
mi.set_variant("llvm_ad_rgb")
scene_path, ref_path, seconds, defines = sys.argv[1], sys.argv[2], float(sys.argv[3]), json.loads(sys.argv[4])
sampler, chunk = sys.argv[5], int(sys.argv[6])
start = time.time()
root = ET.parse(scene_path).getroot()
if sampler != "scene":
    # The sensor's sampler (or the default, `independent`) replaced by the one asked for; its
    # properties go too (another sampler may refuse them), `spp` below sets the count.
    sensors = root.findall("sensor")
    if len(sensors) != 1:
        sys.exit(f"{scene_path}: {len(sensors)} top-level <sensor>s, cannot swap the sampler "
                 "(--mitsuba-sampler scene keeps the scene's)")
    for old in sensors[0].findall("sampler"):
        sensors[0].remove(old)
    ET.SubElement(sensors[0], "sampler", {"type": sampler})
mi.file_resolver().prepend(os.path.dirname(os.path.abspath(scene_path)))
scene = mi.load_string(ET.tostring(root, encoding="unicode"), **defines)
acc, spp, seed = None, 0, 0
while acc is None or time.time() - start < seconds:
    img = np.array(mi.render(scene, spp=chunk, seed=seed))[..., :3]
    acc = img * chunk if acc is None else acc + img * chunk
    spp += chunk
    seed += 1
img = acc / spp
out = {"spp": spp, "seconds": time.time() - start}
if ref_path:
    ref = np.array(mi.Bitmap(ref_path).convert(mi.Bitmap.PixelFormat.RGB, mi.Struct.Type.Float32, False))
    out["rmse"] = float(np.sqrt(np.mean((img - ref) ** 2)))
print(json.dumps(out))
'''

RMSE = r'''
import json, sys
import numpy as np
import mitsuba as mi
mi.set_variant("scalar_rgb")
load = lambda p: np.array(mi.Bitmap(p).convert(mi.Bitmap.PixelFormat.RGB, mi.Struct.Type.Float32, False))
a, b = load(sys.argv[1]), load(sys.argv[2])
print(json.dumps({"rmse": float(np.sqrt(np.mean((a - b) ** 2)))}))
'''


def ours(coordinator, scene, ref, defines, method, seconds, py):
    with tempfile.TemporaryDirectory() as d:
        out = os.path.join(d, "out.exr")
        cmd = [coordinator, "render", scene, "--integrator", method, "--time-limit", str(seconds), "--out", out]
        for k, v in defines.items():
            cmd += ["-D", f"{k}={v}"]
        start = time.time()
        p = subprocess.run(cmd, capture_output=True, text=True)
        took = time.time() - start
        if p.returncode != 0:
            return {"error": p.stderr.strip().splitlines()[-1] if p.stderr.strip() else "failed"}
        m = re.search(r"wrote .* \((\d+) (passes|iterations)", p.stderr)
        passes = int(m.group(1)) if m else None
        if ref is None:
            return {"spp": passes, "seconds": took}
        r = subprocess.run([py, "-c", RMSE, out, ref], capture_output=True, text=True)
        if r.returncode != 0:
            return {"error": (r.stderr.strip().splitlines() or ["cannot compare"])[-1]}
        return {"spp": passes, "rmse": json.loads(r.stdout)["rmse"], "seconds": took}


def mitsuba(py, scene, ref, defines, seconds, method, sampler, chunk):
    if method is not None:
        defines = dict(defines, integrator=method)
    env = dict(os.environ)
    if os.path.exists(LLVM):
        env.setdefault("DRJIT_LIBLLVM_PATH", LLVM)
    p = subprocess.run([py, "-c", MITSUBA_WORKER, scene, ref or "", str(seconds), json.dumps(defines), sampler,
                        str(chunk)],
                       capture_output=True, text=True, env=env)
    if p.returncode != 0:
        return {"error": (p.stderr.strip().splitlines() or ["failed"])[-1]}
    r = json.loads(p.stdout.strip().splitlines()[-1])
    r["method"] = method
    return r


def cell(r):
    if "error" in r:
        return "error: " + r["error"][:40]
    method = f", {r['method']}" if r.get("method") else ""
    if "rmse" not in r:
        return f"{r.get('spp') or '?'} spp{method}"
    return f"{r['rmse']:.4f} ({r['spp']}{method})"


def extra_scene(spec):
    """`NAME=PATH[,key=value...]`: a scene raced for speed only (no reference)."""
    name, _, rest = spec.partition("=")
    path, *pairs = rest.split(",")
    if not name or not os.path.exists(path):
        raise argparse.ArgumentTypeError(f"{spec}: want NAME=PATH[,key=value...] of an existing scene")
    return (name, path, None, dict(p.split("=", 1) for p in pairs), PATH, [])


def main():
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--seconds", type=float, default=60.0, help="wall time per renderer and scene")
    ap.add_argument("--only", action="append", help="race only scenes whose name starts with this")
    ap.add_argument("--venv", default=os.path.join(ROOT, ".mitsuba"), help="Mitsuba's virtual environment")
    ap.add_argument("--coordinator", default=os.path.join(ROOT, "target", "release", "coordinator"))
    ap.add_argument("--mitsuba-sampler", default="ldsampler",
                    help="Mitsuba's sampler, replacing the scene's ('scene' keeps it); ldsampler measured best")
    ap.add_argument("--mitsuba-chunk", type=int, default=64,
                    help="Mitsuba's samples per pixel per render call, each call with a new seed")
    ap.add_argument("--scene", action="append", type=extra_scene, default=[], metavar="NAME=PATH[,k=v...]",
                    help="also race this scene, for samples per second only (it has no reference)")
    args = ap.parse_args()
    if not os.path.exists(args.coordinator):
        sys.exit(f"{args.coordinator} is missing: cargo build --release -p coordinator")
    py = ensure_mitsuba(args.venv)
    print(f"equal-time race, {args.seconds:g} s per renderer and scene, on {os.cpu_count()} cores; "
          "RMSE against Mitsuba 3.9.1 references (samples or iterations reached); Mitsuba with "
          f"{args.mitsuba_sampler} in {args.mitsuba_chunk}-spp calls")
    print("| scene | ours, path | ours, SPPM | Mitsuba 3, best method | best of ours / Mitsuba (RMSE) | path spp ours / Mitsuba |")
    print("|---|---|---|---|---|---|")
    for name, scene, ref, defines, methods, our_extra in SCENES + args.scene:
        if args.only and not any(name.startswith(o) for o in args.only):
            continue
        path = ours(args.coordinator, scene, ref, defines, "path", args.seconds, py)
        # SPPM and the other methods race for accuracy, which needs a reference.
        sppm = ours(args.coordinator, scene, ref, defines, "sppm", args.seconds, py) if ref else {"error": "no reference"}
        extra = [ours(args.coordinator, scene, ref, defines, m, args.seconds, py) for m in our_extra]
        runs = [mitsuba(py, scene, ref, defines, args.seconds, m, args.mitsuba_sampler, args.mitsuba_chunk)
                for m in methods]
        mi_r = min(runs, key=lambda r: r.get("rmse", float("inf")))
        mi_path = next((r for r, m in zip(runs, methods) if m in (None, "path")), mi_r)
        best = min((r["rmse"] for r in [path, sppm] + extra if "rmse" in r), default=float("nan"))
        ratio = best / mi_r["rmse"] if "rmse" in mi_r else float("nan")
        spp_ratio = (path["spp"] / mi_path["spp"]) if "error" not in path and "error" not in mi_path and path["spp"] else float("nan")
        print(f"| {name} | {cell(path)} | {cell(sppm)} | {cell(mi_r)} | {ratio:.2f} | {spp_ratio:.2f} |", flush=True)
        for r, m in zip(extra, our_extra):
            print(f"|   (ours, {m}: {cell(r)}) | | | | | |", flush=True)
        for r, m in zip(runs, methods):
            if r is not mi_r:
                print(f"|   (Mitsuba's {m}: {cell(r)}) | | | | | |", flush=True)


if __name__ == "__main__":
    main()
