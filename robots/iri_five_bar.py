"""The five-bar planar parallel robot of IRI (CSIC-UPC, Barcelona), from its authors' published model.

Source
------
The geometry is the model ``Scherbot2.m`` (a five-bar built by Beta Robots)
that R. Bordalba published with the code of

    R. Bordalba, T. Schoels, L. Ros, J. M. Porta and M. Diehl, "Direct
    collocation methods for trajectory optimization in constrained robotic
    systems", IEEE Transactions on Robotics 39(1), 183-202, 2023,

whose five-bar experiments plan and execute motions through forward (Type 2)
singularities: repository ``rbordalba/collocation_constrained_systems``,
file ``libraries/spatial_v2.1/models_closed_chain/Scherbot2.m``, commit
``314989f945273510d6781b0615b84ea5a4799501``, section "PARAMETERS".  That file
gives, each marked "measured in lab":

* base link (distance between the two motor axes) ``L0 = 0.12 m``;
* proximal links ``0.2 m`` (both legs);
* distal links ``0.15 m`` (both legs).

The same file gives estimated link masses and inertias, a 0.5 kg load, viscous
friction and torque limits (2 N m in the model, 1.4 N m in the five-bar
scripts); they are not used here (no dynamic model ships).  The paper's own
text was not available when this module was written: every number above is
the model file's.

Model
-----
The same loop closure as the DexTAR (:func:`robots.dextar.dextar_loop_closure`,
imported, not copied): motors at ``A1 = (-d/2, 0)`` and ``A2 = (d/2, 0)``,
elbows ``B_i = A_i + l_i1 (cos(q_i + delta_i), sin(q_i + delta_i))``,
``f_i = |E - B_i|^2 - l_i2^2``, ``xi = (l11, l21, l12, l22, d, delta1, delta2)``,
assembly mode +1 when ``E`` is left of the directed line ``B1 -> B2``
(``mode_sign = +1``, :func:`robots.dextar.mode_by_cross_product`).  The source
puts the left motor at the origin; here the frame is centred between the
motors, as the DexTAR's (a translation: nothing certified depends on it).

Assumed values (the source is silent on them; each is the DexTAR's choice)
-------------------------------------------------------------------------
* Calibration box: intervals as wide as the DexTAR's (Table I of the paper
  crosscert implements), centred on the published values: half-widths
  0.0815, 0.093, 0.0755, 0.1035 and 0.132 mm for ``l11, l21, l12, l22, d``,
  and +-0.004 rad for the two encoder offsets.  A calibration as good as the
  DexTAR's is an assumption: the source gives lengths to the millimetre.
* Joint range: one full turn per motor centred on the upward vertical,
  ``[-pi/2, 3pi/2]`` rad (the source's model bounds the angles only by
  ``+-10 pi``).
* ``a_max = 80 m/s^2`` per axis, ``eps_q = pi/34000 rad``, ``t_s = 1 ms``,
  ``xd0 = 0.1 m/s``, and the split of the two offsets in halves.  ``a_max``
  is an upper bound the certificate assumes on ``|x''|``; the source's torque
  limits and masses suggest a lower real capability, and a larger bound only
  weakens what is assumed.

Benchmark crossing: down the ``Y`` axis in the "elbows out" working mode
through the Type 2 locus, where the two distal links are aligned (near
``y = 0.179 m``, motors near 117 deg and 63 deg).  SI units: m, rad.
"""

from __future__ import annotations

import functools

import numpy as np

from .base import BenchmarkCrossing, Robot
from .dextar import DEXTAR, axis_singular_y, dextar_loop_closure, elbows_out_ik, mode_by_cross_product
from .errors import ModelError
from .kinematics import KinematicModel

__all__ = ["IRI_FIVE_BAR", "iri_singular_y", "iri_benchmark_crossing"]

PARAM_NAMES = ("l11", "l21", "l12", "l22", "d", "delta1", "delta2")

# Published geometry (Scherbot2.m, "measured in lab"), m.
_PROXIMAL = 0.2
_DISTAL = 0.15
_BASE = 0.12
# Half-widths of the DexTAR's Table I intervals, m (l11, l21, l12, l22, d) and rad (offsets).
_HALF_WIDTHS = (0.0815e-3, 0.093e-3, 0.0755e-3, 0.1035e-3, 0.132e-3, 0.004, 0.004)
_NOMINAL = (_PROXIMAL, _PROXIMAL, _DISTAL, _DISTAL, _BASE, 0.0, 0.0)
#: Y range (m) scanned, downwards, for the benchmark's crossing of the locus on ``x = 0``.
_BENCH_Y_RANGE = (0.10, 0.30)


def _mode_reference(x, q, xi) -> int:
    """``Robot.mode_reference``: the geometric mode at one configuration (module level, so the robot pickles)."""
    return int(mode_by_cross_product(x, q, xi)[0])


IRI_FIVE_BAR = Robot(
    name="iri-five-bar",
    n=2,
    param_names=PARAM_NAMES,
    xi_nominal=_NOMINAL,
    xi_lo=tuple(v - w for v, w in zip(_NOMINAL, _HALF_WIDTHS)),
    xi_hi=tuple(v + w for v, w in zip(_NOMINAL, _HALF_WIDTHS)),
    # not in the source: the DexTAR's range, one full turn each centred on the upward vertical
    q_lo=DEXTAR.q_lo,
    q_hi=DEXTAR.q_hi,
    # |E - A_i| <= l_i1 + l_i2 <= 0.35018 m with |A1 A2| >= 0.11986 m gives
    # |x| <= 0.2904 m and |y| <= 0.3449 m; rounded outwards.
    x_bounds=((-0.30, -0.36), (0.30, 0.36)),
    loop_closure=dextar_loop_closure,
    pose_units=DEXTAR.pose_units,  # E = (x, y), m
    # not in the source: the DexTAR's bounds and hypotheses, read from it (one home for the shared choice)
    a_max=DEXTAR.a_max,
    eps_q=DEXTAR.eps_q,
    t_s=DEXTAR.t_s,
    xd0=DEXTAR.xd0,
    xi_splits=DEXTAR.xi_splits,
    # the loop closure reads q_i only through q_i + delta_i, as the DexTAR's
    joint_offsets=DEXTAR.joint_offsets,
    mode_sign=DEXTAR.mode_sign,
    mode_reference=_mode_reference,
    description=(
        "IRI (CSIC-UPC) five-bar planar parallel robot: lengths of the authors' published model "
        "(Bordalba et al., IEEE T-RO 2023, code file Scherbot2.m): base 0.12 m, proximal 0.2 m, distal "
        "0.15 m; loop closure as the DexTAR's. ASSUMED (source silent, DexTAR's choices): calibration "
        "intervals as wide as the DexTAR's, joint range, a_max, eps_q, t_s, xd0. Pose x = E = (x, y) in m, "
        "joints (q1, q2) in rad, xi = (l11, l21, l12, l22, d, delta1, delta2). Assembly mode +1: E left of "
        "the directed line B1->B2."
    ),
)


@functools.lru_cache(maxsize=1)
def _model() -> KinematicModel:
    return KinematicModel(IRI_FIVE_BAR)


def _xi_or_nominal(xi) -> np.ndarray:
    xi = IRI_FIVE_BAR.xi_nominal_array if xi is None else np.asarray(xi, dtype=float).reshape(-1)
    if xi.shape != (7,):
        raise ModelError(f"iri-five-bar: xi must have 7 entries, got shape {xi.shape}")
    return xi


def iri_singular_y(xi=None, *, y_range: tuple[float, float] = _BENCH_Y_RANGE, samples: int = 201) -> float:
    """Height ``y_s`` (m) where the line ``x = 0`` meets the Type 2 locus, elbows out
    (:func:`robots.dextar.axis_singular_y`).

    Parameters
    ----------
    xi : array_like, shape (7,), optional
        True geometry (default nominal).
    y_range : (float, float)
        Search interval, m.
    samples : int
        Scan points.
    """
    return axis_singular_y(_model(), _xi_or_nominal(xi), y_range, samples)


def iri_benchmark_crossing(xi=None) -> BenchmarkCrossing:
    """The benchmark crossing (down the ``Y`` axis, elbows out) for ``xi`` (default: nominal)."""
    xi = _xi_or_nominal(xi)
    point = np.array([0.0, iri_singular_y(xi)])
    return BenchmarkCrossing(
        point=point,
        direction=np.array([0.0, -1.0]),
        q_point=elbows_out_ik(point, xi),
        xi=xi.copy(),
    )
