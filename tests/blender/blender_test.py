# Runs inside Blender (tests/blender/blender_test.sh): imports ganache output folders with tools/blender's add-on and
# checks what an artist would see: the objects, the frame range and fps, meshes and volumes in the same place on
# every frame, and the particles with their attributes.
#   blender -b --factory-startup --python-exit-code 1 --python blender_test.py -- ADDON_DIR OUT_PLY OUT_OBJ
import importlib.util
import sys

import bpy
from mathutils import Vector

addon_dir, out_ply, out_obj = sys.argv[sys.argv.index("--") + 1:]
spec = importlib.util.spec_from_file_location("ganache_blender", f"{addon_dir}/ganache_blender.py")
ganache = importlib.util.module_from_spec(spec)
spec.loader.exec_module(ganache)
failures = []


def check(ok, what):
    if not ok:
        failures.append(what)
        print("FAIL:", what)


def world_bounds(obj):
    evaluated = obj.evaluated_get(bpy.context.evaluated_depsgraph_get())
    corners = [evaluated.matrix_world @ Vector(c) for c in evaluated.bound_box]
    return (Vector([min(c[k] for c in corners) for k in range(3)]),
            Vector([max(c[k] for c in corners) for k in range(3)]))


def check_folder(folder, particles):
    bpy.ops.wm.read_factory_settings(use_empty=True)
    made = ganache.load_output(folder, particles)
    scene = bpy.context.scene
    expected = {"mesh", "surface"} | ({"points"} if particles else set())
    check(set(made) == expected, f"{folder}: objects {sorted(made)}, expected {sorted(expected)}")
    check(len(bpy.data.collections["tiny"].objects) == len(expected), f"{folder}: one collection holds them")
    check((scene.frame_start, scene.frame_end) == (1, 5), f"{folder}: frames {scene.frame_start}-{scene.frame_end}")
    check(abs(scene.render.fps / scene.render.fps_base - 10) < 1e-6, f"{folder}: fps {scene.render.fps}")
    material = made["mesh"].data.materials[0]
    check(max(abs(a - b) for a, b in zip(material.diffuse_color[:3], (0.85, 0.55, 0.1))) < 0.3,
          f"{folder}: the honey's colour, got {tuple(material.diffuse_color)}")
    # The tiny scene's voxel is 0.01 m, its level set reaches 3 voxels past the surface, and Blender bounds a volume
    # by its grid's leaf nodes (8 voxels): the volume's box is the mesh's grown by 0.03 m and rounded out to 0.08 m,
    # at most 0.11 m more on each side. A volume left in y-up axes misses by the block's height or more (checked: 0.1
    # m short below on y, 0.16 m over above on z).
    for frame in range(1, 6):
        scene.frame_set(frame)
        check(made["mesh"].data.name == f"tiny_mesh.{frame:04d}", f"{folder}: frame {frame} shows {made['mesh'].data.name}")
        mesh_lo, mesh_hi = world_bounds(made["mesh"])
        volume_lo, volume_hi = world_bounds(made["surface"])
        for k in range(3):
            check(0 <= mesh_lo[k] - volume_lo[k] < 0.111 and 0 <= volume_hi[k] - mesh_hi[k] < 0.111,
                  f"{folder}: frame {frame} axis {k}: mesh {mesh_lo[k]:.3f}..{mesh_hi[k]:.3f}, "
                  f"volume {volume_lo[k]:.3f}..{volume_hi[k]:.3f}")
        check(mesh_hi[2] > mesh_lo[2] + 0.02 and mesh_lo[2] > -0.05, f"{folder}: frame {frame}: the fluid stands on z")
        if particles:
            points = made["points"].data
            check(len(points.vertices) > 20 and not points.polygons, f"{folder}: frame {frame}: a point cloud")
            for name in ("velocity", "mass", "id"):
                check(name in points.attributes, f"{folder}: points carry {name}")
            points_lo, points_hi = world_bounds(made["points"])
            for k in range(3):
                check(mesh_lo[k] - 0.001 <= points_lo[k] and points_hi[k] <= mesh_hi[k] + 0.001,
                      f"{folder}: frame {frame} axis {k}: points outside the mesh")
    print(f"{folder}: {len(made)} objects, frames 1-5 checked")


check_folder(out_ply, True)
check_folder(out_obj, False)
if failures:
    sys.exit(f"{len(failures)} check(s) failed")
print("PASS")
