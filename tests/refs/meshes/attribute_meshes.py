#!/usr/bin/env python3
"""Writes the PLY meshes of refs/mesh-attributes.xml: a sphere with float vertex and face
attributes (color_0..2 per vertex, color_0..2 and weight_0 per face, as mitsuba-data's
sphere_attribute.ply has them) and a floor with red, green, blue vertex colours (floats: Mitsuba
3.9.1 takes 8-bit ones as they are, 0 to 255). ASCII, so that a diff shows what changed."""

import math
import os

HERE = os.path.dirname(os.path.abspath(__file__))


def write_ply(path, vertex_props, vertices, face_props, faces):
    with open(path, "w") as f:
        f.write("ply\nformat ascii 1.0\n")
        f.write(f"element vertex {len(vertices)}\n")
        for kind, name in vertex_props:
            f.write(f"property {kind} {name}\n")
        f.write(f"element face {len(faces)}\n")
        f.write("property list uchar int vertex_indices\n")
        for kind, name in face_props:
            f.write(f"property {kind} {name}\n")
        f.write("end_header\n")
        for v in vertices:
            f.write(" ".join(fmt(x) for x in v) + "\n")
        for idx, extra in faces:
            f.write(" ".join([str(len(idx))] + [str(i) for i in idx] + [fmt(x) for x in extra]) + "\n")


def fmt(x):
    return str(x) if isinstance(x, int) else f"{x:.6f}"


def sphere(rings=12, segments=20):
    verts = []
    for i in range(rings + 1):
        theta = math.pi * i / rings
        for j in range(segments + 1):
            phi = 2 * math.pi * j / segments
            x, y, z = math.sin(theta) * math.cos(phi), math.cos(theta), math.sin(theta) * math.sin(phi)
            # The normal is the position; a smooth colour over the sphere.
            color = (0.5 + 0.4 * x, 0.5 + 0.4 * y, 0.5 - 0.4 * z)
            verts.append((x, y, z, x, y, z) + color)
    faces = []
    k = 0
    for i in range(rings):
        for j in range(segments):
            a = i * (segments + 1) + j
            b, c, d = a + segments + 1, a + segments + 2, a + 1
            for tri in ((a, b, c), (a, c, d)):
                if len({verts[t][:3] for t in tri}) < 3:
                    continue  # degenerate at the poles
                color = ((k * 7) % 10 / 10 * 0.8 + 0.1, (k * 3) % 10 / 10 * 0.8 + 0.1, 0.9 - (k * 5) % 10 / 10 * 0.8)
                weight = (k * 37) % 11 / 10
                # Out of the sphere's outward winding: (a, c, b) faces outwards here.
                faces.append(((tri[0], tri[2], tri[1]), color + (weight,)))
                k += 1
    return verts, faces


def floor(n=6):
    verts = []
    for i in range(n + 1):
        for j in range(n + 1):
            x, z = -1 + 2 * j / n, -1 + 2 * i / n
            rgb = (0.1 + 0.8 * j / n, 0.9 - 0.8 * i / n, 0.2 + 0.6 * ((i + j) % 2))
            verts.append((x, 0.0, z) + rgb)
    faces = []
    for i in range(n):
        for j in range(n):
            a = i * (n + 1) + j
            b, c, d = a + n + 1, a + n + 2, a + 1
            faces.append(((a, b, c), ()))
            faces.append(((a, c, d), ()))
    return verts, faces


v, f = sphere()
write_ply(
    os.path.join(HERE, "attribute-sphere.ply"),
    [("float", n) for n in ("x", "y", "z", "nx", "ny", "nz", "color_0", "color_1", "color_2")],
    v,
    [("float", n) for n in ("color_0", "color_1", "color_2", "weight_0")],
    f,
)
v, f = floor()
write_ply(
    os.path.join(HERE, "attribute-floor.ply"),
    [("float", n) for n in ("x", "y", "z", "red", "green", "blue")],
    v,
    [],
    f,
)
