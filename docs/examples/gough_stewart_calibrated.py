"""The shipped Gough–Stewart calibrated ten times tighter, as a robot file.

``crosscert certify --robot docs/examples/gough_stewart_calibrated.py --plan docs/examples/gough_stewart_crossing.csv``

The same design, bounds and loop closure as ``gough-stewart`` (robots/gough_stewart.py); only the
calibration box ``[xi]`` differs: each half-width a tenth of the shipped one (base coordinates
+-25 um, platform coordinates +-15 um instead of +-0.25 mm and +-0.15 mm), centred on the same
geometry.  With the shipped box the planned crossing of gough_stewart_crossing.csv is not certified
(docs/robots.md, "The Gough–Stewart 6-6 platform"): the spread of the forward kinematics over the
box leaves the tracker's pose boxes tens of mrad wide while the platform is still far from the
locus.  This file states the calibration that certifies it; it is an assumption about a better
calibrated hexapod, not a property of the shipped one.  SI units: m, rad.
"""

import dataclasses

from crosscert.robots import GOUGH_STEWART, RobotEntry
from crosscert.robots.gough_stewart import gs_reference_motion

_CENTRE = GOUGH_STEWART.xi_center
_HALF = 0.05 * (GOUGH_STEWART.xi_hi_array - GOUGH_STEWART.xi_lo_array)  # a tenth of the shipped half-widths, m

CALIBRATED = RobotEntry(
    dataclasses.replace(GOUGH_STEWART, name="gough-stewart-calibrated", xi_nominal=tuple(_CENTRE),
                        xi_lo=tuple(_CENTRE - _HALF), xi_hi=tuple(_CENTRE + _HALF)),
    motion=gs_reference_motion,
)
