"""When the method counts a contact site as airborne: one named threshold per purpose.

Heights are a site's height above the surface under it [m] (`solver.surfaces.StaticSurfaces`). The
capture's contact detection has its own thresholds (`runner.capture.contact_detection`), the published
metrics theirs (`runner.motion_metrics`), the viewer its own.
"""
from __future__ import annotations

#: a site higher than this above every surface is airborne [m]: the field's flight height, under the
#: GMD foot-contact height of 5 cm (../shared/METRICS.md) and over the 0.2-2.3 cm of a walker's heel at
#: heel strike (16_23); the flight time metric, the flight and ground constraints, and the capture's
#: contact detection, whose entry height it is (`runner.capture.contact_detection`).
FLIGHT_HEIGHT = 0.03

# -- the root-residual term's flight indicator phi (`solver.terms.dynamics.RootResidual`)
#: a site at least this clear of every surface is in the air (phi = 1), one touching a surface is not
#: (phi = 0), smooth in between [m].
FLIGHT_CLEARANCE = 0.05
