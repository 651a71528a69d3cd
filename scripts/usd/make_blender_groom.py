"""Makes a small groom in Blender and exports it with Blender's own USD
exporter: the test fixture of USD import (tests/data/usd/blender-groom.usda)
and the control points Blender reports for it (blender-groom.json).

The scene: particle hair on a sphere (Blender exports it as linear curves,
with no widths), a hair-curves object (cubic Catmull-Rom, pinned, with a
radius per point), a camera and a sun. Needs Blender 5.0 as a Python module
(PyPI's bpy 5.0.1, about 1 GB; Debian's Blender is built without USD):

    python3 -m venv /work/.venv-bpy && /work/.venv-bpy/bin/pip install bpy==5.0.1
    /work/.venv-bpy/bin/python scripts/usd/make_blender_groom.py tests/data/usd

Not deterministic. The hair curves' points and radii, the camera and the sun
are computed here and come out the same on every run, but Blender 5.0.1
places the particle hair differently on every run, whatever the particle
system's seed (with the emission's randomisation off, or the scene's
threads fixed to 1, as well), and its exporter writes the prims in a
different order. So the .usda and the .json are a pair from one run:
regenerate both together, never one of them.
"""

import json
import math
import os
import sys

import bpy
from mathutils import Matrix, Vector

PARTICLE_STRANDS = 120  # particle hair on the sphere
CURVE_STRANDS = 80      # hair-curves strands
CURVE_POINTS = 6        # points per hair-curves strand


def build_scene():
    bpy.ops.wm.read_factory_settings(use_empty=True)
    scene = bpy.context.scene

    # Particle hair on a sphere.
    bpy.ops.mesh.primitive_uv_sphere_add(radius=1.0, segments=16, ring_count=8,
                                         location=(0, 0, 0))
    sphere = bpy.context.active_object
    sphere.name = "scalp"
    modifier = sphere.modifiers.new("fur", type="PARTICLE_SYSTEM")
    settings = modifier.particle_system.settings
    settings.type = "HAIR"
    settings.count = PARTICLE_STRANDS
    settings.hair_length = 0.4
    settings.hair_step = 4
    settings.display_step = 2
    settings.render_step = 2
    settings.child_type = "NONE"
    modifier.particle_system.seed = 7

    # A hair-curves object: strands of CURVE_POINTS points, Catmull-Rom (the
    # default curve type), a radius per point.
    curves = bpy.data.hair_curves.new("lock")
    curves.add_curves([CURVE_POINTS] * CURVE_STRANDS)
    positions = curves.attributes["position"].data
    radius = curves.attributes.get("radius") or curves.attributes.new("radius", "FLOAT", "POINT")
    for strand in range(CURVE_STRANDS):
        angle = 2 * math.pi * strand / CURVE_STRANDS
        for k in range(CURVE_POINTS):
            t = k / (CURVE_POINTS - 1)
            index = strand * CURVE_POINTS + k
            positions[index].vector = (
                0.3 * math.cos(angle) + 0.05 * math.sin(3 * t + strand),
                0.3 * math.sin(angle) + 0.05 * math.cos(2 * t + strand),
                1.0 + 0.8 * t)
            radius.data[index].value = 0.004 * (1 - 0.7 * t)
    lock = bpy.data.objects.new("lock", curves)
    scene.collection.objects.link(lock)
    lock.location = (0.2, -0.1, 0.05)
    lock.rotation_euler = (0.1, 0.0, 0.3)

    # Camera and sun.
    camera_data = bpy.data.cameras.new("camera")
    camera_data.lens = 50
    camera_data.sensor_width = 36
    camera = bpy.data.objects.new("camera", camera_data)
    scene.collection.objects.link(camera)
    camera.location = (0, -6, 1)
    camera.rotation_euler = (math.radians(85), 0, 0)
    scene.camera = camera
    sun_data = bpy.data.lights.new("sun", type="SUN")
    sun_data.energy = 3.0
    sun = bpy.data.objects.new("sun", sun_data)
    scene.collection.objects.link(sun)
    sun.rotation_euler = (math.radians(40), 0, math.radians(30))
    scene.render.resolution_x, scene.render.resolution_y = 320, 240
    return sphere, lock, camera, sun


def reported_points(sphere, lock):
    """The control points as Blender reports them, in world space: the
    particle hair's path cache (what its exporter writes) and the hair
    curves' positions."""
    depsgraph = bpy.context.evaluated_depsgraph_get()
    evaluated = sphere.evaluated_get(depsgraph)
    system = evaluated.particle_systems[0]
    steps = 2 ** system.settings.display_step + 1
    particle = [[list(system.co_hair(evaluated, particle_no=p, step=s)) for s in range(steps)]
                for p in range(len(system.particles))]
    world = lock.matrix_world
    curves = lock.data
    lock_points = []
    for curve in curves.curves:
        lock_points.append([list(world @ curves.points[curve.first_point_index + k].position)
                            for k in range(curve.points_length)])
    radii = [[curves.points[curve.first_point_index + k].radius
              for k in range(curve.points_length)] for curve in curves.curves]
    return {"particle_hair": particle, "hair_curves": lock_points, "hair_curves_radius": radii,
            "hair_curves_world_scale": 1.0}


def main():
    folder = sys.argv[-1] if len(sys.argv) > 1 else "."
    os.makedirs(folder, exist_ok=True)
    sphere, lock, camera, sun = build_scene()
    usd = os.path.join(folder, "blender-groom.usda")
    bpy.ops.wm.usd_export(filepath=os.path.abspath(usd), export_hair=True,
                          export_materials=False)
    points = reported_points(sphere, lock)
    points["blender"] = bpy.app.version_string
    points["camera"] = {"lens_mm": camera.data.lens, "sensor_width_mm": camera.data.sensor_width,
                        "location": list(camera.matrix_world.translation)}
    points["sun"] = {"direction": list(sun.matrix_world.to_3x3() @ Vector((0, 0, 1))),
                     "energy": sun.data.energy}
    with open(os.path.join(folder, "blender-groom.json"), "w") as file:
        json.dump(points, file, indent=0)
    print(f"wrote {usd} ({os.path.getsize(usd)} bytes) and blender-groom.json")


if __name__ == "__main__":
    main()
