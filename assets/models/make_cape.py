#!/usr/bin/env python3
"""Writes cape.gltf: the cape of the `gltf_cape` example, modelled here (no external source).

A 0.8 m × 1.1 m cape of 16 × 22 quads, curved around the wearer's back (z = 0.12 (1 − (2x/w)²)),
top edge at y = 0, hanging down to y = −1.1. Its UVs are two islands — left and right halves,
as an artist unwraps a cape — so the middle column of vertices is split in two (a UV seam:
same positions, different UVs). The top row is painted red (COLOR_0 = (1, 0, 0, 1)): the pinned
rim. Two empty nodes, `pin_left` and `pin_right`, mark the shoulders. Run from this folder:
`python3 make_cape.py`.
"""
import base64, json, struct

NX, NY, W, H = 16, 22, 0.8, 1.1
SEAM = NX // 2

pos, nrm, uv, col = [], [], [], []
left, right = {}, {}

def vertex(i, j, island):
    x = -W / 2 + W * i / NX
    y = -H * j / NY
    z = 0.12 * (1 - (2 * x / W) ** 2)
    # normal of the curved sheet: −∂z/∂x, 0, 1
    dzdx = -0.12 * 8 * x / (W * W)
    n = (-dzdx, 0.0, 1.0)
    l = sum(c * c for c in n) ** 0.5
    # islands: u in [0, 0.48] (left) and [0.52, 1] (right)
    if island == 0:
        u = 0.48 * i / SEAM
    else:
        u = 0.52 + 0.48 * (i - SEAM) / (NX - SEAM)
    v = j / NY
    pos.append((x, y, z))
    nrm.append(tuple(c / l for c in n))
    uv.append((u, v))
    col.append((1.0, 0.0, 0.0, 1.0) if j == 0 else (1.0, 1.0, 1.0, 1.0))
    return len(pos) - 1

for j in range(NY + 1):
    for i in range(NX + 1):
        if i <= SEAM:
            left[i, j] = vertex(i, j, 0)
        if i >= SEAM:
            right[i, j] = vertex(i, j, 1)

idx = []
for j in range(NY):
    for i in range(NX):
        m = left if i < SEAM else right
        a, b, c, d = m[i, j], m[i + 1, j], m[i + 1, j + 1], m[i, j + 1]
        # counter-clockwise seen from +z (the outside of the cape)
        idx += [a, d, c, a, c, b]

def pack(fmt, rows):
    return b"".join(struct.pack(fmt, *r) for r in rows)

chunks = [
    pack("<3f", pos),
    pack("<3f", nrm),
    pack("<2f", uv),
    pack("<4f", col),
    struct.pack(f"<{len(idx)}I", *idx),
]
views, offset = [], 0
blob = b""
for k, c in enumerate(chunks):
    views.append({"buffer": 0, "byteOffset": offset, "byteLength": len(c),
                  "target": 34963 if k == 4 else 34962})
    blob += c
    offset += len(c)
    pad = (-len(blob)) % 4
    blob += b"\0" * pad
    offset += pad

n = len(pos)
mins = [min(p[k] for p in pos) for k in range(3)]
maxs = [max(p[k] for p in pos) for k in range(3)]
gltf = {
    "asset": {"version": "2.0", "generator": "bevy_soft_body make_cape.py"},
    "scene": 0,
    "scenes": [{"nodes": [0, 1, 2]}],
    "nodes": [
        {"name": "cape", "mesh": 0},
        {"name": "pin_left", "translation": [-W / 2, 0.0, 0.0]},
        {"name": "pin_right", "translation": [W / 2, 0.0, 0.0]},
    ],
    "meshes": [{"name": "cape", "primitives": [{
        "attributes": {"POSITION": 0, "NORMAL": 1, "TEXCOORD_0": 2, "COLOR_0": 3},
        "indices": 4, "material": 0, "mode": 4}]}],
    "materials": [{"name": "cape cloth", "doubleSided": True,
                   "pbrMetallicRoughness": {"baseColorFactor": [0.55, 0.12, 0.6, 1.0],
                                            "metallicFactor": 0.0, "roughnessFactor": 0.9}}],
    "accessors": [
        {"bufferView": 0, "componentType": 5126, "count": n, "type": "VEC3", "min": mins, "max": maxs},
        {"bufferView": 1, "componentType": 5126, "count": n, "type": "VEC3"},
        {"bufferView": 2, "componentType": 5126, "count": n, "type": "VEC2"},
        {"bufferView": 3, "componentType": 5126, "count": n, "type": "VEC4"},
        {"bufferView": 4, "componentType": 5125, "count": len(idx), "type": "SCALAR"},
    ],
    "bufferViews": views,
    "buffers": [{"byteLength": len(blob),
                 "uri": "data:application/octet-stream;base64," + base64.b64encode(blob).decode()}],
}
with open("cape.gltf", "w") as f:
    json.dump(gltf, f, indent=1)
print(f"cape.gltf: {n} vertices ({NY + 1} on the seam twice), {len(idx) // 3} triangles")
