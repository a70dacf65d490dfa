"""Compiled kernels of the tracker (numba): interval operations, the tape
interpreter, interval linear algebra, contractors and the step itself.

Nothing here names a robot: a robot's tapes reach the kernels as arrays
(:func:`verifier.compiled.tape.pack`).  Kernels are compiled once per machine
and cached next to this package (``__pycache__``); the first call after an
install pays the compilation (see benchmarks/README.md).
"""
