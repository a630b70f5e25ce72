#!/usr/bin/env python3
"""Writes the multi-object benchmark scenes of scenes/ (run from the repository root):
killeroo2.rib (2 killeroos), bigguy9.rib / bigguy24.rib (3x3 and 6x4 grids of the 3570-patch Big Guy;
bigguy24_instanced.rib: the same with ObjectInstance) and
bigguy_box.rib (Big Guy in a five-walled box, for the lighting work to come) and smooth_polygons.rib
(polygons with per-vertex normals and colours)."""
import math

def normalize(v):
    l = math.sqrt(sum(c * c for c in v))
    return [c / l for c in v]

def cross(a, b):
    return [a[1] * b[2] - a[2] * b[1], a[2] * b[0] - a[0] * b[2], a[0] * b[1] - a[1] * b[0]]

def look_at(eye, target, up):
    """RIB Transform (row vectors) for a left-handed camera at eye looking at target in a right-handed world."""
    z = normalize([t - e for t, e in zip(target, eye)])
    x = normalize(cross(z, up))   # right = forward x up
    y = cross(x, z)               # up = right x forward
    rows = [x, y, z]
    t = [-sum(r[i] * eye[i] for i in range(3)) for r in rows]
    # Column-vector matrix A has rows x, y, z; the RIB array is A transposed, written row by row.
    m = [[rows[j][i] for j in range(3)] + [0] for i in range(3)] + [t + [1]]
    return "Transform [ " + " ".join(f"{v:.6g}" for row in m for v in row) + " ]"

HEADER = """##RenderMan RIB
# Tessera benchmark scene written by scripts/make_scenes.py: {what}
version 3.04
Display "{name}.png" "file" "rgba"
Format {w} {h} 1
PixelSamples 4 4
ShadingRate 1
Projection "perspective" "fov" [ {fov} ]
{xform}
Clipping {near} {far}
WorldBegin
"""

OUT_DIR = "scenes"  # bench/reyes_memory.sh writes its larger grids elsewhere (with an archives/ link)

def write(name, what, w, h, fov, eye, target, up, near, far, body):
    with open(f"{OUT_DIR}/{name}.rib", "w") as f:
        f.write(HEADER.format(what=what, name=name, w=w, h=h, fov=fov, xform=look_at(eye, target, up),
                              near=near, far=far))
        f.write(body)
        f.write("WorldEnd\n")

LIGHTS_Y_UP = """LightSource "ambientlight" 1 "intensity" [ 0.06 ]
Attribute "light" "shadows" [ "on" ]  # the key light casts shadows
LightSource "distantlight" 2 "intensity" [ 0.95 ] "from" [ 8 14 12 ] "to" [ 0 0 0 ]
Attribute "light" "shadows" [ "off" ]  # fill lights do not
LightSource "distantlight" 3 "intensity" [ 0.3 ] "lightcolor" [ 0.8 0.88 1 ] "from" [ -14 2 6 ] "to" [ 0 0 0 ]
"""

def bigguy_grid(name, cols, rows, instanced=False):
    """instanced: the Big Guy is one object (ObjectBegin) and each cell an ObjectInstance of it, the same
    scene as the ReadArchive copies (the ray tracer shares the instances' subpatch trees, docs/rt.md)."""
    body = LIGHTS_Y_UP + 'Surface "plastic" "Ka" [ 1 ] "Kd" [ 0.8 ] "Ks" [ 0.35 ] "roughness" [ 0.15 ]\n'
    if instanced:
        body += 'ObjectBegin "bigguy"\nReadArchive "archives/bigguy_patches.rib"\nObjectEnd\n'
    place = 'ObjectInstance "bigguy"' if instanced else 'ReadArchive "archives/bigguy_patches.rib"'
    sx, sz = 6.5, 6.5
    for r in range(rows):
        for c in range(cols):
            x, z = (c - (cols - 1) / 2) * sx, (r - (rows - 1) / 2) * sz
            hue = (0.55 + 0.3 * ((r * cols + c) % 3) / 2, 0.6, 0.5 + 0.2 * (c % 2))
            body += (f"AttributeBegin\nTranslate {x:g} 0 {z:g}\nColor [ {hue[0]:.3g} {hue[1]:.3g} {hue[2]:.3g} ]\n"
                     f"{place}\nAttributeEnd\n")
    extent = max(cols * sx, rows * sz)
    eye = [0.3 * extent, 0.45 * extent, 1.3 * extent]
    write(name, f"{cols * rows} Big Guys ({cols * rows * 3570} bicubic patches) on a {cols}x{rows} grid" +
          (", instances of one object" if instanced else ""),
          1024, 768, 42, eye, [0, -1, 0], [0, 1, 0], 0.5, 1000, body)

def killeroo2():
    body = """LightSource "ambientlight" 1 "intensity" [ 0.04 ]
Attribute "light" "shadows" [ "on" ]  # the key light casts shadows
LightSource "distantlight" 2 "intensity" [ 1.1 ] "from" [ -10 -5 8 ] "to" [ 0 0 0 ]
Attribute "light" "shadows" [ "off" ]  # fill lights do not
LightSource "distantlight" 3 "intensity" [ 0.2 ] "lightcolor" [ 0.85 0.9 1 ] "from" [ -8 12 -2 ] "to" [ 0 0 0 ]
Surface "matte" "Ka" [ 1 ] "Kd" [ 1 ]
AttributeBegin
Translate 0 -130 0
Color [ 0.82 0.8 0.76 ]
ReadArchive "archives/killeroo_model.rib"
AttributeEnd
AttributeBegin
Translate 40 150 0
Rotate 180 0 0 1
Color [ 0.7 0.75 0.82 ]
ReadArchive "archives/killeroo_model.rib"
AttributeEnd
"""
    write("killeroo2", "two Killeroos (23064 bicubic patches)", 1024, 768, 40, [-560, 40, 200], [10, 10, -40],
          [0, 0, 1], 10, 5000, body)

def bigguy_box(glossy=False):
    # Five walls (floor, ceiling, back, left, right) as bilinear patches around one Big Guy; open front.
    # glossy: the floor and Big Guy are Surface "glossy" (paper 002 sec. 5.3.5's spreads 0.1 and 0.4).
    s, h = 6.0, 5.0
    def quad(p):
        return 'Patch "bilinear" "P" [ ' + " ".join(f"{v:g}" for pt in p for v in pt) + " ]\n"
    floor_y = -3.0
    walls = [
        ("floor", [0.8, 0.8, 0.8], [[-s, floor_y, -s], [s, floor_y, -s], [-s, floor_y, s], [s, floor_y, s]]),
        ("ceiling", [0.8, 0.8, 0.8], [[-s, floor_y + 2 * h, s], [s, floor_y + 2 * h, s], [-s, floor_y + 2 * h, -s], [s, floor_y + 2 * h, -s]]),
        ("back", [0.8, 0.8, 0.8], [[-s, floor_y, -s], [-s, floor_y + 2 * h, -s], [s, floor_y, -s], [s, floor_y + 2 * h, -s]]),
        ("left", [0.75, 0.2, 0.2], [[-s, floor_y, s], [-s, floor_y + 2 * h, s], [-s, floor_y, -s], [-s, floor_y + 2 * h, -s]]),
        ("right", [0.2, 0.6, 0.25], [[s, floor_y, -s], [s, floor_y + 2 * h, -s], [s, floor_y, s], [s, floor_y + 2 * h, s]]),
    ]
    body = """LightSource "ambientlight" 1 "intensity" [ 0.08 ]
Attribute "light" "shadows" [ "on" ]  # the key light casts shadows
LightSource "pointlight" 2 "intensity" [ 40 ] "from" [ 0 6 3 ]
Surface "matte" "Ka" [ 1 ] "Kd" [ 0.9 ]
"""
    for name, col, pts in walls:
        gloss = ('Surface "glossy" "Ka" [ 1 ] "Kd" [ 0.45 ] "Ks" [ 0.5 ] "spread" [ 0.1 ] "samples" [ 4 ]\n'
                 if glossy and name == "floor" else "")
        body += f"AttributeBegin # {name}\nColor [ {col[0]} {col[1]} {col[2]} ]\n" + gloss + quad(pts) + "AttributeEnd\n"
    surface = ('Surface "glossy" "Ka" [ 1 ] "Kd" [ 0.3 ] "Ks" [ 0.6 ] "roughness" [ 0.15 ] "spread" [ 0.4 ] '
               '"samples" [ 4 ]\n' if glossy else
               'Surface "plastic" "Ka" [ 1 ] "Kd" [ 0.8 ] "Ks" [ 0.35 ] "roughness" [ 0.15 ]\n')
    body += ('AttributeBegin # Big Guy\nColor [ 0.8 0.62 0.5 ]\n' + surface +
             'ReadArchive "archives/bigguy_patches.rib"\nAttributeEnd\n')
    if glossy:
        write("bigguy_box_glossy", "the Big Guy box with a glossy floor (spread 0.1) and a glossy Big Guy (spread "
              "0.4), 4 reflection rays per camera hit (ray traced: --engine rt)",
              400, 400, 48, [0, 2.5, 17.5], [0, 2, 0], [0, 1, 0], 0.5, 1000, body)
    else:
        write("bigguy_box", "Big Guy (3570 patches) in a five-walled box (a Cornell-box-like set for lighting work)",
              800, 800, 48, [0, 2.5, 17.5], [0, 2, 0], [0, 1, 0], 0.5, 1000, body)

def polygon_sphere(nu, nv, normals):
    """A UV sphere of radius 1 as RIB PointsPolygons (triangles at the poles), with its exact normals as
    vertex "N" when `normals`."""
    pts, nverts, verts = [], [], []
    for j in range(nv + 1):
        th = math.pi * j / nv
        for i in range(nu):
            ph = 2 * math.pi * i / nu
            pts.append((math.sin(th) * math.cos(ph), math.sin(th) * math.sin(ph), math.cos(th)))
    for j in range(nv):
        for i in range(nu):
            a, b = j * nu + i, j * nu + (i + 1) % nu
            c, d = (j + 1) * nu + (i + 1) % nu, (j + 1) * nu + i
            if j == 0:
                nverts.append(3); verts += [a, d, c]
            elif j == nv - 1:
                nverts.append(3); verts += [a, d, b]
            else:
                nverts.append(4); verts += [a, d, c, b]
    xyz = " ".join(f"{x:.6f} {y:.6f} {z:.6f}" for x, y, z in pts)
    s = f"PointsPolygons [ {' '.join(map(str, nverts))} ]\n  [ {' '.join(map(str, verts))} ]\n  \"P\" [ {xyz} ]\n"
    if normals:
        s += f"  \"N\" [ {xyz} ]\n"
    return s

def smooth_polygons():
    body = """LightSource "ambientlight" 1 "intensity" [ 0.15 ]
Attribute "light" "shadows" [ "on" ]  # the key light casts shadows
LightSource "distantlight" 2 "intensity" [ 0.9 ] "from" [ -1 3 -1 ] "to" [ 0 0 0 ]
Surface "plastic" "Ks" [ 0.4 ] "roughness" [ 0.1 ]
Color [ 0.8 0.75 0.6 ]
"""
    for x, normals in ((2.4, False), (0, True)):  # look_at mirrors x: +x is on the left
        body += f"AttributeBegin\nTranslate {x} 0 0\n" + polygon_sphere(16, 8, normals) + "AttributeEnd\n"
    body += """AttributeBegin
Translate -2.4 0 0
Sphere 1 -1 1 360
AttributeEnd
Surface "matte"
Polygon "P" [ -4 -1 -1.5  4 -1 -1.5  4 -1 3  -4 -1 3 ]
  "Cs" [ 0.9 0.2 0.2  0.2 0.9 0.2  0.2 0.3 0.9  0.9 0.9 0.9 ]
"""
    write("smooth_polygons", "polygons with per-vertex normals and colours: a 16 x 8 polygon sphere without "
          "\"N\" (faceted, left), the same with vertex \"N\" (smooth, middle), an RI Sphere (right), on a floor "
          "with vertex \"Cs\"", 480, 240, 30, [0, 3.3, -8.4], [0, 0, 0], [0, 1, 0], 0.1, 100, body)

if __name__ == "__main__":
    bigguy_grid("bigguy9", 3, 3)
    bigguy_grid("bigguy24", 6, 4)
    bigguy_grid("bigguy24_instanced", 6, 4, instanced=True)
    killeroo2()
    bigguy_box()
    bigguy_box(glossy=True)
    smooth_polygons()
