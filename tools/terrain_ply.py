#!/usr/bin/env python3
"""A height-field terrain as a binary PLY: N x N vertices, 2 (N - 1)^2 triangles, a scene as large
as a user's scan, made here (no data that is not ours).

    python3 tools/terrain_ply.py N OUT.ply

N = 960 gives 1,839,362 triangles, whose fast kd-tree needs more than 2^23 leaf-entry texels (the
default texel-buffer passes then index with WIDE_INDICES; README, *Two backends, one core*).
The surface: y = 0.1 sin(6x) cos(5z) over x, z in [-1, 1]."""
import math
import struct
import sys


def main():
    if len(sys.argv) != 3:
        sys.exit("usage: terrain_ply.py N OUT.ply")
    n = int(sys.argv[1])
    if n < 2:
        sys.exit("terrain_ply.py: N must be at least 2")
    triangles = 2 * (n - 1) * (n - 1)
    with open(sys.argv[2], "wb") as out:
        out.write((f"ply\nformat binary_little_endian 1.0\nelement vertex {n * n}\n"
                   "property float x\nproperty float y\nproperty float z\n"
                   f"element face {triangles}\nproperty list uchar int vertex_indices\nend_header\n").encode())
        vertex = struct.Struct("<fff")
        for r in range(n):
            z = -1.0 + 2.0 * r / (n - 1)
            out.write(b"".join(vertex.pack(x, 0.1 * math.sin(6.0 * x) * math.cos(5.0 * z), z)
                               for x in (-1.0 + 2.0 * c / (n - 1) for c in range(n))))
        face = struct.Struct("<Biii")
        for r in range(n - 1):
            row = bytearray()
            for c in range(n - 1):
                a = r * n + c
                row += face.pack(3, a, a + 1, a + n + 1)
                row += face.pack(3, a, a + n + 1, a + n)
            out.write(row)
    print(f"{sys.argv[2]}: {n * n} vertices, {triangles} triangles")


if __name__ == "__main__":
    main()
