"""The tape interpreter behind the callback interface of the straight-line code.

Programs too long to be written out (:data:`verifier.compiled.straight.MAX_STRAIGHT_NODES`)
are run by :func:`verifier.compiled.tape.interpret` / :func:`~verifier.compiled.tape.interpret_hc4`
through this one C callback, of :data:`verifier.compiled.tape.C_SIGNATURE`, so
the kernels call every program the same way and compile no interpreter of their own.
Imported only when such a program is linked (the callback is compiled, or loaded
from numba's cache, on import).
"""

from __future__ import annotations

from numba import carray, cfunc

from .tape import C_SIGNATURE, Program, interpret, interpret_hc4

__all__ = ["interpreter"]


@cfunc(C_SIGNATURE, cache=True)
def interpreter(sel, n_out, in_lo_p, in_hi_p, n_in, lo_p, hi_p, n_nodes, mk_p, mv_p, slots,
                code_p, n_code, value_p, outs_p, n_outs, meta_p, n_tapes):
    """Tape ``sel`` forward (``sel < n_tapes``), else HC4Revise on tape ``sel - n_tapes``."""
    meta = carray(meta_p, (n_tapes, 3))
    # the interpreter reads no addresses: ``fns`` only completes the tuple
    prog = Program(carray(code_p, (n_code, 3)), carray(value_p, (n_code,)), carray(outs_p, (n_outs,)), meta,
                   n_nodes, meta)
    in_lo = carray(in_lo_p, (n_in,))
    in_hi = carray(in_hi_p, (n_in,))
    lo = carray(lo_p, (n_nodes,))
    hi = carray(hi_p, (n_nodes,))
    mk = carray(mk_p, (slots, 3))
    mv = carray(mv_p, (slots, 2))
    if sel < n_tapes:
        interpret(prog, sel, in_lo, in_hi, lo, hi, mk, mv)
    else:
        interpret_hc4(prog, sel - n_tapes, n_out, in_lo, in_hi, lo, hi, mk, mv)
