#!/usr/bin/env python3
"""Checks a cloth_sphere screenshot: the cloth and the sphere must both be visible.
With `--cape`, checks the gltf_cape screenshot (see `cape` below); with `--playground`, the
avian_playground screenshot (see `playground`).
With `--tear`, the tearing screenshot (see `tear`).
With `--body`, checks a finite-element screenshot (fem_bunny, fem_armadillo) instead: the
skinned display mesh's beige (sRGB 0.78, 0.72, 0.62), lit — red ≥ green ≥ blue, red 12–70
above blue, red > 120 — must cover more than 3 % of the frame right of the panel (10.9 % in
docs/fem_bunny.png, 5.5 % in docs/fem_armadillo.png; 0 % in an empty frame or fem_beam's blue).

Pixel statistics against the known colours of the scene (no image libraries needed):
- cloth: the red material (sRGB 0.85, 0.25, 0.22), lit: red clearly above green and blue;
- sphere: the grey material (0.75, 0.78, 0.82), lit or shadowed: near-neutral, brighter than
  the background (0.09, 0.10, 0.12) and right of the panel on the left (x > 380).
Thresholds are far below what a correct frame shows (7.9 % cloth, 1.6 % sphere in docs/cloth_sphere.png at
1280×720, with the panel on the left) and far above what an empty or black frame shows (0 %).
"""
import struct
import sys
import zlib


def read_png(path):
    data = open(path, "rb").read()
    assert data[:8] == b"\x89PNG\r\n\x1a\n", "not a PNG"
    pos, idat, w = 8, b"", None
    while pos < len(data):
        n, kind = struct.unpack(">I4s", data[pos:pos + 8])
        body = data[pos + 8:pos + 8 + n]
        if kind == b"IHDR":
            w, h, depth, ctype = struct.unpack(">IIBB", body[:10])
            assert depth == 8 and ctype in (2, 6), f"unsupported PNG: depth {depth} colour type {ctype}"
            bpp = 3 if ctype == 2 else 4
        elif kind == b"IDAT":
            idat += body
        pos += 12 + n
    raw = zlib.decompress(idat)
    stride = w * bpp
    rows, prev = [], bytearray(stride)
    for y in range(h):
        f = raw[y * (stride + 1)]
        line = bytearray(raw[y * (stride + 1) + 1:(y + 1) * (stride + 1)])
        for i in range(stride):
            a = line[i - bpp] if i >= bpp else 0
            b = prev[i]
            c = prev[i - bpp] if i >= bpp else 0
            if f == 1:
                line[i] = (line[i] + a) & 255
            elif f == 2:
                line[i] = (line[i] + b) & 255
            elif f == 3:
                line[i] = (line[i] + (a + b) // 2) & 255
            elif f == 4:
                p = a + b - c
                pa, pb, pc = abs(p - a), abs(p - b), abs(p - c)
                line[i] = (line[i] + (a if pa <= pb and pa <= pc else b if pb <= pc else c)) & 255
        rows.append(line)
        prev = line
    return w, h, bpp, rows


def main(path):
    w, h, bpp, rows = read_png(path)
    cloth = sphere = 0
    for y, line in enumerate(rows):
        for x in range(w):
            r, g, b = line[x * bpp], line[x * bpp + 1], line[x * bpp + 2]
            if r > 90 and r > 1.6 * g and r > 1.6 * b:
                cloth += 1
            elif x > 380 and 40 < r < 235 and abs(r - g) < 14 and abs(g - b) < 18:
                sphere += 1
    n = w * h
    print(f"{path}: {w}x{h}, cloth {100 * cloth / n:.2f} %, sphere {100 * sphere / n:.2f} %")
    ok = cloth > 0.02 * n and sphere > 0.002 * n
    if not ok:
        print("FAIL: cloth needs > 2 % of the pixels and the sphere > 0.2 %")
    return 0 if ok else 1


def body(path):
    w, h, bpp, rows = read_png(path)
    hits = total = 0
    for line in rows:
        for x in range(380, w):
            r, g, b = line[x * bpp], line[x * bpp + 1], line[x * bpp + 2]
            total += 1
            if r > 120 and r >= g >= b and 12 <= r - b <= 70:
                hits += 1
    share = 100 * hits / total
    print(f"{path}: {w}x{h}, body {share:.2f} % of the frame right of the panel")
    if share <= 3.0:
        print("FAIL: the body needs > 3 % of those pixels")
        return 1
    return 0


def cape(path):
    """gltf_cape: the cape's purple glTF material (sRGB 0.55, 0.12, 0.60), lit — red and blue
    both well above green — must cover more than 3 % of the frame right of the panel, and the
    cape must hang below its pole's crossbar: purple in the lower half of the frame too."""
    w, h, bpp, rows = read_png(path)
    hits = low = total = 0
    for y, line in enumerate(rows):
        for x in range(380, w):
            r, g, b = line[x * bpp], line[x * bpp + 1], line[x * bpp + 2]
            total += 1
            if r > 90 and b > 90 and r - g > 40 and b - g > 40:
                hits += 1
                low += y > h // 2
    share = 100 * hits / total
    print(f"{path}: {w}x{h}, cape {share:.2f} % of the frame right of the panel, "
          f"{100 * low / max(hits, 1):.0f} % of it in the lower half")
    if share <= 3.0 or low < 0.1 * hits:
        print("FAIL: the cape needs > 3 % of those pixels, a tenth of them in the lower half")
        return 1
    return 0


def tear(path):
    """tearing at t = 2.5 s: the curtain's red (sRGB 0.80, 0.30, 0.25), lit, must cover more
    than 5 % of the frame right of the panel, and be torn: at least 20 rows in which a run of
    10 or more background pixels (all channels under 50; the clear colour is sRGB 0.09, 0.10,
    0.12) lies between red on both sides. docs/tearing.png: 24 % red, torn in 157 rows; the
    curtain still whole at t = 0.25 s: 23 % red, 6 rows (its slanted top edge)."""
    w, h, bpp, rows = read_png(path)
    hits = total = torn_rows = 0
    for line in rows:
        red = []
        dark = []
        for x in range(380, w):
            r, g, b = line[x * bpp], line[x * bpp + 1], line[x * bpp + 2]
            total += 1
            is_red = r > 90 and r > 1.6 * g and r > 1.6 * b
            hits += is_red
            red.append(is_red)
            dark.append(r < 50 and g < 50 and b < 50)
        if not any(red):
            continue
        first = red.index(True)
        last = len(red) - 1 - red[::-1].index(True)
        run = best = 0
        for i in range(first, last + 1):
            run = run + 1 if dark[i] else 0
            best = max(best, run)
        torn_rows += best >= 10
    share = 100 * hits / total
    print(f"{path}: {w}x{h}, curtain {share:.2f} % of the frame right of the panel, "
          f"torn in {torn_rows} rows")
    if share <= 5.0 or torn_rows < 20:
        print("FAIL: the curtain needs > 5 % of those pixels and a hole in at least 20 rows")
        return 1
    return 0


def playground(path):
    """avian_playground at t = 4.5 s: the soft bodies' red (the default surface, sRGB 0.85,
    0.25, 0.22) must cover more than 3 % of the frame between the two panels (x 350–960), and
    the crate (sRGB 0.6, 0.45, 0.25: red > green > blue, red 50–130 above blue) must be there
    and resting on the trampoline, not on the ground 0.8 m below: more than 0.3 % of those
    pixels, their mean height above 58 % of the frame's (the trampoline is drawn about half
    way down, the ground under it about two thirds). docs/avian_playground.png: 6.9 % red,
    0.8 % crate at 50 %."""
    w, h, bpp, rows = read_png(path)
    red = krate = krate_y = total = 0
    for y, line in enumerate(rows):
        for x in range(350, min(960, w)):
            r, g, b = line[x * bpp], line[x * bpp + 1], line[x * bpp + 2]
            total += 1
            if r > 90 and r > 1.6 * g and r > 1.6 * b:
                red += 1
            elif r > 80 and r > g > b and 50 <= r - b <= 130 and g - b > 15:
                krate += 1
                krate_y += y
    mean = krate_y / max(krate, 1) / h
    print(f"{path}: {w}x{h}, soft bodies {100 * red / total:.2f} %, crate {100 * krate / total:.2f} % "
          f"at {100 * mean:.0f} % of the height")
    if red <= 0.03 * total or krate <= 0.003 * total or mean > 0.58:
        print("FAIL: soft bodies need > 3 %, the crate > 0.3 % above 58 % of the height")
        return 1
    return 0


if __name__ == "__main__":
    if sys.argv[1] == "--tear":
        sys.exit(tear(sys.argv[2]))
    if sys.argv[1] == "--playground":
        sys.exit(playground(sys.argv[2]))
    if sys.argv[1] == "--body":
        sys.exit(body(sys.argv[2]))
    if sys.argv[1] == "--cape":
        sys.exit(cape(sys.argv[2]))
    sys.exit(main(sys.argv[1]))
