"""A planned 6-DOF crossing of the Gough–Stewart platform, for ``crosscert certify --plan``.

Writes ``gough_stewart_crossing.csv`` (``t, q1..q6, x1..x6``; docs/file-formats.md,
"Planned trajectory"): a rest-to-rest straight segment in the pose space from
``START`` to ``GOAL``, every coordinate moving, through the Type 2 locus at
``yaw = pi/2`` (the platform turned by a quarter turn about the vertical;
robots/gough_stewart.py), timed by crosscert's own smoothstep law
(:func:`planner.plan.plan_crossing`: speed ramps peaking at ``--a-peak``,
constant speed through the crossing point, the crossing instant on a sample).

The pose mixes metres and radians, and ``plan_crossing`` measures the segment
in the plain Euclidean norm of the pose vector.  This script states the speed
as ``certify --plan`` reports it, the translational speed at the singularity
(m/s), and converts: along this segment the yaw rate is
``|GOAL - START|_yaw / |GOAL - START|_translation`` = 13.9 rad per metre
translated.  The ramps' peak (``--a-peak``, in the same mixed norm) lands
almost entirely on the yaw axis: keep it within the robot's 120 rad/s^2.

    python docs/examples/gough_stewart_crossing.py            # writes docs/examples/gough_stewart_crossing.csv
    crosscert certify --robot gough-stewart --plan docs/examples/gough_stewart_crossing.csv

SI units: m, rad, s.
"""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

import numpy as np

try:
    import crosscert  # noqa: F401
except ImportError:  # run from a checkout without installing: the repository root on the path
    sys.path.insert(0, str(Path(__file__).resolve().parents[2]))

from crosscert.planner.plan import plan_crossing
from crosscert.planner.task import CrossingTask, PlanningBounds
from crosscert.robots import KinematicModel, get_robot
from crosscert.robots.gough_stewart import gs_ik
from crosscert.verifier.trajfile import write_trajectory

#: Start and goal at rest (p_x, p_y, p_z m; yaw, pitch, roll rad): a yaw turn of 1.5 rad through the locus at
#: pi/2 (0.97 rad before it, where the first sample's pose is still isolated; 0.53 rad after it), with 108 mm of
#: translation and +-0.03 rad of pitch and roll on the way.  The goal's joints also reach a mode -1 pose inside
#: x_bounds (p_z = 0.978 m, yaw = 1.04 rad): the final readings alone do not decide the mode.
START = (-0.04, -0.03, 0.78, 0.6, -0.03, 0.02)
GOAL = (0.04, 0.03, 0.82, 2.1, 0.03, -0.02)
#: Translational speed at the singularity, m/s (6.96 rad/s of yaw), and the ramps' peak in the pose norm.
V_SING = 0.5
A_PEAK = 119.0
HERE = Path(__file__).resolve().parent


def planned_crossing(v_sing: float = V_SING, a_peak: float = A_PEAK, start=START, goal=GOAL):
    """The plan: crosscert's smoothstep law along ``start -> goal`` at translational speed ``v_sing`` (m/s)."""
    robot = get_robot("gough-stewart")
    start, goal = np.asarray(start, float), np.asarray(goal, float)
    d = goal - start
    path_speed = v_sing * np.linalg.norm(d) / np.linalg.norm(d[:3])  # the segment's norm per translated metre
    task = CrossingTask(start, goal, gs_ik(start, robot.xi_center))
    return plan_crossing(KinematicModel(robot), task, path_speed, PlanningBounds(a_peak=a_peak))


def main(argv=None) -> int:
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--v-sing", type=float, default=V_SING, help="translational speed at the singularity, m/s")
    p.add_argument("--a-peak", type=float, default=A_PEAK, help="peak of the speed ramps (pose norm)")
    p.add_argument("-o", "--output", default=str(HERE / "gough_stewart_crossing.csv"))
    a = p.parse_args(argv)
    plan = planned_crossing(a.v_sing, a.a_peak)
    write_trajectory(a.output, plan.t, plan.q, x=plan.x)
    k = plan.k_sing
    print(f"wrote {a.output}: {len(plan.t)} samples, crossing at sample {k} (yaw {plan.x[k, 3]:.4f} rad), "
          f"{np.linalg.norm(plan.xd[k, :3]):.3f} m/s and {plan.xd[k, 3]:.2f} rad/s there, peak |xdd| per axis "
          + ", ".join(f"{v:.1f}" for v in np.abs(plan.xdd).max(axis=0)))
    return 0


if __name__ == "__main__":
    sys.exit(main())
