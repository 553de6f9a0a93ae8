#!/usr/bin/env python3
"""Writes the project's own CAD parts into workpieces/: meshes drawn here from nominal package
dimensions (no model is copied from any library), in the formats engineers receive them.

  hex-standoff.stl      binary STL, mm: a 14 mm across-flats hex standoff, 20 mm long, 6.8 mm bore
  to220.wrl             VRML 2.0 as KiCad's 3D library writes it (units of 0.1 inch): a TO-220
                        transistor, body, tab with its 3.6 mm hole, three leads (one lead mesh
                        placed three times by Transform nodes)
  dip8.wrl              VRML 2.0, KiCad units: a DIP-8 (300 mil), body and eight bent legs
  smd-elcap.obj         OBJ, mm, polygon faces: an SMD aluminium electrolytic, 8 mm can, 10.2 mm
                        tall, on its chamfered 8.3 mm base with two terminals beneath

Each solid is closed and wound outward; separate bodies (leads, legs, terminals) touch the body
without overlapping. Run from the repository root: python3 scripts/make-cad-parts.py
"""

import math
import os
import struct

OUT = os.path.join(os.path.dirname(os.path.abspath(__file__)), "..", "workpieces")
KICAD_UNIT_MM = 2.54


def box(lo, hi):
    """A closed box from corner lo to corner hi, wound outward."""
    v = []
    for i in range(8):
        v.append((hi[0] if i & 1 else lo[0], hi[1] if i & 2 else lo[1], hi[2] if i & 4 else lo[2]))
    t = [(0, 2, 3), (0, 3, 1), (4, 5, 7), (4, 7, 6), (0, 1, 5), (0, 5, 4),
         (2, 6, 7), (2, 7, 3), (0, 4, 6), (0, 6, 2), (1, 3, 7), (1, 7, 5)]
    return v, t


def ray_hit(poly, c, ang):
    """Where the ray from c at angle ang leaves the convex polygon poly (counter-clockwise)."""
    d = (math.cos(ang), math.sin(ang))
    best = None
    for k in range(len(poly)):
        a, b = poly[k], poly[(k + 1) % len(poly)]
        e = (b[0] - a[0], b[1] - a[1])
        den = d[0] * e[1] - d[1] * e[0]
        if abs(den) < 1e-15:
            continue
        w = (a[0] - c[0], a[1] - c[1])
        s = (w[0] * e[1] - w[1] * e[0]) / den
        u = (w[0] * d[1] - w[1] * d[0]) / den
        if s > 0 and -1e-12 <= u <= 1 + 1e-12 and (best is None or s < best):
            best = s
    return (c[0] + best * d[0], c[1] + best * d[1])


def ring_angles(poly, c, n):
    """n uniform angles about c, with the angles of the polygon's corners added."""
    angs = {round(2 * math.pi * k / n, 12) for k in range(n)}
    for p in poly:
        a = math.atan2(p[1] - c[1], p[0] - c[0]) % (2 * math.pi)
        angs.add(round(a, 12))
    out = sorted(angs)
    # Drop angles closer than 0.5 degree to the previous (a corner next to a uniform angle).
    keep = [out[0]]
    for a in out[1:]:
        if a - keep[-1] > math.radians(0.5):
            keep.append(a)
    return keep


def holed_plate(poly, c, r, z0, z1, n=36):
    """A convex polygon plate z0..z1 with a round hole of radius r about c, closed and outward."""
    angs = ring_angles(poly, c, n)
    outer = [ray_hit(poly, c, a) for a in angs]
    inner = [(c[0] + r * math.cos(a), c[1] + r * math.sin(a)) for a in angs]
    m = len(angs)
    v = []
    for z in (z0, z1):
        v += [(p[0], p[1], z) for p in outer]
        v += [(p[0], p[1], z) for p in inner]
    ob, ib, ot, it = 0, m, 2 * m, 3 * m
    t = []
    for k in range(m):
        n_ = (k + 1) % m
        t += [(ot + k, ot + n_, it + n_), (ot + k, it + n_, it + k)]      # top ring, seen from +z
        t += [(ob + k, ib + n_, ob + n_), (ob + k, ib + k, ib + n_)]      # bottom ring
        t += [(ob + k, ob + n_, ot + n_), (ob + k, ot + n_, ot + k)]      # outer wall
        t += [(ib + k, it + n_, ib + n_), (ib + k, it + k, it + n_)]      # bore wall
    return v, t


def prism(poly, z0, z1):
    """A closed prism over a convex counter-clockwise polygon."""
    m = len(poly)
    v = [(p[0], p[1], z0) for p in poly] + [(p[0], p[1], z1) for p in poly]
    t = []
    for k in range(1, m - 1):
        t.append((0, k + 1, k))              # bottom, seen from -z
        t.append((m, m + k, m + k + 1))      # top
    for k in range(m):
        n_ = (k + 1) % m
        t += [(k, n_, m + n_), (k, m + n_, m + k)]
    return v, t


def merge(*bodies):
    v, t = [], []
    for bv, bt in bodies:
        b = len(v)
        v += bv
        t += [(a + b, c + b, d + b) for a, c, d in bt]
    return v, t


def volume(v, t):
    s = 0.0
    for a, b, c in t:
        p, q, r = v[a], v[b], v[c]
        s += (p[0] * (q[1] * r[2] - q[2] * r[1]) - p[1] * (q[0] * r[2] - q[2] * r[0])
              + p[2] * (q[0] * r[1] - q[1] * r[0]))
    return s / 6.0


def check(name, *bodies):
    for i, (v, t) in enumerate(bodies):
        vol = volume(v, t)
        assert vol > 0, f"{name}: body {i} is wound inward ({vol})"


def write_stl_binary(path, v, t, name):
    with open(path, "wb") as f:
        f.write(name.encode().ljust(80, b" ")[:80])
        f.write(struct.pack("<I", len(t)))
        for a, b, c in t:
            p, q, r = v[a], v[b], v[c]
            u = [q[i] - p[i] for i in range(3)]
            w = [r[i] - p[i] for i in range(3)]
            n = [u[1] * w[2] - u[2] * w[1], u[2] * w[0] - u[0] * w[2], u[0] * w[1] - u[1] * w[0]]
            ln = math.sqrt(sum(x * x for x in n)) or 1.0
            f.write(struct.pack("<3f", *[x / ln for x in n]))
            for pt in (p, q, r):
                f.write(struct.pack("<3f", *pt))
            f.write(b"\0\0")


def vrml_shape(v, t, material, first):
    """A KiCad-style Shape: a material (DEF on first use), an IndexedFaceSet in 0.1 inch."""
    mat = (f"material DEF {material[0]} Material {{\n  ambientIntensity 0.2\n  diffuseColor {material[1]}\n"
           f"  specularColor 0.2 0.2 0.2\n  shininess 0.3\n  transparency 0\n  }}" if first
           else f"material USE {material[0]}")
    idx = ",".join(f"{a},{b},{c},-1" for a, b, c in t)
    pts = ",".join(" ".join(f"{x / KICAD_UNIT_MM:.6f}" for x in p) for p in v)
    return (f"Shape {{ appearance Appearance {{{mat} }}\n"
            f"geometry IndexedFaceSet\n{{ creaseAngle 0.50\ncoordIndex\n[{idx}]\n"
            f"coord Coordinate {{ point [{pts}]\n}}}}\n}}\n")


def hex_standoff():
    af, length, bore = 14.0, 20.0, 6.8 / 2
    r = af / math.sqrt(3)  # corner radius
    hexagon = [(r * math.cos(math.radians(60 * k)), r * math.sin(math.radians(60 * k))) for k in range(6)]
    v, t = holed_plate(hexagon, (0.0, 0.0), bore, 0.0, length, n=36)
    check("hex-standoff", (v, t))
    write_stl_binary(os.path.join(OUT, "hex-standoff.stl"), v, t, "binpick hex standoff 14AF x 20")


def to220():
    # Body 10 x 9 x 4.4 mm, its back at z = 0; the tab 10 x 6.5 x 1.3 mm continues the back
    # above the body (y 9 .. 15.5) with a 3.6 mm hole; three leads 0.8 x 13 x 0.5 mm at 2.54 mm
    # pitch leave the body's lower face at mid-thickness.
    body = box((-5.0, 0.0, 0.0), (5.0, 9.0, 4.4))
    tab = holed_plate([(-5.0, 9.0), (5.0, 9.0), (5.0, 15.5), (-5.0, 15.5)], (0.0, 12.25), 1.8, 0.0, 1.3, n=36)
    lead = box((-0.4, -13.0, -0.25), (0.4, 0.0, 0.25))
    check("to220", body, tab, lead)
    s = "#VRML V2.0 utf8\n#binpick: TO-220, drawn by scripts/make-cad-parts.py (units of 0.1 inch)\n"
    s += vrml_shape(*merge(body), ("BODY-01", "0.1 0.1 0.1"), True)
    s += vrml_shape(*tab, ("TAB-01", "0.82 0.82 0.78"), True)
    # One lead mesh at the origin, placed three times (DEF/USE and Transform, as exporters do).
    for k, x in enumerate((-2.54, 0.0, 2.54)):
        tr = f"{x / KICAD_UNIT_MM:.6f} 0 {2.2 / KICAD_UNIT_MM:.6f}"
        if k == 0:
            inner = vrml_shape(*lead, ("PIN-01", "0.82 0.82 0.78"), True).replace(
                "geometry IndexedFaceSet", "geometry DEF LEAD IndexedFaceSet", 1)
        else:
            inner = "Shape { appearance Appearance {material USE PIN-01 }\ngeometry USE LEAD\n}\n"
        s += f"Transform {{ translation {tr}\nchildren [\n{inner}] }}\n"
    with open(os.path.join(OUT, "to220.wrl"), "w") as f:
        f.write(s)


def dip8():
    # 300 mil DIP-8: body 9.3 x 6.35 x 3.3 mm seated 0.5 mm above the board (z 0.5 .. 3.8); each
    # leg a shoulder out of the body's side (1.2 x 0.8 x 0.25 mm) and a pin down to z = -3.0
    # (0.5 x 0.25 mm), rows 7.62 mm apart, 2.54 mm pitch.
    body = box((-4.65, -3.175, 0.5), (4.65, 3.175, 3.8))
    legs = []
    for side in (-1, 1):
        for x in (-3.81, -1.27, 1.27, 3.81):
            y_in, y_out = 3.175, 3.81 + 0.125
            lo_y, hi_y = (y_in, y_out) if side > 0 else (-y_out, -y_in)
            shoulder = box((x - 0.6, lo_y, 1.6), (x + 0.6, hi_y, 1.85))
            py = (3.81 - 0.125, 3.81 + 0.125) if side > 0 else (-3.81 - 0.125, -3.81 + 0.125)
            pin = box((x - 0.25, py[0], -3.0), (x + 0.25, py[1], 1.6))
            legs += [shoulder, pin]
    check("dip8", body, *legs)
    s = "#VRML V2.0 utf8\n#binpick: DIP-8 300 mil, drawn by scripts/make-cad-parts.py (units of 0.1 inch)\n"
    s += vrml_shape(*body, ("BODY-01", "0.15 0.15 0.15"), True)
    s += vrml_shape(*merge(*legs), ("PIN-01", "0.82 0.82 0.78"), True)
    with open(os.path.join(OUT, "dip8.wrl"), "w") as f:
        f.write(s)


def smd_elcap():
    # Base 8.3 x 8.3 x 1.0 mm (z 0.2 .. 1.2), two corners chamfered 1.0 mm (the + side); the
    # can, 8.0 mm across (32 sides), from the base to z = 10.2, one solid with the base (the
    # base's top is the ring about the can); two terminals 0.9 x 3.25 x 0.2 mm beneath.
    h, ch, rc, n = 4.15, 1.0, 4.0, 32
    base_poly = [(-h + ch, -h), (h, -h), (h, h), (-h + ch, h), (-h, h - ch), (-h, -h + ch)]
    angs = ring_angles(base_poly, (0.0, 0.0), n)
    outer = [ray_hit(base_poly, (0.0, 0.0), a) for a in angs]
    # The can is a regular 32-gon; ring angles that are not its corners lie on its sides.
    def on_can(a):
        k = math.floor(a / (2 * math.pi / n))
        a0, a1 = 2 * math.pi * k / n, 2 * math.pi * (k + 1) / n
        p0 = (rc * math.cos(a0), rc * math.sin(a0))
        p1 = (rc * math.cos(a1), rc * math.sin(a1))
        return ray_hit([(0, 0), p0, p1], (0.0, 0.0), a) if abs(a - a0) > 1e-9 else p0
    inner = [on_can(a) for a in angs]
    m = len(angs)
    z0, z1, z2 = 0.2, 1.2, 10.2
    v = [(p[0], p[1], z0) for p in outer] + [(p[0], p[1], z1) for p in outer]
    v += [(p[0], p[1], z1) for p in inner] + [(p[0], p[1], z2) for p in inner]
    ob, ot, ib, it = 0, m, 2 * m, 3 * m
    faces = []
    # Base bottom: a fan about its centre (its rim has collinear points, which a fan from a rim
    # point would turn into triangles without area).
    v.append((0.0, 0.0, z0))
    cb = len(v) - 1
    for k in range(m):
        faces.append([cb, ob + (k + 1) % m, ob + k])
    for k in range(m):
        n_ = (k + 1) % m
        faces.append([ot + k, ot + n_, ib + n_, ib + k])       # base top ring, seen from +z
        faces.append([ob + k, ob + n_, ot + n_, ot + k])       # base side
        faces.append([ib + k, ib + n_, it + n_, it + k])       # can wall
    faces.append(list(range(it, it + m)))                      # can top, one polygon
    tris = []
    for f in faces:
        tris += [(f[0], f[k], f[k + 1]) for k in range(1, len(f) - 1)]
    for a, b, c in tris:
        p, q, r = v[a], v[b], v[c]
        u = [q[i] - p[i] for i in range(3)]
        w = [r[i] - p[i] for i in range(3)]
        cr = [u[1] * w[2] - u[2] * w[1], u[2] * w[0] - u[0] * w[2], u[0] * w[1] - u[1] * w[0]]
        assert math.sqrt(sum(x * x for x in cr)) > 1e-9, "a polygon fans into a triangle without area"
    body = (v, tris)
    term = [box((-4.75, -0.45, 0.0), (-1.5, 0.45, 0.2)), box((1.5, -0.45, 0.0), (4.75, 0.45, 0.2))]
    check("smd-elcap", body, *term)
    lines = ["# binpick: SMD aluminium electrolytic 8 x 10.2 mm on its base, drawn by",
             "# scripts/make-cad-parts.py (units: mm)", "o can_and_base"]
    lines += [f"v {p[0]:.6f} {p[1]:.6f} {p[2]:.6f}" for p in v]
    lines += ["f " + " ".join(str(i + 1) for i in f) for f in faces]
    base = len(v)
    for k, (tv, tt) in enumerate(term):
        lines.append(f"o terminal_{k + 1}")
        lines += [f"v {p[0]:.6f} {p[1]:.6f} {p[2]:.6f}" for p in tv]
        lines += [f"f {a + base + 1} {b + base + 1} {c + base + 1}" for a, b, c in tt]
        base += len(tv)
    with open(os.path.join(OUT, "smd-elcap.obj"), "w") as f:
        f.write("\n".join(lines) + "\n")


if __name__ == "__main__":
    hex_standoff()
    to220()
    dip8()
    smd_elcap()
    print("wrote hex-standoff.stl, to220.wrl, dip8.wrl, smd-elcap.obj in", os.path.normpath(OUT))
