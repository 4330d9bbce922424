"""The figure's contact points over a motion and their clearance above the scene's surfaces, and the
smoothing of the corrections that stand feet on them (`runner.capture.root_height.correct_root_height`,
`runner.capture.foot_plant.plant_feet`)."""
from __future__ import annotations

import numpy as np

from solver.contacts import contact_radii, lowest_points
from solver.figure import Figure

__all__ = ["CONTACT_CLEARANCE", "SMOOTH_S", "ContactClearance", "smoothing_width", "moving_average"]

#: clearance of the lowest site of a foot in contact after the height correction [m]: a small positive
#: margin so that keyframes, rounded to 6 decimals in a JSON file, never touch below the surface.
CONTACT_CLEARANCE = 0.002
#: [s] the moving average that smooths the height correction: 9 frames at 120 Hz, so that a correction
#: switching from one resting foot to the other changes over about as long as weight takes to shift, not
#: in one frame; a duration, so that a 60 Hz clip is smoothed over the same time (5 frames)
SMOOTH_S = 0.075


class ContactClearance:
    """Contact points of the figure over a motion, by MuJoCo forward kinematics.

    Attributes:
        figure: the model's `Figure`. names: its contact sites, foot by foot. feet: {foot: its sites}.
        surfaces: the scene's `StaticSurfaces`.
    """

    def __init__(self, model):
        import mujoco

        from solver.surfaces import StaticSurfaces

        self.model = model
        self.data = mujoco.MjData(model)
        self.surfaces = StaticSurfaces.from_model(model, self.data)
        self.figure = Figure.from_model(model)  # raises InputError naming a missing site
        self.names = list(self.figure.contact_sites)  # foot by foot, heel then toe
        self.feet = dict(self.figure.feet)
        self.ids = self.figure.contact_site_ids
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


def smoothing_width(n: int, frame_time: float) -> int:
    """The odd number of frames of the moving average over `SMOOTH_S` at `frame_time` [s], at most the n
    frames of the motion (9 at 120 Hz, 5 at 60 Hz)."""
    return min(2 * int(SMOOTH_S / (2 * frame_time)) + 1, n if n % 2 else n - 1)


def moving_average(x: np.ndarray, width: int) -> np.ndarray:
    """(n,) the mean of x over a centred window of `width` frames (odd), the ends padded with the end
    values; x itself when width < 3."""
    if width < 3:
        return x
    pad = width // 2
    return np.convolve(np.pad(x, pad, mode="edge"), np.ones(width) / width, mode="valid")
