"""The control step's names and defaults that the command line shows: no numpy.

The one source of the choices and defaults that :class:`~bearnav_cli.runtime.settings.ControlSettings`,
:mod:`~bearnav_cli.runtime.bearing` and ``bearnav simulate``'s ``Params`` (:mod:`bearnav_cli.params.simulate`)
share; ``bearnav simulate --help`` reads them without importing numpy.
"""

import math
import numbers
from typing import Any

from bearnav_cli.errors import InvalidParamsError

__all__ = [
    "ALPHA",
    "BEARING_SIGMA",
    "LOOP_DEFAULTS",
    "MIN_SPREAD_DEG",
    "check_camera",
    "DYNAMICS",
    "ESTIMATORS",
    "MEASUREMENTS",
    "METHODS",
    "ODOMETRY_DRIFT",
    "SPEED",
]

DYNAMICS = ("single", "unicycle")
MEASUREMENTS = ("bearing", "displacement")
#: The estimators of the control step: bounded-error sets (ALGORITHMS §12.2) or the scalar filter.
ESTIMATORS = ("set", "kalman")
#: Bearing reconstructions (§6.2–6.4).
METHODS = ("lsq", "pair", "rescale")
#: Reference speed ``v_ref`` of the single integrator (map units / s): the one default of
#: ``bearnav simulate``, ``bearnav verify`` and :class:`~bearnav_cli.runtime.Controller`.
SPEED = 0.1
#: Forward gain ``α`` of the unicycle (map units / s), likewise.
ALPHA = 0.1
#: Odometry error (1σ) per unit travelled that the filter assumes (its process noise): 5%.
ODOMETRY_DRIFT = 0.05
#: Bearing noise (1σ, radians) the filter assumes when the caller does not know its camera's: 1°.
#: Not 0: a filter that assumes exact bearings gives every fix zero variance, so after one fix the
#: odometry's prediction (variance ``(odometry_drift·d)²``) rejects every later fix that errs by more
#: than its 3σ: it trusts odometry over every noisy fix.
BEARING_SIGMA = math.radians(1.0)
#: ``θ_min`` of §6.2 (degrees): a pair of bearings closer than this gives no fix.
MIN_SPREAD_DEG = 2.0
#: The defaults of the loop's rules that :class:`~bearnav_cli.runtime.settings.ControlSettings`, ``bearnav
#: simulate`` (:mod:`bearnav_cli.params.simulate`) and the ROS node (contrib/ros2) share, by field name.
#: ``clamp_reverse`` is off: a base that may not drive backwards says so in its map (``robot: {reverse:
#: false}``), which clamps wherever the plan is run; a clamped look-ahead step is not certified.
LOOP_DEFAULTS = {
    "dynamics": DYNAMICS[0], "measurement": MEASUREMENTS[0], "estimator": ESTIMATORS[0], "keep_clear": True,
    "speed": SPEED, "alpha": ALPHA, "beta": 0.5, "clamp_reverse": False, "turn_first": True,
    "certified_heading": True, "reconstruction": METHODS[0], "odometry": True, "odometry_drift": ODOMETRY_DRIFT,
    "hold_time": 2.0, "look_on_purpose": False,
}  # fmt: skip


def _is_number(value: Any) -> bool:
    """A real number of Python or numpy (a registered :class:`numbers.Real`), and not a bool."""
    return isinstance(value, numbers.Real) and not isinstance(value, bool)


def check_camera(fov_deg: Any, noise_deg: Any, min_spread_deg: Any = 2.0) -> None:
    """Raise :class:`InvalidParamsError` naming the field for a camera outside its ranges.

    The one check of ``bearnav simulate``, ``bearnav tags`` and the perception report; booleans
    are not numbers.

    Parameters
    ----------
    fov_deg : float
        Horizontal field of view (degrees), in ``(0, 360]``; the error names field ``fov``.
    noise_deg : float
        Bearing noise, 1σ (degrees), finite and ``≥ 0``.
    min_spread_deg : float
        ``θ_min`` of §6.2 (degrees), in ``(0, 90]``; the error names ``min_spread_deg``.

    Raises
    ------
    InvalidParamsError
        For the first value out of its range, naming its field.
    """

    if not _is_number(fov_deg) or not 0 < fov_deg <= 360:
        raise InvalidParamsError(f"must be in (0, 360] degrees, got {fov_deg!r}", field="fov")
    if not _is_number(noise_deg) or not (noise_deg >= 0 and math.isfinite(noise_deg)):
        raise InvalidParamsError(f"must be zero or positive, got {noise_deg!r}", field="noise_deg")
    if not _is_number(min_spread_deg) or not 0 < min_spread_deg <= 90:
        raise InvalidParamsError(f"must be in (0, 90] degrees, got {min_spread_deg!r}", field="min_spread_deg")
