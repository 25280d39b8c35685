#!/usr/bin/env python3
"""Writes the maps of bumpy.xml, 8-bit PNGs that both renderers read as raw values:

- waves.png, a tangent-space normal map of ridges running along v, tilting the normal by up to
  about 50 degrees along u, and a fainter ripple along v;
- dimples.png, a height map of a grid of round bumps (grey levels, read as luminance).

Needs numpy and Mitsuba (its Bitmap writes the PNGs): run once, check the PNGs in.
"""

import os

import numpy as np


def main():
    import mitsuba as mi

    mi.set_variant("scalar_rgb")
    here = os.path.dirname(os.path.abspath(__file__))
    n = 64
    x = (np.arange(n) + 0.5) / n
    u, v = np.meshgrid(x, x)  # rows are v, from the top, as both renderers read them
    # Heights h = 0.05 sin(2π 4u) + 0.01 sin(2π 6v); the normal is (-dh/du, -dh/dv, 1), in
    # units where one texture repeat spans one unit.
    dhdu = 0.05 * 2 * np.pi * 4 * np.cos(2 * np.pi * 4 * u)
    dhdv = 0.01 * 2 * np.pi * 6 * np.cos(2 * np.pi * 6 * v)
    normal = np.stack([-dhdu, -dhdv, np.ones_like(u)], axis=-1)
    normal /= np.linalg.norm(normal, axis=-1, keepdims=True)
    rgb = np.round((normal * 0.5 + 0.5) * 255).astype(np.uint8)
    mi.Bitmap(rgb, pixel_format=mi.Bitmap.PixelFormat.RGB).write(os.path.join(here, "waves.png"))

    # Round bumps on a 4 x 4 grid: a smooth cosine cap in each cell.
    cu, cv = (u * 4) % 1 - 0.5, (v * 4) % 1 - 0.5
    r = np.sqrt(cu**2 + cv**2)
    h = np.where(r < 0.4, 0.5 + 0.5 * np.cos(np.pi * r / 0.4), 0.0)
    grey = np.round(h * 255).astype(np.uint8)[:, :, None]
    mi.Bitmap(grey, pixel_format=mi.Bitmap.PixelFormat.Y).write(os.path.join(here, "dimples.png"))


if __name__ == "__main__":
    main()
