"""The paper's weighted objective (Ramamoorthi, Ball & Barr, eq. 1 and fig. 5), apart from the figure solver.

`solve` minimizes a weighted sum of objective terms over the variable frames of a spline (optimize ->
subdivide -> optimize ...); `orient` is the paper's sec. 3 example on it, one orientation's covariant
interpolation, with its accuracy request (`orient_refine`, `error_estimate`). The figure's least-change
solver (`solver.problem`, `solver.least_change`) does not use this package; this package uses the shared
pieces below it (frames, spline, quadrature, objective terms, subdivision scores). `solver/__init__.py`
exports the public names (`solver.solve`, `solver.orient`, `solver.SolveOptions`, ...).
"""
