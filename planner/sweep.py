"""Operating-range sweep (the paper's Table II) on simulated crossings.

For each speed at the singularity, a crossing is simulated with the true
geometry, then tracked under each velocity error model; all speeds of one
model run as one batch (shorter runs are padded with their last sample: the
robot rests).  Generic over robots: the caller gives the crossing.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from crosscert.verifier.model import IntervalModel
from crosscert.verifier.settings import TrackerSettings, VelocityModel, Verdict
from crosscert.verifier.tracker import initial_box_from_mode, track_batch

from .simulate import ramp_length, simulate_crossing
from .simulate.run import A_PEAK

__all__ = ["SweepRow", "sweep", "cruise_for", "T_REST"]

#: Rest before each simulated crossing of the sweep, s.
T_REST = 0.1


@dataclass(frozen=True)
class SweepRow:
    """One line of the table: a speed under one error model."""

    v_sing: float
    velocity_model: str
    verdict: Verdict
    max_width_pose: float  # m_x, m
    max_width_velocity: float  # m_xd, m/s
    certified_at_step: int | None  # first sample of the certified final mode; None when not certified
    k_sing: int
    contained: bool  # true pose and velocity inside every box (simulation only)


def cruise_for(v_sing, a_peak=A_PEAK, start_distance=0.035, minimum=0.005):
    """Half-length (m) of the constant-speed zone so that every run starts at
    least ``start_distance`` (m) before the locus, whatever its speed."""
    return max(minimum, start_distance - ramp_length(v_sing, a_peak)[1])


def sweep(robot, kin, crossing, speeds, models=(VelocityModel.PAPER, VelocityModel.SOUND), *, xi_true=None,
          seed=0, t_rest=T_REST, a_peak=A_PEAK, start_distance=0.035, initial_mode=None, settings_kw=None, progress=None,
          record_speed=None):
    """Track simulated crossings at several speeds under several error models.

    Parameters
    ----------
    robot : robots.Robot
    kin : robots.KinematicModel
    crossing : object with ``point``, ``direction``, ``q_point``
        The nominal crossing (point on the locus, m; unit direction; joints near it).
    speeds : sequence of float
        Speeds at the singularity, m/s.
    models : sequence of VelocityModel
    xi_true : array (m,), optional
        True geometry (nominal by default).
    start_distance : float
        Every run starts at least this far (m) before the locus (the constant
        speed zone grows for slow crossings), so slow runs do not start next to it.
    initial_mode : int, optional
        Assembly mode at the start, given to the tracker; default the mode of
        each simulated run's first sample (which side of the locus the
        benchmark starts on depends on the robot).
    record_speed : float, optional
        Speed whose boxes are returned for figures.

    Returns
    -------
    rows : list of SweepRow
    figures : dict
        ``{model: (run, boxes)}`` for ``record_speed`` (empty if none).
    """
    imodel = IntervalModel(robot)
    runs = [
        simulate_crossing(kin, crossing.point, crossing.direction, v, xi_true=xi_true, t_rest=t_rest,
                          a_peak=a_peak, cruise=cruise_for(v, a_peak, start_distance), working_guess=crossing.q_point,
                          seed=seed)
        for v in speeds
    ]
    K = max(r.n_samples for r in runs)
    q = np.stack([np.vstack([r.q_meas, np.repeat(r.q_meas[-1:], K - r.n_samples, axis=0)]) for r in runs])
    rows = []
    figures = {}
    for vm in models:
        s = TrackerSettings.for_robot(robot, velocity_model=vm, **(settings_kw or {}))
        boxes = [initial_box_from_mode(imodel, q[b, 0], int(runs[b].mode_true[0]) if initial_mode is None else initial_mode,
                                       s) for b in range(len(runs))]
        x0 = (np.array([b[0] for b in boxes]), np.array([b[1] for b in boxes]))
        res, rec = track_batch(imodel, q, s, x0, record=True, progress=progress)
        for b, r in enumerate(runs):
            N = r.n_samples
            ok = res.inconsistent_at_step[b] < 0
            inside = bool(
                np.all(rec["x_lo"][b, :N] <= r.x_true) and np.all(r.x_true <= rec["x_hi"][b, :N])
                and np.all(rec["xd_lo"][b, 1:N] <= r.xd_true[1:]) and np.all(r.xd_true[1:] <= rec["xd_hi"][b, 1:N])
            ) if ok else False
            step = int(res.certified_at_step[b])
            rows.append(SweepRow(float(r.v_sing), str(vm), res.verdict[b], float(res.max_width_pose[b]),
                                 float(res.max_width_velocity[b]), None if step < 0 else step, int(r.k_sing), inside))
            if record_speed is not None and abs(r.v_sing - record_speed) < 1e-12:
                figures[str(vm)] = (r, {k: v[b, :N] for k, v in rec.items()})
    return rows, figures
