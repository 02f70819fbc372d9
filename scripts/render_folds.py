#!/usr/bin/env python3
"""Renders solved meshes side by side, headless, for docs/solver.md "Folds".

Usage: render_folds.py OUT.png SIZE PANEL [PANEL ...]
PANEL: MESH.obj[:FOLDED.txt[:VIEW]] where FOLDED.txt lists triangle indices to draw red
(facecap bench --stress --worst-dir writes both) and VIEW is front (default), left or
below. Every panel is framed on the folded triangles of the first panel that has any
(the whole mesh when none has), so before and after show the same patch. A small
z-buffered, flat-shaded rasteriser in plain Python (no dependencies): OBJ faces are
triangulated as fans.
"""
import math
import struct
import sys
import zlib


def read_obj(path):
    vertices, triangles = [], []
    with open(path) as f:
        for line in f:
            p = line.split()
            if not p:
                continue
            if p[0] == "v":
                vertices.append(tuple(float(x) for x in p[1:4]))
            elif p[0] == "f":
                idx = [int(x.split("/")[0]) - 1 for x in p[1:]]
                for i in range(1, len(idx) - 1):
                    triangles.append((idx[0], idx[i], idx[i + 1]))
    return vertices, triangles


def view_transform(view):
    if view == "left":  # looking along +x: screen x = -z
        return lambda v: (-v[2], v[1], v[0])
    if view == "below":  # looking up: screen y = z
        return lambda v: (v[0], v[2], -v[1])
    return lambda v: (v[0], v[1], v[2])  # front: the face looks +z


def render(vertices, triangles, folded, box, size, view):
    to_view = view_transform(view)
    pts = [to_view(v) for v in vertices]
    (x0, y0, x1, y1) = box
    scale = (size - 1) / max(x1 - x0, y1 - y0)
    sx = [(p[0] - x0) * scale for p in pts]
    sy = [(y1 - p[1]) * scale for p in pts]
    depth = [float("-inf")] * (size * size)
    image = bytearray([255] * (size * size * 3))
    light = (0.3, 0.4, 0.87)
    for t, (a, b, c) in enumerate(triangles):
        pa, pb, pc = pts[a], pts[b], pts[c]
        u = (pb[0] - pa[0], pb[1] - pa[1], pb[2] - pa[2])
        w = (pc[0] - pa[0], pc[1] - pa[1], pc[2] - pa[2])
        n = (u[1] * w[2] - u[2] * w[1], u[2] * w[0] - u[0] * w[2], u[0] * w[1] - u[1] * w[0])
        length = math.sqrt(n[0] ** 2 + n[1] ** 2 + n[2] ** 2) or 1.0
        shade = abs(n[0] * light[0] + n[1] * light[1] + n[2] * light[2]) / length
        back = n[2] < 0  # facing away from the viewer: drawn darker
        if t in folded:
            colour = (int(120 + 135 * shade), int(30 * shade), int(30 * shade))
        else:
            g = int((90 if back else 150) + (60 if back else 105) * shade)
            colour = (g, int(g * 0.93), int(g * 0.85))
        xs, ys = (sx[a], sx[b], sx[c]), (sy[a], sy[b], sy[c])
        minx, maxx = max(0, int(min(xs))), min(size - 1, int(max(xs)) + 1)
        miny, maxy = max(0, int(min(ys))), min(size - 1, int(max(ys)) + 1)
        if minx > maxx or miny > maxy:
            continue
        area = (xs[1] - xs[0]) * (ys[2] - ys[0]) - (xs[2] - xs[0]) * (ys[1] - ys[0])
        if area == 0:
            continue
        za, zb, zc = pa[2], pb[2], pc[2]
        for y in range(miny, maxy + 1):
            for x in range(minx, maxx + 1):
                l1 = ((xs[1] - x) * (ys[2] - y) - (xs[2] - x) * (ys[1] - y)) / area
                l2 = ((xs[2] - x) * (ys[0] - y) - (xs[0] - x) * (ys[2] - y)) / area
                l3 = 1.0 - l1 - l2
                if l1 < 0 or l2 < 0 or l3 < 0:
                    continue
                z = l1 * za + l2 * zb + l3 * zc
                i = y * size + x
                if z > depth[i]:
                    depth[i] = z
                    image[3 * i:3 * i + 3] = bytes(colour)
    return image


def write_png(path, width, height, rgb):
    raw = b"".join(b"\x00" + bytes(rgb[3 * width * y:3 * width * (y + 1)]) for y in range(height))

    def chunk(kind, data):
        return struct.pack(">I", len(data)) + kind + data + struct.pack(">I", zlib.crc32(kind + data) & 0xFFFFFFFF)

    with open(path, "wb") as f:
        f.write(b"\x89PNG\r\n\x1a\n" + chunk(b"IHDR", struct.pack(">IIBBBBB", width, height, 8, 2, 0, 0, 0)) +
                chunk(b"IDAT", zlib.compress(raw, 9)) + chunk(b"IEND", b""))


def main():
    out, size, panels = sys.argv[1], int(sys.argv[2]), sys.argv[3:]
    loaded = []
    for spec in panels:
        parts = spec.split(":")
        vertices, triangles = read_obj(parts[0])
        folded = set()
        if len(parts) > 1 and parts[1]:
            with open(parts[1]) as f:
                folded = {int(line) for line in f if line.strip()}
        loaded.append((vertices, triangles, folded, parts[2] if len(parts) > 2 else "front"))
    # Frame: the first panel's folded triangles (in its view), with a margin.
    frame = next((p for p in loaded if p[2]), loaded[0])
    to_view = view_transform(frame[3])
    chosen = frame[2] or set(range(len(frame[1])))
    xs = [to_view(frame[0][v])[0] for t in chosen for v in frame[1][t]]
    ys = [to_view(frame[0][v])[1] for t in chosen for v in frame[1][t]]
    cx, cy = (min(xs) + max(xs)) / 2, (min(ys) + max(ys)) / 2
    half = max(max(xs) - min(xs), max(ys) - min(ys)) * 0.5 * 1.8 + 1e-9
    if frame[2]:
        half = max(half, 1.5)  # at least 3 rig units across: the surroundings show
    box = (cx - half, cy - half, cx + half, cy + half)
    images = [render(v, t, f, box, size, view) for v, t, f, view in loaded]
    gap = 6
    width = len(images) * size + (len(images) - 1) * gap
    canvas = bytearray([255] * (width * size * 3))
    for k, img in enumerate(images):
        for y in range(size):
            start = 3 * (y * width + k * (size + gap))
            canvas[start:start + 3 * size] = img[3 * y * size:3 * (y + 1) * size]
    write_png(out, width, size, canvas)


if __name__ == "__main__":
    main()
