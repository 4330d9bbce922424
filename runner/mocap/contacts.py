"""Feet and surfaces: the root height correction that puts a resting foot on the surface under it (and no
contact site below a surface), and how far resting feet are from their surfaces (`runner.mocap.stance`
says when a foot rests)."""
from __future__ import annotations

import numpy as np

from runner.mocap.retarget import Reference
from solver.contact_thresholds import STANCE_SPEED_ON
from solver.contacts import contact_radii, lowest_points
from solver.figure import Figure

#: the wide height window [m] in which `correct_root_height` looks for feet at rest to measure the
#: retargeting's height error (the retargeted feet can be several cm off before the correction)
FIT_HEIGHT = 0.15
#: clearance of the lowest site of a foot in contact after the height correction [m]: a small positive
#: margin so that keyframes, rounded to 6 decimals in a JSON file, never touch below the surface.
CONTACT_CLEARANCE = 0.002


# --------------------------------------------------------------------------------------------------
# feet and surfaces
# --------------------------------------------------------------------------------------------------


class _SiteKinematics:
    """Contact points of the figure over a motion, by MuJoCo forward kinematics."""

    def __init__(self, model):
        import mujoco

        from solver.surfaces import StaticSurfaces

        self.model = model
        self.data = mujoco.MjData(model)
        self.surfaces = StaticSurfaces.from_model(model, self.data)
        figure = Figure.from_model(model)  # raises InputError naming a missing site
        self.names = list(figure.contact_sites)  # foot by foot, heel then toe
        self.feet = dict(figure.feet)
        self.ids = figure.contact_site_ids
        self.radii = contact_radii(model, self.names)

    def positions(self, qpos: np.ndarray) -> np.ndarray:
        """(n, 4, 3) world positions [m] of the contact points of l_heel, l_toe, r_heel, r_toe (the lowest
        points of rounded sites' spheres, `solver.contacts.lowest_points`) for (n, nq) qpos."""
        import mujoco

        qpos = np.atleast_2d(qpos)
        out = np.empty((len(qpos), len(self.ids), 3))
        for i, q in enumerate(qpos):
            self.data.qpos[:] = q
            mujoco.mj_kinematics(self.model, self.data)
            out[i] = self.data.site_xpos[self.ids]
        return lowest_points(out, self.radii)

    def clearance(self, pos: np.ndarray) -> np.ndarray:
        """(n, 4) height [m] of each site above the surface under it (negative: below the surface)."""
        return self.surfaces.height_above(pos)


def worst_contact_distance(reference: Reference, model) -> float:
    """Acceptance figure: the worst |clearance| of a foot's lowest contact site while the foot rests.

    Over the frames in which a foot rests on a surface (`runner.mocap.stance.capture_rest`: in the
    capture's stance, its lowest site below the flight height and still), the largest distance between
    that site (heel or toe) and the surface under it, above or below (docs/contacts.md, "Feet on their
    surfaces").

    Args:
        reference: the motion. model: the scene's MjModel.
    Returns:
        distance [m]; 0.0 if no foot ever rests.
    Raises:
        InputError: the model lacks the contact sites or the feet.
    """
    from runner.mocap.stance import capture_rest

    rest, lowest = capture_rest(model, reference.qpos, reference.frame_time)
    if not rest.any():
        return 0.0
    return float(np.max(np.abs(lowest[rest])))


def correct_root_height(qpos: np.ndarray, model, frame_time: float) -> np.ndarray:
    """Shift the root height per frame so feet in contact stand on the surfaces, and nothing sinks.

    1. The retargeting's height error: the retargeted feet can be several cm off before the
       correction (another subject's bone lengths, the shipped figure), nearly the same offset all
       through a clip. It is the median, over the frames where a foot is provisionally at rest (its
       lowest site within the wide window `FIT_HEIGHT` of the surface and slower than STANCE_SPEED_ON),
       of CONTACT_CLEARANCE - the lowest clearance of those feet.
    2. Contact frames: the frames in which a foot rests once that offset is applied, by the one
       definition the detection is judged against and the acceptance figure uses (`runner.mocap.
       stance`: the capture's stance, and in it the lowest site below the flight height and still,
       `resting`). Only these are put on their surfaces: a foot near the top of a small hop is slow
       (its vertical speed passes through 0) and within the wide window, and putting it on the floor
       would pull the whole figure down and erase the flight (a 15 cm hop kept 3 cm of its height);
       a foot rolling off its toes is in the stance's way out, up to 5 cm high, and putting it on
       the floor would pull the other foot into the surface. dz = CONTACT_CLEARANCE - lowest
       clearance of the resting feet, so the lowest contact site of a standing foot ends
       `CONTACT_CLEARANCE` above its surface.
    3. Frames without contact (flight): dz interpolated linearly between the neighbouring contact
       frames (held constant before the first and after the last; the offset of step 1 if no frame
       is in contact).
    4. dz smoothed over 9 frames (a moving average), then raised where needed so that every contact
       site of every frame is at least `CONTACT_CLEARANCE` above the surface under it.

    Args:
        qpos: (n, nq) retargeted motion. model: the scene's MjModel. frame_time: [s].
    Returns:
        (n, nq) qpos with the root z changed.
    """
    from runner.mocap.stance import lowest_sites, resting, stance_mask

    kin = _SiteKinematics(model)
    pos = kin.positions(qpos)
    clear = kin.clearance(pos)
    n = len(qpos)
    times = np.arange(n) * frame_time
    lowest, speed = lowest_sites(times, pos, clear, kin.feet, kin.names)
    provisional = (lowest < FIT_HEIGHT) & (speed < STANCE_SPEED_ON)
    frames = np.arange(n)
    dz = np.zeros(n)
    if provisional.any():
        offset = float(np.median((CONTACT_CLEARANCE - np.where(provisional, lowest, np.inf).min(axis=1))[
            provisional.any(axis=1)]))
        # the same site is the lowest of each foot with or without the uniform offset: `lowest` stays
        stance = stance_mask(times, pos, clear + offset, kin.feet, kin.names)
        rest = resting(stance, lowest + offset, speed)
        on = rest.any(axis=1)
        if on.any():
            target = CONTACT_CLEARANCE - np.where(rest, lowest, np.inf).min(axis=1)
            dz = np.interp(frames, frames[on], target[on])
        else:
            dz = np.full(n, offset)
    width = min(9, n if n % 2 else n - 1)
    if width >= 3:
        pad = width // 2
        dz = np.convolve(np.pad(dz, pad, mode="edge"), np.ones(width) / width, mode="valid")
    floor = CONTACT_CLEARANCE - clear.min(axis=1)
    dz = np.maximum(dz, floor)
    out = qpos.copy()
    out[:, 2] += dz
    return out
