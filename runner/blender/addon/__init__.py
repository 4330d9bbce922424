"""dynsplines for Blender: solve the active armature's action with the installed `dynsplines` command.

Two operators, in the 3D viewport's sidebar (tab "dynsplines") on the active armature:

* `dynsplines.inbetween`: the frames keyed in the armature's action are the keyframes (poses as keyed,
  feet not planted), the in-betweens solved as `dynsplines animate` does;
* `dynsplines.clean`: the action as a capture, keyed as `dynsplines mocap` keys a clip (every 0.25 s).

Either way the result is a new action `<action>.dynsplines`, baked at every scene frame between the first
and the last key and assigned to the armature; the original action is kept (a fake user). Re-running
replaces the result. How: the action goes out as BVH with Blender's own exporter (the armature's bones,
rest pose and frame rate), `dynsplines mocap` recognises the skeleton (CMU, Mixamo, Rigify, LAFAN1, ...),
solves, and `dynsplines export` writes the result back onto that skeleton; Blender's importer reads it
and the motion is carried onto the armature's bones (actions.py).

The command runs in a subprocess (job.py), not in Blender's Python: its path is in the add-on's
preferences (found on PATH when empty). Interactively a modal operator polls it on a timer (progress in
the status bar, Esc cancels and keeps the best path so far); in background mode (`blender -b`, scripts,
tests) the operators run to completion. A failed command is an error report with its one line.

This package imports only Blender's modules and the standard library (it runs in Blender's Python).
"""
import json
import os
import tempfile

import bpy

from . import actions
from .job import Job, JobError, find_cli

#: the skeleton map given with the exported BVH: it starts at the first key, no rest pose before the motion
_MAP = {"rest_frames": 0}
#: [s] the timer's period while a solve runs (Blender redraws the status bar at this rate)
_TICK = 0.2


class DynsplinesPreferences(bpy.types.AddonPreferences):
    bl_idname = __package__

    cli: bpy.props.StringProperty(
        name="dynsplines command", subtype="FILE_PATH", default="",
        description="Path of the installed `dynsplines` executable; empty: found on PATH")

    def draw(self, context):
        self.layout.prop(self, "cli")


class DynsplinesSettings(bpy.types.PropertyGroup):
    terms: bpy.props.EnumProperty(
        name="Terms", default="default",
        items=[("default", "Default", "The constraints (contacts, joints, no jolts)"),
               ("all", "All", "Also the force bounds (--terms all)")])
    tol: bpy.props.FloatProperty(name="Tolerance", default=0.01, min=1e-4, max=1.0,
                                 description="Refinement tolerance: the decrease of E still predicted, over E (--tol)")
    scene: bpy.props.EnumProperty(
        name="Scene", default="floor",
        items=[("floor", "Floor", "Blender's ground plane (z = 0 of the armature) and the selected meshes as boxes "
                                  "(--scene floor --boxes)"),
               ("auto", "Fitted", "A floor and boxes fitted to where the feet rest (--scene auto)")])
    skeleton_map: bpy.props.StringProperty(
        name="Skeleton map", subtype="FILE_PATH", default="",
        description="A JSON file naming the bone of each role the recogniser cannot find, and the unit and up "
                    "axis, e.g. {\"hips\": \"pelvis\", \"unit\": \"cm\"} (--skeleton-map, docs/mocap.md); empty: "
                    "every role recognised")
    out_dir: bpy.props.StringProperty(
        name="Keep files in", subtype="DIR_PATH", default="",
        description="A folder for the command's files (the BVH, keyframe file, saved path .npz for `dynsplines "
                    "view`, metrics); empty: a temporary folder, removed after the run")
    max_evals: bpy.props.IntProperty(name="Max evaluations", default=0, min=0,
                                     description="Cap on the solve's evaluations, 0: none (--max-evals)")


def _cli_path(context):
    addon = context.preferences.addons.get(__package__)
    return addon.preferences.cli if addon is not None else ""


def _commands(context, bvh, frames, clean, out):
    """[(label, argv)] of one solve: mocap (keys, solve, saved path) then export (onto the skeleton)."""
    s = context.scene.dynsplines
    cli = find_cli(_cli_path(context))
    npz = os.path.join(out, "path.npz")
    mocap = [cli, "mocap", bvh, "--out-dir", out, "--save-path", npz, "--no-render", "--no-summary",
             "--terms", s.terms, "--tol", f"{s.tol:g}", "--scene", s.scene]
    user_map = _user_map(s)
    if clean:  # a capture: its rest pose (a T-pose before the motion, as CMU's clips have) found as mocap finds it
        mocap += ["--every", "0.25"]
        if user_map:
            mocap += ["--skeleton-map", bpy.path.abspath(s.skeleton_map)]
    else:
        skel = os.path.join(out, "skeleton.json")
        with open(skel, "w", encoding="utf-8") as f:
            json.dump({**user_map, **_MAP}, f)
        mocap += ["--key-frames", ",".join(str(f - frames[0]) for f in frames), "--skeleton-map", skel]
        partial = actions.partial_keys(context.active_object)
        if partial:  # a bone keyed on some channels keys the bone; a frame keying some bones is partial
            path = os.path.join(out, "key_joints.json")
            with open(path, "w", encoding="utf-8") as f:
                json.dump({str(k - frames[0]): v for k, v in partial.items()}, f)
            mocap += ["--key-joints", path]
    boxes = _boxes(context) if s.scene == "floor" else []
    if boxes:
        path = os.path.join(out, "boxes.json")
        with open(path, "w", encoding="utf-8") as f:
            json.dump(boxes, f)
        mocap += ["--boxes", path]
    if s.max_evals > 0:
        mocap += ["--max-evals", str(s.max_evals)]
    # the feet where the solve put them on the floor (clean: the capture stood on it; in-between: no change)
    export = [cli, "export", npz, "--to", os.path.join(out, "result.bvh"), "--skeleton", "source",
              "--root-height", "solved"]
    return [("solving", mocap), ("exporting", export)]


def _user_map(settings):
    """The user's skeleton map (the panel's file) as a dict, {} without one.

    Raises:
        JobError: the file is missing or not a JSON object (its own keys are checked by the command).
    """
    if not settings.skeleton_map:
        return {}
    path = bpy.path.abspath(settings.skeleton_map)
    try:
        with open(path, encoding="utf-8") as f:
            doc = json.load(f)
    except (OSError, ValueError) as e:
        raise JobError(f"dynsplines: error: skeleton map {path}: cannot read it as JSON ({e}); give a JSON file "
                       "such as {\"hips\": \"pelvis\", \"unit\": \"cm\"}") from None
    if not isinstance(doc, dict):
        raise JobError(f"dynsplines: error: skeleton map {path}: a JSON object is expected, e.g. "
                       "{\"hips\": \"pelvis\", \"unit\": \"cm\"}")
    return doc


def _boxes(context):
    """[{"min", "max"}] the selected mesh objects as boxes (`--boxes`): the bounds of their world-space
    bounding boxes, taken into the active armature's space (the space its BVH is written in), axis-aligned."""
    from mathutils import Vector

    arm = context.active_object
    to_arm = arm.matrix_world.inverted()
    out = []
    for obj in context.selected_objects:
        if obj.type != "MESH" or obj is arm:
            continue
        corners = [to_arm @ (obj.matrix_world @ Vector(c)) for c in obj.bound_box]
        out.append({"min": [min(c[i] for c in corners) for i in range(3)],
                    "max": [max(c[i] for c in corners) for i in range(3)]})
    return out


def _armature(context):
    """The active armature with an action, or a one-line reason why not."""
    obj = context.active_object
    if obj is None or obj.type != "ARMATURE":
        return None, "dynsplines: select an armature (the active object is not one)"
    if actions.source_action(obj) is None:
        return None, f"dynsplines: the armature {obj.name} has no action; key its bones first"
    return obj, None


def _export_bvh(context, obj, frames, path):
    """The armature's motion over the keyed range as BVH (Blender's exporter: armature space, scene rate)."""
    with context.temp_override(active_object=obj, object=obj, selected_objects=[obj]):
        bpy.ops.export_anim.bvh(filepath=path, frame_start=frames[0], frame_end=frames[-1], rotate_mode="NATIVE",
                                root_transform_only=False, global_scale=1.0)


def _import_result(context, obj, path, first):
    """Read the result BVH (Blender's importer, file axes as written: armature space) and carry its motion
    onto `obj` as the new action; the temporary armature is removed. Returns the new action."""
    before = set(bpy.data.objects)
    actions_before = set(bpy.data.actions)
    selected = [o.name for o in context.selected_objects]  # the importer selects its armature alone
    bpy.ops.import_anim.bvh(filepath=path, axis_forward="Y", axis_up="Z", global_scale=1.0, frame_start=first,
                            use_fps_scale=False, update_scene_fps=False, update_scene_duration=False,
                            rotate_mode="NATIVE")  # makes the new armature the active object
    [tmp] = [o for o in bpy.data.objects if o not in before]
    try:
        action, _ = actions.assigned_action(tmp)
        start, end = (int(round(v)) for v in action.frame_range)
        original, _ = actions.assigned_action(obj)
        keys = actions.sample_motion(tmp, obj, range(start, end + 1))
        original.use_fake_user = True  # kept when the result takes its place
        return actions.write_action(obj, original.name + actions.RESULT_SUFFIX, keys)
    finally:
        data = tmp.data
        bpy.data.objects.remove(tmp)
        bpy.data.armatures.remove(data)
        for a in set(bpy.data.actions) - actions_before:
            if not a.name.endswith(actions.RESULT_SUFFIX):
                bpy.data.actions.remove(a)
        for name in selected:
            if name in bpy.data.objects:
                bpy.data.objects[name].select_set(True)
        context.view_layer.objects.active = obj


def _bug(e):
    """The report of an unexpected failure of the add-on itself."""
    return (f"dynsplines: the add-on failed: {type(e).__name__}: {e} (please report it, with the Blender "
            "version and the rig)")


class SolveRun:
    """One solve of an armature's action, outside any operator (the operators drive it; scripts may too):
    `prepare` exports the action and makes the job, `job.poll()` / `job.run()` runs the command,
    `finish` reads the result back as the new action and returns the message, `cleanup` removes the
    temporary folder. Raises JobError with the one line to report."""

    def __init__(self, clean=False):
        self.clean, self.job, self.folder, self.keep = clean, None, None, False

    def prepare(self, context):
        obj, why = _armature(context)
        if obj is None:
            raise JobError(why)
        frames = actions.keyed_frames(obj)
        if len(frames) < 2:
            raise JobError(f"dynsplines: the action of {obj.name} has keys at {len(frames)} frame(s); key at "
                           "least two frames")
        self.obj, self.frames = obj.name, frames
        kept = bpy.path.abspath(context.scene.dynsplines.out_dir) if context.scene.dynsplines.out_dir else ""
        if kept:
            os.makedirs(kept, exist_ok=True)
        self.folder, self.keep = kept or tempfile.mkdtemp(prefix="dynsplines-"), bool(kept)
        bvh = os.path.join(self.folder, f"{bpy.path.clean_name(obj.name)}.bvh")
        frame = context.scene.frame_current
        _export_bvh(context, obj, frames, bvh)
        context.scene.frame_set(frame)
        self.job = Job(_commands(context, bvh, frames, self.clean, self.folder), self.folder)

    def finish(self, context):
        """The result as the armature's new action; returns the message to report."""
        obj = bpy.data.objects[self.obj]
        frame = context.scene.frame_current
        action = _import_result(context, obj, os.path.join(self.folder, "result.bvh"), self.frames[0])
        context.scene.frame_set(frame)
        how = "cancelled: the best path so far" if self.job.cancelled else "solved"
        return (f"dynsplines: {how}; wrote the action {action.name} on {obj.name} ({len(self.frames)} keyed "
                f"frames, {self.frames[0]}..{self.frames[-1]})")

    def cleanup(self):
        import shutil

        if self.folder and not self.keep:
            shutil.rmtree(self.folder, ignore_errors=True)


class _Solve:
    """The shared body of the two operators (a `SolveRun`, to completion or modal)."""

    bl_options = {"REGISTER", "UNDO"}
    clean = False

    @classmethod
    def poll(cls, context):
        obj = context.active_object
        return obj is not None and obj.type == "ARMATURE"

    def execute(self, context):
        """Run to completion (background mode, scripts, F3 without a window)."""
        run = SolveRun(self.clean)
        try:
            run.prepare(context)
            run.job.run()
            self._report_result(context, run)
        except JobError as e:
            self.report({"ERROR"}, str(e))
            return {"CANCELLED"}
        except Exception as e:  # noqa: BLE001 - a bug of the add-on: one line, not a traceback
            self.report({"ERROR"}, _bug(e))
            return {"CANCELLED"}
        finally:
            run.cleanup()
        return {"FINISHED"}

    def _report_result(self, context, run):
        """The result read back (`SolveRun.finish`) and reported, with each warning of the job's commands."""
        self.report({"INFO"}, run.finish(context))
        for line in run.job.warnings:
            self.report({"WARNING"}, line)

    def invoke(self, context, event):
        if bpy.app.background or context.window_manager is None or context.window is None:
            return self.execute(context)
        self._run = SolveRun(self.clean)
        try:
            self._run.prepare(context)
        except Exception as e:  # noqa: BLE001 - the command's line, or a bug of the add-on: one line
            self._run.cleanup()
            self.report({"ERROR"}, str(e) if isinstance(e, JobError) else _bug(e))
            return {"CANCELLED"}
        wm = context.window_manager
        self._timer = wm.event_timer_add(_TICK, window=context.window)
        wm.progress_begin(0, 100)
        wm.modal_handler_add(self)
        return {"RUNNING_MODAL"}

    def modal(self, context, event):
        wm, job = context.window_manager, self._run.job
        if event.type == "ESC" and event.value == "PRESS":
            job.cancel()  # the solve ends with its best path so far, which still comes back
            return {"RUNNING_MODAL"}
        if event.type != "TIMER":
            return {"PASS_THROUGH"}
        try:
            done = job.poll()
        except OSError as e:  # the command could not be started
            job.error, done = f"dynsplines: the command {job.commands[0][1][0]} could not be run: {e}", True
        wm.progress_update(int(90 - 80 / (1 + job.rounds / 4) if job.index == 0 else 95))
        context.workspace.status_text_set(f"dynsplines {job.label} (Esc cancels): {job.status}")
        if not done:
            return {"RUNNING_MODAL"}
        wm.event_timer_remove(self._timer)
        wm.progress_end()
        context.workspace.status_text_set(None)
        try:
            if job.error is not None:
                self.report({"ERROR"}, job.error)
                return {"CANCELLED"}
            self._report_result(context, self._run)
            return {"FINISHED"}
        except Exception as e:  # noqa: BLE001 - a bug of the add-on: one line, not a traceback
            self.report({"ERROR"}, _bug(e))
            return {"CANCELLED"}
        finally:
            self._run.cleanup()


class DYNSPLINES_OT_inbetween(_Solve, bpy.types.Operator):
    """Solve the in-betweens of the keyed frames (they are the keyframes) into a new action"""

    bl_idname = "dynsplines.inbetween"
    bl_label = "In-between keys"


class DYNSPLINES_OT_clean(_Solve, bpy.types.Operator):
    """Clean the action as a capture (keyed every 0.25 s, as dynsplines mocap does) into a new action"""

    bl_idname = "dynsplines.clean"
    bl_label = "Clean capture"
    clean = True


class DYNSPLINES_PT_panel(bpy.types.Panel):
    bl_label = "dynsplines"
    bl_space_type = "VIEW_3D"
    bl_region_type = "UI"
    bl_category = "dynsplines"

    @classmethod
    def poll(cls, context):
        obj = context.active_object
        return obj is not None and obj.type == "ARMATURE"

    def draw(self, context):
        layout, s = self.layout, context.scene.dynsplines
        obj = context.active_object
        action, _ = actions.assigned_action(obj)
        layout.label(text=f"Action: {action.name if action else 'none'}", icon="ACTION")
        if action is not None:  # its frame range (counting its keys at every redraw would slow the UI)
            start, end = action.frame_range
            layout.label(text=f"Frames {start:g}..{end:g}")
        for name in ("terms", "tol", "scene", "skeleton_map", "out_dir", "max_evals"):
            layout.prop(s, name)
        col = layout.column(align=True)
        col.operator(DYNSPLINES_OT_inbetween.bl_idname, icon="IPO_BEZIER")
        col.operator(DYNSPLINES_OT_clean.bl_idname, icon="MOD_SMOOTH")


_CLASSES = (DynsplinesPreferences, DynsplinesSettings, DYNSPLINES_OT_inbetween, DYNSPLINES_OT_clean,
            DYNSPLINES_PT_panel)


def register():
    for cls in _CLASSES:
        bpy.utils.register_class(cls)
    bpy.types.Scene.dynsplines = bpy.props.PointerProperty(type=DynsplinesSettings)


def unregister():
    del bpy.types.Scene.dynsplines
    for cls in reversed(_CLASSES):
        bpy.utils.unregister_class(cls)
