"""When the method counts a contact site as "in contact": one named threshold per purpose, in one place.

Heights are a site's height above the surface under it [m] (`solver.surfaces.StaticSurfaces`), speeds
its 3-D speed [m/s]. Each purpose has its own value for a reason given beside it; the modules that
apply them import them from here. The published metrics' own thresholds (what counts as ground, skate
or float) are with the metrics (`runner.motion_metrics`), the viewer's with the viewer.
"""
from __future__ import annotations

# -- detecting contact from a motion, with hysteresis: a reference's contact schedule
#    (`solver.contacts.detect_contacts`, values measured in its docstring) and the capture's own stance
#    per foot (`runner.mocap.stance.capture_stance`, on the foot's lowest site). Speeds after the
#    kinematic gait-event rules validated against pressure insoles (Ghoussayni et al. 2004, Gait & Posture
#    20:266, 0.5 m/s; Bonci et al. 2022, Front. Bioeng. Biotechnol. 10:868928: 3-D heel or forefoot speed
#    under 0.5 m/s at initial contact, forefoot speed over 1.0 m/s at final contact).
#: a site enters contact below this height [m]: the flight height, so a contact never begins in a frame
#: the flight metric counts as airborne ...
DETECT_HEIGHT_ON = 0.03
#: ... and leaves above this one [m] (Guided Motion Diffusion's foot-contact height, ../shared/METRICS.md).
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

#: a site higher than this above every surface is airborne [m] (the flight time metric, the flight
#: constraint; the detection's entry height).
FLIGHT_HEIGHT = DETECT_HEIGHT_ON

# -- the root-residual term's flight indicator phi (`solver.terms.dynamics.RootResidual`)
#: a site at least this clear of every surface is in the air (phi = 1), one touching a surface is not
#: (phi = 0), smooth in between [m].
FLIGHT_CLEARANCE = 0.05
