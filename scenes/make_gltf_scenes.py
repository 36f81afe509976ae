#!/usr/bin/env python3
"""Writes Tessera's own glTF scenes (standard library only):

  cornell-spheres.gltf  the default scene of cornell-spheres.dae in glTF: same box, colours,
                        light (an emissive quad) and spheres (as fine meshes); its camera is
                        the one CS184 framing gives the .dae at 480x360.
  dof-row.gltf          five spheres in a row receding from the camera over a textured
                        floor, lit by a KHR_lights_punctual point and directional light:
                        for depth of field with -b and -d.
  material-spheres.gltf the glTF material model in rows of spheres, lit only by an
                        environment (render with --env scenes/sky.hdr): gold metal and red
                        plastic at roughness 0, 0.25, 0.5, 0.75, 1; then half-metal, clear
                        rough glass (0.1, 0.3) and absorbing glass (KHR_materials_volume,
                        smooth and rough). bench/cycles/compare_gltf.py renders it in Cycles.
  cornell-animated.gltf the Cornell box with its spheres moving (the glass one LINEAR, the
                        mirror one hopping along a CUBICSPLINE path) and the camera turning
                        (rotation slerp) and dollying in, over 2 s: 48 frames at 24 fps.
  cornell-shapes.gltf   the glTF Cornell box with caustic casters of other shapes than spheres:
                        a glass cube (flat faces, turned 30 degrees) and a mirror torus
                        standing on its rim, as meshes; for the light tracer's figures
                        (bench/cycles/caustics_report.py) beside the spheres.
  skinned-bar.gltf      a square bar on two joints that bends 90 degrees over 2 s (a skin,
                        the weights blended across the middle), over a floor whose corner
                        rises by an animated morph target; lit by the default environment.

Run: python3 scenes/make_gltf_scenes.py   (rewrites the files beside this script)
"""
import base64
import json
import math
import os
import struct
import zlib

HERE = os.path.dirname(os.path.abspath(__file__))


class Builder:
    def __init__(self):
        self.blob = bytearray()
        self.g = {"asset": {"version": "2.0", "generator": "tessera scenes/make_gltf_scenes.py"},
                  "scene": 0, "scenes": [{"nodes": []}], "nodes": [], "meshes": [], "materials": [],
                  "accessors": [], "bufferViews": [], "buffers": []}

    def _view(self, data, target):
        while len(self.blob) % 4:
            self.blob.append(0)
        view = {"buffer": 0, "byteOffset": len(self.blob), "byteLength": len(data)}
        if target:
            view["target"] = target
        self.g["bufferViews"].append(view)
        self.blob += data
        return len(self.g["bufferViews"]) - 1

    def _accessor(self, values, comps, ctype, fmt, target, minmax=False):
        data = struct.pack("<%d%s" % (len(values), fmt), *values)
        acc = {"bufferView": self._view(data, target), "componentType": ctype, "count": len(values) // comps,
               "type": {1: "SCALAR", 2: "VEC2", 3: "VEC3", 4: "VEC4"}[comps]}
        if minmax:
            acc["min"] = [min(values[i::comps]) for i in range(comps)]
            acc["max"] = [max(values[i::comps]) for i in range(comps)]
        self.g["accessors"].append(acc)
        return len(self.g["accessors"]) - 1

    def material(self, m):
        self.g["materials"].append(m)
        return len(self.g["materials"]) - 1

    def mesh(self, name, positions, indices, material, normals=None, uvs=None, translation=None):
        attrs = {"POSITION": self._accessor(positions, 3, 5126, "f", 34962, True)}
        if normals:
            attrs["NORMAL"] = self._accessor(normals, 3, 5126, "f", 34962)
        if uvs:
            attrs["TEXCOORD_0"] = self._accessor(uvs, 2, 5126, "f", 34962)
        big = max(indices) > 65535
        idx = self._accessor(indices, 1, 5125 if big else 5123, "I" if big else "H", 34963)
        self.g["meshes"].append({"name": name, "primitives": [{"attributes": attrs, "indices": idx, "material": material}]})
        node = {"name": name, "mesh": len(self.g["meshes"]) - 1}
        if translation:
            node["translation"] = translation
        return self.node(node)

    def node(self, node):
        self.g["nodes"].append(node)
        self.g["scenes"][0]["nodes"].append(len(self.g["nodes"]) - 1)
        return len(self.g["nodes"]) - 1

    def animate(self, node, path, times, values, interpolation="LINEAR", name="move"):
        """One channel of the animation `name`: values flat, 3 (4 for rotation) per key,
        three times that for CUBICSPLINE (in-tangent, value, out-tangent)."""
        anims = self.g.setdefault("animations", [])
        anim = next((a for a in anims if a["name"] == name), None)
        if anim is None:
            anim = {"name": name, "channels": [], "samplers": []}
            anims.append(anim)
        comps = 4 if path == "rotation" else 3
        anim["samplers"].append({"input": self._accessor(times, 1, 5126, "f", None, True),
                                 "output": self._accessor(values, comps, 5126, "f", None),
                                 "interpolation": interpolation})
        anim["channels"].append({"sampler": len(anim["samplers"]) - 1, "target": {"node": node, "path": path}})

    def write(self, path):
        self.g["buffers"] = [{"byteLength": len(self.blob),
                              "uri": "data:application/octet-stream;base64," + base64.b64encode(bytes(self.blob)).decode()}]
        with open(path, "w") as f:
            json.dump(self.g, f, separators=(",", ":"))
            f.write("\n")


def quad(p0, p1, p2, p3):
    return [c for p in (p0, p1, p2, p3) for c in p], [0, 1, 2, 0, 2, 3]


def uv_sphere(radius, seg=96, rings=48):
    pos, nrm, idx = [], [], []
    for r in range(rings + 1):
        th = math.pi * r / rings
        for s in range(seg + 1):
            ph = 2 * math.pi * s / seg
            n = (math.sin(th) * math.cos(ph), math.cos(th), -math.sin(th) * math.sin(ph))
            nrm += n
            pos += [radius * c for c in n]
    for r in range(rings):
        for s in range(seg):
            a, b = r * (seg + 1) + s, (r + 1) * (seg + 1) + s
            if r > 0:
                idx += [a, b, a + 1]          # counter-clockwise seen from outside
            if r < rings - 1:
                idx += [a + 1, b, b + 1]
    return pos, nrm, idx


def cube(size):
    """An axis-aligned cube centred on the origin, each face its own four vertices (flat normals)."""
    pos, nrm, idx = [], [], []
    h = size / 2
    for axis in range(3):
        for sign in (1, -1):
            n = [0, 0, 0]
            n[axis] = sign
            u, v = [0, 0, 0], [0, 0, 0]
            u[(axis + 1) % 3], v[(axis + 2) % 3] = 1, 1
            base = len(pos) // 3
            for a, b in ((-1, -1), (1, -1), (1, 1), (-1, 1)):
                pos += [h * (n[k] + a * u[k] + b * v[k]) for k in range(3)]
                nrm += n
            # counter-clockwise seen from outside: u x v = n for sign +1
            idx += [base, base + 1, base + 2, base, base + 2, base + 3] if sign > 0 else \
                   [base, base + 2, base + 1, base, base + 3, base + 2]
    return pos, nrm, idx


def torus(major, minor, seg=96, rings=32):
    """A torus about +Z (its hole faces the camera), smooth normals."""
    pos, nrm, idx = [], [], []
    for i in range(seg + 1):
        a = 2 * math.pi * i / seg
        ca, sa = math.cos(a), math.sin(a)
        for j in range(rings + 1):
            b = 2 * math.pi * j / rings
            cb, sb = math.cos(b), math.sin(b)
            n = (ca * cb, sa * cb, sb)
            nrm += n
            pos += [(major + minor * cb) * ca, (major + minor * cb) * sa, minor * sb]
    for i in range(seg):
        for j in range(rings):
            a, b = i * (rings + 1) + j, (i + 1) * (rings + 1) + j
            idx += [a, b, b + 1, a, b + 1, a + 1]
    return pos, nrm, idx


def cornell(animated=False, shapes=False):
    b = Builder()
    # ior 1: a glTF dielectric without its specular coat, i.e. exactly the .dae's Lambertian walls.
    lam = lambda name, c: b.material({"name": name, "pbrMetallicRoughness": {"baseColorFactor": c + [1], "metallicFactor": 0,
                                                                           "roughnessFactor": 1},
                                      "extensions": {"KHR_materials_ior": {"ior": 1.0}}})
    white, red, green = lam("white", [0.73, 0.73, 0.73]), lam("red", [0.63, 0.065, 0.05]), lam("green", [0.14, 0.45, 0.091])
    h = 0.75
    # The same quads as cornell-spheres.dae (winding normals face into the room).
    walls = {"floor": ([-1, -h, -1], [-1, -h, 1], [1, -h, 1], [1, -h, -1], white),
             "ceiling": ([-1, h, -1], [1, h, -1], [1, h, 1], [-1, h, 1], white),
             "backWall": ([-1, -h, -1], [1, -h, -1], [1, h, -1], [-1, h, -1], white),
             "leftWall": ([-1, -h, -1], [-1, h, -1], [-1, h, 1], [-1, -h, 1], red),
             "rightWall": ([1, -h, -1], [1, -h, 1], [1, h, 1], [1, h, -1], green)}
    for name, (p0, p1, p2, p3, m) in walls.items():
        pos, idx = quad(p0, p1, p2, p3)
        b.mesh(name, pos, idx, m)
    light = b.material({"name": "light", "pbrMetallicRoughness": {"baseColorFactor": [0, 0, 0, 1], "metallicFactor": 0},
                        "emissiveFactor": [1, 1, 1], "extensions": {"KHR_materials_emissive_strength": {"emissiveStrength": 12}}})
    # 0.5 x 0.5 at y = 0.74, facing down (one-sided, like the CGL area light).
    pos, idx = quad([-0.25, 0.74, -0.25], [0.25, 0.74, -0.25], [0.25, 0.74, 0.25], [-0.25, 0.74, 0.25])
    b.mesh("light", pos, idx, light)
    mirror = b.material({"name": "mirror",
                         "pbrMetallicRoughness": {"baseColorFactor": [0.95, 0.95, 0.95, 1], "metallicFactor": 1, "roughnessFactor": 0}})
    glass = b.material({"name": "glass", "pbrMetallicRoughness": {"baseColorFactor": [1, 1, 1, 1], "metallicFactor": 0, "roughnessFactor": 0},
                        "extensions": {"KHR_materials_transmission": {"transmissionFactor": 1}, "KHR_materials_ior": {"ior": 1.5},
                                       "KHR_materials_volume": {"thicknessFactor": 0.6}}})  # a solid sphere
    if shapes:
        # A glass cube of side 0.4 just above the floor, turned 30 degrees about +Y, and a mirror
        # torus (radii 0.22 and 0.07) standing on its rim, its hole facing the camera.
        pos, nrm, idx = cube(0.4)
        node = b.mesh("glassCube", pos, idx, glass, nrm, translation=[0.4, -h + 0.201, 0.25])  # (not coplanar with the floor)
        b.g["nodes"][node]["rotation"] = [0, math.sin(math.radians(15)), 0, math.cos(math.radians(15))]
        pos, nrm, idx = torus(0.22, 0.07)
        b.mesh("mirrorTorus", pos, idx, mirror, nrm, translation=[-0.4, -h + 0.29, -0.3])
    else:
        pos, nrm, idx = uv_sphere(0.3) if not animated else uv_sphere(0.3, 64, 32)
        mirror_node = b.mesh("mirrorSphere", pos, idx, mirror, nrm, translation=[-0.42, -0.449, -0.3])
        glass_node = b.mesh("glassSphere", pos, idx, glass, nrm, translation=[0.42, -0.449, 0.3])
    # CS184 framing of the .dae at 480x360: eye 1.5 box diagonals from the centre, and the
    # 800x600 view's pixel pitch (tan(vfov/2) = 360 / (2 * 875)).
    d = 1.5 * math.sqrt(4 + 2.25 + 4)
    b.g["cameras"] = [{"type": "perspective", "perspective": {"yfov": 2 * math.atan(360 / 1750), "aspectRatio": 4 / 3,
                                                               "znear": 0.01, "zfar": 100}}]
    camera_node = b.node({"name": "camera", "camera": 0, "translation": [0, 0, d]})
    b.g["extensionsUsed"] = ["KHR_materials_emissive_strength", "KHR_materials_transmission", "KHR_materials_ior",
                             "KHR_materials_volume"]
    if not animated:
        b.write(os.path.join(HERE, "cornell-shapes.gltf" if shapes else "cornell-spheres.gltf"))
        return
    # The glass sphere rolls to the back left (LINEAR), the mirror sphere hops forward and
    # right (CUBICSPLINE: zero tangents at the ends, an upward out-tangent for the hop), and
    # the camera turns 20 degrees about +Y (slerp) while dollying in.
    b.animate(glass_node, "translation", [0, 2], [0.42, -0.449, 0.3, -0.3, -0.449, -0.45])
    b.animate(mirror_node, "translation", [0, 1, 2],
              [0, 0, 0, -0.42, -0.449, -0.3, 0, 1.2, 0,
               0, 0, 0, 0.0, 0.2, 0.0, 0, 0, 0,
               0, -1.2, 0, 0.45, -0.449, 0.35, 0, 0, 0], "CUBICSPLINE")
    half = math.radians(20) / 2
    b.animate(camera_node, "rotation", [0, 2], [0, 0, 0, 1, 0, math.sin(half), 0, math.cos(half)])
    b.animate(camera_node, "translation", [0, 2],
              [0, 0, d, d * 0.8 * math.sin(2 * half), 0, d * 0.8 * math.cos(2 * half)])
    b.write(os.path.join(HERE, "cornell-animated.gltf"))


def checker_png(n=8, cell=16):
    size = n * cell
    rows = b""
    for y in range(size):
        row = bytearray([0])
        for x in range(size):
            v = 200 if ((x // cell) + (y // cell)) % 2 == 0 else 60
            row += bytes([v, v, v])
        rows += bytes(row)
    chunk = lambda t, d: struct.pack(">I", len(d)) + t + d + struct.pack(">I", zlib.crc32(t + d) & 0xFFFFFFFF)
    return (b"\x89PNG\r\n\x1a\n" + chunk(b"IHDR", struct.pack(">IIBBBBB", size, size, 8, 2, 0, 0, 0)) +
            chunk(b"IDAT", zlib.compress(rows, 9)) + chunk(b"IEND", b""))


def dof_row():
    b = Builder()
    b.g["images"] = [{"uri": "data:image/png;base64," + base64.b64encode(checker_png()).decode()}]
    b.g["samplers"] = [{"wrapS": 10497, "wrapT": 10497}]
    b.g["textures"] = [{"source": 0, "sampler": 0}]
    floor = b.material({"pbrMetallicRoughness": {"baseColorFactor": [1, 1, 1, 1], "baseColorTexture": {"index": 0},
                                                 "metallicFactor": 0, "roughnessFactor": 1}})
    # A 40 x 40 floor with the checker repeated 10 times (uv 0..10).
    pos, idx = quad([-20, 0, -30], [-20, 0, 10], [20, 0, 10], [20, 0, -30])
    b.mesh("floor", pos, idx, floor, [0, 1, 0] * 4, [0, 0, 0, 10, 10, 10, 10, 0])
    colours = [[0.8, 0.1, 0.1], [0.9, 0.6, 0.1], [0.2, 0.7, 0.2], [0.1, 0.3, 0.8], [0.6, 0.2, 0.7]]
    pos, nrm, idx = uv_sphere(0.5, 64, 32)
    for i, c in enumerate(colours):
        m = b.material({"pbrMetallicRoughness": {"baseColorFactor": c + [1], "metallicFactor": 0, "roughnessFactor": 1}})
        b.mesh("sphere%d" % i, pos, idx, m, nrm, translation=[-1.5 + 0.9 * i, 0.5, 2 - 3 * i])  # z 2, -1, -4, -7, -10
    gold = b.material({"pbrMetallicRoughness": {"baseColorFactor": [1.0, 0.8, 0.4, 1], "metallicFactor": 1, "roughnessFactor": 0.3}})
    b.mesh("goldSphere", pos, idx, gold, nrm, translation=[1.6, 0.5, -2.5])
    b.g["extensionsUsed"] = ["KHR_lights_punctual"]
    b.g["extensions"] = {"KHR_lights_punctual": {"lights": [
        {"type": "directional", "color": [1.0, 0.95, 0.85], "intensity": 1500},       # lux
        {"type": "point", "color": [1, 1, 1], "intensity": 8000}]}}                  # candela
    b.node({"name": "sun", "rotation": [-0.3826834, 0.2, 0, 0.9238795], "extensions": {"KHR_lights_punctual": {"light": 0}}})
    b.node({"name": "lamp", "translation": [0, 6, 0], "extensions": {"KHR_lights_punctual": {"light": 1}}})
    b.g["cameras"] = [{"type": "perspective", "perspective": {"yfov": 0.6, "aspectRatio": 1.5, "znear": 0.05, "zfar": 100}}]
    # Eye at (0, 1.2, 6) looking down -z, tilted slightly toward the floor.
    b.node({"name": "camera", "camera": 0, "translation": [0, 1.2, 6], "rotation": [-0.0499792, 0, 0, 0.9987503]})
    b.write(os.path.join(HERE, "dof-row.gltf"))


# Material spheres: row y of the grid, column x; radius 0.4, 1 apart, camera on +z.
SPHERE_SPACING, SPHERE_RADIUS = 1.0, 0.4


def material_spheres():
    b = Builder()
    pos, nrm, idx = uv_sphere(SPHERE_RADIUS, 96, 48)
    roughness = [0, 0.25, 0.5, 0.75, 1]
    gold, red = [1.0, 0.78, 0.34, 1], [0.8, 0.1, 0.1, 1]
    volume = {"thicknessFactor": 0.8}
    absorbing = {"thicknessFactor": 0.8, "attenuationColor": [0.9, 0.5, 0.3], "attenuationDistance": 0.4}
    glass = lambda r, v: {"pbrMetallicRoughness": {"baseColorFactor": [1, 1, 1, 1], "metallicFactor": 0, "roughnessFactor": r},
                          "extensions": {"KHR_materials_transmission": {"transmissionFactor": 1},
                                         "KHR_materials_volume": v}}
    rows = [
        [("metal r%g" % r, {"pbrMetallicRoughness": {"baseColorFactor": gold, "metallicFactor": 1, "roughnessFactor": r}})
         for r in roughness],
        [("plastic r%g" % r, {"pbrMetallicRoughness": {"baseColorFactor": red, "metallicFactor": 0, "roughnessFactor": r}})
         for r in roughness],
        [("half-metal r0.4", {"pbrMetallicRoughness": {"baseColorFactor": gold, "metallicFactor": 0.5, "roughnessFactor": 0.4}}),
         ("glass r0.1", glass(0.1, volume)), ("glass r0.3", glass(0.3, volume)),
         ("absorbing glass r0", glass(0, absorbing)), ("absorbing glass r0.2", glass(0.2, absorbing))],
    ]
    # One sphere's accessors, shared by every sphere's mesh (a mesh per material).
    attrs = {"POSITION": b._accessor(pos, 3, 5126, "f", 34962, True), "NORMAL": b._accessor(nrm, 3, 5126, "f", 34962)}
    indices = b._accessor(idx, 1, 5123, "H", 34963)
    for y, row in enumerate(rows):
        for x, (name, mat) in enumerate(row):
            mat["name"] = name
            b.g["meshes"].append({"name": name, "primitives": [{"attributes": attrs, "indices": indices,
                                                                "material": b.material(mat)}]})
            b.node({"name": name, "mesh": len(b.g["meshes"]) - 1,
                    "translation": [(x - 2) * SPHERE_SPACING, (1 - y) * SPHERE_SPACING, 0]})
    b.g["cameras"] = [{"type": "perspective", "perspective": {"yfov": 0.5, "aspectRatio": 4 / 3, "znear": 0.05, "zfar": 100}}]
    b.node({"name": "camera", "camera": 0, "translation": [0, 0, 7.5]})
    b.g["extensionsUsed"] = ["KHR_materials_transmission", "KHR_materials_volume"]
    b.write(os.path.join(HERE, "material-spheres.gltf"))


def skinned_bar():
    b = Builder()
    grey = b.material({"name": "grey", "pbrMetallicRoughness": {"baseColorFactor": [0.6, 0.6, 0.6, 1], "metallicFactor": 0}})
    orange = b.material({"name": "orange", "pbrMetallicRoughness": {"baseColorFactor": [0.9, 0.4, 0.1, 1],
                                                                     "metallicFactor": 0, "roughnessFactor": 0.5}})
    # The bar: 9 rings of 4 vertices along x in [0, 2], a 0.2 x 0.2 section.
    pos, joints, weights, idx = [], [], [], []
    rings = 9
    for r in range(rings):
        x = 2 * r / (rings - 1)
        t = min(max((x - 0.75) / 0.5, 0), 1)
        w1 = t * t * (3 - 2 * t)  # smoothstep across the joint at x = 1
        for y, z in ((-0.1, -0.1), (0.1, -0.1), (0.1, 0.1), (-0.1, 0.1)):
            pos += [x, y, z]
            joints += [0, 1, 0, 0]
            weights += [1 - w1, w1, 0, 0]
    for r in range(rings - 1):
        for k in range(4):
            a, bb = 4 * r + k, 4 * r + (k + 1) % 4
            idx += [a, bb, bb + 4, a, bb + 4, a + 4]
    attrs = {"POSITION": b._accessor(pos, 3, 5126, "f", 34962, True),
             "JOINTS_0": b._accessor(joints, 4, 5121, "B", 34962),
             "WEIGHTS_0": b._accessor(weights, 4, 5126, "f", 34962)}
    ibm = [1, 0, 0, 0, 0, 1, 0, 0, 0, 0, 1, 0, 0, 0, 0, 1,
           1, 0, 0, 0, 0, 1, 0, 0, 0, 0, 1, 0, -1, 0, 0, 1]  # column-major: identity, translate(-1, 0, 0)
    b.g["accessors"].append({"bufferView": b._view(struct.pack("<32f", *ibm), None), "componentType": 5126,
                             "count": 2, "type": "MAT4"})
    ibm_acc = len(b.g["accessors"]) - 1
    b.g["meshes"].append({"name": "bar", "primitives": [{"attributes": attrs, "material": orange,
                                                         "indices": b._accessor(idx, 1, 5123, "H", 34963)}]})
    bar = b.node({"name": "bar", "mesh": len(b.g["meshes"]) - 1, "skin": 0})
    root = b.node({"name": "root", "translation": [0, 0.3, 0], "children": [len(b.g["nodes"]) + 1]})
    b.g["nodes"].append({"name": "elbow", "translation": [1, 0, 0]})
    elbow = len(b.g["nodes"]) - 1
    b.g["skins"] = [{"joints": [root, elbow], "inverseBindMatrices": ibm_acc}]
    # The floor, with a morph target lifting its far right corner by 0.5.
    fpos, fidx = quad([-1.5, 0, 1.5], [2.5, 0, 1.5], [2.5, 0, -1.5], [-1.5, 0, -1.5])
    lift = b._accessor([0, 0, 0, 0, 0, 0, 0, 0.5, 0, 0, 0, 0], 3, 5126, "f", None, True)
    b.g["meshes"].append({"name": "floor", "weights": [0],
                          "primitives": [{"attributes": {"POSITION": b._accessor(fpos, 3, 5126, "f", 34962, True)},
                                          "indices": b._accessor(fidx, 1, 5123, "H", 34963), "material": grey,
                                          "targets": [{"POSITION": lift}]}]})
    floor = b.node({"name": "floor", "mesh": len(b.g["meshes"]) - 1})
    half = math.radians(90) / 2
    b.animate(elbow, "rotation", [0, 2], [0, 0, 0, 1, 0, 0, math.sin(half), math.cos(half)], name="bend")
    anim = b.g["animations"][0]
    anim["samplers"].append({"input": b._accessor([0, 2], 1, 5126, "f", None, True),
                             "output": b._accessor([0, 1], 1, 5126, "f", None), "interpolation": "LINEAR"})
    anim["channels"].append({"sampler": len(anim["samplers"]) - 1, "target": {"node": floor, "path": "weights"}})
    b.g["cameras"] = [{"type": "perspective", "perspective": {"yfov": 0.7, "aspectRatio": 4 / 3, "znear": 0.05, "zfar": 100}}]
    b.node({"name": "camera", "camera": 0, "translation": [1, 0.8, 4.5]})
    del bar
    b.write(os.path.join(HERE, "skinned-bar.gltf"))


if __name__ == "__main__":
    material_spheres()
    cornell()
    cornell(animated=True)
    cornell(shapes=True)
    dof_row()
    skinned_bar()
