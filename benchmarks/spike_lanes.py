"""Spike of issue 43: rows in lanes for the velocity contraction alone.

The displacement model's velocity contraction (``verifier.compiled.contractors.velocity_displacement``:
per baseline, the tape of ``J_x`` and ``J_q rate``, the midpoint preconditioning and one Gauss–Seidel sweep
on ``J_x u = -J_q rate``) runs today once per row.  Here the same operations run over many rows at once:
bounds stored structure-of-arrays (``[feature, row]``), one tape instruction dispatched once for all rows,
the inner loop over rows.  Three kernels on the same inputs:

* ``per-row``: today's kernel, called row after row from a compiled loop;
* ``lanes``: rows in lanes with today's scalar operations (``verifier.compiled.interval``: the bit-level
  ``nextafter`` step); its boxes must be the per-row kernel's bit for bit (asserted);
* ``lanes-rzbm``: rows in lanes with the branch-free outward step of Rump, Zimmermann, Boldo and
  Melquiond (BIT 49, 2009) in the sums and products: ``c - (phi |c| + eta)`` below and ``c + (phi |c| +
  eta)`` above, ``phi = u (1 + 2 u)``, ``u = 2^-53``, ``eta`` the smallest positive subnormal.  Their
  theorem needs a finite ``c`` in round-to-nearest with the two operations of ``phi |c| + eta`` rounded
  separately (no FMA, no fast-math); it gives a bound at least one float out, and exactly one float out
  except for ``|c|`` near the smallest normal number, where it may be two.  The overflowed sum
  (``c = +-inf``) is sent to ``+-max`` by a select, as ``nextafter`` does.  Division, sin, cos, the
  midpoint and the 2x2 inverse keep today's operations.  Its boxes are compared with the others: how
  many bounds differ, by how many ulp, and which way.

Inputs are real rows: every call of the velocity contraction by the numpy reference tracker on a
simulated DexTAR crossing (the benchmark crossing at ``--speed`` m/s, the robot's default settings:
4 geometry hypotheses, baselines 1, 2, 4, 8, 16 samples), recorded and replayed.  The times are per row
and sample (one contraction of one row); the batch sizes R = 1, 16, 64, 256 take consecutive rows of
the recording.  Whether a loop vectorised is read from numba's assembly of each kernel (packed AVX
instructions on ymm registers, ``<4 x double>`` in the LLVM IR).

Not library code: nothing imports it.  Run ``python benchmarks/spike_lanes.py`` (about 2 min on 2
cores, most of it the numpy run and the compilations).
"""

from __future__ import annotations

import os

for _var in ("OMP_NUM_THREADS", "OPENBLAS_NUM_THREADS", "MKL_NUM_THREADS"):
    os.environ[_var] = "1"  # before numpy is imported

import argparse  # noqa: E402
import re  # noqa: E402
import time  # noqa: E402

import numpy as np  # noqa: E402
from numba import njit  # noqa: E402

import crosscert.verifier.step as step_module  # noqa: E402
from crosscert.planner.simulate import simulate_crossing  # noqa: E402
from crosscert.planner.sweep import cruise_for  # noqa: E402
from crosscert.robots import DEXTAR, KinematicModel  # noqa: E402
from crosscert.robots.dextar import benchmark_crossing  # noqa: E402
from crosscert.verifier import interval as I  # noqa: E402
from crosscert.verifier.compiled import interval as ops  # noqa: E402
from crosscert.verifier.compiled.contractors import scratch_arrays, thread_scratch, velocity_displacement  # noqa: E402
from crosscert.verifier.compiled.linalg import _inverse_2  # noqa: E402
from crosscert.verifier.compiled.tape import T_VEL, trig, trig_memo  # noqa: E402
from crosscert.verifier.constants import AXIS_DTYPE, BASELINE_DTYPE  # noqa: E402
from crosscert.verifier.model import IntervalModel  # noqa: E402
from crosscert.verifier.tape import OPCODES  # noqa: E402
from crosscert.verifier.tracker import TrackerSettings, track  # noqa: E402
from bench_window import _cpu as cpu_name  # noqa: E402  (one reading of the CPU's name for the benchmarks)

FLAGS = dict(nogil=True, _nrt=False)  # the kernels' flags (verifier.compiled.interval.KERNEL_FLAGS): no fast-math
INF = np.inf
MAX = float(np.finfo(np.float64).max)
U = 2.0**-53
PHI = U * (1.0 + 2.0 * U)  # u (1 + 2u), a float: 2^-53 + 2^-105
ETA = 5e-324
_INPUT, _CONST, _ADD, _SUB, _MUL, _DIV = (OPCODES[k] for k in ("OP_INPUT", "OP_CONST", "OP_ADD", "OP_SUB", "OP_MUL",
                                                                "OP_DIV"))
_NEG, _SQ, _SIN, _COS, _TWICE = (OPCODES[k] for k in ("OP_NEG", "OP_SQ", "OP_SIN", "OP_COS", "OP_TWICE"))


# ---------------------------------------------------------------------------- real rows


def capture(speed: float):
    """Every row of every velocity contraction (all four baselines) of the numpy tracker on the benchmark
    crossing at ``speed`` m/s: the inputs as the compiled kernel reads them, and the numpy result."""
    model = IntervalModel(DEXTAR)
    bench = benchmark_crossing()
    run = simulate_crossing(KinematicModel(DEXTAR), bench.point, bench.direction, speed, t_rest=0.05,
                            working_guess=bench.q_point, cruise=cruise_for(speed))
    settings = TrackerSettings.for_robot(DEXTAR)
    calls = []
    original = step_module.velocity_displacement

    def recording(model_, X, Q, pasts, XI, XD, a_max):
        copy = lambda box: tuple(np.array(b, dtype=np.float64) for b in box)  # noqa: E731  (the step reuses arrays)
        args = (copy(X), copy(Q), [(copy(p[0]), copy(p[1]), copy(p[2]), p[3]) for p in pasts], copy(XI), copy(XD))
        out = original(model_, X, Q, pasts, XI, XD, a_max)
        if len(pasts) == len(settings.baselines):
            calls.append((*args, np.asarray(a_max, dtype=np.float64).copy(), copy(out)))
        return out

    step_module.velocity_displacement = recording
    try:
        track(model, run.q_meas, settings, initial_mode=int(run.mode_true[0]), backend="numpy")
    finally:
        step_module.velocity_displacement = original
    box = lambda lo, hi: np.stack([lo, hi], axis=-2)  # noqa: E731  (rows, 2, d)
    X = np.concatenate([box(*c[0]) for c in calls])
    Q = np.concatenate([box(*c[1]) for c in calls])
    XI = np.concatenate([box(*c[3]) for c in calls])
    XD = np.concatenate([box(*c[4]) for c in calls])
    want = np.concatenate([box(*c[6]) for c in calls])
    J = len(settings.baselines)
    h = np.array([(float(np.min(p[3][0])), float(np.max(p[3][1]))) for p in calls[0][2]])
    for c in calls:  # the same baselines in every call
        assert np.array_equal(h, [(float(np.min(p[3][0])), float(np.max(p[3][1]))) for p in c[2]])
        assert np.array_equal(c[5], calls[0][5])
    past_x = np.concatenate([np.stack([box(*p[0]) for p in c[2]], axis=1) for c in calls])  # (N, J, 2, n)
    past_q = np.concatenate([np.stack([box(*p[1]) for p in c[2]], axis=1) for c in calls])
    # the kernel's caller divides the joint differences by h once per sample (as verifier.compiled.step does)
    rate = []
    for c in calls:
        per = [np.stack(I.div(*p[2], h[j, 0], h[j, 1]), axis=-2) for j, p in enumerate(c[2])]  # (B, 2, n) each
        rate.append(np.stack(per, axis=1))
    rate = np.concatenate(rate)  # (N, J, 2, n)
    baseline = np.zeros(J, BASELINE_DTYPE)
    baseline["j"] = settings.baselines
    baseline["h_lo"], baseline["h_hi"] = h[:, 0], h[:, 1]
    axis = np.zeros(DEXTAR.n, AXIS_DTYPE)
    axis["a_max"] = calls[0][5]
    return dict(model=model, X=X, Q=Q, XI=XI, XD=XD, past_x=past_x, past_q=past_q, rate=rate, baseline=baseline,
                axis=axis, want=want, samples=len(calls))


# ---------------------------------------------------------------------------- today's kernel, row after row


@njit(**FLAGS)
def per_row(prog, X, Q, XI, XD0, XD, past_x, past_q, DQ, baseline, idx, axis, S, R, reps):
    """Today's kernel on rows ``0 .. N - 1`` (``R`` only shapes the loop as the lanes' batches do)."""
    sc = thread_scratch(S, 0)
    n = X.shape[2]
    m = XI.shape[2]
    J = idx.shape[0]
    N = X.shape[0] // R * R
    for _ in range(reps):
        for s in range(0, N, R):
            for r in range(s, s + R):
                for i in range(n):
                    XD[r, 0, i] = XD0[r, 0, i]
                    XD[r, 1, i] = XD0[r, 1, i]
                velocity_displacement(prog, X, r, Q, r, XI, r, XD, r, past_x, past_q, r, DQ, r * J, baseline, idx, J,
                                      axis, n, m, sc)


# ---------------------------------------------------------------------------- outward steps that vectorise

# numba compiles a called @njit function on its own and calls it (ops.mul and the others are not inlined into
# the loops over rows, which then cannot vectorise); inline="always" puts the body into the loop first
INLINE = dict(FLAGS, inline="always")


@njit(**INLINE)
def bit_dn(c):
    """``np.nextafter(c, -inf)`` (``ops.dn``'s floats) by selects on the bit pattern, no branch."""
    b = ops._bits(c)
    stepped = ops._float(b - 1 if b > 0 else b + 1)
    r = -ETA if c == 0.0 else stepped
    return c if (c != c or c == -INF) else r


@njit(**INLINE)
def bit_up(c):
    b = ops._bits(c)
    stepped = ops._float(b + 1 if b > 0 else b - 1)
    r = ETA if c == 0.0 else stepped
    return c if (c != c or c == INF) else r


@njit(**INLINE)
def rz_dn(c):
    """RZBM: a float at or below the predecessor of a finite ``c``; ``+inf`` (an overflowed lower bound) to
    ``max``, as ``nextafter`` does."""
    d = c - (PHI * abs(c) + ETA)
    return MAX if c == INF else d


@njit(**INLINE)
def rz_up(c):
    d = c + (PHI * abs(c) + ETA)
    return -MAX if c == -INF else d


@njit(**INLINE)
def _mn(x, y):
    return x if x < y else y


@njit(**INLINE)
def _mx(x, y):
    return x if x > y else y


def make_ops(dn, up):
    """``add, sub, mul_fast, mul, pmul`` with the outward step ``dn, up``: today's operations
    (``verifier.compiled.interval``) written as selects.  ``mul_fast`` is ``ops.mul``'s common case (every bound
    nonzero and not NaN, no product rounded to 0) with a flag: False sends the lane to today's general
    path (``ops._mul_general``), in a second loop over the flagged lanes only."""

    @njit(**INLINE)
    def add(al, ah, bl, bh):
        lo = al + bl
        hi = ah + bh
        # a sum that rounds to 0 is exactly 0 (gradual underflow): kept, as today
        return (0.0 if lo == 0.0 else dn(lo)), (0.0 if hi == 0.0 else up(hi))

    @njit(**INLINE)
    def sub(al, ah, bl, bh):
        lo = al - bh
        hi = ah - bl
        return (0.0 if lo == 0.0 else dn(lo)), (0.0 if hi == 0.0 else up(hi))

    @njit(**INLINE)
    def mul_fast(al, ah, bl, bh):
        p1 = al * bl
        p2 = al * bh
        p3 = ah * bl
        p4 = ah * bh
        lo = dn(_mn(_mn(p1, p2), _mn(p3, p4)))
        hi = up(_mx(_mx(p1, p2), _mx(p3, p4)))
        ok = (al != 0.0) & (ah != 0.0) & (bl != 0.0) & (bh != 0.0) & (al == al) & (ah == ah) & (bl == bl) & (bh == bh)
        return lo, hi, ok & (lo != 0.0) & (hi != 0.0)

    @njit(**INLINE)
    def mul(al, ah, bl, bh):
        lo, hi, ok = mul_fast(al, ah, bl, bh)
        if not ok:
            lo, hi = ops._mul_general(al, ah, bl, bh)
        return lo, hi

    @njit(**INLINE)
    def pmul(c, bl, bh):
        p1 = c * bl
        p2 = c * bh
        lo = dn(_mn(p1, p2))
        hi = up(_mx(p1, p2))
        if not ((c != 0.0) & (bl != 0.0) & (bh != 0.0) & (c == c) & (bl == bl) & (bh == bh) & (lo != 0.0) & (hi != 0.0)):
            lo, hi = ops._mul_general(c, c, bl, bh)
        return lo, hi

    return add, sub, mul_fast, mul, pmul


BITS = make_ops(bit_dn, bit_up)
RZBM = make_ops(rz_dn, rz_up)


@njit(**INLINE)
def _today_mul_fast(al, ah, bl, bh):
    lo, hi = ops.mul(al, ah, bl, bh)
    return lo, hi, True


TODAY = (ops.add, ops.sub, _today_mul_fast, ops.mul, ops.pmul)


# ---------------------------------------------------------------------------- rows in lanes


def make_lanes(add, sub, mul_fast, mul, pmul):
    """The lanes kernel with the scalar interval operations ``add``, ``sub``, ``mul``, ``pmul`` in its loops
    over rows (the tape's products as ``mul_fast`` over all rows, then today's general path on the lanes it
    flags); everything else is today's operations."""

    @njit(**FLAGS)
    def tape(code, value, c0, count, il, ih, lo, hi, R, mk, mv, flag):
        # one dispatch per instruction, the inner loop over the R rows; sin and cos through today's memo
        # (verifier.compiled.tape.trig: the same floats, hit or miss)
        for k in range(count):
            op = code[c0 + k, 0]
            a = code[c0 + k, 1]
            b = code[c0 + k, 2]
            if op == _INPUT:
                for r in range(R):
                    lo[k, r] = il[a, r]
                    hi[k, r] = ih[a, r]
            elif op == _CONST:
                v = value[c0 + k]
                for r in range(R):
                    lo[k, r] = v
                    hi[k, r] = v
            elif op == _ADD:
                for r in range(R):
                    lo[k, r], hi[k, r] = add(lo[a, r], hi[a, r], lo[b, r], hi[b, r])
            elif op == _SUB:
                for r in range(R):
                    lo[k, r], hi[k, r] = sub(lo[a, r], hi[a, r], lo[b, r], hi[b, r])
            elif op == _MUL:
                for r in range(R):
                    lo[k, r], hi[k, r], flag[r] = mul_fast(lo[a, r], hi[a, r], lo[b, r], hi[b, r])
                for r in range(R):
                    if not flag[r]:
                        lo[k, r], hi[k, r] = ops._mul_general(lo[a, r], hi[a, r], lo[b, r], hi[b, r])
            elif op == _TWICE:
                for r in range(R):
                    lo[k, r], hi[k, r] = add(lo[a, r], hi[a, r], lo[a, r], hi[a, r])
            elif op == _DIV:
                for r in range(R):
                    lo[k, r], hi[k, r] = ops.div(lo[a, r], hi[a, r], lo[b, r], hi[b, r])
            elif op == _NEG:
                for r in range(R):
                    lo[k, r], hi[k, r] = ops.neg(lo[a, r], hi[a, r])
            elif op == _SQ:
                for r in range(R):
                    lo[k, r], hi[k, r] = ops.sqr(lo[a, r], hi[a, r])
            elif op == _SIN or op == _COS:
                for r in range(R):
                    lo[k, r], hi[k, r] = trig(op, lo[a, r], hi[a, r], mk, mv)
            else:
                raise ValueError("an opcode the velocity tape of the DexTAR does not use")

    @njit(**FLAGS)
    def contract(code, value, outs, meta, X, Q, XI, XD, PX, PQ, DQ, baseline, axis, s, R, il, ih, nl, nh, w, mat, mk, mv,
                 flag):
        """Contract ``XD[:, :, s:s + R]`` (``[bound, component, row]``) with every baseline.  ``X, Q, XI``
        ``(2, d, N)``, ``PX, PQ, DQ`` ``(J, 2, n, N)``; scratch ``il, ih`` (inputs, R), ``nl, nh`` (nodes, R),
        ``w`` (R-wide temporaries), ``mat`` (the 2x2 inverse of one row)."""
        n = X.shape[1]
        m = XI.shape[1]
        J = baseline.shape[0]
        nn = n * n
        c0 = meta[T_VEL, 0]
        count = meta[T_VEL, 1]
        o0 = meta[T_VEL, 2]
        # rows of w: J_x lo/hi (nn each), b lo/hi (n), y lo/hi (n), C (nn), G lo/hi (nn), Cb lo/hi (n),
        # beta, accumulated lo/hi (n), slack lo/hi (n, the same for all rows)
        JL, JH, BL, BH, YL, YH = 0, nn, 2 * nn, 2 * nn + n, 2 * nn + 2 * n, 2 * nn + 3 * n
        C = 2 * nn + 4 * n
        GL, GH = C + nn, C + 2 * nn
        CL, CH = C + 3 * nn, C + 3 * nn + n
        BETA = C + 3 * nn + 2 * n
        AL, AH = BETA + 1, BETA + 1 + n
        for jb in range(J):
            h_hi = baseline[jb].h_hi
            for i in range(n):
                for r in range(R):
                    il[i, r], ih[i, r] = ops.hull(X[0, i, s + r], X[1, i, s + r], PX[jb, 0, i, s + r], PX[jb, 1, i, s + r])
                    il[n + i, r], ih[n + i, r] = ops.hull(Q[0, i, s + r], Q[1, i, s + r], PQ[jb, 0, i, s + r],
                                                          PQ[jb, 1, i, s + r])
                    il[2 * n + m + i, r] = DQ[jb, 0, i, s + r]
                    ih[2 * n + m + i, r] = DQ[jb, 1, i, s + r]
            for i in range(m):
                for r in range(R):
                    il[2 * n + i, r] = XI[0, i, s + r]
                    ih[2 * n + i, r] = XI[1, i, s + r]
            half_h = ops.scale(0.5, h_hi, h_hi)[1]
            tape(code, value, c0, count, il, ih, nl, nh, R, mk, mv, flag)
            for e in range(nn + n):
                node = outs[o0 + e]
                for r in range(R):
                    if e < nn:
                        w[JL + e, r] = 0.0 if node < 0 else nl[node, r]
                        w[JH + e, r] = 0.0 if node < 0 else nh[node, r]
                    else:  # b = -(J_q rate)
                        w[BL + e - nn, r] = -0.0 if node < 0 else -nh[node, r]
                        w[BH + e - nn, r] = -0.0 if node < 0 else -nl[node, r]
            for i in range(n):
                a = axis[i].a_max
                sl, sh = ops.mul(-half_h, half_h, -a, a)
                for r in range(R):
                    w[YL + i, r], w[YH + i, r] = add(XD[0, i, s + r], XD[1, i, s + r], sl, sh)
            # precondition: C = inv(mid J_x) (today's 2x2 Gauss-Jordan, row by row), G = C J_x, beta >= |I - G|
            for r in range(R):
                for e in range(nn):
                    mat[e] = ops.midpoint(w[JL + e, r], w[JH + e, r])
                _inverse_2(mat, 0, nn)
                for e in range(nn):
                    w[C + e, r] = mat[nn + e]
            for i in range(n):
                for j in range(n):
                    for r in range(R):
                        lo, hi = pmul(w[C + i * n, r], w[JL + j, r], w[JH + j, r])
                        for k in range(1, n):
                            pl, ph = pmul(w[C + i * n + k, r], w[JL + k * n + j, r], w[JH + k * n + j, r])
                            lo, hi = add(lo, hi, pl, ph)
                        w[GL + i * n + j, r] = lo
                        w[GH + i * n + j, r] = hi
            for r in range(R):
                beta = 0.0
                for i in range(n):
                    row = 0.0
                    for k in range(n):
                        e = 1.0 if i == k else 0.0
                        el, eh = sub(e, e, w[GL + i * n + k, r], w[GH + i * n + k, r])
                        mag = ops.maxn(abs(el), abs(eh))
                        row = mag if k == 0 else add(row, row, mag, mag)[1]
                    beta = row if i == 0 else ops.maxn(beta, row)
                w[BETA, r] = beta
            # solve: Cb = C b, the Neumann bound, one Gauss-Seidel sweep on G y = Cb
            for i in range(n):
                for r in range(R):
                    lo, hi = pmul(w[C + i * n, r], w[BL, r], w[BH, r])
                    for k in range(1, n):
                        pl, ph = pmul(w[C + i * n + k, r], w[BL + k, r], w[BH + k, r])
                        lo, hi = add(lo, hi, pl, ph)
                    w[CL + i, r] = lo
                    w[CH + i, r] = hi
            for r in range(R):
                cmag = 0.0
                for i in range(n):
                    cm = ops.maxn(abs(w[CL + i, r]), abs(w[CH + i, r]))
                    cmag = cm if i == 0 else ops.maxn(cmag, cm)
                beta = w[BETA, r]
                denom = sub(1.0, 1.0, beta, beta)[0]
                rad = np.inf
                if beta < 1.0 and denom > 0.0:
                    rad = ops.div(cmag, cmag, denom, denom)[1]
                    if not np.isfinite(rad):
                        rad = np.inf
                for i in range(n):
                    w[YL + i, r], w[YH + i, r] = ops.intersect(w[YL + i, r], w[YH + i, r], -rad, rad)
            for i in range(n):
                for r in range(R):
                    sl = w[CL + i, r]
                    sh = w[CH + i, r]
                    for j in range(n):
                        if j != i:
                            pl, ph = mul(w[GL + i * n + j, r], w[GH + i * n + j, r], w[YL + j, r], w[YH + j, r])
                            sl, sh = sub(sl, sh, pl, ph)
                    dl = w[GL + i * n + i, r]
                    dh = w[GH + i * n + i, r]
                    ql, qh = ops.div(sl, sh, dl, dh)
                    if dl <= 0.0 and dh >= 0.0 and sl <= 0.0 and sh >= 0.0:
                        ql = -np.inf
                        qh = np.inf
                    w[YL + i, r], w[YH + i, r] = ops.intersect(w[YL + i, r], w[YH + i, r], ql, qh)
            for i in range(n):
                a = axis[i].a_max
                sl, sh = ops.mul(-half_h, half_h, -a, a)
                for r in range(R):
                    ul, uh = add(w[YL + i, r], w[YH + i, r], sl, sh)
                    w[AL + i, r] = ul if jb == 0 else ops.maxn(w[AL + i, r], ul)
                    w[AH + i, r] = uh if jb == 0 else ops.minn(w[AH + i, r], uh)
        for i in range(n):
            for r in range(R):
                XD[0, i, s + r] = ops.maxn(XD[0, i, s + r], w[AL + i, r])
                XD[1, i, s + r] = ops.minn(XD[1, i, s + r], w[AH + i, r])

    @njit(**FLAGS)
    def run(code, value, outs, meta, X, Q, XI, XD0, XD, PX, PQ, DQ, baseline, axis, R, reps, il, ih, nl, nh, w, mat, mk,
            mv, flag):
        N = X.shape[2] // R * R
        for _ in range(reps):
            for s in range(0, N, R):
                for i in range(X.shape[1]):
                    for r in range(s, s + R):
                        XD[0, i, r] = XD0[0, i, r]
                        XD[1, i, r] = XD0[1, i, r]
                contract(code, value, outs, meta, X, Q, XI, XD, PX, PQ, DQ, baseline, axis, s, R, il, ih, nl, nh, w,
                         mat, mk, mv, flag)

    @njit(**FLAGS)
    def run_tape(code, value, meta, X, Q, XI, PX, PQ, DQ, J, R, reps, il, ih, nl, nh, mk, mv, flag):
        """The part of :func:`run` that is the tape: its inputs and the sweep, every baseline."""
        N = X.shape[2] // R * R
        n = X.shape[1]
        m = XI.shape[1]
        for _ in range(reps):
            for s in range(0, N, R):
                for jb in range(J):
                    for i in range(n):
                        for r in range(R):
                            il[i, r], ih[i, r] = ops.hull(X[0, i, s + r], X[1, i, s + r], PX[jb, 0, i, s + r],
                                                          PX[jb, 1, i, s + r])
                            il[n + i, r], ih[n + i, r] = ops.hull(Q[0, i, s + r], Q[1, i, s + r], PQ[jb, 0, i, s + r],
                                                                  PQ[jb, 1, i, s + r])
                            il[2 * n + m + i, r] = DQ[jb, 0, i, s + r]
                            ih[2 * n + m + i, r] = DQ[jb, 1, i, s + r]
                    for i in range(m):
                        for r in range(R):
                            il[2 * n + i, r] = XI[0, i, s + r]
                            ih[2 * n + i, r] = XI[1, i, s + r]
                    tape(code, value, meta[T_VEL, 0], meta[T_VEL, 1], il, ih, nl, nh, R, mk, mv, flag)

    return run, contract, tape, run_tape


KERNELS = {"lanes": make_lanes(*TODAY), "lanes-bits": make_lanes(*BITS), "lanes-rzbm": make_lanes(*RZBM)}


@njit(**FLAGS)
def _steps(c, dn_rz, up_rz, dn_bits, up_bits):
    for i in range(c.shape[0]):
        dn_rz[i] = rz_dn(c[i])
        up_rz[i] = rz_up(c[i])
        dn_bits[i] = bit_dn(c[i])
        up_bits[i] = bit_up(c[i])


def make_op_loops(add, mul_fast):
    """``add`` and ``mul`` over the lanes alone (the product in two passes as in the tape): do they vectorise?"""

    @njit(**FLAGS)
    def add_loop(al, ah, bl, bh, ol, oh, flag, reps):
        for _ in range(reps):
            for r in range(al.shape[0]):
                ol[r], oh[r] = add(al[r], ah[r], bl[r], bh[r])

    @njit(**FLAGS)
    def mul_loop(al, ah, bl, bh, ol, oh, flag, reps):
        for _ in range(reps):
            for r in range(al.shape[0]):
                ol[r], oh[r], flag[r] = mul_fast(al[r], ah[r], bl[r], bh[r])
            for r in range(al.shape[0]):
                if not flag[r]:
                    ol[r], oh[r] = ops._mul_general(al[r], ah[r], bl[r], bh[r])

    return {"add": add_loop, "mul": mul_loop}


STEPS = {"nextafter (today's ops, called)": TODAY, "bits (selects, inlined)": BITS, "rzbm (inlined)": RZBM}
OP_LOOPS = {(op, step): loop for step, o in STEPS.items() for op, loop in make_op_loops(o[0], o[2]).items()}


# ---------------------------------------------------------------------------- measuring


def soa(a):
    """``(N, ..., 2, d)`` boxes to ``(..., 2, d, N)`` (rows last, contiguous)."""
    return np.ascontiguousarray(np.moveaxis(a, 0, -1))


def vector_report(dispatcher) -> str:
    """What numba generated for ``dispatcher`` (compiled once): packed double instructions on ymm / xmm
    registers and ``<4 x double>`` / ``<2 x double>`` operations in the LLVM IR."""
    sig = dispatcher.signatures[0]
    asm = dispatcher.inspect_asm(sig)
    ir = dispatcher.inspect_llvm(sig)
    lines = [line for line in asm.splitlines() if re.search(r"\bv(?:add|sub|mul|min|max|div|and|cmp\w*)[ps]d\b", line)]
    ymm = sum(1 for line in lines if re.search(r"pd\b", line) and "ymm" in line)
    xmm_packed = sum(1 for line in lines if re.search(r"pd\b", line) and "ymm" not in line)
    scalar = sum(1 for line in lines if re.search(r"sd\b", line))
    v4 = len(re.findall(r"<4 x double>", ir))
    v2 = len(re.findall(r"<2 x double>", ir))
    return (f"packed ymm {ymm}, packed xmm {xmm_packed}, scalar sd {scalar}; "
            f"IR <4 x double> {v4}, <2 x double> {v2}")


def _timed(fn, *args):
    t = time.perf_counter()
    fn(*args)
    return time.perf_counter() - t


def ulps(a, b):
    """Floats between ``a`` and ``b`` (same sign assumed for nonzero finite values; else -1)."""
    ia = a.view(np.int64)
    ib = b.view(np.int64)
    ok = np.isfinite(a) & np.isfinite(b) & ((np.sign(a) == np.sign(b)) | (a == 0) | (b == 0))
    return np.where(ok, np.abs(ia - ib), -1)


def main(argv=None):
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--speed", type=float, default=1.0, help="crossing speed of the recorded run, m/s")
    parser.add_argument("--rows-time", type=float, default=0.3, help="seconds of work per measurement (about)")
    args = parser.parse_args(argv)
    print(f"CPU: {cpu_name()} ({os.cpu_count()} logical CPUs); numpy {np.__version__}")
    t0 = time.perf_counter()
    d = capture(args.speed)
    N = d["X"].shape[0]
    print(f"recorded {N} rows ({d['samples']} calls x 4 hypotheses, {d['baseline'].shape[0]} baselines each) of the numpy "
          f"tracker on the "
          f"benchmark crossing at {args.speed} m/s in {time.perf_counter() - t0:.1f} s")
    prog = d["model"].program
    J = d["baseline"].shape[0]
    n, m = d["X"].shape[2], d["XI"].shape[2]
    idx = np.arange(J, dtype=np.int64)
    DQ = np.ascontiguousarray(d["rate"].reshape(N * J, 2, n))
    S = scratch_arrays(1, prog.n_nodes, n, m, J, 0, 1)
    XD_row = d["XD"].copy()
    # SoA copies for the lanes
    X, Q, XI, XD0 = soa(d["X"]), soa(d["Q"]), soa(d["XI"]), soa(d["XD"])
    PX = soa(d["past_x"])  # (J, 2, n, N)
    PQ = soa(d["past_q"])
    DQs = soa(d["rate"])
    R_MAX = 256
    il, ih = np.zeros((5 * n + m, R_MAX)), np.zeros((5 * n + m, R_MAX))
    nl, nh = np.zeros((prog.n_nodes, R_MAX)), np.zeros((prog.n_nodes, R_MAX))
    w = np.zeros((6 * n * n + 10 * n + 4, R_MAX))
    mat = np.zeros(2 * n * n)
    mk, mv = trig_memo()
    flag = np.zeros(R_MAX, np.bool_)
    lane_args = (prog.code, prog.value, prog.outs, prog.meta, X, Q, XI, XD0)
    rest = (PX, PQ, DQs, d["baseline"], d["axis"])

    def run_per_row(R, reps, out):
        per_row(prog, d["X"], d["Q"], d["XI"], d["XD"], out, d["past_x"], d["past_q"], DQ, d["baseline"], idx,
                d["axis"], S, R, reps)

    def run_lanes(kernel, R, reps, out):
        kernel[0](*lane_args, out, *rest, R, reps, il, ih, nl, nh, w, mat, mk, mv, flag)

    # ------------------------------------------------------------------ the same boxes
    t0 = time.perf_counter()
    run_per_row(1, 1, XD_row)
    assert np.array_equal(XD_row.view(np.int64), d["want"].view(np.int64)), "per-row kernel != numpy reference"
    results = {}
    for name, kernel in KERNELS.items():
        for R in (1, 16, 64, 256):
            out = XD0.copy()
            run_lanes(kernel, R, 1, out)
            M = N // R * R
            results[(name, R)] = np.moveaxis(out, -1, 0)[:M]
    print(f"compiled and checked in {time.perf_counter() - t0:.1f} s")
    for name in ("lanes", "lanes-bits"):
        for R in (1, 16, 64, 256):
            M = N // R * R
            got = results[(name, R)]
            assert np.array_equal(got.view(np.int64), XD_row[:M].view(np.int64)), f"{name} (R = {R}) != per-row, bits"
    print("lanes and lanes-bits: every box bit for bit the per-row kernel's (and the numpy reference's), "
          "R = 1, 16, 64, 256")
    rz = results[("lanes-rzbm", 1)]
    for R in (16, 64, 256):
        M = N // R * R
        assert np.array_equal(results[("lanes-rzbm", R)].view(np.int64), rz[:M].view(np.int64))
    differ = rz.view(np.int64) != XD_row.view(np.int64)
    rows_differ = differ.reshape(N, -1).any(1)
    wider = (rz[:, 0] < XD_row[:, 0]).sum() + (rz[:, 1] > XD_row[:, 1]).sum()
    narrower = (rz[:, 0] > XD_row[:, 0]).sum() + (rz[:, 1] < XD_row[:, 1]).sum()
    u = ulps(rz, XD_row)[differ]
    print(f"lanes-rzbm: {differ.sum()} of {differ.size} bounds differ from today's ({rows_differ.sum()} of {N} rows), "
          f"wider {wider}, narrower {narrower}; ulp apart: max {u.max(initial=0)}")
    # the step alone on floats of every magnitude, and around the smallest normal number (2^-1022)
    rng = np.random.default_rng(4302)
    c = np.concatenate([rng.choice([-1.0, 1.0], 10**6) * 10.0 ** rng.uniform(-323, 308, 10**6),
                        rng.choice([-1.0, 1.0], 10**5) * 2.0 ** rng.uniform(-1024, -1020, 10**5),
                        rng.uniform(-10, 10, 10**5)])
    c = c[np.isfinite(c)]
    dn_rz, up_rz, dn_bits, up_bits = (np.empty_like(c) for _ in range(4))
    _steps(c, dn_rz, up_rz, dn_bits, up_bits)
    assert np.array_equal(dn_bits, np.nextafter(c, -INF)) and np.array_equal(up_bits, np.nextafter(c, INF))
    assert np.all(dn_rz <= dn_bits) and np.all(up_rz >= up_bits)  # at least one float out
    two = (dn_rz < dn_bits) | (up_rz > up_bits)
    near = np.abs(c[two])
    print(f"the step alone on {c.size} floats of every magnitude: bits = np.nextafter everywhere; rzbm one float "
          f"further out at {two.sum()} ({100 * two.mean():.2f} %), all with |c| in "
          f"[{near.min(initial=np.inf):.3g}, {near.max(initial=0):.3g}] (smallest normal {np.finfo(float).tiny:.3g})")
    # ------------------------------------------------------------------ times
    print(f"\nns per row and sample (one velocity contraction of one row, every baseline), best of 7 interleaved, "
          f"N = {N} rows")
    names = list(KERNELS)
    print(f"{'R':>5} {'per-row':>9}" + "".join(f" {k:>11}" for k in names) + "".join(f" {'/' + k:>12}" for k in names)
          + "   (per-row / lanes)")

    def calibrate(fn, R):
        reps = 1
        while True:  # about args.rows_time / 5 seconds per timing
            t = time.perf_counter()
            fn(R, reps)
            if time.perf_counter() - t > args.rows_time / 5 or reps > 10**6:
                return reps
            reps *= 2

    def best(fns, R, rounds=7):
        """ns per row of each of ``fns`` (interleaved, the best of ``rounds``: the cores are shared)."""
        reps = [calibrate(fn, R) for fn in fns]
        times = [[] for _ in fns]
        for _ in range(rounds):
            for i, fn in enumerate(fns):
                t = time.perf_counter()
                fn(R, reps[i])
                times[i].append(time.perf_counter() - t)
        return [min(t) / (k * (N // R * R)) * 1e9 for t, k in zip(times, reps)]

    scratch_out = XD0.copy()
    fns = [lambda R_, k: run_per_row(R_, k, XD_row)]
    fns += [lambda R_, k, kern=kern: run_lanes(kern, R_, k, scratch_out) for kern in KERNELS.values()]
    for R in (1, 16, 64, 256):
        base, *t = best(fns, R)
        print(f"{R:>5} {base:>9.0f}" + "".join(f" {x:>11.0f}" for x in t) + "".join(f" {base / x:>12.2f}" for x in t))
    tape_fns = [lambda R_, k, kern=kern: kern[3](prog.code, prog.value, prog.meta, X, Q, XI, PX, PQ, DQs, J, R_, k, il, ih,
                                                 nl, nh, mk, mv, flag) for kern in KERNELS.values()]
    t_tape = dict(zip(KERNELS, best(tape_fns, 256)))
    print("of which the tape (inputs and sweep, every baseline), R = 256: "
          + ", ".join(f"{k} {v:.0f} ns" for k, v in t_tape.items()))
    print("\none operation over 256 lanes alone (seeded operands from 1e-3 to 1e3, both signs, no zeros), ns per lane:")
    rng = np.random.default_rng(43)
    lanes_ = 256
    a = rng.choice([-1.0, 1.0], (4, lanes_)) * 10.0 ** rng.uniform(-3, 3, (4, lanes_))
    al, ah = np.minimum(a[0], a[1]), np.maximum(a[0], a[1])
    bl, bh = np.minimum(a[2], a[3]), np.maximum(a[2], a[3])
    outs_ = {}
    fl = np.zeros(lanes_, np.bool_)
    for (op, stp), loop in OP_LOOPS.items():
        ol, oh = np.empty(lanes_), np.empty(lanes_)
        loop(al, ah, bl, bh, ol, oh, fl, 1)
        outs_[(op, stp)] = (ol.copy(), oh.copy())
        reps = 20000
        t = min(_timed(loop, al, ah, bl, bh, ol, oh, fl, reps) for _ in range(5))
        print(f"  {op} {stp:>32}: {t / (reps * lanes_) * 1e9:6.2f} ns; {vector_report(loop)}")
    steps = list(STEPS)
    for op in ("add", "mul"):
        same = [all(np.array_equal(x.view(np.int64), y.view(np.int64))
                    for x, y in zip(outs_[(op, steps[0])], outs_[(op, stp)])) for stp in steps[1:]]
        print(f"  {op}: bit for bit today's: " + ", ".join(f"{stp.split()[0]} {ok}" for stp, ok in zip(steps[1:], same)))
    print("\nvectorisation (numba's assembly and LLVM IR of each compiled function):")
    for name, kernel in KERNELS.items():
        print(f"  {name:>10} tape interpreter: {vector_report(kernel[2])}")
        print(f"  {name:>10} contraction:      {vector_report(kernel[1])}")


if __name__ == "__main__":
    main()
