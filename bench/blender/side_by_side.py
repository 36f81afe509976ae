"""Two EXRs side by side as one sRGB JPEG (run inside Blender, for bench/blender/fidelity.py):
  blender -b --factory-startup --python side_by_side.py -- LEFT.exr RIGHT.exr OUT.jpg
Linear values clamped to [0, 1] and encoded with the sRGB curve (Blender's "Standard" view),
a 2-pixel black gap between the two."""
import sys

import bpy
import numpy as np

left, right, out = sys.argv[sys.argv.index("--") + 1:][:3]
images = [bpy.data.images.load(p) for p in (left, right)]
w, h = images[0].size
px = []
for im in images:
    a = np.empty(w * h * 4, dtype=np.float32)
    im.pixels.foreach_get(a)
    px.append(a.reshape(h, w, 4))
gap = np.zeros((h, 2, 4), dtype=np.float32)
both = np.concatenate([px[0], gap, px[1]], axis=1)
rgb = np.clip(both[..., :3], 0, 1)
srgb = np.where(rgb <= 0.0031308, 12.92 * rgb, 1.055 * np.power(rgb, 1 / 2.4) - 0.055)
both[..., :3] = srgb
both[..., 3] = 1
img = bpy.data.images.new("side-by-side", 2 * w + 2, h, alpha=False)
img.colorspace_settings.name = "Non-Color"  # the values are already sRGB-encoded
img.pixels.foreach_set(both.ravel())
img.filepath_raw = out
img.file_format = "JPEG"
img.save()
print("wrote", out)
