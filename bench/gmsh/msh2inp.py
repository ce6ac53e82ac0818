#!/usr/bin/env python3
"""Gmsh 4.1 ASCII mesh of 10-node tetrahedra -> CalculiX mesh include, for the tet10 peer case
(bench/ccx/bracket.inp *INCLUDEs it; our bench reads the .msh itself).

    python3 msh2inp.py bracket.msh PX PY PZ > mesh_bracket.inp

Writes *NODE (Gmsh node tags kept), *ELEMENT TYPE=C3D10 ELSET=PART (Gmsh's nodes 8 and 9 swapped
into Abaqus order: Gmsh numbers the edges 2-3 and 1-3 the other way round), one *NSET per 2-D
physical group (every node of its triangles), *NSET PROBE (the node nearest to the point
PX PY PZ, as our probes pick it), and for a physical surface named "loaded" the tetrahedra whose
face k it covers as *ELSET LOADED1..LOADED4 (for *DLOAD LOADEDk, Pk; CalculiX's C3D10 faces
1-2-3, 1-4-2, 2-4-3, 3-4-1), matched on their corner nodes with the group's 6-node triangles.
"""
import sys


def sections(path):
    out, name, body = {}, None, []
    with open(path) as f:
        for line in f:
            line = line.strip()
            if line.startswith("$End"):
                out[name] = body
                name, body = None, []
            elif line.startswith("$"):
                name = line[1:]
            elif name is not None:
                body.append(line)
    return out


def main():
    if len(sys.argv) != 5:
        sys.exit(__doc__)
    sec = sections(sys.argv[1])
    probe = [float(v) for v in sys.argv[2:5]]
    names = {}
    for line in sec["PhysicalNames"][1:]:
        dim, tag, name = line.split(maxsplit=2)
        names[(int(dim), int(tag))] = name.strip('"')
    # entity (dim, tag) -> physical tags
    ent = sec["Entities"]
    counts = [int(v) for v in ent[0].split()]
    phys, row = {}, 1
    for dim, n in enumerate(counts):
        for _ in range(n):
            v = ent[row].split()
            row += 1
            k = 4 if dim == 0 else 7  # point: tag x y z; others: tag and a bounding box
            phys[(dim, int(v[0]))] = [int(t) for t in v[k + 1:k + 1 + int(v[k])]]
    nodes = {}
    body, row = sec["Nodes"], 1
    while row < len(body):
        _, _, parametric, n = (int(v) for v in body[row].split())
        if parametric:
            sys.exit("parametric nodes are not supported: save without Mesh.SaveParametric")
        tags = [int(body[row + 1 + i]) for i in range(n)]
        for i, t in enumerate(tags):
            nodes[t] = body[row + 1 + n + i].split()[:3]
        row += 1 + 2 * n
    tets, groups = [], {}
    body, row = sec["Elements"], 1
    while row < len(body):
        dim, tag, etype, n = (int(v) for v in body[row].split())
        for line in body[row + 1:row + 1 + n]:
            v = [int(x) for x in line.split()]
            if etype == 11:
                tets.append(v)
            elif etype == 9:
                for p in phys.get((dim, tag), []):
                    groups.setdefault(names[(dim, p)], []).append(v[1:])
            elif dim == 3:
                sys.exit(f"element type {etype} in a volume: only 10-node tetrahedra (11)")
        row += 1 + n
    w = sys.stdout.write
    w(f"** {sys.argv[1]}: {len(nodes)} nodes, {len(tets)} C3D10 (written by msh2inp.py)\n*NODE\n")
    for t in sorted(nodes):
        x, y, z = nodes[t]
        w(f"{t}, {x}, {y}, {z}\n")
    w("*ELEMENT, TYPE=C3D10, ELSET=PART\n")
    for v in tets:
        n = v[1:]
        n[8], n[9] = n[9], n[8]
        w(f"{v[0]}, " + ", ".join(map(str, n[:8])) + ",\n" + ", ".join(map(str, n[8:])) + "\n")
    for name, tris in sorted(groups.items()):
        ids = sorted({t for tri in tris for t in tri})
        w(f"*NSET, NSET={name.upper()}\n")
        for i in range(0, len(ids), 16):
            w(", ".join(map(str, ids[i:i + 16])) + "\n")

    def dist2(t):
        return sum((float(a) - b) ** 2 for a, b in zip(nodes[t], probe))

    best = min(nodes, key=dist2)
    w(f"** probe: node {best} at {' '.join(nodes[best])}\n*NSET, NSET=PROBE\n{best}\n")
    if "loaded" in groups:
        want = {frozenset(tri[:3]) for tri in groups["loaded"]}
        faces = ((0, 1, 2), (0, 3, 1), (1, 3, 2), (2, 3, 0))
        by_face = [[], [], [], []]
        for v in tets:
            for s, f in enumerate(faces):
                if frozenset(v[1 + i] for i in f) in want:
                    by_face[s].append(v[0])
        found = sum(map(len, by_face))
        if found != len(want):
            sys.exit(f"{found} tetrahedron faces match the {len(want)} triangles of 'loaded'")
        for s, ids in enumerate(by_face):
            w(f"*ELSET, ELSET=LOADED{s + 1}\n")
            for i in range(0, len(ids), 16):
                w(", ".join(map(str, ids[i:i + 16])) + "\n")


main()
