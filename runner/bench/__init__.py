"""Benchmarks: the workloads (`figure`, `orient`), the competing methods (`barr92`, `bspline`, `baselines`)
and the independent sphere reference (`sphere_reference`, which imports nothing from solver nor anything
else from runner). Not part of the library (`solver/` holds the method only); of the project it imports `solver` only.

Functions here take the model, keyframes and files as arguments and return data; printing is the
command's job (runner/commands/bench.py), through an optional `out` callback.
"""
