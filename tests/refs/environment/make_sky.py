#!/usr/bin/env python3
"""Writes sky.exr for environment.xml (run once; the output is checked in): a 64 x 32
equirectangular sky, blue at the zenith, white at the horizon, brown below, with a small warm
sun 30 degrees above the horizon, so that the map's orientation and its sampling both show."""

import os

import numpy as np
import mitsuba as mi

mi.set_variant("scalar_rgb")
W, H = 64, 32
v = (np.arange(H) + 0.5) / H            # 0 at the zenith (+y), 1 at the nadir
u = (np.arange(W) + 0.5) / W
img = np.zeros((H, W, 3), np.float32)
for y in range(H):
    t = v[y]
    if t < 0.5:
        k = t / 0.5
        img[y, :] = (1 - k) * np.array([0.15, 0.3, 0.9]) + k * np.array([1.0, 1.0, 1.0])
    else:
        img[y, :] = [0.25, 0.18, 0.1]
# The sun: 2 x 2 texels at v = 1/3 (30 degrees up), u = 0.3.
sy, sx = int(H / 3), int(0.3 * W)
img[sy:sy + 2, sx:sx + 2] = [60.0, 50.0, 35.0]
# A dimmer patch on the other side, so the map is not symmetric.
img[10:14, 50:56] = [0.2, 2.0, 0.4]
mi.Bitmap(img, pixel_format=mi.Bitmap.PixelFormat.RGB).write(
    os.path.join(os.path.dirname(os.path.abspath(__file__)), "sky.exr"))
