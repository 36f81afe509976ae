#!/usr/bin/env python3
"""Generates `heavy`: a procedural scene of about one million triangles for performance
work (standard library only; nothing is checked in). A rolling heightfield of 707 x 707
quads (999,698 triangles) with analytic normals, a few mirror and glass spheres (as
meshes) on it, a directional sun and a camera looking across it.

Usage: python3 scenes/make_heavy.py [OUT_DIR] [--size N]
Writes OUT_DIR/heavy.gltf and OUT_DIR/heavy.bin (default OUT_DIR: build/scenes).
"""
import array
import json
import math
import os
import sys


def height(x, z):
    return 0.6 * math.sin(0.35 * x) * math.cos(0.3 * z) + 0.25 * math.sin(1.3 * x + 0.7 * z) + 0.08 * math.cos(3.1 * x - 2.3 * z)


def slope(x, z):  # d(height)/dx, d(height)/dz
    dx = 0.6 * 0.35 * math.cos(0.35 * x) * math.cos(0.3 * z) + 0.25 * 1.3 * math.cos(1.3 * x + 0.7 * z) - 0.08 * 3.1 * math.sin(3.1 * x - 2.3 * z)
    dz = -0.6 * 0.3 * math.sin(0.35 * x) * math.sin(0.3 * z) + 0.25 * 0.7 * math.cos(1.3 * x + 0.7 * z) + 0.08 * 2.3 * math.sin(3.1 * x - 2.3 * z)
    return dx, dz


def main():
    out = "build/scenes"
    n = 707
    args = sys.argv[1:]
    animated = False  # --animated: the chrome sphere rolls 3 units over 2 s (heavy-animated.gltf)
    while args:
        a = args.pop(0)
        if a == "--size":
            n = int(args.pop(0))
        elif a == "--animated":
            animated = True
        else:
            out = a
    os.makedirs(out, exist_ok=True)
    extent = 40.0
    pos, nrm, idx = array.array("f"), array.array("f"), array.array("I")
    for j in range(n + 1):
        z = -extent / 2 + extent * j / n
        for i in range(n + 1):
            x = -extent / 2 + extent * i / n
            pos.extend((x, height(x, z), z))
            dx, dz = slope(x, z)
            l = math.sqrt(dx * dx + 1 + dz * dz)
            nrm.extend((-dx / l, 1 / l, -dz / l))
    for j in range(n):
        for i in range(n):
            a = j * (n + 1) + i
            b, c, d = a + 1, a + n + 1, a + n + 2
            idx.extend((a, c, b, b, c, d))  # counter-clockwise seen from above
    # A UV sphere mesh reused by three nodes.
    sp_pos, sp_nrm, sp_idx = array.array("f"), array.array("f"), array.array("I")
    seg, rings = 64, 32
    for r in range(rings + 1):
        th = math.pi * r / rings
        for s in range(seg + 1):
            ph = 2 * math.pi * s / seg
            v = (math.sin(th) * math.cos(ph), math.cos(th), -math.sin(th) * math.sin(ph))
            sp_pos.extend(v)
            sp_nrm.extend(v)
    for r in range(rings):
        for s in range(seg):
            a, b = r * (seg + 1) + s, (r + 1) * (seg + 1) + s
            if r > 0:
                sp_idx.extend((a, b, a + 1))
            if r < rings - 1:
                sp_idx.extend((a + 1, b, b + 1))

    blob = bytearray()
    views, accessors = [], []

    def add(arr, comps, ctype, target, minmax=False):
        while len(blob) % 4:
            blob.append(0)
        data = arr.tobytes()
        views.append({"buffer": 0, "byteOffset": len(blob), "byteLength": len(data), "target": target})
        blob.extend(data)
        acc = {"bufferView": len(views) - 1, "componentType": ctype, "count": len(arr) // comps,
               "type": {1: "SCALAR", 3: "VEC3"}[comps]}
        if target is None:
            del views[-1]["target"]
        if minmax:
            acc["min"] = [min(arr[k::comps]) for k in range(comps)]
            acc["max"] = [max(arr[k::comps]) for k in range(comps)]
        accessors.append(acc)
        return len(accessors) - 1

    terrain = {"attributes": {"POSITION": add(pos, 3, 5126, 34962, True), "NORMAL": add(nrm, 3, 5126, 34962)},
               "indices": add(idx, 1, 5125, 34963), "material": 0}
    sphere = {"attributes": {"POSITION": add(sp_pos, 3, 5126, 34962, True), "NORMAL": add(sp_nrm, 3, 5126, 34962)},
              "indices": add(sp_idx, 1, 5125, 34963)}
    spheres = [(-2.0, -4.0, 1.0), (1.5, -6.0, 1.2), (4.0, -3.0, 0.8)]
    animations = []
    if animated:  # node 1 (sphere0) moves; the million-triangle terrain does not
        x, z, r = spheres[0]
        y = height(x, z) + r * 0.9
        times = add(array.array("f", [0, 2]), 1, 5126, None, True)
        path = add(array.array("f", [x, y, z, x + 3, y, z]), 3, 5126, None)
        animations = [{"name": "roll", "samplers": [{"input": times, "output": path}],
                       "channels": [{"sampler": 0, "target": {"node": 1, "path": "translation"}}]}]
    name = "heavy-animated" if animated else "heavy"
    with open(os.path.join(out, name + ".bin"), "wb") as f:
        f.write(blob)
    materials = [
        {"name": "ground", "pbrMetallicRoughness": {"baseColorFactor": [0.45, 0.5, 0.35, 1], "metallicFactor": 0, "roughnessFactor": 1}},
        {"name": "chrome", "pbrMetallicRoughness": {"baseColorFactor": [0.9, 0.9, 0.9, 1], "metallicFactor": 1, "roughnessFactor": 0}},
        {"name": "glass", "pbrMetallicRoughness": {"metallicFactor": 0, "roughnessFactor": 0},
         "extensions": {"KHR_materials_transmission": {"transmissionFactor": 1}, "KHR_materials_ior": {"ior": 1.5}}},
        {"name": "copper", "pbrMetallicRoughness": {"baseColorFactor": [0.95, 0.64, 0.54, 1], "metallicFactor": 1, "roughnessFactor": 0.35}}]
    meshes = [{"name": "terrain", "primitives": [terrain]}]
    nodes = [{"name": "terrain", "mesh": 0}]
    for k, (x, z, r) in enumerate(spheres):
        meshes.append({"name": "sphere%d" % k, "primitives": [dict(sphere, material=1 + k)]})
        nodes.append({"name": "sphere%d" % k, "mesh": len(meshes) - 1,
                      "translation": [x, height(x, z) + r * 0.9, z], "scale": [r, r, r]})
    g = {"asset": {"version": "2.0", "generator": "tessera scenes/make_heavy.py"},
         "extensionsUsed": ["KHR_lights_punctual", "KHR_materials_transmission", "KHR_materials_ior"],
         "extensions": {"KHR_lights_punctual": {"lights": [{"type": "directional", "intensity": 2500, "color": [1, 0.95, 0.9]}]}},
         "scene": 0, "scenes": [{"nodes": list(range(len(nodes) + 2))}],
         "nodes": nodes + [
             {"name": "sun", "rotation": [-0.4, 0.3, 0.1, 0.86], "extensions": {"KHR_lights_punctual": {"light": 0}}},
             {"name": "camera", "camera": 0, "translation": [0, 3.5, 6], "rotation": [-0.17, 0, 0, 0.985]}],
         "cameras": [{"type": "perspective", "perspective": {"yfov": 0.8, "aspectRatio": 1.5, "znear": 0.05, "zfar": 200}}],
         "meshes": meshes, "materials": materials, "accessors": accessors, "bufferViews": views,
         "buffers": [{"byteLength": len(blob), "uri": name + ".bin"}]}
    if animations:
        g["animations"] = animations
    with open(os.path.join(out, name + ".gltf"), "w") as f:
        json.dump(g, f)
    print("%s/%s.gltf: %d triangles" % (out, name, len(idx) // 3 + 3 * (len(sp_idx) // 3)))


if __name__ == "__main__":
    main()
