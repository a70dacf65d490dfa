"""A certificate's promise at run time: the readings checked, sample by sample, against the certified envelope.

A planning-time certificate (``certificate.json`` of ``crosscert certify``)
proves its verdict for every execution whose effective joints stay within the
certified class around the planned joints ``q_plan`` (:mod:`planner.execution`):
the certifying run fed the tracker ``q_plan(t_k)`` with reading error ``e``
(split, for a ``cartesian`` class, into a fast part ``f`` and a slow part
changing by at most ``d`` per sample: assumption A9 of docs/soundness.md).

At run time the encoders read ``q̂_k = q_k + n_k`` with ``|n_k| <= eps_q``.
Write ``D_k = q̂_k - q_plan(t_k)``.  The certifying run's reading error of
this execution is ``q_plan(t_k) - q_k = -D_k + n_k``; split it as slow part
``-D_k`` and fast part ``n_k``.  It satisfies the certifying run's assumptions
whenever, at every sample and joint,

* ``|D_k| + eps_q <= e`` (the total bound),
* ``eps_q <= f`` (the fast part; checked once, when the envelope is loaded),
* ``|D_k - D_{k-1}| <= d`` (the slow part's drift; ``cartesian`` classes only).

The other assumptions (the true geometry in the calibration box, ``|ẍ| <=
a_max``, a start at rest in the plan's initial mode, the plan's sampling
period) are the run-time tracker's own.  So while the readings up to the
sample where the certified run decided lie in the envelope, the true motion
is one the certifying run enclosed, and the certificate's verdict holds for
this execution from that sample on.  Every comparison is rounded against the
claim (the deviations up, the bounds down), so a reading exactly on the
envelope's edge counts as outside.  When a reading leaves the envelope the
check says where and by how much, and the run-time tracker's own reasoning
answers from then on.
"""

from __future__ import annotations

import hashlib
import json
from dataclasses import dataclass
from enum import StrEnum
from pathlib import Path

import numpy as np

from crosscert.robots.errors import InputError
from crosscert.verifier.settings import Verdict
from crosscert.verifier.trajfile import read_trajectory

__all__ = ["EnvelopeState", "EnvelopeStatus", "CertifiedEnvelope", "EnvelopeMonitor"]


class EnvelopeState(StrEnum):
    """Where a run stands against a certificate's envelope after a sample."""

    INSIDE = "inside"  # every reading so far in the envelope; the certified run has not decided yet
    CERTIFIED = "certified"  # every reading up to the certified run's decision in it: its verdict holds
    LEFT = "left"  # a reading left the envelope before the decision: the run-time tracker answers
    BEYOND_PLAN = "beyond-plan"  # more samples than the plan: the certificate says nothing of them


@dataclass(frozen=True)
class EnvelopeStatus:
    """After sample ``k``: the ``state``; the certificate's ``verdict`` once ``CERTIFIED``, else ``UNKNOWN``;
    where the run left the envelope (``left_at`` sample, ``joint`` 0-based, ``excess`` in the joint's unit
    beyond the bound; ``-1`` and ``0.0`` while it has not) and which check it failed (``what``)."""

    k: int
    state: EnvelopeState
    verdict: Verdict
    left_at: int = -1
    joint: int = -1
    excess: float = 0.0
    what: str = ""

    @property
    def holds(self) -> bool:
        """The certificate's verdict holds for this run (``CERTIFIED``, or ``BEYOND_PLAN`` after it)."""
        return self.state in (EnvelopeState.CERTIFIED, EnvelopeState.BEYOND_PLAN)

    def summary(self) -> dict:
        return {"k": self.k, "state": self.state.value, "verdict": self.verdict.value,
                "left_at_sample": None if self.left_at < 0 else self.left_at,
                "joint": None if self.joint < 0 else self.joint + 1, "excess": self.excess, "check": self.what or None}


def _down(v) -> np.ndarray:
    return np.nextafter(np.asarray(v, float), -np.inf)


@dataclass(frozen=True, eq=False)
class CertifiedEnvelope:
    """The envelope of one certificate (read-only arrays; SI, joint units).

    Attributes
    ----------
    robot : str
    q_plan : ndarray (K, n)
        The certified plan's joints.
    t_s : float
        Its sampling period, s.
    radius : ndarray (n,)
        ``e - eps_q`` rounded down: the largest ``|D_k|`` admitted.
    step : ndarray (n,) or None
        ``d`` rounded down: the largest ``|D_k - D_{k-1}|`` admitted (None: the class has no drift model).
    verdict : Verdict
        The certificate's verdict.
    decided_at : int
        The sample at which the certified run decided (its forward pass's, else the plan's last sample, the
        window passes having read the whole run).
    initial_mode, final_mode : int
    sha256 : str
        Of the plan file.
    """

    robot: str
    q_plan: np.ndarray
    t_s: float
    radius: np.ndarray
    step: np.ndarray | None
    verdict: Verdict
    decided_at: int
    initial_mode: int
    final_mode: int
    sha256: str

    @classmethod
    def load(cls, certificate, robot, eps_q, plan=None) -> CertifiedEnvelope:
        """The envelope of ``certificate`` (a ``certificate.json`` path) for ``robot`` read within ``eps_q``.

        ``plan``: the certified plan file (default: the one the certificate names, looked up beside the
        certificate, then as given).

        Raises
        ------
        InputError
            A certificate of another robot, without a certified run, whose plan file is missing or differs
            from the one certified (sha256), or whose fast reading error is below ``eps_q``.
        """
        path = Path(certificate)
        try:
            report = json.loads(path.read_text())
        except (OSError, ValueError) as exc:
            raise InputError(f"--certificate {certificate}: cannot read a certificate: {exc}") from None
        if not isinstance(report, dict) or not str(report.get("schema", "")).startswith("crosscert-certificate/"):
            raise InputError(f"--certificate {certificate}: not a crosscert certificate")
        if report.get("robot") != robot.name:
            raise InputError(f"--certificate {certificate}: a certificate of robot {report.get('robot')!r}, "
                             f"not {robot.name!r}")
        run, source, cls_ = report.get("certified_run"), report.get("plan"), report.get("execution")
        if not run or not source or not cls_:
            raise InputError(f"--certificate {certificate}: it certifies no plan (verdict "
                             f"{report.get('verdict')!r}): nothing to hold a run against")
        if plan is None:
            beside = path.parent / Path(source["file"]).name
            plan = beside if beside.is_file() else Path(source["file"])
        try:
            digest = hashlib.sha256(Path(plan).read_bytes()).hexdigest()
        except OSError as exc:
            raise InputError(f"--certificate {certificate}: cannot read its plan {plan}: {exc}") from None
        if digest != source["sha256"]:
            raise InputError(f"--certificate {certificate}: the plan {plan} is not the certified one (sha256 "
                             f"{digest[:12]}..., certified {source['sha256'][:12]}...)")
        traj = read_trajectory(plan, robot.n, nominal_t_s=robot.t_s)
        return cls.of(robot, traj.q, traj.t_s, cls_, eps_q, verdict=Verdict(report["verdict"]),
                      decided_at=int(run["decided_at_sample"]), initial_mode=int(run["initial_mode"]),
                      final_mode=int(run["final_mode"]), sha256=digest, where=f"--certificate {certificate}: ")

    @classmethod
    def of(cls, robot, q_plan, t_s, execution: dict, eps_q, *, verdict: Verdict, decided_at: int,
           initial_mode: int, final_mode: int, sha256: str = "", where: str = "") -> CertifiedEnvelope:
        """The envelope of a certified run: the plan's joints ``q_plan`` (K, n) at period ``t_s`` (s), its
        execution class as in ``certificate.json`` (``execution``: ``ExecutionClass.summary()``), readings
        within ``eps_q`` (joint units), the certified ``verdict`` reached at sample ``decided_at``.

        Raises
        ------
        InputError
            The fast reading error is below ``eps_q`` (``where`` prefixes the message).
        """
        eps = np.broadcast_to(np.asarray(eps_q, float), (robot.n,))
        e = np.broadcast_to(np.asarray(execution["reading_error"], float), (robot.n,))
        fast = execution.get("fast_error")
        fast = e if fast is None else np.broadcast_to(np.asarray(fast, float), (robot.n,))
        if np.any(eps > fast):
            raise InputError(f"{where}the readings' error eps_q = {float(np.max(eps)):.4g} exceeds the certified "
                             f"fast reading error {float(np.min(fast)):.4g}: the certificate does not cover "
                             "readings that coarse")
        radius = _down(e - eps)
        if np.any(radius < 0.0):
            radius = np.zeros(robot.n)  # no room left around the plan: only the plan itself, never reached
        d = execution.get("drift_per_sample")
        step = None if d is None else _down(np.broadcast_to(np.asarray(d, float), (robot.n,)))
        q = np.array(q_plan, float)
        for a in (q, radius) + (() if step is None else (step,)):
            a.setflags(write=False)
        return cls(robot.name, q, float(t_s), radius, step, verdict, int(decided_at), int(initial_mode),
                   int(final_mode), sha256)

    def check(self, q) -> EnvelopeStatus:
        """The readings ``q`` (K, n) of one run checked up to the certified decision, as ``monitor
        --certificate`` checks them: ``CERTIFIED`` when all of them lie in the envelope (the certificate's
        verdict holds for that run), else where they left it (``LEFT``, or ``INSIDE`` for a run that ends
        before the decision)."""
        mon = EnvelopeMonitor(self)
        for k in range(min(len(q), self.decided_at + 1)):
            if mon.update(q[k]).state is EnvelopeState.LEFT:
                break
        return mon.status


class EnvelopeMonitor:
    """The envelope check of one run, a reading at a time (a few microseconds per sample, no allocation
    beyond the reading's difference)."""

    def __init__(self, envelope: CertifiedEnvelope):
        self.envelope = envelope
        self.k = -1
        self._last = None  # D_{k-1}
        self.status = EnvelopeStatus(-1, EnvelopeState.INSIDE, Verdict.UNKNOWN)

    def update(self, q) -> EnvelopeStatus:
        """Check the reading ``q`` (n,) of the next sample; the status after it."""
        env = self.envelope
        self.k += 1
        k = self.k
        st = self.status.state
        if st in (EnvelopeState.LEFT, EnvelopeState.BEYOND_PLAN):
            self.status = EnvelopeStatus(k, st, self.status.verdict, self.status.left_at, self.status.joint,
                                         self.status.excess, self.status.what)
            return self.status
        if k >= len(env.q_plan):
            self.status = EnvelopeStatus(k, EnvelopeState.BEYOND_PLAN if st is EnvelopeState.CERTIFIED
                                         else EnvelopeState.LEFT, self.status.verdict,
                                         *(() if st is EnvelopeState.CERTIFIED else (k, -1, 0.0, "beyond the plan")))
            return self.status
        D = np.asarray(q, float) - env.q_plan[k]
        # |D| rounded up: the true difference of the two floats is within half an ulp of the computed one
        dev = np.nextafter(np.abs(D), np.inf)
        bad = dev > env.radius
        what = "reading"
        excess = dev - env.radius
        if not bad.any() and env.step is not None and self._last is not None:
            jump = np.abs(D - self._last)
            # each D carries half an ulp, the subtraction one more rounding: add both spacings, round up
            jump = np.nextafter(jump + np.spacing(np.abs(D)) + np.spacing(np.abs(self._last)), np.inf)
            bad = jump > env.step
            what, excess = "drift", jump - env.step
        self._last = D
        if bad.any():
            j = int(np.argmax(np.where(bad, excess, -np.inf)))
            self.status = EnvelopeStatus(k, EnvelopeState.LEFT, Verdict.UNKNOWN, k, j, float(excess[j]), what)
        elif st is EnvelopeState.CERTIFIED or k >= env.decided_at:
            self.status = EnvelopeStatus(k, EnvelopeState.CERTIFIED, env.verdict)
        else:
            self.status = EnvelopeStatus(k, EnvelopeState.INSIDE, Verdict.UNKNOWN)
        return self.status

    def describe(self) -> str:
        """One line on where the run stands against the certificate."""
        s, env = self.status, self.envelope
        if s.state is EnvelopeState.CERTIFIED or s.state is EnvelopeState.BEYOND_PLAN:
            return (f"certificate: readings inside the certified envelope up to sample {env.decided_at}: "
                    f"{env.verdict.value} (mode {env.final_mode:+d}) holds for this execution")
        if s.state is EnvelopeState.LEFT:
            where = "the recording is longer than the plan" if s.joint < 0 else (
                f"joint {s.joint + 1} by {s.excess:.3g} ({s.what} bound)")
            return (f"certificate: the reading of sample {s.left_at} left the certified envelope ({where}): "
                    "the run-time tracker answers")
        return f"certificate: readings inside the envelope so far; the certified run decides at sample {env.decided_at}"
