"""The compiled backend's side in Python: :class:`CompiledStep`, the twin of :class:`verifier.step.NumpyStep`.

It hands the numba kernels of :mod:`verifier.compiled.step` the state's arrays (under the names of
:mod:`verifier.state`), per-thread scratch and the block of readings, and runs a batch's slots on threads
(the kernels release the GIL).  The kernels are imported, and compiled or loaded from the cache, on first
use only: importing this module imports no numba.
"""

from __future__ import annotations

import os
import threading
from concurrent.futures import ThreadPoolExecutor

import numpy as np

from ..constants import SOUND
from ..motion_model import contract_tubes

__all__ = ["CompiledStep"]


#: Rows per thread from which a batch of the ``SOUND`` velocity model runs in lanes
#: (:mod:`verifier.compiled.lanes`): below it the per-row driver is faster (benchmarks/README.md).
LANES_MIN_ROWS = 16
#: Rows in one chunk of lanes (whole scenarios): enough for the loops over lanes to pay, few
#: enough that a chunk's state stays in the cache.
LANES_CHUNK_ROWS = 128


class CompiledStep:
    """The numba kernels of :mod:`verifier.compiled.step`, imported (and
    compiled or loaded from the cache) on first use only."""

    @staticmethod
    def _threads(config, st):
        """Which driver runs ``st`` and with how many scratch slots (threads): the hypotheses of a
        sample over numba's threads (``spread_hypotheses``), or :func:`run_slot` once per slot, the
        slots on Python threads (``parallel``; the kernels release the GIL)."""
        import numba

        from . import step as kernels

        threads = numba.config.NUMBA_NUM_THREADS
        if threads > 1 and config.spread_hypotheses and st.batch < threads and st.hypotheses > 1:
            return kernels.run_hypotheses_parallel, min(threads, st.hypotheses)
        slots = min(threads, st.batch) if threads > 1 and config.parallel and st.batch > 1 else 1
        if (int(config.const.velocity_model) == SOUND and st.batch * st.hypotheses >= LANES_MIN_ROWS * slots
                and _lanes_ready()):
            from .lanes.step import run_lanes

            return run_lanes, slots
        return kernels.run_slot, slots

    def _args(self, config, st):
        """The kernel's arguments that stay the same from call to call, built
        once per state: the state's arrays as tuples, the per-thread scratch
        and the empty record and prior."""
        a = st.kernel_args
        if not a or a["config"] is not config or a["rows"].x is not st.x or a["scen"].mode is not st.mode:
            # first call, another configuration (the scratch is sized from it), or
            # a state copied with other arrays (dataclasses.replace)
            a = st.kernel_args = {"config": config}
            from . import step as kernels
            from .contractors import scratch_arrays

            model, c = config.model, config.const
            run, threads = self._threads(config, st)
            lanes = run is not kernels.run_slot and run is not kernels.run_hypotheses_parallel
            lane_scratch = _lane_scratch(model, c, st, threads) if lanes else None
            if run is kernels.run_slot:
                from . import warm

                # a child process may be compiling it (planner.cli starts one): its cache entry, not a second
                # compilation here; without one (or if it failed) the first call below compiles as usual
                if int(c.velocity_model) in warm.pending():
                    _load_pair_kernel(model.n)  # meanwhile: the window's, which it would compile after the driver
                warm.wait(c.velocity_model)
            B, n = st.batch, model.n
            a.update(
                run=run,
                # the extra arguments of each call per block: run_slot's (slot, slots), once per slot (the
                # lanes' driver: its lanes scratch first); the hypotheses' driver is called once, with none
                slots=(tuple((lane_scratch, t, threads) for t in range(threads)) if lanes
                       else tuple((t, threads) for t in range(threads)) if run is kernels.run_slot else ((),)),
                # the kernels' views of the state, field by field under the same names
                rows=kernels.Rows(*(getattr(st, f) for f in kernels.Rows._fields)),
                scen=kernels.Scenarios(*(getattr(st, f) for f in kernels.Scenarios._fields)),
                scratch=scratch_arrays(threads, model.program.n_nodes, n, model.m, c.baseline.shape[0],
                                       c.split_boxes, st.hypotheses),
                no_record=kernels.Record(np.zeros((B, 0, 2, n)), np.zeros((B, 0, 2, n)), np.zeros((B, 0), np.int64),
                                         np.zeros((B, 0, n))),
                no_prior=kernels.Prior(np.zeros((B, 0, 2, n)), np.zeros((B, 0, 2, n))),
                # its type selects the velocity model's kernels: a driver compiled per model in use
                vel=kernels.velocity_strategy(c.velocity_model),
                Record=kernels.Record, Prior=kernels.Prior)
        return a

    def advance(self, config, st, q, record=None, prior=None, const=None):
        a = self._args(config, st)
        slots = a["slots"]
        head = (config.model.program, config.const if const is None else const, a["vel"], a["rows"], a["scen"],
                a["scratch"])
        if record is None and prior is None and len(slots) == 1:
            # the online path: every argument's type is fixed for this state (q is a
            # C-contiguous float64 copy), so after the first call the compiled entry
            # point runs directly; numba's dispatcher would spend longer typing the
            # nested tuples of arrays than the kernel takes for a sample at rest
            args = head + slots[0] + (int(st.k), q, False, a["no_record"], False, a["no_prior"])
            entry = a.get("entry")
            if entry is None:
                a["run"](*args)
                a["entry"] = _entry_point(a["run"], args)
            else:
                entry(*args)
        else:
            rec = a["no_record"] if record is None else a["Record"](*record)
            pri = a["no_prior"] if prior is None else a["Prior"](*prior)
            tail = (int(st.k), q, record is not None, rec, prior is not None, pri)
            # slot 0 on this thread, the others on the pool's
            others = [_slot_pool(len(slots) - 1).submit(a["run"], *head, *extra, *tail) for extra in slots[1:]]
            try:
                a["run"](*head, *slots[0], *tail)
            finally:
                for f in others:
                    f.result()  # every slot finishes before the state is read; re-raises a slot's error
        st.k += q.shape[1]

    def pose_solutions(self, model, Q, XI, X_search, tol, small, max_boxes, sweeps):
        from .contractors import pose_solutions as kernel

        box = lambda b: np.ascontiguousarray(np.stack([np.asarray(b[0], float), np.asarray(b[1], float)])[None])  # noqa: E731
        out, modes, scratch, work = _enumeration_buffers(model, int(max_boxes))
        count = kernel(model.program, box(Q), box(XI), box(X_search), float(tol), float(small), int(max_boxes),
                       int(sweeps), out, modes, scratch, work)
        if count < 0:
            return None
        return out[:count].copy(), modes[:count].copy()


#: Whether a batch may compile the lanes driver in this process when it is neither compiled here nor in
#: numba's disk cache (tests and benchmarks set it).  By default such a batch runs row by row (the same boxes)
#: while the compile child (:mod:`verifier.compiled.warm`) writes the lanes driver to the cache: its
#: compilation (about 40 s of CPU) never lengthens a command.
LANES_COMPILE_HERE = False


_ASKED_FOR_LANES = []
#: Environment variable: ``0`` keeps every batch on the per-row path (the same boxes; for comparisons).
LANES_ENV = "CROSSCERT_LANES"


def _lanes_ready() -> bool:
    """Whether the lanes driver runs without a compilation in this process (or may compile here).  The first
    time a batch finds it missing, a child that compiles it is asked for (:func:`verifier.compiled.warm.start_lanes`:
    one when a core is free and none runs), so that a script's later batches run in lanes."""
    if os.environ.get(LANES_ENV, "").strip() == "0":
        return False
    if LANES_COMPILE_HERE:
        return True
    from . import warm

    if warm.lanes_cached():
        return True
    if not _ASKED_FOR_LANES:
        _ASKED_FOR_LANES.append(True)
        warm.start_lanes()
    return False


def _lane_scratch(model, c, st, threads):
    """The lanes driver's scratch for ``threads`` slots: chunks of whole scenarios, about
    :data:`LANES_CHUNK_ROWS` rows, no more than a slot's share of the batch."""
    from .lanes.step import lane_scratch_arrays

    P = st.hypotheses
    chunk = max(1, min(LANES_CHUNK_ROWS // P, -(-st.batch // threads)))
    return lane_scratch_arrays(threads, chunk, P, model.program.n_nodes, model.n, model.m, c.baseline.shape[0])


def _load_pair_kernel(n: int) -> None:
    """Compile (or load) the window's pair contraction (:func:`verifier.compiled.motion_model.pair_kernel`) by
    contracting two samples of one row whose velocity boxes are disjoint: the argument types of every call
    (C-contiguous tubes of ``n`` pose coordinates)."""
    x = np.zeros((1, 2, 2, n))
    xd = np.zeros((1, 2, 2, n))
    xd[0, 1] = 1.0
    contract_tubes(x, xd, 1e-3, np.ones(n), offsets=(1,), compiled=True)


_BUFFERS = threading.local()


def _enumeration_buffers(model, max_boxes: int):
    """The compiled enumeration's output, scratch and stack ``(max_boxes + 4, 2, n)`` for this thread,
    allocated once per size (the fixed-lag window enumerates at nearly every sample; the kernel
    overwrites whatever it reads)."""
    from .contractors import scratch_arrays

    key = (model.n, model.m, model.program.n_nodes, max_boxes)
    got = getattr(_BUFFERS, "by_size", None)
    if got is None or got[0] != key:
        got = _BUFFERS.by_size = (key, (np.empty((max_boxes, 2, model.n)), np.empty(max_boxes, np.int64),
                                        scratch_arrays(1, model.program.n_nodes, model.n, model.m, 0, 0, 1),
                                        np.empty((max_boxes + 4, 2, model.n))))
    return got[1]


_POOL: dict = {}
_POOL_LOCK = threading.Lock()


def _slot_pool(threads):
    """The threads that run a batch's slots: one pool per thread count, for the process."""
    with _POOL_LOCK:
        if threads not in _POOL:
            _POOL[threads] = ThreadPoolExecutor(max_workers=threads, thread_name_prefix="crosscert-slot")
        return _POOL[threads]


def _entry_point(dispatcher, args):
    """The compiled function a numba dispatcher runs for ``args``, called
    without the dispatcher's typing of every argument (``dispatcher`` itself
    when it has no such overload)."""
    import numba

    try:
        return dispatcher.overloads[tuple(numba.typeof(v) for v in args)].entry_point
    except (KeyError, AttributeError):
        return dispatcher
