"""When a contact site counts as "in contact": one named threshold per purpose, all in one place.

Heights are a site's height above the surface under it [m] (`solver.surfaces.StaticSurfaces`), speeds
its 3-D speed [m/s]. Each purpose has its own value for a reason given beside it; the modules that
apply them import them from here and define none of their own.
"""
from __future__ import annotations

# -- detecting a contact schedule from a motion (`solver.contacts.detect_contacts`, with hysteresis;
#    the values are measured in the solver/contacts.py docstring)
#: a site enters contact below this height [m] ...
DETECT_HEIGHT_ON = 0.03
#: ... and leaves above this one [m].
DETECT_HEIGHT_OFF = 0.05
#: a site enters contact below this speed [m/s] ...
DETECT_SPEED_ON = 0.5
#: ... and leaves above this one [m/s].
DETECT_SPEED_OFF = 1.0
#: detected contacts shorter than this are dropped [s] by `detect_contacts` when asked
#: (`min_duration`; the scene fit's resting feet). The contact schedule of a reference keeps every
#: contact (`SCHEDULE_MIN_DURATION`): a hop's or a hopscotch's 10-40 ms touch-down is a real one.
DETECT_MIN_DURATION = 0.05
#: the contact schedule of a reference (`solver.contacts.reference_contacts`): no contact is dropped [s].
SCHEDULE_MIN_DURATION = 0.0

# -- the capture's own stance (`runner.mocap.stance.capture_stance`): a foot rests on a surface while
#    its lowest contact site is near the surface under it and nearly still, with hysteresis and no
#    minimum duration. Speeds after the kinematic gait-event rules validated against pressure insoles
#    (Ghoussayni et al. 2004, Gait & Posture 20:266, 0.5 m/s; Bonci et al. 2022, Front. Bioeng.
#    Biotechnol. 10:868928: 3-D heel or forefoot speed under 0.5 m/s at initial contact, forefoot
#    speed over 1.0 m/s at final contact).
#: a foot enters stance when its lowest site is below this height [m]: the flight height, so a stance
#: never begins in a frame the flight metric counts as airborne ...
STANCE_HEIGHT_ON = 0.03
#: ... and leaves above this one [m] (Guided Motion Diffusion's foot-contact height, ../shared/METRICS.md).
STANCE_HEIGHT_OFF = 0.05
#: a foot enters stance when its lowest site moves slower than this [m/s] (3-D speed) ...
STANCE_SPEED_ON = 0.5
#: ... and leaves when it moves faster than this [m/s].
STANCE_SPEED_OFF = 1.0

# -- metrics of a motion (`solver.motion_metrics`), as the published metrics define them
#: PhysDiff skate: a site is on the ground at most this high [m].
SKATE_HEIGHT = 0.02
#: PhysDiff float: the lowest site counts as floating above this height [m].
FLOAT_TOL = 0.005
#: Guided Motion Diffusion's skating ratio: a site is in contact below this height [m].
GMD_HEIGHT = 0.05
#: flight time: every site above this height [m] (the detection's entry height).
FLIGHT_HEIGHT = DETECT_HEIGHT_ON

# -- the root-residual term's flight indicator phi (`solver.terms.dynamics.RootResidual`)
#: a site at least this clear of every surface is in the air (phi = 1), one touching a surface is not
#: (phi = 0), smooth in between [m].
FLIGHT_CLEARANCE = 0.05

# -- keyframes against the contact schedule (`solver.terms.contact.Planted.conflicts` and `slides`)
#: a keyframe inside a contact that holds its site farther than this from the plant height, or two
#: keyframes in one contact that hold it farther than this apart horizontally, contradict it [m].
KEYFRAME_TOLERANCE = 0.01

# -- the browser viewer (`runner.viewer.server`)
#: a site this close to a surface, or closer, is drawn "in contact" [m].
VIEWER_HEIGHT = 0.01
