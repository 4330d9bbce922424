"""Reading an armature's keyed frames and writing a solved motion back as a new action (Blender's side).

Actions are layered since Blender 4.4 (5.0 removed `Action.fcurves`): F-curves live in the channelbag of
the action slot the armature uses (`bpy_extras.anim_utils`); Blender 4.2 and 4.3 keep them on the action.

The solved motion comes back as a BVH file on the armature's own skeleton (`dynsplines export --skeleton
source`), which Blender's importer turns into a temporary armature with its own bone rolls. Its motion is
carried over bone by bone as the change from rest, in armature space: the BVH exporter writes each joint's
pose as D = P R^-1 (P the posed bone matrix, R its rest matrix), so the source armature's bone is posed
at P' = D R' with its own rest R', which keeps any roll the rig's bones have. The local channels follow
from the posed matrices: basis = (R_parent^-1 R)^-1 (P_parent^-1 P) (a bone that inherits its parent's
rotation and scale, as rigs' deform bones do).
"""
import bpy

#: the suffix of the result action's name: `<action>.dynsplines`
RESULT_SUFFIX = ".dynsplines"
#: F-curve keyframe interpolation 'LINEAR' as `foreach_set` takes it (the enum's index): a dense bake
#: at every frame is the motion itself, linear between frames
_LINEAR = 1


def assigned_action(obj):
    """(action, slot) the object's animation uses (slot None before Blender 4.4), or (None, None)."""
    ad = obj.animation_data
    if ad is None or ad.action is None:
        return None, None
    return ad.action, getattr(ad, "action_slot", None)


def source_action(obj):
    """The action to solve: the assigned one, or, when that is an earlier result (`<action>.dynsplines`)
    whose action is still there, that action, assigned again (a re-run solves the keys, not the bake)."""
    action, _ = assigned_action(obj)
    if action is None or not action.name.endswith(RESULT_SUFFIX):
        return action
    original = bpy.data.actions.get(action.name[: -len(RESULT_SUFFIX)])
    if original is None:
        return action
    ad = obj.animation_data
    ad.action = original
    if hasattr(ad, "action_slot") and ad.action_slot is None and len(original.slots):
        ad.action_slot = original.slots[0]
    return original


def fcurves_of(action, slot):
    """The F-curves of `slot` in `action` (layered actions), or the action's own (Blender 4.2, 4.3)."""
    if hasattr(action, "layers"):  # Blender 4.4+
        from bpy_extras import anim_utils

        bag = anim_utils.action_get_channelbag_for_slot(action, slot) if slot is not None else None
        return list(bag.fcurves) if bag is not None else []
    return list(action.fcurves)


def keyed_bones(obj):
    """{frame: set of bone names keyed there} of the object's action: any channel of a bone keyed at a
    frame keys the bone (subframe keys round to the nearest frame: the solve works on whole frames)."""
    action, slot = assigned_action(obj)
    out = {}
    if action is None:
        return out
    for fc in fcurves_of(action, slot):
        if fc.data_path.startswith('pose.bones["'):
            bone = bpy.utils.unescape_identifier(fc.data_path[len('pose.bones["'):].split('"]', 1)[0])
            co = [0.0] * (2 * len(fc.keyframe_points))
            fc.keyframe_points.foreach_get("co", co)  # (frame, value) pairs, read at once
            for f in co[::2]:
                out.setdefault(int(round(f)), set()).add(bone)
    return out


def keyed_frames(obj):
    """The frames (sorted ints) where any bone channel of the object's action has a key."""
    return sorted(keyed_bones(obj))


def partial_keys(obj):
    """{frame: sorted bone names} of the frames where only some of the animated bones are keyed (a
    partial keyframe); the other keyed frames key every animated bone."""
    keys = keyed_bones(obj)
    animated = set().union(*keys.values()) if keys else set()
    return {f: sorted(bones) for f, bones in keys.items() if bones != animated}


def _pose_matrices(src, dst, names):
    """{bone: posed matrix (armature space) of `dst`'s bone}: the change from rest of `src`'s same-named
    bone (module docstring), at the current frame."""
    out = {}
    for name in names:
        sb = src.data.bones[name]
        out[name] = src.pose.bones[name].matrix @ sb.matrix_local.inverted() @ dst.data.bones[name].matrix_local
    return out


def _basis(bone, posed):
    """The bone's local transform (its channels) that gives the armature-space matrix posed[bone.name]."""
    rest = bone.matrix_local
    if bone.parent is None:
        return rest.inverted() @ posed[bone.name]
    parent = bone.parent
    rel_rest = parent.matrix_local.inverted() @ rest
    rel_pose = posed[parent.name].inverted() @ posed[bone.name]
    return rel_rest.inverted() @ rel_pose


def _channels(pb, basis, prev):
    """{data path: values} of pose bone `pb` for the local transform `basis`; prev: the previous frame's
    rotation (keeps quaternions in one hemisphere and Euler angles continuous)."""
    loc, quat, _ = basis.decompose()
    out = {} if pb.bone.use_connect else {"location": tuple(loc)}
    mode = pb.rotation_mode
    if mode == "QUATERNION":
        if prev is not None and quat.dot(prev) < 0:
            quat.negate()
        out["rotation_quaternion"] = tuple(quat)
        return out, quat
    if mode == "AXIS_ANGLE":
        axis, angle = quat.to_axis_angle()
        out["rotation_axis_angle"] = (angle, *axis)
        return out, quat
    euler = quat.to_euler(mode, prev) if prev is not None else quat.to_euler(mode)
    out["rotation_euler"] = tuple(euler)
    return out, euler


def sample_motion(src, dst, frames):
    """{(data path, index): [(frame, value)]}: the motion of armature `src` (the imported result) carried
    onto armature `dst`, at the scene frames `frames` (module docstring). Bones of `dst` that `src` lacks
    are left out."""
    scene = bpy.context.scene
    names = [b.name for b in dst.data.bones if b.name in src.data.bones]
    keys, prev = {}, {}
    for f in frames:
        scene.frame_set(f)
        posed = _pose_matrices(src, dst, names)
        for name in names:
            pb = dst.pose.bones[name]
            channels, prev[name] = _channels(pb, _basis(pb.bone, posed), prev.get(name))
            for prop, values in channels.items():
                path = f'pose.bones["{bpy.utils.escape_identifier(name)}"].{prop}'
                for i, v in enumerate(values):
                    keys.setdefault((path, i, name), []).append((f, v))
    return keys


def _new_fcurves(action, obj):
    """The F-curve collection of a new action for `obj` (its slot made and assigned), and the slot."""
    ad = obj.animation_data_create()
    if hasattr(action, "layers"):  # Blender 4.4+
        slot = action.slots.new(id_type="OBJECT", name=obj.name)
        layer = action.layers.new("Layer")
        strip = layer.strips.new(type="KEYFRAME")
        bag = strip.channelbag(slot, ensure=True)
        ad.action = action
        ad.action_slot = slot
        return bag.fcurves, slot
    ad.action = action
    return action.fcurves, None


def write_action(obj, name, keys):
    """A new action `name` on `obj` with the keys {(data path, index, bone): [(frame, value)]}, linear
    between frames, replacing an action of that name (a re-run replaces its result). Returns it."""
    old = bpy.data.actions.get(name)
    if old is not None:
        bpy.data.actions.remove(old)
    action = bpy.data.actions.new(name)
    fcurves, _ = _new_fcurves(action, obj)
    for (path, index, group), points in keys.items():
        fc = fcurves.new(path, index=index, action_group=group) if not hasattr(action, "layers") else \
            fcurves.new(path, index=index, group_name=group)
        fc.keyframe_points.add(len(points))
        fc.keyframe_points.foreach_set("co", [c for p in points for c in p])
        fc.keyframe_points.foreach_set("interpolation", [_LINEAR] * len(points))
        fc.update()
    return action

