"""Benchmarks: the workloads (`figure`, `orient`), the competing methods (`barr92`, `bspline`, `baselines`)
and the independent sphere reference (`sphere_reference`, which imports nothing else from solver).

Functions here take the model, keyframes and files as arguments and return data; printing is the
command's job (runner/commands/bench.py), through an optional `out` callback.
"""
