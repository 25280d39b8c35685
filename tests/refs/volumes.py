#!/usr/bin/env python3
"""Writes the grids of `heterogeneous.xml` in Mitsuba's `.vol` format (version 3, float32, x
fastest): a chromatic puff of smoke whose density falls off from its centre and wobbles, and an
albedo that varies from warm to cool across its box. Run once; the files are checked in."""

import math
import os
import struct


def write_vol(path, res, channels, value):
    with open(path, "wb") as f:
        f.write(b"VOL\x03")
        f.write(struct.pack("<iiiii", 1, res, res, res, channels))
        f.write(struct.pack("<6f", 0, 0, 0, 1, 1, 1))
        for z in range(res):
            for y in range(res):
                for x in range(res):
                    p = [(i + 0.5) / res for i in (x, y, z)]
                    f.write(struct.pack(f"<{channels}f", *value(*p)))


def puff(x, y, z):
    r2 = (x - 0.5) ** 2 + (y - 0.45) ** 2 + (z - 0.5) ** 2
    wobble = 1 + 0.5 * math.sin(9 * x) * math.cos(7 * y + 2 * z)
    d = max(0.0, 1 - r2 / 0.2) * wobble
    return (d, 0.7 * d, 0.4 * d)


def albedo(x, y, z):
    return (0.9 - 0.3 * x, 0.6 + 0.2 * y, 0.4 + 0.5 * x * z)


here = os.path.join(os.path.dirname(os.path.abspath(__file__)), "volumes")
os.makedirs(here, exist_ok=True)
write_vol(os.path.join(here, "puff.vol"), 12, 3, puff)
write_vol(os.path.join(here, "albedo.vol"), 6, 3, albedo)
