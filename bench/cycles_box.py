# Blender (Cycles) side of bench/cycles_compare.sh: builds scenes/bigguy_box_area.rib with every surface
# Lambertian, as the comparison's Tessera scene is, and path traces it with Cycles, an independent path
# tracer, to a linear OpenEXR. Run: blender -b --python bench/cycles_box.py -- ARCHIVE OUT.exr RES SPP
# The geometry is the same surfaces: the bilinear walls as quads, Big Guy's 3570 bicubic Bezier patches
# (the RIB archive the scene reads) tessellated here to 8 x 8 quads each, evaluated from their control
# points (Bernstein form). Camera: the scene's Transform and 48-degree field of view; the area light emits
# 30 (radiance) from its front (downwards) only, as RI's arealight; diffuse albedos Kd x Cs.
import math
import re
import sys

import bpy

argv = sys.argv[sys.argv.index("--") + 1:]
archive, out, res, spp = argv[0], argv[1], int(argv[2]), int(argv[3])

scene = bpy.context.scene
for o in list(bpy.data.objects):
    bpy.data.objects.remove(o, do_unlink=True)


def material(name, color, emission=0.0):
    m = bpy.data.materials.new(name)
    m.use_nodes = True
    nt = m.node_tree
    for n in list(nt.nodes):
        nt.nodes.remove(n)
    outn = nt.nodes.new("ShaderNodeOutputMaterial")
    diffuse = nt.nodes.new("ShaderNodeBsdfDiffuse")
    diffuse.inputs["Color"].default_value = (*color, 1.0)
    diffuse.inputs["Roughness"].default_value = 0.0  # Lambert
    if emission <= 0:
        nt.links.new(diffuse.outputs[0], outn.inputs["Surface"])
        return m
    # Front side emits (RI arealight), the back is the black matte surface.
    emit = nt.nodes.new("ShaderNodeEmission")
    emit.inputs["Color"].default_value = (1, 1, 1, 1)
    emit.inputs["Strength"].default_value = emission
    geo = nt.nodes.new("ShaderNodeNewGeometry")
    mix = nt.nodes.new("ShaderNodeMixShader")
    nt.links.new(geo.outputs["Backfacing"], mix.inputs[0])
    nt.links.new(emit.outputs[0], mix.inputs[1])
    nt.links.new(diffuse.outputs[0], mix.inputs[2])
    nt.links.new(mix.outputs[0], outn.inputs["Surface"])
    return m


def add_mesh(name, verts, faces, mat):
    mesh = bpy.data.meshes.new(name)
    mesh.from_pydata(verts, [], faces)
    mesh.update()
    obj = bpy.data.objects.new(name, mesh)
    obj.data.materials.append(mat)
    scene.collection.objects.link(obj)
    return obj


# Walls: the scene's bilinear patches (P00 P10 P01 P11) as quads (P00 P10 P11 P01); albedo Kd 0.9 x Cs.
walls = [
    ("floor", (0.8, 0.8, 0.8), [(-6, -3, -6), (6, -3, -6), (-6, -3, 6), (6, -3, 6)]),
    ("ceiling", (0.8, 0.8, 0.8), [(-6, 7, 6), (6, 7, 6), (-6, 7, -6), (6, 7, -6)]),
    ("back", (0.8, 0.8, 0.8), [(-6, -3, -6), (-6, 7, -6), (6, -3, -6), (6, 7, -6)]),
    ("left", (0.75, 0.2, 0.2), [(-6, -3, 6), (-6, 7, 6), (-6, -3, -6), (-6, 7, -6)]),
    ("right", (0.2, 0.6, 0.25), [(6, -3, -6), (6, 7, -6), (6, -3, 6), (6, 7, 6)]),
]
for name, cs, p in walls:
    add_mesh(name, p, [(0, 1, 3, 2)], material(name, tuple(0.9 * c for c in cs)))
# The light: 3 x 3 at y = 6.95, its front facing down (-y): the face's winding gives that normal.
light = [(-1.5, 6.95, -1.5), (1.5, 6.95, -1.5), (1.5, 6.95, 1.5), (-1.5, 6.95, 1.5)]
add_mesh("light", light, [(0, 1, 2, 3)], material("light", (0, 0, 0), emission=30.0))
lo = bpy.data.objects["light"]
assert lo.data.polygons[0].normal.y < 0, "the light must face down"

# Big Guy: matte Kd 0.8 x Cs (0.8 0.62 0.5).
text = open(archive).read()
nums = re.compile(r'Patch\s+"bicubic"\s+"P"\s*\[([^\]]*)\]')
N = 8
verts, faces = [], []
bern = []
for i in range(N + 1):
    t = i / N
    bern.append(((1 - t) ** 3, 3 * t * (1 - t) ** 2, 3 * t * t * (1 - t), t ** 3))
for m in nums.finditer(text):
    v = [float(x) for x in m.group(1).split()]
    cp = [(v[3 * k], v[3 * k + 1], v[3 * k + 2]) for k in range(16)]  # row-major, u fastest
    base = len(verts)
    for j in range(N + 1):
        bv = bern[j]
        for i in range(N + 1):
            bu = bern[i]
            x = y = z = 0.0
            for r in range(4):
                for c in range(4):
                    w = bv[r] * bu[c]
                    p = cp[4 * r + c]
                    x += w * p[0]
                    y += w * p[1]
                    z += w * p[2]
            verts.append((x, y, z))
    for j in range(N):
        for i in range(N):
            a = base + j * (N + 1) + i
            faces.append((a, a + 1, a + N + 2, a + N + 1))
add_mesh("bigguy", verts, faces, material("bigguy", (0.8 * 0.8, 0.8 * 0.62, 0.8 * 0.5)))
print("big guy quads", len(faces))

# Camera: RIB Transform (world to a left-handed camera, row vectors). Blender's camera looks down its -Z
# with +Y up: its axes are the RI camera's x, y and -z in world space, at the RI eye.
T = [1, 0, 0, 0, -0, 0.999592, -0.0285598, 0, 0, -0.0285598, -0.999592, 0, -0, -1.99918, 17.5643, 1]
M = [[T[4 * r + c] for c in range(4)] for r in range(4)]  # p_cam = p_world_row * M
R = [[M[i][j] for i in range(3)] for j in range(3)]       # R[j] = world vector of camera axis j (rows)
t = [M[3][j] for j in range(3)]
eye = [-sum(R[j][i] * t[j] for j in range(3)) for i in range(3)]  # R orthonormal: eye = -R^T t
cam_data = bpy.data.cameras.new("cam")
cam_data.angle = math.radians(48)
cam_data.sensor_fit = "AUTO"
cam_data.clip_start, cam_data.clip_end = 0.5, 1000
cam = bpy.data.objects.new("cam", cam_data)
import mathutils  # noqa: E402

X, Y, Z = mathutils.Vector(R[0]), mathutils.Vector(R[1]), -mathutils.Vector(R[2])
cam.matrix_world = mathutils.Matrix(((X[0], Y[0], Z[0], eye[0]), (X[1], Y[1], Z[1], eye[1]),
                                     (X[2], Y[2], Z[2], eye[2]), (0, 0, 0, 1)))
scene.collection.objects.link(cam)
scene.camera = cam

scene.world = bpy.data.worlds.new("black")
scene.world.use_nodes = True
scene.world.node_tree.nodes["Background"].inputs["Strength"].default_value = 0.0
scene.render.engine = "CYCLES"
cy = scene.cycles
cy.device = "CPU"
cy.samples = spp
cy.use_adaptive_sampling = False
cy.use_denoising = False
cy.max_bounces = cy.diffuse_bounces = 16
cy.glossy_bounces = cy.transmission_bounces = cy.transparent_max_bounces = 0
cy.sample_clamp_direct = cy.sample_clamp_indirect = 0.0
cy.filter_type = "GAUSSIAN"
cy.filter_width = 1.5
cy.seed = 1
scene.render.resolution_x = scene.render.resolution_y = res
scene.render.resolution_percentage = 100
scene.render.threads_mode = "FIXED"
scene.render.threads = 2
scene.view_settings.view_transform = "Standard"
scene.render.image_settings.file_format = "OPEN_EXR"
scene.render.image_settings.color_depth = "32"
scene.render.image_settings.color_mode = "RGBA"
scene.render.filepath = out
bpy.ops.render.render(write_still=True)
