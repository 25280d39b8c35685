#!/usr/bin/env python3
"""Writes the small assets of textures.xml (run once; the outputs are checked in):
a colourful 8-bit sRGB PNG, an 8-bit JPEG, a float EXR roughness map, and a wavy OBJ and PLY
strip with texture coordinates (the OBJ's v is flipped on load by Mitsuba, the PLY's is not)."""

import math
import os
import struct
import zlib

import numpy as np

HERE = os.path.dirname(os.path.abspath(__file__))


def write_png(path, rgb8):
    h, w, _ = rgb8.shape
    raw = b"".join(b"\x00" + rgb8[y].tobytes() for y in range(h))

    def chunk(tag, data):
        c = struct.pack(">I", len(data)) + tag + data
        return c + struct.pack(">I", zlib.crc32(tag + data) & 0xFFFFFFFF)

    with open(path, "wb") as f:
        f.write(b"\x89PNG\r\n\x1a\n")
        f.write(chunk(b"IHDR", struct.pack(">IIBBBBB", w, h, 8, 2, 0, 0, 0)))
        f.write(chunk(b"IDAT", zlib.compress(raw, 9)))
        f.write(chunk(b"IEND", b""))


def main():
    # 24 x 16 texels: smooth gradients plus a sharp stripe, so filtering and orientation show.
    h, w = 16, 24
    y, x = np.mgrid[0:h, 0:w]
    rgb = np.stack([x / (w - 1), y / (h - 1), 0.5 + 0.5 * np.sin(x * 0.7) * np.cos(y * 0.9)], -1)
    rgb[3:5, :, :] = [0.95, 0.9, 0.1]
    write_png(os.path.join(HERE, "colors.png"), (rgb * 255 + 0.5).astype(np.uint8))

    import mitsuba as mi

    mi.set_variant("scalar_rgb")
    # A JPEG: a 12 x 12 checker of two colours with a diagonal band.
    j = np.zeros((12, 12, 3), np.uint8)
    for yy in range(12):
        for xx in range(12):
            j[yy, xx] = (200, 60, 40) if (xx // 3 + yy // 3) % 2 else (40, 90, 210)
            if abs(xx - yy) < 2:
                j[yy, xx] = (240, 240, 240)
    mi.Bitmap(j, pixel_format=mi.Bitmap.PixelFormat.RGB).write(os.path.join(HERE, "checker.jpg"), quality=100)
    # Roughness: 8 x 8 floats from 0.02 to 0.6.
    r = np.linspace(0.02, 0.6, 64, dtype=np.float32).reshape(8, 8)
    mi.Bitmap(np.repeat(r[:, :, None], 3, -1), pixel_format=mi.Bitmap.PixelFormat.RGB).write(
        os.path.join(HERE, "roughness.exr"))

    # A wavy strip in the z = 0 plane over [-1, 1]², 10 x 6 quads, uv over [0, 1]².
    nx, ny = 10, 6
    verts, uvs = [], []
    for j_ in range(ny + 1):
        for i in range(nx + 1):
            u, v = i / nx, j_ / ny
            verts.append((2 * u - 1, 2 * v - 1, 0.15 * math.sin(3 * u) * math.cos(2 * v)))
            uvs.append((u, v))
    faces = []
    for j_ in range(ny):
        for i in range(nx):
            a = j_ * (nx + 1) + i
            faces.append((a, a + 1, a + nx + 2))
            faces.append((a, a + nx + 2, a + nx + 1))
    with open(os.path.join(HERE, "strip.obj"), "w") as f:
        f.write("# wavy strip with texture coordinates\n")
        for p in verts:
            f.write("v %.6f %.6f %.6f\n" % p)
        for t in uvs:
            f.write("vt %.6f %.6f\n" % t)
        for a, b, c in faces:
            f.write("f %d/%d %d/%d %d/%d\n" % (a + 1, a + 1, b + 1, b + 1, c + 1, c + 1))
    with open(os.path.join(HERE, "strip.ply"), "w") as f:
        f.write("ply\nformat ascii 1.0\nelement vertex %d\n" % len(verts))
        f.write("property float x\nproperty float y\nproperty float z\nproperty float u\nproperty float v\n")
        f.write("element face %d\nproperty list uchar int vertex_indices\nend_header\n" % len(faces))
        for p, t in zip(verts, uvs):
            f.write("%.6f %.6f %.6f %.6f %.6f\n" % (p + t))
        for a, b, c in faces:
            f.write("3 %d %d %d\n" % (a, b, c))


if __name__ == "__main__":
    main()
