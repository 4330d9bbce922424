"""Exit codes of the `dynsplines` command (a leaf: imports nothing).

    0   success (also when --max-time ended the optimization: the best path so far is written)
    1   internal error (a bug: please report it with the --debug traceback)
    2   bad input (a file, field or option); the message says what and how to fix it
    3   the optimization failed partway (a non-finite objective or gradient, named by term, or an
        optimizer failure); the best path before it (it meets every keyframe) and the outputs were written.
        Also: the objective is non-finite on the plain spline itself (named by term); nothing was written
    130 interrupted (Ctrl-C); the best path so far and the requested outputs were written (a second
        Ctrl-C aborts at once and writes nothing; Ctrl-C while rendering leaves any earlier video as it was)
"""
EXIT_OK = 0
EXIT_INTERNAL = 1
EXIT_INPUT = 2
EXIT_FAILED = 3
EXIT_INTERRUPTED = 130
