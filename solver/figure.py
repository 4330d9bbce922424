"""`Figure`: what the tools know about the articulated figure, read from its MuJoCo model.

Everything figure-specific that the solver and the runner use comes from here, so that another figure
(other proportions, masses or contact sites) is another MJCF file and nothing else:

- from MuJoCo's own fields: the bodies and their tree, the joints (kind, `qpos`/`qvel` addresses), the
  masses, the segment geometry (body positions) and the standing height (geom extents at `qpos0`);
- from the MJCF's `<custom>` annotations (models/README.md, "The figure's annotations"):
    ``<text name="figure:foot:SIDE" data="HEEL TOE"/>``      the contact sites of each foot; the figure's
                                                             contact sites are the feet's, in file order;
    ``<numeric name="figure:flexion:JOINT" data="x y z"/>``  the flexion axis of a hinge-like ball joint
                                                             (knee, elbow) in the joint's frame;
    ``<text name="figure:end:BODY" data="SITE"/>``           where the segment of a body without a single
                                                             child body ends (top of the head, ball of
                                                             the foot, wrist);
- by name: the geom ``neck`` (a capsule from the neck's base to the skull's base) and the site ``head``
  (top of the head), for the neck and head bones of a skeleton export.

The shipped figure is `FIGURE_FILE` (models/humanoid39.xml); `shipped_figure()` reads it once.
"""
from __future__ import annotations

from collections.abc import Mapping, Sequence
from dataclasses import dataclass
from functools import lru_cache
from pathlib import Path
from types import MappingProxyType

import numpy as np

from solver.errors import InputError
from solver.layout import Joint, StateLayout, find_joint

__all__ = ["MODELS_DIR", "FIGURE_FILE", "Figure", "Segment", "NeckChain", "foot_sites", "model_contact_sites", "model_feet", "shipped_figure"]

#: the folder of the shipped models (figure, scenes, example keyframe files, the CMU clip): beside this
#: package, where a checkout links the top-level models/ (solver/models) and an installation copies it
MODELS_DIR = Path(__file__).resolve().parent / "models"
#: the shipped figure's MJCF file: the one place its path is written
FIGURE_FILE = MODELS_DIR / "humanoid39.xml"

_FOOT, _FLEXION, _END, _SOLE = "figure:foot:", "figure:flexion:", "figure:end:", "figure:sole:"
_NECK_GEOM, _HEAD_SITE = "neck", "head"


@dataclass(frozen=True, eq=False)
class Segment:
    """The segment (bone) of one body at the model's rest pose (`qpos0`).

    Attributes:
        body: the body's name.
        end: (3,) end of the segment in the body frame [m]; it starts at the body origin (the joint
            centre). The end is the origin of the body's single child body, else the site named by
            ``figure:end:BODY``.
    """

    body: str
    end: np.ndarray

    @property
    def length(self) -> float:
        """|end| [m]."""
        return float(np.linalg.norm(self.end))

    @property
    def direction(self) -> np.ndarray:
        """(3,) unit direction from the joint centre to the end, body frame."""
        return self.end / self.length


@dataclass(frozen=True, eq=False)
class NeckChain:
    """The neck and head of a figure whose head is rigid with its trunk, as bones for a skeleton export.

    Attributes:
        body: the body that holds the neck geom and the head site (the torso).
        neck: (3,) base of the neck [m], body frame: the neck capsule's lower end.
        skull: (3,) base of the skull [m], body frame: the neck capsule's upper end.
        top: (3,) top of the head [m], body frame: the site ``head``.
    """

    body: str
    neck: np.ndarray
    skull: np.ndarray
    top: np.ndarray


@dataclass(frozen=True, eq=False)
class Figure:
    """The articulated figure of a MuJoCo model: the free-joint body and its descendants.

    Attributes:
        bodies: (B,) body names, MuJoCo's (depth-first) order, the root first.
        body_ids: (B,) MuJoCo body ids.
        parents: (B,) index into `bodies` of each body's parent; -1 for the root.
        joints: the figure's joints in `qpos` order (`solver.layout.Joint`: name, kind free/ball/slide/
            hinge, qpos address and width, dof address and width).
        joint_bodies: {joint name: (parent body, child body)}; the free root joint has parent "".
        flexion_axes: {joint name: (3,) unit flexion axis in the joint's frame} for the hinge-like ball
            joints (knees, elbows); flexion is the twist about it (`solver.quaternion.twist_angle`),
            hyperextension is flexion < 0 (paper sec. 5).
        contact_sites: (k,) the contact site names (the feet's, foot by foot).
        contact_site_ids: (k,) their MuJoCo site ids.
        feet: {side: (heel site, toe site)}.
        leg_joints: the root joint and every joint between the root body and a foot's sites, in
            `qpos` order (root, hips, knees, ankles): what pins the stride.
        segments: {body: Segment} for every body but the root that has a segment end (a single child
            body or a ``figure:end:BODY`` site); consumers check for the ones they need.
        body_masses: (B,) [kg]. total_mass: [kg].
        standing_height: [m] top of the highest geom minus the lowest contact site, at `qpos0`
            (standing upright: the identity pose).
        neck: the neck and head bones, or None if the model has no geom ``neck`` or site ``head``.
        soles: {side: (inner edge site, outer edge site)} (``figure:sole:SIDE``; {} when not annotated): the
            edges of a foot's sole across the ball of the foot, held in a clean no deeper in any surface than the
            capture holds them (the sole constraint), never in contact themselves (docs/contacts.md, "The soles'
            edges").
    Equality is identity (the fields hold arrays); build one per model with `from_model`.
    """

    bodies: tuple[str, ...]
    body_ids: np.ndarray
    parents: np.ndarray
    joints: tuple[Joint, ...]
    joint_bodies: Mapping[str, tuple[str, str]]
    flexion_axes: Mapping[str, np.ndarray]
    contact_sites: tuple[str, ...]
    contact_site_ids: np.ndarray
    feet: Mapping[str, tuple[str, str]]
    leg_joints: tuple[str, ...]
    segments: Mapping[str, Segment]
    body_masses: np.ndarray
    total_mass: float
    standing_height: float
    neck: NeckChain | None
    soles: Mapping[str, tuple[str, ...]]

    @property
    def sole_sites(self) -> tuple[str, ...]:
        """The soles' edge sites, side by side (`soles`)."""
        return tuple(s for pair in self.soles.values() for s in pair)

    @property
    def surface_sites(self) -> tuple[str, ...]:
        """The sites held out of every surface (penetration): the contact sites, then the soles' edges."""
        return self.contact_sites + self.sole_sites

    @property
    def root(self) -> str:
        """The root body's name (the one with the free joint)."""
        return self.bodies[0]

    def joint(self, name: str) -> Joint:
        """The figure's joint called `name`. Raises InputError listing the joints."""
        found = find_joint(self.joints, name)
        if found is None:
            raise InputError(f"the figure has no joint {name!r}; its joints are: {', '.join(j.name for j in self.joints)}")
        return found

    @classmethod
    def from_model(cls, model) -> Figure:
        """Read the figure of an MjModel (a figure file or a scene that includes one).

        Args:
            model: mujoco.MjModel with exactly one free joint, the figure's root.
        Returns:
            the Figure.
        Raises:
            InputError: no free joint or several; no ``figure:foot`` annotation; a ``figure:``
                annotation naming a site, joint or body the model does not have, or an axis that is not
                3 numbers of norm > 0; a segment of zero length.
        """
        import mujoco

        root = _root_body(model)
        ids = [root] + [b for b in range(root + 1, model.nbody) if _descends(model, b, root)]
        names = tuple(_name(model, mujoco.mjtObj.mjOBJ_BODY, b) for b in ids)
        parents = np.array([-1] + [ids.index(int(model.body_parentid[b])) for b in ids[1:]], int)
        joints, joint_bodies = [], {}
        for jid, j in enumerate(StateLayout.from_model(model).joints):  # joint id order
            if int(model.jnt_bodyid[jid]) in ids:
                b = ids.index(int(model.jnt_bodyid[jid]))
                joints.append(j)
                joint_bodies[j.name] = (names[parents[b]] if parents[b] >= 0 else "", names[b])
        joints = tuple(joints)
        texts, numerics = _custom(model)
        feet = _feet(model, texts)
        sites = foot_sites(feet)
        site_ids = np.array([model.site(s).id for s in sites], int)
        axes = _flexion_axes(numerics, {j.name: j for j in joints})
        segments = {names[i]: _segment(model, ids, names, i, texts) for i in range(1, len(ids))}
        segments = {b: seg for b, seg in segments.items() if seg is not None}
        masses = np.array(model.body_mass[ids], float)
        legs = _leg_bodies(model, ids, names, site_ids)
        leg_joints = tuple(j.name for j in joints if joint_bodies[j.name][1] in legs)
        return cls(names, _frozen(ids, int), _frozen(parents, int), joints, MappingProxyType(joint_bodies),
                   MappingProxyType(axes), sites, _frozen(site_ids, int), MappingProxyType(feet), leg_joints,
                   MappingProxyType(segments), _frozen(masses, float), float(masses.sum()),
                   _standing_height(model, ids, site_ids), _neck(model, ids, names),
                   MappingProxyType(_soles(model, texts, feet)))


def foot_sites(feet: Mapping[str, Sequence[str]]) -> tuple[str, ...]:
    """The contact sites of `feet` ({foot: its sites}, `Figure.feet`), foot by foot: the figure's contact
    sites (`Figure.contact_sites`) and the columns of its `site_pos` arrays."""
    return tuple(s for members in feet.values() for s in members)


def model_feet(model) -> dict[str, tuple[str, str]]:
    """The feet of the figure in an MjModel, {side: (heel site, toe site)}, from its ``figure:foot:SIDE``
    annotations alone (what `Figure.from_model(model).feet` holds, without reading the rest of the figure).

    Raises:
        InputError: no ``figure:foot`` annotation, one that does not name two sites, or names a site the
            model does not have.
    """
    return _feet(model, _custom(model)[0])


def model_contact_sites(model) -> tuple[str, ...]:
    """The contact sites of the figure in an MjModel, foot by foot (`Figure.contact_sites`, `model_feet`).

    Raises:
        InputError: as `model_feet`.
    """
    return foot_sites(model_feet(model))


@lru_cache(maxsize=1)
def shipped_figure() -> Figure:
    """The Figure of the shipped figure file `FIGURE_FILE`, read once."""
    import mujoco

    return Figure.from_model(mujoco.MjModel.from_xml_path(str(FIGURE_FILE)))


# ----------------------------------------------------------------------------------------- reading
def _frozen(values, dtype) -> np.ndarray:
    """A read-only copy of `values` (the Figure is a value: its arrays do not change)."""
    out = np.array(values, dtype)
    out.flags.writeable = False
    return out


def _leg_bodies(model, ids: list[int], names: tuple[str, ...], site_ids) -> set[str]:
    """The bodies from the root body down to the bodies holding the contact sites."""
    legs = set()
    for s in site_ids:
        b = int(model.site_bodyid[s])
        while b in ids:
            legs.add(names[ids.index(b)])
            b = int(model.body_parentid[b])
    return legs


def _name(model, kind, i: int) -> str:
    import mujoco

    return mujoco.mj_id2name(model, kind, int(i)) or f"#{i}"


def _root_body(model) -> int:
    import mujoco

    free = [j for j in range(model.njnt) if model.jnt_type[j] == mujoco.mjtJoint.mjJNT_FREE]
    if len(free) != 1:
        raise InputError(f"the model has {len(free)} free joints; the figure needs exactly one (its root): "
                         "include one figure (models/humanoid39.xml) and give other bodies no free joint")
    return int(model.jnt_bodyid[free[0]])


def _descends(model, body: int, root: int) -> bool:
    while body > 0:
        if body == root:
            return True
        body = int(model.body_parentid[body])
    return False


def _custom(model) -> tuple[dict[str, str], dict[str, np.ndarray]]:
    """The model's `<custom>` texts {name: data} and numerics {name: (size,) data}."""
    import mujoco

    texts = {}
    for i in range(model.ntext):
        adr, size = int(model.text_adr[i]), int(model.text_size[i])
        raw = bytes(model.text_data[adr:adr + size]).split(b"\0")[0].decode()
        texts[_name(model, mujoco.mjtObj.mjOBJ_TEXT, i)] = raw
    numerics = {}
    for i in range(model.nnumeric):
        adr, size = int(model.numeric_adr[i]), int(model.numeric_size[i])
        numerics[_name(model, mujoco.mjtObj.mjOBJ_NUMERIC, i)] = np.array(model.numeric_data[adr:adr + size], float)
    return texts, numerics


def _site(model, name: str, where: str) -> int:
    import mujoco

    i = mujoco.mj_name2id(model, mujoco.mjtObj.mjOBJ_SITE, name)
    if i < 0:
        raise InputError(f"{where} names the site {name!r}, which the model does not have; add "
                         f'<site name="{name}" .../> to the body it belongs to or fix the name')
    return i


def _feet(model, texts: dict[str, str]) -> dict[str, tuple[str, str]]:
    feet = {}
    for key, data in texts.items():
        if not key.startswith(_FOOT):
            continue
        pair = tuple(data.split())
        if len(pair) != 2:
            raise InputError(f'<text name="{key}" data="{data}">: give two site names, heel then toe')
        for s in pair:
            _site(model, s, f'<text name="{key}">')
        feet[key[len(_FOOT):]] = pair
    if not feet:
        raise InputError('the figure has no feet: add <custom><text name="figure:foot:left" data="l_heel l_toe"/>'
                         "...</custom> to its MJCF (models/README.md, \"The figure's annotations\")")
    return feet


def _soles(model, texts: dict[str, str], feet: Mapping[str, tuple[str, str]]) -> dict[str, tuple[str, str]]:
    """{side: (inner, outer)} of every ``figure:sole:SIDE`` annotation (`Figure.soles`)."""
    out = {}
    for key, data in texts.items():
        if not key.startswith(_SOLE):
            continue
        pair, side = tuple(data.split()), key[len(_SOLE):]
        if len(pair) != 2 or side not in feet:
            raise InputError(f'<text name="{key}" data="{data}">: give two site names, the sole\'s inner then outer edge, '
                             f"of a foot the figure has ({', '.join(f'figure:sole:{f}' for f in feet)})")
        for s in pair:
            _site(model, s, f'<text name="{key}">')
        out[side] = pair
    return out


def _flexion_axes(numerics: dict[str, np.ndarray], joints: dict[str, Joint]) -> dict[str, np.ndarray]:
    axes = {}
    for key, data in numerics.items():
        if not key.startswith(_FLEXION):
            continue
        name = key[len(_FLEXION):]
        if name not in joints or joints[name].kind != "ball":
            raise InputError(f'<numeric name="{key}">: the figure has no ball joint {name!r}; name a ball joint '
                             f"({', '.join(n for n, j in joints.items() if j.kind == 'ball')})")
        if data.shape != (3,) or not np.isfinite(data).all() or np.linalg.norm(data) == 0:
            raise InputError(f'<numeric name="{key}" data="{" ".join(map(str, data))}">: give an axis, 3 numbers '
                             'not all zero, e.g. data="0 1 0"')
        axes[name] = _frozen(data / np.linalg.norm(data), float)
    return axes


def _segment(model, ids: list[int], names: tuple[str, ...], i: int, texts: dict[str, str]) -> Segment | None:
    """The segment of body `names[i]`, or None if it has neither a single child body nor an end site."""
    body = names[i]
    children = [ids[c] for c in range(len(ids)) if c > 0 and int(model.body_parentid[ids[c]]) == ids[i]]
    key = _END + body
    if key in texts:
        end = np.array(model.site_pos[_site(model, texts[key].strip(), f'<text name="{key}">')], float)
        if int(model.site_bodyid[model.site(texts[key].strip()).id]) != ids[i]:
            raise InputError(f'<text name="{key}">: the site {texts[key].strip()!r} is not on the body {body!r}; '
                             "name a site of that body")
    elif len(children) == 1:
        end = np.array(model.body_pos[children[0]], float)
    else:
        return None
    if np.linalg.norm(end) == 0:
        raise InputError(f"the segment of the figure's body {body!r} has zero length; move its end away from "
                         "the joint centre")
    return Segment(body, _frozen(end, float))


def _standing_height(model, ids: list[int], site_ids: np.ndarray) -> float:
    """Top of the highest geom of the figure minus its lowest contact site [m], at `qpos0`.

    A geom's top is its world centre plus the z extent of its bounding box (`geom_aabb`, geom frame)."""
    import mujoco

    data = mujoco.MjData(model)
    mujoco.mj_kinematics(model, data)
    top = -np.inf
    for g in range(model.ngeom):
        if int(model.geom_bodyid[g]) not in ids:
            continue
        R = data.geom_xmat[g].reshape(3, 3)
        center, half = model.geom_aabb[g, :3], model.geom_aabb[g, 3:]
        top = max(top, data.geom_xpos[g, 2] + R[2] @ center + np.abs(R[2]) @ half)
    return float(top - data.site_xpos[site_ids, 2].min())


def _neck(model, ids: list[int], names: tuple[str, ...]) -> NeckChain | None:
    import mujoco

    g = mujoco.mj_name2id(model, mujoco.mjtObj.mjOBJ_GEOM, _NECK_GEOM)
    s = mujoco.mj_name2id(model, mujoco.mjtObj.mjOBJ_SITE, _HEAD_SITE)
    if g < 0 or s < 0 or int(model.geom_bodyid[g]) != int(model.site_bodyid[s]) or int(model.geom_bodyid[g]) not in ids:
        return None
    R = np.empty(9)
    mujoco.mju_quat2Mat(R, model.geom_quat[g])
    half = float(model.geom_size[g, 1]) * R.reshape(3, 3)[:, 2]
    ends = sorted((model.geom_pos[g] - half, model.geom_pos[g] + half), key=lambda p: p[2])
    body = names[ids.index(int(model.geom_bodyid[g]))]
    return NeckChain(body, _frozen(ends[0], float), _frozen(ends[1], float), _frozen(model.site_pos[s], float))
