#!/usr/bin/env python3
"""How cost grows: time per pass against resolution, triangle count and photons per iteration.

Runs the `coordinator` binary (default: target/release/coordinator; build it first with
`cargo build --release -p coordinator`) on:
  - tests/refs/cbox.xml, path tracing, at 128² to 2048² pixels;
  - the same box with a bumpy sphere of 2k to 2M triangles in place of a small box (written as a
    binary PLY), at 256²;
  - tests/refs/cbox-spheres.xml, SPPM, 12.5k to 1.6M photons per iteration, at 256².
It reads the render time the command prints ("N passes in T s", which excludes loading and BVH
building; passes are added until it is at least 2 s), prints a table of seconds per pass and writes a log-log chart (SVG, three panels) with
the slope of each line, so that linear growth shows as slope 1 and logarithmic as nearly 0.

    python3 bench/growth.py [--coordinator PATH] [--out growth.svg] [--quick]
"""

import argparse
import math
import os
import re
import struct
import subprocess
import sys
import tempfile

ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
REFS = os.path.join(ROOT, "tests", "refs")


def render(coordinator, scene, args, flag):
    """Seconds per pass: renders with more passes (`flag`: --spp or --iterations) until the
    printed render time (0.1 s resolution) is at least 2 s."""
    passes = 1
    while True:
        with tempfile.TemporaryDirectory() as d:
            out = os.path.join(d, "out.exr")
            cmd = [coordinator, "render", scene, "--out", out, flag, str(passes)] + args
            res = subprocess.run(cmd, capture_output=True, text=True)
            if res.returncode != 0:
                sys.exit(f"{' '.join(cmd)} failed:\n{res.stderr}")
            m = re.search(r"\((\d+) (?:passes|iterations) in ([0-9.]+) s\)", res.stderr + res.stdout)
            if not m:
                sys.exit(f"no timing in the output of {' '.join(cmd)}:\n{res.stderr}")
            seconds = float(m.group(2))
            if seconds >= 2.0:
                return seconds / int(m.group(1))
            passes = math.ceil(passes * 2.5 / max(seconds, 0.05))


def bumpy_sphere(path, rings, segments):
    """A lat-long sphere with a bumpy radius, binary little-endian PLY; returns triangles."""
    verts = []
    for i in range(rings + 1):
        theta = math.pi * i / rings
        for j in range(segments):
            phi = 2 * math.pi * j / segments
            r = 0.45 * (1 + 0.06 * math.sin(13 * theta) * math.sin(17 * phi))
            verts.append((r * math.sin(theta) * math.cos(phi), -0.5 + r * math.cos(theta),
                          r * math.sin(theta) * math.sin(phi)))
    faces = []
    for i in range(rings):
        for j in range(segments):
            a, b = i * segments + j, i * segments + (j + 1) % segments
            faces.append((a, a + segments, b))
            faces.append((b, a + segments, b + segments))
    with open(path, "wb") as f:
        f.write((f"ply\nformat binary_little_endian 1.0\nelement vertex {len(verts)}\n"
                 "property float x\nproperty float y\nproperty float z\n"
                 f"element face {len(faces)}\nproperty list uchar int vertex_indices\nend_header\n").encode())
        f.write(b"".join(struct.pack("<3f", *v) for v in verts))
        f.write(b"".join(struct.pack("<B3i", 3, *t) for t in faces))
    return len(faces)


def mesh_scene(d, rings, segments):
    """cbox.xml with the bumpy sphere in place of its small box; returns (path, triangles)."""
    tris = bumpy_sphere(os.path.join(d, "bumpy.ply"), rings, segments)
    text = open(os.path.join(REFS, "cbox.xml")).read()
    start = text.index('<shape type="cube" id="small-box">')
    text = (text[:start] + '<shape type="ply"><string name="filename" value="bumpy.ply"/>'
            '<ref id="white"/></shape>\n</scene>\n')
    path = os.path.join(d, "bumpy.xml")
    open(path, "w").write(text)
    return path, tris


def slope(points):
    """Least-squares slope of log(time) against log(x)."""
    xs = [math.log(x) for x, _ in points]
    ys = [math.log(y) for _, y in points]
    mx, my = sum(xs) / len(xs), sum(ys) / len(ys)
    return sum((x - mx) * (y - my) for x, y in zip(xs, ys)) / sum((x - mx) ** 2 for x in xs)


def svg(panels, path):
    """Three log-log panels side by side."""
    w, h, pad = 300, 240, 50
    parts = [f'<svg xmlns="http://www.w3.org/2000/svg" width="{3 * (w + pad) + pad}" height="{h + 2 * pad}" '
             'font-family="sans-serif" font-size="11">']
    for k, (title, xlabel, points) in enumerate(panels):
        ox = pad + k * (w + pad)
        lx = [math.log10(x) for x, _ in points]
        ly = [math.log10(y) for _, y in points]
        x0, x1 = math.floor(min(lx)), math.ceil(max(lx))
        y0, y1 = math.floor(min(ly)), math.ceil(max(ly))
        px = lambda v: ox + (v - x0) / max(x1 - x0, 1e-9) * w
        py = lambda v: pad + h - (v - y0) / max(y1 - y0, 1e-9) * h
        parts.append(f'<rect x="{ox}" y="{pad}" width="{w}" height="{h}" fill="none" stroke="#888"/>')
        for e in range(x0, x1 + 1):
            parts.append(f'<line x1="{px(e)}" y1="{pad}" x2="{px(e)}" y2="{pad + h}" stroke="#ddd"/>'
                         f'<text x="{px(e)}" y="{pad + h + 14}" text-anchor="middle">1e{e}</text>')
        for e in range(y0, y1 + 1):
            parts.append(f'<line x1="{ox}" y1="{py(e)}" x2="{ox + w}" y2="{py(e)}" stroke="#ddd"/>'
                         f'<text x="{ox - 4}" y="{py(e) + 4}" text-anchor="end">1e{e}</text>')
        pts = " ".join(f"{px(a):.1f},{py(b):.1f}" for a, b in zip(lx, ly))
        parts.append(f'<polyline points="{pts}" fill="none" stroke="#1f6fd1" stroke-width="2"/>')
        for a, b in zip(lx, ly):
            parts.append(f'<circle cx="{px(a):.1f}" cy="{py(b):.1f}" r="3" fill="#1f6fd1"/>')
        parts.append(f'<text x="{ox + w / 2}" y="{pad - 18}" text-anchor="middle" font-size="13">{title}</text>'
                     f'<text x="{ox + w / 2}" y="{pad - 4}" text-anchor="middle">slope {slope(points):.2f} '
                     'in log-log</text>'
                     f'<text x="{ox + w / 2}" y="{pad + h + 30}" text-anchor="middle">{xlabel}</text>')
    parts.append(f'<text x="14" y="{pad + h / 2}" transform="rotate(-90 14 {pad + h / 2})" '
                 'text-anchor="middle">seconds per pass</text></svg>')
    open(path, "w").write("\n".join(parts))


def main():
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--coordinator", default=os.path.join(ROOT, "target", "release", "coordinator"))
    ap.add_argument("--out", default="growth.svg", help="the chart (SVG)")
    ap.add_argument("--quick", action="store_true", help="fewer and smaller points")
    args = ap.parse_args()
    c = args.coordinator
    if not os.path.exists(c):
        sys.exit(f"{c} not found: cargo build --release -p coordinator")

    resolutions = [128, 256, 512] if args.quick else [128, 256, 512, 1024, 2048]
    res_points = []
    for r in resolutions:
        t = render(c, os.path.join(REFS, "cbox.xml"), ["--integrator", "path", "-D", f"res={r}"], "--spp")
        res_points.append((r * r, t))
        print(f"path, cbox, {r}x{r}: {t * 1e3:.1f} ms per pass ({t / (r * r) * 1e9:.1f} ns per pixel)", flush=True)

    sizes = [(16, 64), (64, 256), (128, 512), (256, 1024)] if args.quick else \
        [(16, 64), (64, 256), (256, 256), (256, 1024), (512, 2048)]
    tri_points = []
    with tempfile.TemporaryDirectory() as d:
        for rings, segments in sizes:
            scene, tris = mesh_scene(d, rings, segments)
            t = render(c, scene, ["--integrator", "path", "-D", "res=256"], "--spp")
            tri_points.append((tris, t))
            print(f"path, bumpy sphere of {tris} triangles, 256x256: {t * 1e3:.1f} ms per pass", flush=True)

    counts = [12_500, 50_000, 200_000] if args.quick else [12_500, 50_000, 200_000, 800_000, 1_600_000]
    photon_points = []
    for n in counts:
        t = render(c, os.path.join(REFS, "cbox-spheres.xml"),
                   ["--integrator", "sppm", "--photons", str(n), "-D", "res=256"], "--iterations")
        photon_points.append((n, t))
        print(f"SPPM, cbox-spheres, 256x256, {n} photons: {t * 1e3:.1f} ms per iteration", flush=True)

    print(f"slopes (log-log): pixels {slope(res_points):.2f}, triangles {slope(tri_points):.2f}, "
          f"photons {slope(photon_points):.2f}")
    svg([("path tracing, cbox", "pixels", res_points),
         ("path tracing, 256², bumpy sphere", "triangles", tri_points),
         ("SPPM, cbox-spheres, 256²", "photons per iteration", photon_points)], args.out)
    print(f"wrote {args.out}")


if __name__ == "__main__":
    main()
