"""Import one BVH or glb file into an empty Blender scene with Blender's default importer and print, as
JSON on the last line of stdout, what a user would see: object and bone names (and each bone's parent),
the scene's frame rate, the animation's frame range, the rest armature's extent and, at every keyed
frame, each object's world position and vertical extent (mesh vertices as drawn, i.e. after modifiers
such as an armature's skinning, or an armature's bone heads and tails) and each bone's world head [m,
Blender's Z up]. Objects the glTF importer makes for its own use (its bone display shape, in the
collection "glTF_not_exported") are left out.

Run with Blender's Python module (`bpy`), not the project's interpreter:
    BPY_PYTHON blender_import.py FILE.bvh|FILE.glb
BVH is imported with "Update Scene FPS" ticked (the one setting docs/export.md asks a user to change).
"""
import json
import sys

import bpy
import numpy as np


def _channelbag_fcurves(action):
    """The F-curves of an action: Blender 4.4+ keeps them in layered actions (layers/strips/channelbags)."""
    if getattr(action, "layers", None):
        return [fc for layer in action.layers for strip in layer.strips for bag in strip.channelbags for fc in bag.fcurves]
    return list(action.fcurves)


def _keyed_frames():
    frames = set()
    for action in bpy.data.actions:
        for fc in _channelbag_fcurves(action):
            frames.update(round(float(k.co[0]), 6) for k in fc.keyframe_points)
    return sorted(frames)


def _points(obj):
    """(k, 3) world-space points of an object at the current frame: mesh vertices, bone heads and tails, or its origin."""
    M = np.array(obj.matrix_world)
    if obj.type == "MESH":
        evaluated = obj.evaluated_get(bpy.context.evaluated_depsgraph_get())  # skinned: the deformed mesh
        mesh = evaluated.to_mesh()
        co = np.empty(3 * len(mesh.vertices))
        mesh.vertices.foreach_get("co", co)
        evaluated.to_mesh_clear()
        local = co.reshape(-1, 3)
    elif obj.type == "ARMATURE":
        local = np.array([p for pb in obj.pose.bones for p in (pb.head, pb.tail)])
    else:
        local = np.zeros((1, 3))
    return local @ M[:3, :3].T + M[:3, 3]


def main(path):
    bpy.ops.wm.read_factory_settings(use_empty=True)
    scene = bpy.context.scene
    if path.lower().endswith(".bvh"):
        bpy.ops.import_anim.bvh(filepath=path, update_scene_fps=True)
    else:
        bpy.ops.import_scene.gltf(filepath=path)
    objects = [o for o in scene.objects if "glTF_not_exported" not in {c.name for c in o.users_collection}]
    out = {
        "blender": bpy.app.version_string,
        "fps": scene.render.fps / scene.render.fps_base,
        "objects": {o.name: o.type for o in objects},
        "bones": {o.name: [b.name for b in o.data.bones] for o in objects if o.type == "ARMATURE"},
        "bone_parents": {o.name: {b.name: b.parent.name if b.parent else None for b in o.data.bones}
                         for o in objects if o.type == "ARMATURE"},
        "frame_ranges": [list(a.frame_range) for a in bpy.data.actions],
        "rest": {},
        "frames": [],
        "positions": {o.name: [] for o in objects},
        "zmin": {o.name: [] for o in objects},
        "zmax": {o.name: [] for o in objects},
        "bone_heads": {},
    }
    for o in objects:
        if o.type == "ARMATURE":
            M = np.array(o.matrix_world)
            pts = np.array([p for b in o.data.bones for p in (b.head_local, b.tail_local)]) @ M[:3, :3].T + M[:3, 3]
            out["rest"][o.name] = [pts[:, 2].min(), pts[:, 2].max()]
            out["bone_heads"].update({f"{o.name}/{b.name}": [] for b in o.pose.bones})
    for f in _keyed_frames():
        scene.frame_set(int(np.floor(f)), subframe=f - np.floor(f))
        out["frames"].append(f)
        for o in objects:
            pts = _points(o)
            out["positions"][o.name].append(list(np.array(o.matrix_world)[:3, 3]))
            out["zmin"][o.name].append(float(pts[:, 2].min()))
            out["zmax"][o.name].append(float(pts[:, 2].max()))
            if o.type == "ARMATURE":
                M = np.array(o.matrix_world)
                for b in o.pose.bones:
                    out["bone_heads"][f"{o.name}/{b.name}"].append(list(M[:3, :3] @ np.array(b.head) + M[:3, 3]))
    print(json.dumps(out, default=float))


if __name__ == "__main__":
    main(sys.argv[1])
