#!/usr/bin/env python3
"""Splits renders' RMSE on scenes/volumetric.xml by region, against two references.

    python3 bench/volumetric_regions.py REF_A.exr REF_B.exr RENDER.exr...

Regions: the caustic spots (pixels where the two references differ by more than 0.02), the
shafts (pixels in the upper half 1.5x brighter than REF_B's median, spots excluded) and the
rest. Prints each render's RMSE per region against each reference, then medians per method
(the render's file name up to "-s<seed>"). Needs numpy and an EXR reader: Mitsuba's
(the race's virtual environment has both).
"""
import os, statistics, sys

import numpy as np
import mitsuba as mi

mi.set_variant("scalar_rgb")


def load(f):
    return np.array(mi.Bitmap(f)).astype(np.float64)[..., :3]


def main():
    if len(sys.argv) < 4:
        sys.exit(__doc__)
    refs = {os.path.basename(f): load(f) for f in sys.argv[1:3]}
    a, b = refs.values()
    diff = np.sqrt(((a - b) ** 2).mean(axis=2))
    spots = diff > 0.02
    lum = b.mean(axis=2)
    shafts = lum > 1.5 * np.median(lum)
    shafts[lum.shape[0] // 2:, :] = False
    shafts &= ~spots
    regions = {"all": np.ones_like(spots), "no-spots": ~spots, "shafts": shafts,
               "rest": ~(spots | shafts), "spots": spots}
    print("pixels:", ", ".join(f"{k} {v.sum()}" for k, v in regions.items()))
    print("references differ:", ", ".join(f"{k} {np.sqrt((diff[v] ** 2).mean()):.4f}" for k, v in regions.items()))
    table = {}
    for f in sys.argv[3:]:
        img = load(f)
        method = os.path.basename(f).rsplit(".", 1)[0].split("-s")[0]
        for name, ref in refs.items():
            e2 = ((img - ref) ** 2).mean(axis=2)
            row = [np.sqrt(e2[v].mean()) for v in regions.values()]
            table.setdefault((method, name), []).append(row)
            print(f"{f} vs {name}: " + " ".join(f"{k} {x:.4f}" for k, x in zip(regions, row)))
    print("medians:")
    for (method, name), rows in sorted(table.items()):
        med = [statistics.median(r[i] for r in rows) for i in range(len(regions))]
        print(f"{method} vs {name} (n={len(rows)}): " + " ".join(f"{k} {x:.4f}" for k, x in zip(regions, med)))


if __name__ == "__main__":
    main()
