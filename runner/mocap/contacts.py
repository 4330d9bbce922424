"""Feet and surfaces: when a foot of a motion is in contact, and the root height correction that puts
a foot in contact on the surface under it (and no contact site below a surface)."""
from __future__ import annotations

import numpy as np

from runner.mocap.retarget import Reference
from solver.contact_thresholds import CAPTURE_HEIGHT as CONTACT_HEIGHT
from solver.contact_thresholds import CAPTURE_SPEED as CONTACT_SPEED
from solver.figure import Figure

# contact definition (see `contact_mask`): CONTACT_HEIGHT, CONTACT_SPEED (solver.contact_thresholds)
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
    """Contact-site positions of the figure over a motion, by MuJoCo forward kinematics."""

    def __init__(self, model):
        import mujoco

        from solver.surfaces import StaticSurfaces

        self.model = model
        self.data = mujoco.MjData(model)
        self.surfaces = StaticSurfaces.from_model(model, self.data)
        figure = Figure.from_model(model)  # raises InputError naming a missing site
        self.names = list(figure.contact_sites)  # foot by foot, heel then toe
        self.ids = figure.contact_site_ids

    def positions(self, qpos: np.ndarray) -> np.ndarray:
        """(n, 4, 3) world positions [m] of l_heel, l_toe, r_heel, r_toe for (n, nq) qpos."""
        import mujoco

        qpos = np.atleast_2d(qpos)
        out = np.empty((len(qpos), len(self.ids), 3))
        for i, q in enumerate(qpos):
            self.data.qpos[:] = q
            mujoco.mj_kinematics(self.model, self.data)
            out[i] = self.data.site_xpos[self.ids]
        return out

    def clearance(self, pos: np.ndarray) -> np.ndarray:
        """(n, 4) height [m] of each site above the surface under it (negative: below the surface)."""
        return self.surfaces.height_above(pos)


def _foot_contact(pos: np.ndarray, clear: np.ndarray, frame_time: float, height: float, speed: float):
    """Per foot: the lowest site's clearance, and whether the foot is in contact.

    Returns:
        lowest: (n, 2) clearance [m] of each foot's lowest site (feet in FEET order).
        contact: (n, 2) bool, lowest clearance < `height` and that site's speed < `speed`.
    """
    vel = np.gradient(pos, frame_time, axis=0) if len(pos) > 1 else np.zeros_like(pos)
    spd = np.linalg.norm(vel, axis=-1)  # (n, 4)
    lowest = np.empty((len(pos), 2))
    contact = np.empty((len(pos), 2), bool)
    for f in range(2):
        c = clear[:, 2 * f : 2 * f + 2]
        k = np.argmin(c, axis=1)
        rows = np.arange(len(pos))
        lowest[:, f] = c[rows, k]
        contact[:, f] = (lowest[:, f] < height) & (spd[:, 2 * f : 2 * f + 2][rows, k] < speed)
    return lowest, contact


def contact_mask(qpos: np.ndarray, model, frame_time: float, height: float = CONTACT_HEIGHT,
                 speed: float = CONTACT_SPEED) -> tuple[np.ndarray, np.ndarray]:
    """Which foot is in contact in each frame of a dense motion, and its lowest site's clearance.

    Contact definition: a foot (heel and toe site) is in contact while its lowest site is less than
    `height` above the surface under it (floor, or the top of a box whose footprint contains the site;
    `StaticSurfaces.height_above`) and that site moves slower than `speed` (central differences over frames).

    Args:
        qpos: (n, nq) motion sampled every `frame_time` seconds. model: the scene's MjModel (figure
            plus static surfaces). frame_time: [s]. height: [m]. speed: [m/s].
    Returns:
        contact: (n, 2) bool, left and right foot.
        lowest: (n, 2) clearance [m] of each foot's lowest site (negative: below the surface).
    Raises:
        InputError: the model lacks the contact sites.
    """
    kin = _SiteKinematics(model)
    pos = kin.positions(qpos)
    lowest, contact = _foot_contact(pos, kin.clearance(pos), frame_time, height, speed)
    return contact, lowest


def worst_contact_distance(reference: Reference, model, height: float = CONTACT_HEIGHT,
                           speed: float = CONTACT_SPEED) -> float:
    """Acceptance figure: the worst |clearance| of a foot's lowest contact site while it is in contact.

    Over all frames and both feet in contact (`contact_mask`), the largest distance between the foot's
    lowest site (heel or toe) and the surface under it, above or below. Should be <= 0.03 m.

    Args:
        reference: the motion. model: the scene's MjModel. height [m], speed [m/s]: the contact
            definition of `contact_mask`.
    Returns:
        distance [m]; 0.0 if no foot is ever in contact.
    """
    contact, lowest = contact_mask(reference.qpos, model, reference.frame_time, height, speed)
    if not contact.any():
        return 0.0
    return float(np.max(np.abs(lowest[contact])))


def correct_root_height(qpos: np.ndarray, model, frame_time: float) -> np.ndarray:
    """Shift the root height per frame so feet in contact stand on the surfaces, and nothing sinks.

    1. The retargeting's height error: the retargeted feet can be several cm off before the
       correction (another subject's bone lengths), nearly the same offset all through a clip. It is
       the median, over the frames where a foot is provisionally in contact (`_foot_contact` with a
       wide height window of `FIT_HEIGHT`), of CONTACT_CLEARANCE - the lowest clearance of the feet
       in contact.
    2. Contact frames: the feet in contact by the standard definition (`contact_mask`: CONTACT_HEIGHT,
       CONTACT_SPEED) once that offset is applied. Only these are put on their surfaces: a foot near
       the top of a small hop is slow (its vertical speed passes through 0) and within the wide
       window, and putting it on the floor would pull the whole figure down and erase the flight
       (a 15 cm hop kept 3 cm of its height before this step). dz = CONTACT_CLEARANCE - lowest
       clearance of the feet in contact, so the lowest contact site of a standing foot ends
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
    kin = _SiteKinematics(model)
    pos = kin.positions(qpos)
    clear = kin.clearance(pos)
    lowest, provisional = _foot_contact(pos, clear, frame_time, height=FIT_HEIGHT, speed=CONTACT_SPEED)
    n = len(qpos)
    frames = np.arange(n)
    dz = np.zeros(n)
    if provisional.any():
        offset = float(np.median((CONTACT_CLEARANCE - np.where(provisional, lowest, np.inf).min(axis=1))[
            provisional.any(axis=1)]))
        # the same site is the lowest of each foot with or without the uniform offset: `lowest` stays
        _, contact = _foot_contact(pos, clear + offset, frame_time, height=CONTACT_HEIGHT, speed=CONTACT_SPEED)
        on = contact.any(axis=1)
        if on.any():
            target = CONTACT_CLEARANCE - np.where(contact, lowest, np.inf).min(axis=1)
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
