#!/usr/bin/env python3
"""Writes the fuzzer's seed corpus (tests/fuzz/corpus/) deterministically: small hand-made glTF,
GLB and OBJ+MTL scenes in the layout of scene_fuzzer.cpp (byte 0 picks the format: '0' .gltf with
an optional b.bin after a NUL byte, '1' .glb, '2' .obj with an optional m.mtl after a NUL byte,
'3' the same with the .mtl passed as LoadOptions::mtl, '4' .nff, '5' .ply, ASCII or binary).
python3 tests/fuzz/make_corpus.py"""
import base64, json, os, struct, zlib

OUT = os.path.join(os.path.dirname(os.path.abspath(__file__)), "corpus")

def f32(*v): return struct.pack("<%df" % len(v), *v)
def u16(*v): return struct.pack("<%dH" % len(v), *v)
def u8(*v): return bytes(v)

def png_2x2():
    raw = b"".join(b"\x00" + bytes([255, 0, 0, 0, 255, 0]) for _ in range(2))
    def chunk(t, d): return struct.pack(">I", len(d)) + t + d + struct.pack(">I", zlib.crc32(t + d) & 0xffffffff)
    return (b"\x89PNG\r\n\x1a\n" + chunk(b"IHDR", struct.pack(">IIBBBBB", 2, 2, 8, 2, 0, 0, 0)) +
            chunk(b"IDAT", zlib.compress(raw)) + chunk(b"IEND", b""))

class Gltf:
    def __init__(self):
        self.bin = bytearray()
        self.j = {"asset": {"version": "2.0"}, "buffers": [], "bufferViews": [], "accessors": []}
    def view(self, data):
        while len(self.bin) % 4: self.bin += b"\x00"
        self.j["bufferViews"].append({"buffer": 0, "byteOffset": len(self.bin), "byteLength": len(data)})
        self.bin += data
        return len(self.j["bufferViews"]) - 1
    def acc(self, data, ctype, count, typ, minmax=None, **extra):
        a = {"bufferView": self.view(data), "componentType": ctype, "count": count, "type": typ}
        if minmax: a["min"], a["max"] = minmax
        a.update(extra)
        self.j["accessors"].append(a)
        return len(self.j["accessors"]) - 1
    def finish(self, uri):
        self.j["buffers"] = [{"byteLength": len(self.bin)}]
        if uri == "data":
            self.j["buffers"][0]["uri"] = "data:application/octet-stream;base64," + base64.b64encode(bytes(self.bin)).decode()
        elif uri:
            self.j["buffers"][0]["uri"] = uri
        return json.dumps(self.j, separators=(",", ":")).encode()

TRI = f32(0, 0, 0, 1, 0, 0, 0, 1, 0)
QUAD = f32(0, 0, 0, 1, 0, 0, 1, 1, 0, 0, 1, 0)

def triangle(mode=None, indexed=False, uri="data"):
    g = Gltf()
    pos = g.acc(QUAD if indexed else TRI, 5126, 4 if indexed else 3, "VEC3", ([0, 0, 0], [1, 1, 0]))
    prim = {"attributes": {"POSITION": pos}}
    if indexed: prim["indices"] = g.acc(u16(0, 1, 2, 0, 2, 3), 5123, 6, "SCALAR")
    if mode is not None: prim["mode"] = mode
    g.j.update(meshes=[{"primitives": [prim]}], nodes=[{"mesh": 0}], scenes=[{"nodes": [0]}], scene=0)
    return g

def full_scene():
    """Normals, texcoords, a textured material, a camera, lights, TRS animation."""
    g = Gltf()
    pos = g.acc(QUAD, 5126, 4, "VEC3", ([0, 0, 0], [1, 1, 0]))
    nrm = g.acc(f32(*([0, 0, 1] * 4)), 5126, 4, "VEC3")
    uv = g.acc(f32(0, 0, 1, 0, 1, 1, 0, 1), 5126, 4, "VEC2")
    idx = g.acc(u8(0, 1, 2, 0, 2, 3), 5121, 6, "SCALAR")
    img = g.view(png_2x2())
    times = g.acc(f32(0, 1, 2), 5126, 3, "SCALAR", ([0], [2]))
    trans = g.acc(f32(0, 0, 0, 1, 0, 0, 0, 0, 0), 5126, 3, "VEC3")
    rot = g.acc(f32(0, 0, 0, 1, 0, 0.7071, 0, 0.7071, 0, 0, 0, 1), 5126, 3, "VEC4")
    g.j.update(
        meshes=[{"primitives": [{"attributes": {"POSITION": pos, "NORMAL": nrm, "TEXCOORD_0": uv},
                                 "indices": idx, "material": 0}]}],
        materials=[{"name": "m", "pbrMetallicRoughness": {"baseColorTexture": {"index": 0},
                    "metallicFactor": 0.5, "roughnessFactor": 0.2},
                    "extensions": {"KHR_materials_transmission": {"transmissionFactor": 0.5},
                                   "KHR_materials_ior": {"ior": 1.4}}}],
        textures=[{"source": 0, "sampler": 0}],
        samplers=[{"wrapS": 33648, "wrapT": 33071}],
        images=[{"bufferView": img, "mimeType": "image/png"}],
        cameras=[{"type": "perspective", "perspective": {"yfov": 0.8, "znear": 0.1}}],
        extensionsUsed=["KHR_lights_punctual", "KHR_materials_transmission", "KHR_materials_ior"],
        extensions={"KHR_lights_punctual": {"lights": [
            {"type": "point", "intensity": 10}, {"type": "spot", "spot": {"outerConeAngle": 0.5}},
            {"type": "directional", "color": [1, 0.5, 0.5]}]}},
        nodes=[{"mesh": 0, "children": [1, 2]}, {"camera": 0, "translation": [0, 0, 3]},
               {"extensions": {"KHR_lights_punctual": {"light": 0}}, "translation": [1, 1, 1],
                "children": [3, 4]},
               {"extensions": {"KHR_lights_punctual": {"light": 1}}, "rotation": [0, 0.7071, 0, 0.7071]},
               {"extensions": {"KHR_lights_punctual": {"light": 2}}, "scale": [1, 2, 1]}],
        scenes=[{"nodes": [0]}], scene=0,
        animations=[{"samplers": [{"input": times, "output": trans},
                                  {"input": times, "output": rot, "interpolation": "STEP"}],
                     "channels": [{"sampler": 0, "target": {"node": 0, "path": "translation"}},
                                  {"sampler": 1, "target": {"node": 1, "path": "rotation"}}]}])
    return g

def texture_transform():
    """full_scene with KHR_texture_transform on the base-colour texture reading TEXCOORD_1."""
    g = full_scene()
    uv1 = g.acc(f32(0, 1, 1, 1, 1, 0, 0, 0), 5126, 4, "VEC2")
    g.j["meshes"][0]["primitives"][0]["attributes"]["TEXCOORD_1"] = uv1
    g.j["materials"][0]["pbrMetallicRoughness"]["baseColorTexture"]["extensions"] = {
        "KHR_texture_transform": {"offset": [0, 1], "rotation": 1.5708, "scale": [0.5, 0.5], "texCoord": 1}}
    g.j["extensionsUsed"].append("KHR_texture_transform")
    return g

def skinned_morph():
    """A skin with two joints, a morph target driven by a weights channel, a sparse accessor,
    a cubic-spline sampler."""
    g = Gltf()
    pos = g.acc(QUAD, 5126, 4, "VEC3", ([0, 0, 0], [1, 1, 0]))
    joints = g.acc(u8(0, 1, 0, 0) * 4, 5121, 4, "VEC4")
    weights = g.acc(f32(*([0.5, 0.5, 0, 0] * 4)), 5126, 4, "VEC4")
    target = g.acc(f32(*([0, 0, 1] * 4)), 5126, 4, "VEC3")
    idx = g.acc(u16(0, 1, 2, 0, 2, 3), 5123, 6, "SCALAR")
    ibm = g.acc(f32(*([1, 0, 0, 0, 0, 1, 0, 0, 0, 0, 1, 0, 0, 0, 0, 1] * 2)), 5126, 2, "MAT4")
    times = g.acc(f32(0, 1), 5126, 2, "SCALAR", ([0], [1]))
    w = g.acc(f32(0, 1), 5126, 2, "SCALAR")
    cubic = g.acc(f32(*([0, 0, 0] * 3 + [1, 1, 0] * 3)), 5126, 6, "VEC3")
    sp_idx = g.view(u16(1))
    sp_val = g.view(f32(0.5, 0.5, 0.5))
    sparse_pos = g.acc(QUAD, 5126, 4, "VEC3", ([0, 0, 0], [1, 1, 0]),
                       sparse={"count": 1, "indices": {"bufferView": sp_idx, "componentType": 5123},
                               "values": {"bufferView": sp_val}})
    g.j.update(
        meshes=[{"primitives": [{"attributes": {"POSITION": pos, "JOINTS_0": joints, "WEIGHTS_0": weights},
                                 "indices": idx, "targets": [{"POSITION": target}]}], "weights": [0.0]},
                {"primitives": [{"attributes": {"POSITION": sparse_pos}, "mode": 6}]}],
        skins=[{"joints": [1, 2], "inverseBindMatrices": ibm}],
        nodes=[{"mesh": 0, "skin": 0}, {"children": [2]}, {"translation": [0, 1, 0]},
               {"mesh": 1, "matrix": [1, 0, 0, 0, 0, 1, 0, 0, 0, 0, -1, 0, 2, 0, 0, 1]}],
        scenes=[{"nodes": [0, 1, 3]}],
        animations=[{"samplers": [{"input": times, "output": w},
                                  {"input": times, "output": cubic, "interpolation": "CUBICSPLINE"}],
                     "channels": [{"sampler": 0, "target": {"node": 0, "path": "weights"}},
                                  {"sampler": 1, "target": {"node": 2, "path": "translation"}}]}])
    return g

def glb(g):
    js = g.finish(None)
    js += b" " * (-len(js) % 4)
    bn = bytes(g.bin) + b"\x00" * (-len(g.bin) % 4)
    body = struct.pack("<I4s", len(js), b"JSON") + js + struct.pack("<I4s", len(bn), b"BIN\x00") + bn
    return struct.pack("<4sII", b"glTF", 2, 12 + len(body)) + body

OBJ = b"""mtllib m.mtl
o quad
v 0 0 0
v 1 0 0
v 1 1 0
v 0 1 0
vt 0 0
vt 1 0
vt 1 1
vt 0 1
vn 0 0 1
usemtl red
f 1/1/1 2/2/1 3/3/1 4/4/1
g second
usemtl glass
f -4//1 -2//1 -1//1
f 1 2 3
"""
MTL = b"""newmtl red
Kd 0.8 0.1 0.1
Ks 0.5 0.5 0.5
Ns 64
illum 3
newmtl glass
Kd 0 0 0
Ni 1.5
d 0.2
Tf 0.9 0.9 0.9
illum 7
map_Kd missing.png
"""

# Every NFF entity: a view, a background, lights with and without colour, materials, a concave
# polygon, a patch, spheres (one inside-out), a cylinder and a pointed cone.
NFF = b"""# every entity
v
from 2 -6 3
at 0 0 0.5
up 0 0 1
angle 45
hither 0.1
resolution 64 48
b 0.1 0.3 0.7
l 4 -3 6
l -3 -2 5 1 0.8 0.6
f 1 0.75 0.33 0.8 0.2 30 0 1
p 6
0 0 0
3 0 0
3 1 0
1 1 0
1 3 0
0 3 0
pp 3
0 0 1 0 0 1
1 0 1 0 0 1
0 1 1 0.6 0 0.8
f 1 0.6 0.4 0.2 0 100000 0.8 1.1
s 0 0 1 0.5
s 1 1 1 -0.25
c
2 2 0 0.3
2 2 1 0.3
c
-1 2 0 0.5
-1 2 1 0
"""

PLY_VERTS = [(0, 0, 0, 0, 0, 1, 0, 0, 255, 0, 0), (1, 0, 0, 0, 0, 1, 1, 0, 0, 255, 0),
             (1, 1, 0, 0, 0, 1, 1, 1, 0, 0, 255), (0, 1, 0, 0, 0, 1, 0, 1, 255, 255, 255)]
PLY_FACES = [(0, 1, 2, 3), (0, 2, 3)]

def ply(fmt):
    """A quad and a triangle with normals, texture coordinates and vertex colours."""
    head = ("ply\nformat %s 1.0\ncomment fuzz seed\nelement vertex %d\n" % (fmt, len(PLY_VERTS)) +
            "".join("property float %s\n" % n for n in ("x", "y", "z", "nx", "ny", "nz", "s", "t")) +
            "property uchar red\nproperty uchar green\nproperty uchar blue\n" +
            "element face %d\nproperty list uchar int vertex_indices\nend_header\n" % len(PLY_FACES)).encode()
    if fmt == "ascii":
        body = "".join(" ".join("%g" % x for x in v) + "\n" for v in PLY_VERTS)
        body += "".join("%d %s\n" % (len(f), " ".join(map(str, f))) for f in PLY_FACES)
        return head + body.encode()
    e = "<" if fmt == "binary_little_endian" else ">"
    body = b"".join(struct.pack(e + "8f3B", *v) for v in PLY_VERTS)
    body += b"".join(struct.pack(e + "B%di" % len(f), len(f), *f) for f in PLY_FACES)
    return head + body

def write(name, data):
    with open(os.path.join(OUT, name), "wb") as f: f.write(data)

def main():
    os.makedirs(OUT, exist_ok=True)
    write("gltf_triangle", b"0" + triangle().finish("data"))
    write("gltf_indexed_strip", b"0" + triangle(mode=5, indexed=True).finish("data"))
    write("gltf_fan_external_bin", b"0" + (lambda g: g.finish("b.bin") + b"\x00" + bytes(g.bin))(triangle(mode=6, indexed=True, uri=None)))
    write("gltf_full_scene", b"0" + full_scene().finish("data"))
    write("gltf_skin_morph_sparse", b"0" + skinned_morph().finish("data"))
    write("gltf_texture_transform", b"0" + texture_transform().finish("data"))
    write("gltf_required_ext", b"0" + (lambda g: (g.j.update(extensionsRequired=["KHR_draco_mesh_compression"],
           extensionsUsed=["KHR_draco_mesh_compression"]), g.finish("data"))[1])(triangle()))
    write("glb_triangle", b"1" + glb(triangle(indexed=True)))
    write("glb_full_scene", b"1" + glb(full_scene()))
    write("glb_skin_morph", b"1" + glb(skinned_morph()))
    write("obj_with_mtllib", b"2" + OBJ + b"\x00" + MTL)
    write("obj_plain", b"2v 0 0 0\nv 1 0 0\nv 0 1 0\nf 1 2 3\n")
    write("obj_mtl_option", b"3" + OBJ.replace(b"mtllib m.mtl\n", b"") + b"\x00" + MTL)
    write("nff_every_entity", b"4" + NFF)
    write("nff_truncated_polygon", b"4" + NFF[:NFF.index(b"3 1 0")])
    for fmt in ("ascii", "binary_little_endian", "binary_big_endian"):
        write("ply_" + fmt, b"5" + ply(fmt))
    write("ply_truncated_binary", b"5" + ply("binary_big_endian")[:-7])

if __name__ == "__main__":
    main()
