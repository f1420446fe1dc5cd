# ganache for Blender: imports a ganache output folder in one step.
#
#   blender --python tools/blender/ganache_blender.py -- OUT [--particles]
#
# or install this file as an add-on (Edit > Preferences > Add-ons > Install) and use File > Import > ganache output.
# What it makes, in a collection named after the scene:
#   <scene>_mesh      the surface meshes (mesh/<scene>.NNNN.obj or .ply), one mesh per frame, swapped as the frame
#                     changes; per-vertex `temperature` when the meshes carry it; the fluid's material colour
#   <scene>_surface   the level-set VDB sequence (surface/<scene>.NNNN.vdb) as a volume object
#   <scene>_points    with --particles: the PLY point clouds of `particles.export: ply` (points/<scene>.NNNN.ply), one
#                     mesh of vertices per frame, with `velocity` and every other property as point attributes
# The scene's frame range and fps come from report.json. ganache writes metres with y up; Blender is z up: every
# mesh and point cloud is turned (x, y, z) -> (x, -z, y) as Blender's own OBJ importer does, and the volume object is
# rotated by the same 90 degrees about x, so that meshes, volumes and points line up.

import json
import math
import sys
from pathlib import Path

import bpy
import numpy as np

bl_info = {
    "name": "ganache output",
    "author": "ganache",
    "version": (1, 0, 0),
    "blender": (3, 4, 0),
    "location": "File > Import > ganache output",
    "description": "Imports a ganache output folder: surface meshes, level-set volumes and particles as sequences",
    "category": "Import-Export",
}

_PLY_TYPES = {
    "char": "i1", "int8": "i1", "uchar": "u1", "uint8": "u1", "short": "<i2", "int16": "<i2", "ushort": "<u2",
    "uint16": "<u2", "int": "<i4", "int32": "<i4", "uint": "<u4", "uint32": "<u4", "float": "<f4",
    "float32": "<f4", "double": "<f8", "float64": "<f8",
}


def read_ply(path):
    """A binary little-endian PLY as ganache writes it: (vertex properties by name, triangles as an (m, 3) array)."""
    data = Path(path).read_bytes()
    end = data.index(b"end_header\n") + len(b"end_header\n")
    header = data[:end].decode("ascii").splitlines()
    if "format binary_little_endian 1.0" not in header:
        raise ValueError(f"{path}: not a binary little-endian PLY")
    elements = []  # (name, count, [(property, dtype)] or a face list)
    for line in header:
        words = line.split()
        if words[:1] == ["element"]:
            elements.append((words[1], int(words[2]), []))
        elif words[:1] == ["property"]:
            if words[1] == "list":
                elements[-1][2].append((words[4], ("list", _PLY_TYPES[words[2]], _PLY_TYPES[words[3]])))
            else:
                elements[-1][2].append((words[2], _PLY_TYPES[words[1]]))
    vertex, triangles, at = {}, np.zeros((0, 3), np.uint32), end
    for name, count, properties in elements:
        if any(isinstance(t, tuple) for _, t in properties):  # faces: triangles, as ganache writes them
            (_, (_, count_type, index_type)), = properties
            record = np.dtype([("n", count_type), ("i", index_type, 3)])
            faces = np.frombuffer(data, record, count, at)
            if count and np.any(faces["n"] != 3):
                raise ValueError(f"{path}: faces must be triangles")
            triangles = faces["i"].astype(np.uint32)
            at += record.itemsize * count
        else:
            record = np.dtype(properties)
            values = np.frombuffer(data, record, count, at)
            if name == "vertex":
                vertex = {p: values[p].astype(np.float64) for p, _ in properties}
            at += record.itemsize * count
    return vertex, triangles


def read_obj(path):
    """An OBJ as ganache writes it: positions, normals, temperatures (vt u) and triangles (v//vn or v/vt/vn)."""
    v, vn, vt, f = [], [], [], []
    with open(path) as file:
        for line in file:
            tag = line[:2]
            if tag == "v ":
                v.append(line[2:].split())
            elif tag == "vn":
                vn.append(line[3:].split())
            elif tag == "vt":
                vt.append(line[3:].split()[0])
            elif tag == "f ":
                f.append([corner.split("/")[0] for corner in line[2:].split()])
    positions = np.array(v, np.float64).reshape(-1, 3)
    vertex = {"x": positions[:, 0], "y": positions[:, 1], "z": positions[:, 2]}
    if vn:
        normals = np.array(vn, np.float64).reshape(-1, 3)
        vertex.update({"nx": normals[:, 0], "ny": normals[:, 1], "nz": normals[:, 2]})
    if vt:
        vertex["temperature"] = np.array(vt, np.float64)
    return vertex, np.array(f, np.int64).reshape(-1, 3).astype(np.uint32) - 1


def _z_up(x, y, z):
    """ganache's y-up metres as Blender's z-up ones."""
    return np.stack([x, -z, y], axis=1)


def _mesh(name, vertex, triangles):
    mesh = bpy.data.meshes.new(name)
    points = _z_up(vertex["x"], vertex["y"], vertex["z"])
    mesh.vertices.add(len(points))
    mesh.vertices.foreach_set("co", points.astype(np.float32).ravel())
    if len(triangles):
        mesh.loops.add(3 * len(triangles))
        mesh.loops.foreach_set("vertex_index", triangles.astype(np.int32).ravel())
        mesh.polygons.add(len(triangles))
        mesh.polygons.foreach_set("loop_start", np.arange(0, 3 * len(triangles), 3, dtype=np.int32))
        mesh.polygons.foreach_set("loop_total", np.full(len(triangles), 3, np.int32))
        mesh.polygons.foreach_set("use_smooth", np.ones(len(triangles), bool))
    mesh.update()
    if len(triangles) and "nx" in vertex:
        mesh.use_auto_smooth = True
        mesh.normals_split_custom_set_from_vertices(_z_up(vertex["nx"], vertex["ny"], vertex["nz"]))
    taken = {"x", "y", "z", "nx", "ny", "nz", "vx", "vy", "vz"}
    if {"vx", "vy", "vz"} <= vertex.keys():
        velocity = mesh.attributes.new("velocity", "FLOAT_VECTOR", "POINT")
        velocity.data.foreach_set("vector", _z_up(vertex["vx"], vertex["vy"], vertex["vz"]).astype(np.float32).ravel())
    for key, values in vertex.items():
        if key == "id":  # Blender's built-in `id` attribute is an integer
            mesh.attributes.new("id", "INT", "POINT").data.foreach_set("value", values.astype(np.int32))
        elif key not in taken:
            mesh.attributes.new(key, "FLOAT", "POINT").data.foreach_set("value", values.astype(np.float32))
    return mesh


def _frame_name(base, frame):
    return f"{base}.{frame:04d}"


@bpy.app.handlers.persistent
def _swap_meshes(scene, depsgraph=None):
    """Each ganache sequence object shows its mesh of the current frame (held before the first and after the last)."""
    for obj in scene.objects:
        base = obj.get("ganache_sequence")
        if not base:
            continue
        frame = min(max(scene.frame_current, obj["ganache_first"]), obj["ganache_last"])
        mesh = bpy.data.meshes.get(_frame_name(base, frame))
        if mesh is not None and obj.data != mesh:
            obj.data = mesh


def _sequence_object(name, base, files, read, first, last, collection, material=None):
    for frame in range(first, last + 1):
        path = files(frame)
        if path.exists():
            mesh = _mesh(_frame_name(base, frame), *read(path))
            if material is not None:
                mesh.materials.append(material)
    obj = bpy.data.objects.new(name, bpy.data.meshes.get(_frame_name(base, first)) or bpy.data.meshes.new(name))
    obj["ganache_sequence"], obj["ganache_first"], obj["ganache_last"] = base, first, last
    collection.objects.link(obj)
    return obj


def load_output(folder, particles=False):
    """Imports a ganache output folder into the current scene; returns the objects made, by role."""
    folder = Path(folder).resolve()
    report = json.loads((folder / "report.json").read_text())
    name, settings = report["scene"]["name"], report["settings"]
    frames = report.get("frames") or {"first": settings["frames"]["start"], "last": settings["frames"]["end"]}
    first, last = int(frames["first"]), int(frames["last"])
    scene = bpy.context.scene
    scene.frame_start, scene.frame_end = first, last
    fps = float(settings["frames"]["fps"])
    scene.render.fps, scene.render.fps_base = max(1, round(fps)), max(1, round(fps)) / fps

    collection = bpy.data.collections.new(name)
    scene.collection.children.link(collection)
    made = {}

    # The fluid's colour, as the previews draw it: the render section's, else the first fluid's material.
    colour = settings.get("render", {}).get("fluid_colour")
    if colour is None and settings.get("fluids"):
        colour = settings.get("materials", {}).get(settings["fluids"][0].get("material"), {}).get("colour")
    material = bpy.data.materials.new(f"{name}_fluid")
    material.use_nodes = True
    if colour is not None:
        material.diffuse_color = (*colour, 1.0)
        material.node_tree.nodes["Principled BSDF"].inputs["Base Color"].default_value = (*colour, 1.0)

    mesh_format = settings.get("surface", {}).get("mesh_format", "obj")
    mesh_file = lambda f: folder / "mesh" / f"{name}.{f:04d}.{mesh_format}"
    if any(mesh_file(f).exists() for f in range(first, last + 1)):
        read = read_ply if mesh_format == "ply" else read_obj
        made["mesh"] = _sequence_object(f"{name}_mesh", f"{name}_mesh", mesh_file, read, first, last, collection,
                                        material)

    vdb = lambda f: folder / "surface" / f"{name}.{f:04d}.vdb"
    existing = [f for f in range(first, last + 1) if vdb(f).exists()]
    if existing:
        volume = bpy.data.volumes.new(f"{name}_surface")
        volume.filepath = str(vdb(existing[0]))
        volume.is_sequence = True
        volume.sequence_mode = "CLIP"
        volume.frame_start = existing[0]            # the scene frame that shows the first file
        volume.frame_offset = existing[0] - 1       # and the file numbers are the scene's frames
        volume.frame_duration = existing[-1] - existing[0] + 1
        obj = bpy.data.objects.new(f"{name}_surface", volume)
        obj.rotation_euler = (math.pi / 2, 0, 0)    # y up to z up, as the meshes
        collection.objects.link(obj)
        made["surface"] = obj

    points = lambda f: folder / "points" / f"{name}.{f:04d}.ply"
    if particles:
        if not any(points(f).exists() for f in range(first, last + 1)):
            raise FileNotFoundError(f"{folder / 'points'}: no point clouds; add `export: ply` to the scene's "
                                    "`particles:` section and simulate again")
        made["points"] = _sequence_object(f"{name}_points", f"{name}_points", points, read_ply, first, last,
                                          collection)

    if _swap_meshes not in bpy.app.handlers.frame_change_pre:
        bpy.app.handlers.frame_change_pre.append(_swap_meshes)
    scene.frame_set(first)
    return made


class ImportGanacheOutput(bpy.types.Operator):
    """Import a ganache output folder: meshes, volumes and particles as sequences"""

    bl_idname = "import_scene.ganache_output"
    bl_label = "Import ganache output"
    directory: bpy.props.StringProperty(subtype="DIR_PATH")
    particles: bpy.props.BoolProperty(name="Particles", description="Also the PLY point clouds (particles.export)")

    def execute(self, context):
        try:
            load_output(self.directory, self.particles)
        except (OSError, ValueError, KeyError) as e:
            self.report({"ERROR"}, str(e))
            return {"CANCELLED"}
        return {"FINISHED"}

    def invoke(self, context, event):
        context.window_manager.fileselect_add(self)
        return {"RUNNING_MODAL"}


def _menu(self, context):
    self.layout.operator(ImportGanacheOutput.bl_idname, text="ganache output (folder)")


def register():
    bpy.utils.register_class(ImportGanacheOutput)
    bpy.types.TOPBAR_MT_file_import.append(_menu)
    if _swap_meshes not in bpy.app.handlers.frame_change_pre:
        bpy.app.handlers.frame_change_pre.append(_swap_meshes)


def unregister():
    bpy.types.TOPBAR_MT_file_import.remove(_menu)
    bpy.utils.unregister_class(ImportGanacheOutput)
    if _swap_meshes in bpy.app.handlers.frame_change_pre:
        bpy.app.handlers.frame_change_pre.remove(_swap_meshes)


if __name__ == "__main__":
    # blender --python ganache_blender.py -- OUT [--particles]
    args = sys.argv[sys.argv.index("--") + 1:] if "--" in sys.argv else []
    if not args or args[0].startswith("-"):
        sys.exit("usage: blender --python tools/blender/ganache_blender.py -- OUT [--particles]")
    load_output(args[0], "--particles" in args)
