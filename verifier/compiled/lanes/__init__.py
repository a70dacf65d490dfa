"""Rows in lanes: one operation over many rows at once.

The per-row kernels (:mod:`verifier.compiled.step`) advance one row (one
geometry hypothesis of one scenario) through a sample at a time.  These
kernels advance every live row of a chunk of scenarios through the sample
together wherever the work is the same for all rows: the velocity tape is
interpreted once per instruction for all of them, its bounds stored
structure-of-arrays (``[node, lane]``), the inner loop over the lanes, so the
dispatch is paid once per instruction and the sums and products vectorise
(:mod:`.interval`: the outward step on the bit pattern written as selects).

Every lane computes the floats its row computes in the per-row kernel, in the
same order: the boxes are the same bit for bit (tests/test_lanes.py), so the
choice between the two drivers is one of speed only
(:class:`verifier.compiled.driver.CompiledStep`).

Modules: :mod:`.interval` (the operations that vectorise), :mod:`.tape` (the
forward sweep over lanes), :mod:`.velocity` (the displacement model's velocity
contraction over lanes), :mod:`.step` (the driver).
"""
