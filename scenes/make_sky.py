#!/usr/bin/env python3
"""Writes scenes/sky.hdr: a small lat-long environment map (Radiance RGBE, standard library
only) for examples and tests of --env: a blue sky brightening toward the horizon, a small
sun of high radiance 35 degrees up, and a darker ground below the horizon.

Layout as CS184's -e (docs/cs184-scene-format.md 7.6): row 0 is straight up (+Y), the
columns run phi = atan2(-z, x) + pi from 0 to 2 pi.

Run: python3 scenes/make_sky.py   (rewrites scenes/sky.hdr)
"""
import math
import os
import struct

W, H = 256, 128
SUN_ELEVATION, SUN_PHI = math.radians(35), math.radians(120)
SUN_RADIUS = math.radians(2.5)
SUN_RADIANCE = (900.0, 820.0, 700.0)


def rgbe(r, g, b):
    m = max(r, g, b)
    if m < 1e-32:
        return bytes((0, 0, 0, 0))
    mant, e = math.frexp(m)
    f = mant * 256.0 / m
    return bytes((int(r * f), int(g * f), int(b * f), e + 128))


def direction(theta, phi):
    s = math.sin(theta)
    return (s * math.cos(phi - math.pi), math.cos(theta), -s * math.sin(phi - math.pi))


def main():
    sun = direction(math.pi / 2 - SUN_ELEVATION, SUN_PHI)
    out = bytearray(b"#?RADIANCE\nFORMAT=32-bit_rle_rgbe\n\n-Y %d +X %d\n" % (H, W))
    for y in range(H):
        theta = math.pi * (y + 0.5) / H
        for x in range(W):
            phi = 2 * math.pi * (x + 0.5) / W
            d = direction(theta, phi)
            if d[1] > 0:  # sky: deep blue at the zenith, pale at the horizon
                t = d[1] ** 0.5
                c = (0.9 - 0.6 * t, 1.0 - 0.4 * t, 1.2 - 0.1 * t)
            else:  # ground
                c = (0.25, 0.22, 0.18)
            cos_sun = sum(a * b for a, b in zip(d, sun))
            if cos_sun > math.cos(SUN_RADIUS):
                c = SUN_RADIANCE
            out += rgbe(*c)
    with open(os.path.join(os.path.dirname(os.path.abspath(__file__)), "sky.hdr"), "wb") as f:
        f.write(out)


if __name__ == "__main__":
    main()
