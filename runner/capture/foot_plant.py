"""The footplant clean-up of an imported capture: every resting foot on the surface under it.

`runner.capture.root_height.correct_root_height` moves the whole figure up or down, so it puts only the lower
of two resting feet on its surface. Where the capture holds the other resting foot higher (its feet
disagree, `runner.capture.root_height.feet_disagreement`: marker offsets, a foot held up while the other
carries the weight), that foot stays above its surface by the difference: on 83_02 the right foot rests
flat 23 mm above the floor for 0.5 s while the left stands on it. Keyframes taken from such a capture hold
the foot up inside its own stance, and then no path through them both meets the keyframes and rests the
foot: it floats there, or taps down between the keys.

`plant_feet` puts every resting foot on its surface, as motion-capture clean-up enforces footplants by
inverse kinematics (Kovar, Schreiner & Gleicher, "Footskate cleanup for motion capture editing", SCA
2002), vertically only (the horizontal slide is the slide constraint's, judged against the capture's
own skate):

1. each foot, in every frame in which it rests (`runner.capture.stance.resting`: in the capture's
   stance, its lowest contact point below the flight height and still, the definition the root
   correction and the float bound use), is moved down by the least height above `CONTACT_CLEARANCE`
   its lowest point has in that rest within `LANDING_S` of the frame (`_settled`, a running minimum): a
   foot the capture holds up, or lets drift up and down while it rests as inertial captures do (a
   Perception Neuron foot sinking 12 mm over 1.3 s, an Xsens foot hovering 24 mm for 2 s after it
   landed), goes down onto the surface, while a landing or a lift-off inside the rest keeps its shape
   within `LANDING_S` of its touchdown. The rest's thresholds (under 3 cm, slower than 0.5 m/s) let a
   foot pass through them in no less than that; one slower than any step is held v LANDING_S over the
   surface (6 mm at 0.1 m/s) until it leaves the rest, where the smoothing below takes it up to the
   capture's height. A foot that would go down by no more than the capture's resolution (0.1 mm,
   `solver.foot_bounds.CAPTURE_RESOLUTION`) stays as captured. It moves by its own leg
   (`runner.capture.leg_ik.move_foot`: the knee flexes about its hinge, the foot keeps its orientation and
   its place along the surface);
2. what a straight knee leaves out of reach, the root is lowered by (the most over the resting feet),
   and a foot that this puts below `CONTACT_CLEARANCE` (the other foot) is lifted back by its leg;
3. nothing ends below `CONTACT_CLEARANCE`: where a leg could not lift its foot far enough, the root
   goes back up by the difference, as in `correct_root_height`.

Between a foot's rests (a swing) its drop is interpolated linearly, and the root's between frames in
which no foot rests (a flight), as `correct_root_height` carries its correction across them, and both
are smoothed by the same moving average (`SMOOTH_S`): a correction is carried over the motion rather
than undone in one frame at a lift-off.
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from runner.capture.clearance import CONTACT_CLEARANCE, ContactClearance, moving_average, smoothing_width
from runner.capture.contact_detection import DETECT_HEIGHT_ON, DETECT_SPEED_ON
from runner.capture.leg_ik import MOVE_TOL, leg_chain, move_foot
from runner.capture.stance import capture_rest
from solver.foot_bounds import CAPTURE_RESOLUTION

__all__ = ["FootPlant", "plant_feet"]

#: [s] the shortest a foot can take through a rest's height, DETECT_HEIGHT_ON (3 cm) at DETECT_SPEED_ON
#: (0.5 m/s): a landing or a lift-off inside a rest is kept within this of its touchdown
LANDING_S = DETECT_HEIGHT_ON / DETECT_SPEED_ON


@dataclass(frozen=True)
class FootPlant:
    """The footplant's result (module docstring).

    Attributes:
        qpos: (n, nq) the motion with its resting feet on their surfaces.
        foot_dz: (n, f) [m] how far each foot was moved in the world (its leg's move and the root's), + up
            (f feet, `Figure.feet` order).
        root_dz: (n,) [m] how far the root was moved, + up: down where a straight knee leaves a resting foot
            out of reach, back up only where a leg cannot lift its foot out of a surface.
        feet: the f foot names.
    """

    qpos: np.ndarray
    foot_dz: np.ndarray
    root_dz: np.ndarray
    feet: tuple[str, ...]

    def moved_at(self, frame: int) -> dict[str, float]:
        """{foot: [mm] how far the footplant lowered it, "root": [mm] how far it lowered the root} at one frame,
        each only where it lowered it by more than the leg IK's `MOVE_TOL` (a micrometre). A root lowered moves
        every joint, and a leg that lifts its foot back up (step 2 of the module docstring) bends a near-straight
        knee far more than the height: a root lowered 0.33 mm moved a knee 11 mm (CMU 12_01's walk), so the root
        is named however little it went down.

        Raises:
            IndexError: a frame outside the motion.
        """
        out = {f: round(-1000.0 * float(dz), 1) for f, dz in zip(self.feet, self.foot_dz[frame]) if dz < -MOVE_TOL}
        if self.root_dz[frame] < -MOVE_TOL:
            out["root"] = round(-1000.0 * float(self.root_dz[frame]), 2)
        return out

    def largest_mm(self) -> dict[str, float]:
        """{foot: the most it was lowered [mm], "root": the most the root was lowered [mm]}."""
        out = {f: round(1000.0 * float(max(0.0, -self.foot_dz[:, i].min())), 1) for i, f in enumerate(self.feet)}
        out["root"] = round(1000.0 * float(max(0.0, -self.root_dz.min())), 1)
        return out


def _spread(values: np.ndarray, on: np.ndarray) -> np.ndarray:
    """(n,) `values` where `on`, linearly interpolated between those frames elsewhere (held before the first
    and after the last); zeros when no frame is on."""
    idx = np.flatnonzero(on)
    if not idx.size:
        return np.zeros(len(values))
    return np.interp(np.arange(len(values)), idx, values[idx])


def _settled(above: np.ndarray, rest: np.ndarray, frame_time: float) -> np.ndarray:
    """(n,) how far the footplant lowers a foot (module docstring, 1): in each run of frames where it rests,
    the least of its heights over the clearance within `LANDING_S` of the frame, inside the run (0 outside
    the rests). above: (n,) [m] its lowest point's height over the clearance; rest: (n,) bool; frame_time [s]."""
    out = np.zeros(len(above))
    half = int(round(LANDING_S / frame_time))
    edges = np.flatnonzero(np.diff(np.concatenate([[0], rest.astype(int), [0]])))
    for a, b in zip(edges[::2], edges[1::2]):
        run = np.pad(above[a:b], half, mode="edge")
        out[a:b] = np.lib.stride_tricks.sliding_window_view(run, 2 * half + 1).min(axis=1)
    return out


def plant_feet(qpos: np.ndarray, model, frame_time: float) -> FootPlant:
    """Put every resting foot of a motion on the surface under it (module docstring).

    Args:
        qpos: (n, nq) the capture on the figure, its root height corrected (`correct_root_height`: no
            contact point below `CONTACT_CLEARANCE`). model: the scene's MjModel (the figure's feet, knee
            flexion axes and the surfaces). frame_time: [s].
    Returns:
        FootPlant; the motion unchanged when the scene has no surface or no foot rests.
    Raises:
        InputError: the figure lacks a leg joint or a knee's flexion axis (`runner.capture.leg_ik.leg_chain`).
    """
    kin = ContactClearance(model)
    n = len(qpos)
    feet = tuple(kin.feet)
    unchanged = FootPlant(qpos, np.zeros((n, len(feet))), np.zeros(n), feet)
    if kin.surfaces.count == 0 or n < 2:
        return unchanged
    width = smoothing_width(n, frame_time)
    rest, lowest = capture_rest(model, qpos, frame_time)
    if not rest.any():
        return unchanged
    legs = [leg_chain(model, kin.figure, side) for side in feet]
    above = np.maximum(0.0, lowest - CONTACT_CLEARANCE)  # (n, f): each foot's height over the clearance
    settled = np.stack([_settled(above[:, f], rest[:, f], frame_time) for f in range(len(feet))], axis=1)
    settled[settled <= CAPTURE_RESOLUTION] = 0.0  # a foot the capture cannot tell from resting on it stays
    # 1. the root's share: what a resting foot's leg cannot reach (its knee straight), the most over the feet
    short = np.zeros(n)
    for f, leg in enumerate(legs):
        _, reached = move_foot(model, leg, qpos, -settled[:, f])
        short = np.maximum(short, np.where(rest[:, f], settled[:, f] + reached, 0.0))
    short[short <= MOVE_TOL] = 0.0
    pinned = rest.all(axis=1) | (short > 0)  # free where one foot rests and its leg absorbs the root's move
    root_dz = -moving_average(_spread(short, pinned), width)
    out = qpos.copy()
    out[:, 2] += root_dz
    # 2. each foot to its target height in the world, by its leg, the root's move taken off
    foot_dz = np.zeros((n, len(feet)))
    for f, leg in enumerate(legs):
        world = np.maximum(-moving_average(_spread(settled[:, f], rest[:, f]), width), -above[:, f])
        out, foot_dz[:, f] = move_foot(model, leg, out, world - root_dz)
    # 3. nothing below the clearance: a foot lifted by its leg, and where the leg cannot, the root goes up
    _, lowest = capture_rest(model, out, frame_time)
    for f, leg in enumerate(legs):
        out, lifted = move_foot(model, leg, out, np.maximum(0.0, CONTACT_CLEARANCE - lowest[:, f]))
        foot_dz[:, f] += lifted
    clear = kin.clearance(kin.positions(out))
    back = np.maximum(0.0, CONTACT_CLEARANCE - clear.min(axis=1))
    out[:, 2] += back
    foot_dz += (root_dz + back)[:, None]  # the feet's moves in the world
    return FootPlant(out, foot_dz, root_dz + back, feet)
