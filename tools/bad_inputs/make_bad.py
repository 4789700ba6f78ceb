import os
import sys, os, json, struct, copy
sys.path.insert(0, os.path.join(os.path.dirname(os.path.abspath(__file__)), "..", "..", "tests", "fuzz"))
import make_corpus as mc
D = sys.argv[1]  # the folder to write the bad inputs into
os.makedirs(D, exist_ok=True)
def w(name, data):
    with open(os.path.join(D, name), "wb") as f: f.write(data if isinstance(data, bytes) else data.encode())
def tri(mod=None, **kw):
    g = mc.triangle(**kw)
    if mod: mod(g)
    return g
def gltf(name, g, uri="data"): w(name, g.finish(uri))
w("empty.gltf", b"")
w("truncated.gltf", b'{ "asset": { "version": "2.0" }, "meshes": [ ')
w("not-json.gltf", b"hello")
w("bad-magic.glb", b"glTF\x02\x00\x00\x00\xff\xff\x00\x00JSON")
w("scene.xyz", b"x")
def acc_oob(g): g.j["accessors"][0]["count"] = 1000
gltf("accessor-out-of-bounds.gltf", tri(acc_oob))
def idx_oob(g): pass
g = mc.triangle(indexed=True); g.bin[48:48+12] = mc.u16(0, 1, 9, 0, 2, 3); gltf("index-out-of-range.gltf", g)
g = mc.triangle(); g.bin[0:4] = struct.pack("<f", float("nan")); gltf("nan-position.gltf", g)
g = mc.triangle(); g.bin[0:4] = struct.pack("<f", float("inf")); gltf("inf-position.gltf", g)
gltf("points-mode.gltf", mc.triangle(mode=0))
gltf("lines-mode.gltf", mc.triangle(mode=1))
g = mc.triangle(); g.j["extensionsRequired"] = ["KHR_draco_mesh_compression"]; g.j["extensionsUsed"] = ["KHR_draco_mesh_compression"]; gltf("draco-required.gltf", g)
gltf("missing-buffer.gltf", mc.triangle(), uri="nothere.bin")
def short_buf(g): pass
g = mc.triangle(); s = g.finish("data"); j = json.loads(s); j["buffers"][0]["byteLength"] = 10; w("buffer-too-short.gltf", json.dumps(j))
g = mc.triangle(); g.j["bufferViews"][0]["byteOffset"] = 1 << 30; gltf("bufferview-outside-buffer.gltf", g)
g = mc.triangle(); g.j["accessors"][0]["componentType"] = 5121; gltf("position-wrong-type.gltf", g)
g = mc.triangle(); g.j["meshes"][0]["primitives"][0]["attributes"] = {}; gltf("no-position.gltf", g)
# textures
g = mc.full_scene(); imgs = g.j["images"]; v = g.view(b"this is not a png"); imgs[0] = {"bufferView": v, "mimeType": "image/png"}; gltf("undecodable-texture.gltf", g)
g = mc.full_scene(); g.j["images"][0] = {"uri": "missing.png"}; gltf("missing-texture.gltf", g)
g = mc.full_scene(); v = g.view(b"RIFF\x1a\x00\x00\x00WEBPVP8 \x0e\x00\x00\x00" + bytes(14)); g.j["images"][0] = {"bufferView": v, "mimeType": "image/webp"}; gltf("webp-texture.gltf", g)
g = mc.full_scene()
mats = []; texs = []
for i in range(49):
    texs.append({"source": i}); mats.append({"pbrMetallicRoughness": {"baseColorTexture": {"index": i}}})
png = mc.png_2x2()
g.j["images"] = [{"bufferView": g.view(png + bytes([i])), "mimeType": "image/png"} for i in range(49)]
g.j["textures"] = texs; g.j["materials"] = mats
prims = []
for i in range(49):
    p = dict(g.j["meshes"][0]["primitives"][0]); p["material"] = i; prims.append(p)
g.j["meshes"][0]["primitives"] = prims
gltf("49-textures.gltf", g)
g = mc.full_scene(); g.j["animations"][0]["samplers"][0]["input"] = g.acc(mc.f32(0, 2, 1), 5126, 3, "SCALAR", ([0], [2])); gltf("keys-not-increasing.gltf", g)
g = mc.full_scene(); g.j["nodes"][0]["children"] = [0]; gltf("node-cycle.gltf", g)
w("ok-triangle.gltf", mc.triangle().finish("data"))
w("no-faces.obj", "v 0 0 0\nv 1 0 0\nv 0 1 0\n")
w("face-out-of-range.obj", "v 0 0 0\nv 1 0 0\nv 0 1 0\nf 1 2 7\n")
w("nan-vertex.obj", "v nan 0 0\nv 1 0 0\nv 0 1 0\nf 1 2 3\n")
w("inf-vertex.obj", "v 1e999 0 0\nv 1 0 0\nv 0 1 0\nf 1 2 3\n")
w("long-texture-name.obj", "mtllib m.mtl\nv 0 0 0\nv 1 0 0\nv 0 1 0\nusemtl a\nf 1 2 3\n")
w("m.mtl", "newmtl a\nmap_Kd " + "x" * 300 + "/" + "y" * 300 + ".png\n")
w("empty.obj", "")
w("binary-garbage.obj", bytes(range(256)))
# NFF (mc.NFF is the fuzz seed with every entity)
w("empty.nff", "")
w("truncated.nff", mc.NFF[:mc.NFF.index(b"3 1 0")])
w("unknown-entity.nff", mc.NFF.replace(b"b 0.1 0.3 0.7", b"bg 0.1 0.3 0.7"))
w("bad-number.nff", mc.NFF.replace(b"s 0 0 1 0.5", b"s 0 0 one 0.5"))
w("polygon-too-many.nff", "f 1 1 1 1 0 1 0 1\np 99999999\n0 0 0\n")
w("cone-coincident.nff", "c\n0 0 0 1\n0 0 0 0.5\n")
w("view-no-angle.nff", "v\nfrom 0 0 5\nat 0 0 0\nup 0 1 0\nresolution 64 48\ns 0 0 0 1\n")
w("binary-garbage.nff", bytes(range(256)))
# PLY
w("empty.ply", "")
w("not-ply.ply", "solid cube\nendsolid\n")
w("truncated-header.ply", mc.ply("ascii")[:40])
w("truncated-binary.ply", mc.ply("binary_little_endian")[:-7])
w("count-over-limit.ply", "ply\nformat binary_little_endian 1.0\nelement vertex 4000000000\nproperty float x\n"
  "property float y\nproperty float z\nend_header\n" + "\0" * 12)
w("face-out-of-range.ply", mc.ply("ascii").replace(b"3 0 2 3", b"3 0 2 30"))
w("unknown-format.ply", mc.ply("ascii").replace(b"format ascii", b"format utf8"))
