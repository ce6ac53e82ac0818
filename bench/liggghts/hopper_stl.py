#!/usr/bin/env python3
"""Hopper of the flowing benchmark (issue 25), an ASCII STL read by both codes (LIGGGHTS'
`fix mesh/surface`, our `kind = "stl"` wall): a square shaft 0.1 x 0.1 m from z = 0.15 m up to
`top`, and below it a pyramidal funnel down to a square outlet of `outlet` m at z = 0.10 m,
centred (the funnel's faces 38.7 degrees from the vertical for a 30 mm outlet). 16 triangles.

    python3 hopper_stl.py [outlet=0.03] [top=0.5] > hopper.stl
"""
import sys

OUTLET = float(sys.argv[1]) if len(sys.argv) > 1 else 0.03
TOP = float(sys.argv[2]) if len(sys.argv) > 2 else 0.5
L, Z_SHAFT, Z_OUT = 0.1, 0.15, 0.10
a, b = 0.5 * (L - OUTLET), 0.5 * (L + OUTLET)


def quad(p, q, r, s):
    """two triangles of the planar quadrilateral p q r s"""
    return [(p, q, r), (p, r, s)]


tris = []
# shaft: four vertical faces
tris += quad((0, 0, Z_SHAFT), (L, 0, Z_SHAFT), (L, 0, TOP), (0, 0, TOP))
tris += quad((L, 0, Z_SHAFT), (L, L, Z_SHAFT), (L, L, TOP), (L, 0, TOP))
tris += quad((L, L, Z_SHAFT), (0, L, Z_SHAFT), (0, L, TOP), (L, L, TOP))
tris += quad((0, L, Z_SHAFT), (0, 0, Z_SHAFT), (0, 0, TOP), (0, L, TOP))
# funnel: four trapezoids from the shaft's bottom edge to the outlet's edge
tris += quad((a, a, Z_OUT), (b, a, Z_OUT), (L, 0, Z_SHAFT), (0, 0, Z_SHAFT))
tris += quad((b, a, Z_OUT), (b, b, Z_OUT), (L, L, Z_SHAFT), (L, 0, Z_SHAFT))
tris += quad((b, b, Z_OUT), (a, b, Z_OUT), (0, L, Z_SHAFT), (L, L, Z_SHAFT))
tris += quad((a, b, Z_OUT), (a, a, Z_OUT), (0, 0, Z_SHAFT), (0, L, Z_SHAFT))


def normal(t):
    (x0, y0, z0), (x1, y1, z1), (x2, y2, z2) = t
    u, v = (x1 - x0, y1 - y0, z1 - z0), (x2 - x0, y2 - y0, z2 - z0)
    n = (u[1] * v[2] - u[2] * v[1], u[2] * v[0] - u[0] * v[2], u[0] * v[1] - u[1] * v[0])
    m = sum(c * c for c in n) ** 0.5
    return tuple(c / m for c in n)


out = sys.stdout
out.write("solid hopper\n")
for t in tris:
    out.write("  facet normal {:.9e} {:.9e} {:.9e}\n    outer loop\n".format(*normal(t)))
    for p in t:
        out.write("      vertex {:.9e} {:.9e} {:.9e}\n".format(*[float(c) for c in p]))
    out.write("    endloop\n  endfacet\n")
out.write("endsolid hopper\n")
