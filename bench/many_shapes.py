#!/usr/bin/env python3
"""Writes a Mitsuba 3 scene of N small spheres on a grid (default 100,000) for timing scene
loading: real exports hold thousands of shapes, and loading once grew with the square of the
file's size (docs/benchmarks.md, "Scene loading").

    python3 bench/many_shapes.py 100000 > /tmp/many.xml
    coordinator render /tmp/many.xml --spp 1 --out /tmp/many.png
"""
import math
import sys

n = int(sys.argv[1]) if len(sys.argv) > 1 else 100_000
side = math.ceil(math.sqrt(n))
out = [
    '<scene version="3.0.0">',
    '  <sensor type="perspective"><float name="fov" value="60"/>',
    '    <transform name="to_world"><lookat origin="0, 0, 4" target="0, 0, 0" up="0, 1, 0"/></transform>',
    '    <film type="hdrfilm"><integer name="width" value="32"/><integer name="height" value="32"/></film>',
    "  </sensor>",
    '  <emitter type="constant"><rgb name="radiance" value="1"/></emitter>',
    '  <bsdf type="diffuse" id="grey"/>',
]
for i in range(n):
    x = -2 + 4 * (i % side) / side
    y = -2 + 4 * (i // side) / side
    out.append(
        f'  <shape type="sphere"><point name="center" x="{x:.5f}" y="{y:.5f}" z="0"/>'
        f'<float name="radius" value="{1 / side:.6f}"/><ref id="grey"/></shape>'
    )
out.append("</scene>")
print("\n".join(out))
