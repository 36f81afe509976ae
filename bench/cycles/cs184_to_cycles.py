"""Builds the Cycles equivalent of a CS184 COLLADA scene and renders it.

Run inside Blender 3.4 (Debian's):
  blender -b --factory-startup --python bench/cycles/cs184_to_cycles.py -- SCENE.dae OUT.exr
      [--spp N] [--seed S] [--threads 2] [--max-bounces 16] [--width 480] [--height 360] [--stats F]

Blender's COLLADA importer drops the CGL spheres, lights and materials, so this reads the
file itself, with Tessera's semantics (docs/cs184-compat.md): Z_UP/Y_UP, node matrices,
polylists and triangles (smooth shaded, as CS184's vertex normals), CGL spheres (as
256x128 smooth UV spheres), the CGL area light
as a one-sided emissive rectangle of radiance `color`, diffuse / mirror (sharp glossy) /
glass (sharp, same ior) / refraction materials, and CS184's camera framing and field of
view. Cycles: Standard view transform, 1 px box filter, no denoising, no clamping, no
adaptive sampling, caustics on, the same max bounces, CPU with a fixed thread count.
"""
import math
import os
import sys
import xml.etree.ElementTree as ET

import bpy
from mathutils import Matrix, Vector

sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))
import cycles_common  # noqa: E402

NS = "{http://www.collada.org/2005/11/COLLADASchema}"


def nums(el):
    return [float(x) for x in el.text.split()]


class Collada:
    def __init__(self, path):
        root = ET.parse(path).getroot()
        self.ids = {e.get("id"): e for e in root.iter() if e.get("id")}
        up = root.find(NS + "asset/" + NS + "up_axis")
        up = up.text.strip() if up is not None else "Y_UP"
        self.G = {"Y_UP": Matrix.Identity(4),
                  "Z_UP": Matrix(((-1, 0, 0, 0), (0, 0, 1, 0), (0, 1, 0, 0), (0, 0, 0, 1))),
                  "X_UP": Matrix(((0, 1, 0, 0), (1, 0, 0, 0), (0, 0, -1, 0), (0, 0, 0, 1)))}[up]
        self.meshes, self.spheres, self.rects, self.camera = [], [], [], None
        vs = self.ref(root.find(NS + "scene/" + NS + "instance_visual_scene").get("url"))
        for node in vs.findall(NS + "node"):
            self.node(node, self.G)

    def ref(self, url):
        return self.ids[url[1:]]

    def local(self, node):
        m = Matrix.Identity(4)
        for e in node:
            tag = e.tag.replace(NS, "")
            if tag == "matrix":
                v = nums(e) + [0.0] * 16
                return Matrix([v[0:4], v[4:8], v[8:12], v[12:16]])
            if tag == "translate":
                m = m @ Matrix.Translation(Vector(nums(e)))
            elif tag == "scale":
                s = nums(e)
                m = m @ Matrix.Diagonal((s[0], s[1], s[2], 1))
            elif tag == "rotate":
                v = nums(e)
                m = m @ Matrix.Rotation(math.radians(v[3]), 4, Vector(v[:3]))
        return m

    def node(self, node, parent):
        w = parent @ self.local(node)
        for c in node.findall(NS + "node"):
            self.node(c, w)
        cam, light, geom = (node.find(NS + t) for t in ("instance_camera", "instance_light", "instance_geometry"))
        if cam is not None:
            self.camera = (self.ref(cam.get("url")), w)
        elif light is not None:
            el = self.ref(light.get("url"))
            cgl = el.find(NS + "extra/" + NS + "technique[@profile='CGL']")
            tech = cgl if cgl is not None else el.find(NS + "technique_common")
            kind = list(tech)[0]
            if kind.tag == NS + "area":
                color = nums(kind.find(NS + "color"))[:3]
                p = (w @ Vector((0, 0, 0, 1))).xyz
                ex = (w @ Vector((-1, 0, 0, 0))).xyz
                ey = (w @ Vector((0, 1, 0, 0))).xyz
                facing = (w @ Vector((0, 0, -1, 0))).xyz
                self.rects.append((p, ex, ey, facing, color))
            else:
                print("cs184_to_cycles: light <%s> not converted" % kind.tag.replace(NS, ""), file=sys.stderr)
        elif geom is not None:
            g = self.ref(geom.get("url"))
            im = geom.find(".//" + NS + "instance_material")
            mat = self.material(self.ref(im.get("target")) if im is not None else None)
            mesh = g.find(NS + "mesh")
            if mesh is not None:
                self.meshes.append((self.mesh(mesh, w), mat, node.get("id")))
            else:
                r = float(g.find(".//" + NS + "sphere/" + NS + "radius").text)
                c = (w @ Vector((0, 0, 0, 1))).xyz
                self.spheres.append((c, r * (w @ Vector((1, 0, 0, 0))).xyz.length, mat, node.get("id")))

    def mesh(self, mesh, w):
        pos_src = self.ref(mesh.find(NS + "vertices/" + NS + "input[@semantic='POSITION']").get("source"))
        p = nums(pos_src.find(NS + "float_array"))
        verts = [(w @ Vector((p[i], p[i + 1], p[i + 2], 1))).xyz for i in range(0, len(p), 3)]
        faces = []
        for prim in mesh:
            tag = prim.tag.replace(NS, "")
            if tag not in ("polylist", "triangles"):
                continue
            inputs = prim.findall(NS + "input")
            stride = max(int(i.get("offset")) for i in inputs) + 1
            voff = int([i for i in inputs if i.get("semantic") == "VERTEX"][0].get("offset"))
            idx = [int(x) for x in prim.find(NS + "p").text.split()]
            counts = [int(x) for x in prim.find(NS + "vcount").text.split()] if tag == "polylist" else [3] * (len(idx) // (3 * stride))
            at = 0
            for n in counts:
                poly = [idx[at + k * stride + voff] for k in range(n)]
                for k in range(1, n - 1):
                    faces.append((poly[0], poly[k], poly[k + 1]))
                at += n * stride
        return verts, faces

    def material(self, mat):
        if mat is None:
            return ("diffuse", (0.5, 0.5, 0.5))
        eff = self.ref(mat.find(NS + "instance_effect").get("url"))
        cgl = None
        for extra in eff.findall(NS + "extra"):
            cgl = extra.find(NS + "technique[@profile='CGL']")
            if cgl is not None:
                break
        if cgl is not None:
            kind = list(cgl)[-1]
            t = kind.tag.replace(NS, "")
            get = lambda k: nums(kind.find(NS + k))
            if t == "mirror":
                return ("mirror", get("reflectance")[:3])
            if t == "glass":
                return ("glass", get("transmittance")[:3], get("ior")[0])
            if t == "refraction":
                return ("refraction", get("transmittance")[:3], get("ior")[0])
            if t == "emission":
                return ("emission", get("radiance")[:3])
            if t == "microfacet":
                return ("microfacet", get("alpha")[0], get("eta")[:3], get("k")[:3])
        for shading in ("phong", "lambert", "blinn"):
            c = eff.find(".//" + NS + shading + "/" + NS + "diffuse/" + NS + "color")
            if c is not None:
                return ("diffuse", nums(c)[:3])
        return ("diffuse", (0.5, 0.5, 0.5))


def to_blender(v):  # our +Y-up world to Blender's +Z-up
    return Vector((v.x, -v.z, v.y))


def node_material(name, spec):
    m = bpy.data.materials.new(name)
    m.use_nodes = True
    nt = m.node_tree
    nt.nodes.clear()
    out = nt.nodes.new("ShaderNodeOutputMaterial")
    kind = spec[0]
    if kind == "diffuse":
        s = nt.nodes.new("ShaderNodeBsdfDiffuse")
        s.inputs["Color"].default_value = (*spec[1], 1)
        s.inputs["Roughness"].default_value = 0
    elif kind == "mirror":
        s = nt.nodes.new("ShaderNodeBsdfGlossy")
        s.distribution = "SHARP"
        s.inputs["Color"].default_value = (*spec[1], 1)
    elif kind in ("glass", "refraction"):
        s = nt.nodes.new("ShaderNodeBsdfGlass" if kind == "glass" else "ShaderNodeBsdfRefraction")
        s.distribution = "SHARP"
        s.inputs["Color"].default_value = (*spec[1], 1)
        s.inputs["IOR"].default_value = spec[2]
    elif kind == "emission":
        s = nt.nodes.new("ShaderNodeEmission")
        s.inputs["Color"].default_value = (*spec[1], 1)
        s.inputs["Strength"].default_value = 1
    else:  # microfacet: Beckmann glossy tinted by the normal-incidence conductor Fresnel
        s = nt.nodes.new("ShaderNodeBsdfGlossy")
        s.distribution = "BECKMANN"
        s.inputs["Roughness"].default_value = math.sqrt(spec[1])  # Cycles squares it
        f0 = [((n - 1) ** 2 + k * k) / ((n + 1) ** 2 + k * k) for n, k in zip(spec[2], spec[3])]
        s.inputs["Color"].default_value = (*f0, 1)
    nt.links.new(s.outputs[0], out.inputs["Surface"])
    return m


def one_sided_emitter(color):
    # Radiance `color` from the front face; black and opaque from behind (as Tessera).
    m = bpy.data.materials.new("area-light")
    m.use_nodes = True
    nt = m.node_tree
    nt.nodes.clear()
    out = nt.nodes.new("ShaderNodeOutputMaterial")
    em = nt.nodes.new("ShaderNodeEmission")
    em.inputs["Color"].default_value = (*color, 1)
    em.inputs["Strength"].default_value = 1
    black = nt.nodes.new("ShaderNodeBsdfDiffuse")
    black.inputs["Color"].default_value = (0, 0, 0, 1)
    geo = nt.nodes.new("ShaderNodeNewGeometry")
    mix = nt.nodes.new("ShaderNodeMixShader")
    nt.links.new(geo.outputs["Backfacing"], mix.inputs["Fac"])
    nt.links.new(em.outputs[0], mix.inputs[1])
    nt.links.new(black.outputs[0], mix.inputs[2])
    nt.links.new(mix.outputs[0], out.inputs["Surface"])
    return m


def add_object(name, verts, faces, material, smooth=False):
    me = bpy.data.meshes.new(name)
    me.from_pydata([to_blender(v) for v in verts], [], faces)
    me.update()
    if smooth:
        for p in me.polygons:
            p.use_smooth = True
    ob = bpy.data.objects.new(name, me)
    ob.data.materials.append(material)
    bpy.context.scene.collection.objects.link(ob)
    return ob


def main():
    o = cycles_common.parse_args(cycles_common.DEFAULTS)
    bpy.ops.wm.read_factory_settings(use_empty=True)
    scene = bpy.context.scene
    c = Collada(o["scene"])
    lo, hi = Vector((1e30,) * 3), Vector((-1e30,) * 3)
    for (verts, faces), spec, name in c.meshes:
        # CS184 shades meshes with area-weighted vertex normals: smooth shading.
        add_object(name, verts, faces, node_material(name, spec), smooth=True)
        for f in faces:
            for i in f:
                lo = Vector(map(min, lo, verts[i]))
                hi = Vector(map(max, hi, verts[i]))
    for center, r, spec, name in c.spheres:
        bpy.ops.mesh.primitive_uv_sphere_add(segments=256, ring_count=128, radius=r, location=to_blender(center))
        ob = bpy.context.active_object
        bpy.ops.object.shade_smooth()
        ob.data.materials.append(node_material(name, spec))
        lo = Vector(map(min, lo, center - Vector((r, r, r))))
        hi = Vector(map(max, hi, center + Vector((r, r, r))))
    for p, ex, ey, facing, color in c.rects:
        hx, hy = ex / 2, ey / 2
        quad = [p - hx - hy, p + hx - hy, p + hx + hy, p - hx + hy]
        face = (0, 1, 2, 3) if ex.cross(ey).dot(facing) >= 0 else (0, 3, 2, 1)
        add_object("area-light", quad, [face], one_sided_emitter(color))

    # CS184 framing (format doc 2.2 and 2.3), as core/camera/camera.cc.
    cam_el, w = c.camera
    persp = cam_el.find(".//" + NS + "perspective")
    get = lambda k, d=None: float(persp.find(NS + k).text) if persp.find(NS + k) is not None else d
    xfov = get("xfov", 50.0)
    tx = math.tan(math.radians(xfov) / 2)
    ty = math.tan(math.radians(get("yfov")) / 2) if get("yfov") else tx / get("aspect_ratio", 4 / 3)
    if tx / ty < 4 / 3:
        tx = ty * 4 / 3
    if tx / ty > 4 / 3:
        ty = tx * 3 / 4
    tan_v = o["height"] / (2 * 600 / (2 * ty))
    d = (w @ Vector((0, 0, -1, 1))).xyz.normalized()
    target = (lo + hi) / 2
    eye = target + d * 1.5 * (hi - lo).length
    z = (eye - target).normalized()
    x = Vector((0, 1, 0)).cross(z).normalized()
    y = z.cross(x).normalized()
    cam_data = bpy.data.cameras.new("camera")
    cam_data.sensor_fit = "VERTICAL"
    cam_data.angle_y = 2 * math.atan(tan_v)
    cam_data.clip_start, cam_data.clip_end = 1e-3, 1e4
    cam = bpy.data.objects.new("camera", cam_data)
    bx, by, bz, be = to_blender(x), to_blender(y), to_blender(z), to_blender(eye)
    cam.matrix_world = Matrix(((bx.x, by.x, bz.x, be.x), (bx.y, by.y, bz.y, be.y), (bx.z, by.z, bz.z, be.z), (0, 0, 0, 1)))
    scene.collection.objects.link(cam)
    scene.camera = cam

    world = bpy.data.worlds.new("black")
    world.use_nodes = True
    world.node_tree.nodes["Background"].inputs["Strength"].default_value = 0
    scene.world = world
    cycles_common.configure(scene, o)
    cycles_common.render(scene, o, "cs184_to_cycles")


main()
