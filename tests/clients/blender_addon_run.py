"""Drive the dynsplines add-on in Blender as a user would, headless, and print what came of it as JSON on
the last line of stdout.

Run with Blender's Python module (`bpy`), not the project's interpreter:
    BPY_PYTHON blender_addon_run.py ADDON.zip DYNSPLINES CLIP.bvh MODE [FRAMES]
FRAMES: scene frames, comma-separated; "82:Hips+LeftUpLeg" keys only those bones at frame 82 (a partial key).
ADDON.zip is installed as an extension (`bpy.ops.extensions.package_install_files`, as Install from Disk
does) and its preference set to DYNSPLINES, the command; CLIP.bvh is imported with Blender's BVH importer
("Update Scene FPS", docs/export.md). MODE:
* inbetween: the action's keys are kept at FRAMES only (comma-separated scene frames), then
  `dynsplines.inbetween`; rerun: the same, twice (the second replaces the first's result);
* clean: `dynsplines.clean` on the action as imported (a key at every frame);
* unknown: the bones renamed b0, b1, ... (no convention's names, so no named length unit), then
  `dynsplines.inbetween` at FRAMES: solved at an assumed size, with a warning report; mapped: the same rig
  with a skeleton map (the panel's file) giving the unit the names no longer say: solved ("bones" are the
  names as imported); badmap: the same rig with a skeleton map whose unit is no unit: the error report;
* fbx, fbx-clean: the imported clip through Blender's FBX exporter and importer first (a rig with FBX's
  bone orientations, object transform and leaf bones), then as inbetween, clean;
* cancel: the keys kept at FRAMES, then the add-on's `SolveRun` (what the modal operator runs) polled as
  its timer does, and cancelled (as Esc does) once the solve has finished its first round.
The JSON: the actions, the armature's action after the run, the error report (or null), the first and
last keyed frame of each action, and for the original and the result action at every scene frame of the
result, the world positions [Blender units] of every bone's head and tail.
"""
import json
import sys

import bpy
import numpy as np


def _install(zip_path, cli):
    bpy.ops.wm.read_factory_settings(use_empty=True)
    bpy.ops.extensions.package_install_files(filepath=zip_path, repo="user_default", enable_on_install=True)
    [name] = [a.module for a in bpy.context.preferences.addons if a.module.endswith("dynsplines")]
    bpy.context.preferences.addons[name].preferences.cli = cli
    return name


def _fcurves(obj):
    from bpy_extras import anim_utils

    return anim_utils.animdata_get_channelbag_for_assigned_slot(obj.animation_data).fcurves


def _keep_keys(obj, frames):
    """Delete every key of the action but those at `frames` (an animator's sparse keys); frames: {frame:
    None (every bone keyed) or the bones keyed there (a partial key)}."""
    for fc in _fcurves(obj):
        bone = fc.data_path.split('"')[1] if fc.data_path.startswith("pose.bones") else None  # else the object's
        pts = fc.keyframe_points
        for i in reversed(range(len(pts))):
            f = int(round(pts[i].co[0]))
            if f not in frames or (frames[f] is not None and bone not in frames[f]):
                pts.remove(pts[i], fast=True)
        fc.update()


def _points(obj, action, frames):
    """(n, 2 B, 3) world heads then tails of every bone at `frames`, playing `action`."""
    ad = obj.animation_data
    ad.action = action
    if hasattr(ad, "action_slot") and len(action.slots):
        ad.action_slot = action.slots[0]
    M = np.array(obj.matrix_world)
    out = []
    for f in frames:
        bpy.context.scene.frame_set(f)
        local = [pb.head for pb in obj.pose.bones] + [pb.tail for pb in obj.pose.bones]
        out.append(np.array(local) @ M[:3, :3].T + M[:3, 3])
    return np.array(out)


def _bone_matrices(obj, action, frames, names):
    """(n, len(names), 4, 4) world matrices of the named pose bones at `frames`, playing `action`."""
    ad = obj.animation_data
    ad.action = action
    if hasattr(ad, "action_slot") and len(action.slots):
        ad.action_slot = action.slots[0]
    M = np.array(obj.matrix_world)
    out = []
    for f in frames:
        bpy.context.scene.frame_set(f)
        out.append([M @ np.array(obj.pose.bones[n].matrix) for n in names])
    return np.array(out)


def _through_fbx(obj, folder):
    """The armature written as FBX (Blender's exporter, its defaults: the animation baked at every frame)
    and read back (its importer's defaults) in place of it; returns the imported armature."""
    import os

    os.makedirs(folder, exist_ok=True)
    path = os.path.join(folder, "clip.fbx")
    bpy.ops.export_scene.fbx(filepath=path, use_selection=True, object_types={"ARMATURE"})
    for o in list(bpy.data.objects):
        bpy.data.objects.remove(o)
    for a in list(bpy.data.actions):
        bpy.data.actions.remove(a)
    bpy.ops.import_scene.fbx(filepath=path)
    [arm] = [o for o in bpy.data.objects if o.type == "ARMATURE"]
    bpy.context.view_layer.objects.active = arm
    return arm


def _cancel(name):
    """Run the add-on's SolveRun as the modal operator does, cancelled after the first round; the error
    line or None."""
    import importlib
    import time

    addon = importlib.import_module(name)
    run = addon.SolveRun(clean=False)
    try:
        run.prepare(bpy.context)
        while not run.job.poll():
            if run.job.rounds >= 1 and not run.job.cancelled:
                run.job.cancel()
            time.sleep(0.02)
        if run.job.error is not None:
            return run.job.error
        message = run.finish(bpy.context)
        if run.job.codes[0] != 130:  # the solve's own exit code when interrupted (README "Exit codes")
            return f"not interrupted: the solve's exit code {run.job.codes[0]}; {message}"
        return None
    finally:
        run.cleanup()


def main(zip_path, cli, clip, mode, frames="", out_dir="", feet=""):
    name = _install(zip_path, cli)
    bpy.ops.import_anim.bvh(filepath=clip, update_scene_fps=True)
    obj = bpy.context.object
    if mode in ("fbx", "fbx-clean"):
        obj = _through_fbx(obj, out_dir)
    keys = {}  # "42" a full key, "82:Hips+LeftUpLeg" a partial key of those bones
    for word in frames.split(",") if frames else []:
        f, _, bones = word.partition(":")
        keys[int(f)] = set(bones.split("+")) if bones else None
    if mode in ("inbetween", "rerun", "unknown", "mapped", "badmap", "cancel", "fbx"):
        _keep_keys(obj, keys)
    if mode == "rerun":  # a box off the path, selected with the armature: the scene's box (x 49..51, y -2..2, z 0..2)
        bpy.ops.mesh.primitive_cube_add(location=(50.0, 0.0, 1.0), scale=(1.0, 2.0, 1.0))
        bpy.context.object.select_set(True)
        obj.select_set(True)
        bpy.context.view_layer.objects.active = obj
    names = [pb.name for pb in obj.pose.bones]  # as imported (a renamed rig's bones in the same order)
    if mode in ("unknown", "mapped", "badmap"):
        for i, bone in enumerate(obj.data.bones):
            bone.name = f"b{i}"
    if mode in ("mapped", "badmap"):
        import os

        os.makedirs(out_dir, exist_ok=True)
        path = os.path.join(out_dir, "..", "map.json")
        with open(path, "w") as f:  # CMU's unit, which only CMU's joint names allow by themselves; or no unit
            f.write('{"unit": "cmu"}' if mode == "mapped" else '{"unit": "furlong"}')
        bpy.context.scene.dynsplines.skeleton_map = path
    bpy.context.scene.dynsplines.out_dir = out_dir
    original = obj.animation_data.action
    error = None
    if mode == "cancel":
        error = _cancel(name)
    else:
        bpy.context.scene.dynsplines.max_evals = 0  # the whole solve: the test checks the keys and the floor
        try:
            for _ in range(2 if mode == "rerun" else 1):
                getattr(bpy.ops.dynsplines, "clean" if mode.endswith("clean") else "inbetween")()
        except RuntimeError as e:  # an operator's ERROR report, as bpy.ops raises it in background mode
            error = str(e)
    out = {"actions": sorted(a.name for a in bpy.data.actions), "assigned": obj.animation_data.action.name,
           "original": original.name, "error": error, "bones": names,
           "ranges": {a.name: list(a.frame_range) for a in bpy.data.actions}}
    result = bpy.data.actions.get(original.name + ".dynsplines")
    if result is not None:
        f0, f1 = (int(round(v)) for v in result.frame_range)
        out["frames"] = list(range(f0, f1 + 1))
        out["result_points"] = _points(obj, result, out["frames"]).tolist()
        out["original_points"] = _points(obj, original, out["frames"]).tolist()
        names = [n for n in feet.split(",") if n in obj.pose.bones] if feet else []  # renamed rigs: none
        out["feet_result"] = _bone_matrices(obj, result, out["frames"], names).tolist()
        out["feet_original"] = _bone_matrices(obj, original, out["frames"], names).tolist()
    print(json.dumps(out))


if __name__ == "__main__":
    main(*sys.argv[1:])
