"""A planar five-bar of your own, as a robot file: ``crosscert ... --robot docs/examples/five_bar.py:FIVE_BAR``.

The worked example of docs/your-robot.md.  Motors at ``A1 = (-d/2, 0)`` and
``A2 = (d/2, 0)``; proximal link ``i`` (length ``l_i1``) ends at the elbow
``B_i = A_i + l_i1 (cos(q_i + delta_i), sin(q_i + delta_i))``; the distal
links (lengths ``l_i2``) meet at the end-effector ``E = (x, y)``.  Proximal
0.25 m, distal 0.30 m, base 0.15 m; lengths calibrated to ±0.2 mm, encoder
offsets to ±3 mrad; encoders of 2^17 counts per turn.  SI units: m, rad, s.
"""

import math

import casadi as ca
import numpy as np

from crosscert.robots import BenchmarkCrossing, Robot, RobotEntry

MM, MRAD = 1e-3, 1e-3
L1, L2, D = 0.25, 0.30, 0.15  # proximal, distal, base, m


def loop_closure(x, q, xi):
    """|E - B_i|^2 - l_i2^2 for both legs, m^2 (CasADi symbols in, one column out)."""
    l11, l21, l12, l22, d, delta1, delta2 = (xi[i] for i in range(7))
    b1x, b1y = -d / 2 + l11 * ca.cos(q[0] + delta1), l11 * ca.sin(q[0] + delta1)
    b2x, b2y = d / 2 + l21 * ca.cos(q[1] + delta2), l21 * ca.sin(q[1] + delta2)
    return ca.vertcat((x[0] - b1x) ** 2 + (x[1] - b1y) ** 2 - l12**2,
                      (x[0] - b2x) ** 2 + (x[1] - b2y) ** 2 - l22**2)


def elbows(q, xi):
    """The elbows B1, B2 (m) for joints ``q`` (rad) and geometry ``xi``."""
    l11, l21, _l12, _l22, d, delta1, delta2 = xi
    return (np.array([-d / 2 + l11 * math.cos(q[0] + delta1), l11 * math.sin(q[0] + delta1)]),
            np.array([d / 2 + l21 * math.cos(q[1] + delta2), l21 * math.sin(q[1] + delta2)]))


def side_of_elbow_line(x, q, xi):
    """The assembly mode: +1 when E is left of the directed line B1 -> B2, else -1."""
    b1, b2 = elbows(q, xi)
    u, v = b2 - b1, np.asarray(x, dtype=float) - b1
    return 1 if u[0] * v[1] - u[1] * v[0] > 0 else -1


# J_x has rows 2 (E - B_i), so det J_x = 4 cross(B2 - B1, E - B1): positive when E is left of B1 -> B2
ROBOT = Robot(
    name="five-bar-250", n=2,
    param_names=("l11", "l21", "l12", "l22", "d", "delta1", "delta2"),
    xi_nominal=(L1, L1, L2, L2, D, 0.0, 0.0),
    xi_lo=(L1 - 0.2 * MM, L1 - 0.2 * MM, L2 - 0.2 * MM, L2 - 0.2 * MM, D - 0.2 * MM, -3 * MRAD, -3 * MRAD),
    xi_hi=(L1 + 0.2 * MM, L1 + 0.2 * MM, L2 + 0.2 * MM, L2 + 0.2 * MM, D + 0.2 * MM, 3 * MRAD, 3 * MRAD),
    q_lo=(-0.5 * math.pi, -0.5 * math.pi), q_hi=(1.5 * math.pi, 1.5 * math.pi),  # one turn each, rad
    # (low corner, high corner): |E - A_i| <= l_i1 + l_i2 = 0.5504 m; each mode has one FK solution in it
    x_bounds=((-0.63, -0.56), (0.63, 0.56)),
    loop_closure=loop_closure,
    pose_units=("m", "m"), joint_units=("rad", "rad"),
    a_max=(80.0, 80.0), xd0=(0.1, 0.1),  # m/s^2, m/s
    eps_q=2 * math.pi / 2**17, t_s=1e-3,  # one count of a 2^17-count encoder, rad; 1 kHz
    xi_splits=(1, 1, 1, 1, 1, 2, 2),  # the two offsets halved: four geometry hypotheses
    joint_offsets=(5, 6),  # the loop closure reads q_i only through q_i + delta_i
    mode_sign=1.0, mode_reference=side_of_elbow_line,
    description="Planar five-bar, proximal 0.25 m, distal 0.30 m, base 0.15 m (docs/your-robot.md).",
)


def elbows_out_ik(x, xi):
    """Joints (rad) placing E at ``x`` with B1 left of A1 -> E and B2 right of A2 -> E ("elbows out")."""
    l11, l21, l12, l22, d, delta1, delta2 = xi
    q = []
    for ax, l1, l2, delta, side in ((-d / 2, l11, l12, delta1, 1.0), (d / 2, l21, l22, delta2, -1.0)):
        vx, vy = x[0] - ax, x[1]
        r = math.hypot(vx, vy)
        q.append(math.atan2(vy, vx) + side * math.acos((l1**2 + r**2 - l2**2) / (2 * l1 * r)) - delta)
    return np.array(q)


def benchmark(xi=None):
    """Down the Y axis through the Type 2 locus, elbows out: the height where E meets the line B1 B2
    (bisection on the mode's cross product between y = 0.2 m, mode +1, and 0.05 m, mode -1)."""
    xi = np.array(ROBOT.xi_nominal if xi is None else xi, dtype=float)

    def cross(y):
        b1, b2 = elbows(elbows_out_ik((0.0, y), xi), xi)
        u, v = b2 - b1, np.array([0.0, y]) - b1
        return u[0] * v[1] - u[1] * v[0]

    hi, lo = 0.2, 0.05
    for _ in range(60):  # 0.15 m / 2^60: below a float's resolution of y
        mid = 0.5 * (hi + lo)
        hi, lo = (mid, lo) if cross(mid) > 0 else (hi, mid)
    point = np.array([0.0, 0.5 * (hi + lo)])
    return BenchmarkCrossing(point=point, direction=np.array([0.0, -1.0]), q_point=elbows_out_ik(point, xi), xi=xi)


FIVE_BAR = RobotEntry(ROBOT, benchmark=benchmark)
