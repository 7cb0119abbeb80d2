"""The robot's parameters (the map's ``robot:`` section) and the look-ahead point (ALGORITHMS §12.6, Lemma 7).

Numpy only. :data:`ROBOT_DEFAULTS` is the one place the defaults of the ``robot:`` section live
(DESIGN §3.4; the map stage, :class:`~bearnav_cli.datatypes.Map` and the runtime read them here).

**Lemma 7.** A unicycle ``ẋ = v h(θ)``, ``θ̇ = ω`` (``h(θ) = (cos θ, sin θ)``, ``h^⊥`` its left
normal) carries the point ``p = x + λ h(θ)``, which moves by ``ṗ = v h + λ ω h^⊥``. For any wanted
``ṗ = w`` the command ``(v, ω) = (w·h, w·h^⊥/λ)`` gives exactly ``ṗ = w``: ``p`` is a single
integrator, with ``|v| ≤ ‖w‖`` and ``|ω| ≤ ‖w‖/λ``. A plan for ``p`` with the robot radius
``ρ + λ`` keeps the body (a disc of radius ``ρ`` around ``x``, within ``ρ + λ`` of ``p``) off every
obstacle. :func:`lookahead_point` and :func:`lookahead_command` are the two formulas.
"""

from __future__ import annotations

import math
from collections.abc import Mapping
from typing import Any

import numpy as np

__all__ = ["ROBOT_DEFAULTS", "ROBOT_KEYS", "lookahead_command", "lookahead_point", "robot_parameters", "robot_problem"]

#: The keys of the map's ``robot:`` section and their defaults (DESIGN §3.4, ALGORITHMS §12.1, §12.6):
#:
#: - ``radius`` ρ (map units): the map's ``robot_radius`` (either spelling; the map keeps it there);
#: - ``lookahead`` λ (map units): the point ``p = x + λh(θ)`` a unicycle is planned and driven for;
#:   the obstacles are inflated by ``ρ + λ``;
#: - ``bearing_error_deg`` η_cam (degrees), ``compass_error_deg`` ψ (degrees, no default: None),
#:   ``slip`` κ (fraction of the distance travelled), ``slip_floor`` ν (map units per step that
#:   translates; no value: ``1e-4·D``), ``max_turn_rate`` ω_max (rad/s, no default:
#:   None): the error bounds and limits of ALGORITHMS §12.1, stored for the bounded-error runtime;
#: - ``reverse``: whether the base may drive backwards (False: the runtime clamps ``v ≥ 0``).
ROBOT_DEFAULTS: dict[str, Any] = {
    "radius": 0.0,
    "lookahead": 0.0,
    "bearing_error_deg": 0.2,
    "compass_error_deg": None,
    "slip": 0.03,
    "slip_floor": None,
    "max_turn_rate": None,
    "reverse": True,
}
#: The keys of the ``robot:`` section, in the order ``docs/maps.md`` lists them.
ROBOT_KEYS: tuple[str, ...] = tuple(ROBOT_DEFAULTS)


def robot_problem(section: Any) -> tuple[str, str] | None:
    """What is wrong with a normalised robot section (``map.json``'s ``robot``), as ``(key, message)``.

    The one check of the section, for ``map.json`` and for the map a robot reads from ``plan.npz``:
    an object of known keys; finite numbers, zero or positive (angles below 90°; the keys whose
    default is None may be None); ``reverse`` true or false. None when it is sound.

    Parameters
    ----------
    section : Any
        The parsed section (None: absent, the defaults).
    """
    if section is None:
        return None
    if not isinstance(section, Mapping):
        return "", f"expected an object, got {type(section).__name__}"
    for key, value in section.items():
        if key not in ROBOT_DEFAULTS:
            return "", f"unknown key {key!r} (expected one of: {', '.join(ROBOT_KEYS)})"
        if key == "reverse":
            if not isinstance(value, bool):
                return key, f"expected true or false, got {value!r}"
            continue
        if value is None and ROBOT_DEFAULTS[key] is None:
            continue
        if isinstance(value, bool) or not isinstance(value, (int, float)) or not math.isfinite(value) or value < 0:
            return key, f"expected a finite number, zero or positive, got {value!r}"
        if key.endswith("_deg") and value >= 90:
            return key, f"must be below 90 degrees, got {value:g}"
    return None


def robot_parameters(section: Mapping[str, Any] | None = None) -> dict[str, Any]:
    """Every robot parameter but ``radius``: the values of ``section`` over :data:`ROBOT_DEFAULTS`.

    Parameters
    ----------
    section : mapping, optional
        A (normalised) robot section, e.g. the ``robot`` object of ``map.json``, which holds only the
        values that differ from the defaults; ``radius`` is ignored (it is the map's ``robot_radius``).

    Returns
    -------
    dict
        ``lookahead``, ``bearing_error_deg``, ``compass_error_deg``, ``slip``, ``slip_floor``, ``max_turn_rate``,
        ``reverse``.
    """
    given = dict(section or {})
    return {key: given.get(key, default) for key, default in ROBOT_DEFAULTS.items() if key != "radius"}


def lookahead_point(x: np.ndarray, heading: np.ndarray, lookahead: float) -> np.ndarray:
    """``p = x + λ(cos θ, sin θ)``, shape (R, 2) (map units): the point the plan is made for.

    Parameters
    ----------
    x : ndarray, shape (R, 2)
        Axle (body centre) positions (map units).
    heading : ndarray, shape (R,)
        Headings θ (rad).
    lookahead : float
        λ (map units); 0 gives ``x`` back.
    """
    x = np.asarray(x, float).reshape(-1, 2)
    if not lookahead:
        return x.copy()
    theta = np.asarray(heading, float).reshape(len(x))
    return x + float(lookahead) * np.column_stack([np.cos(theta), np.sin(theta)])


def lookahead_command(
    w: np.ndarray, heading: np.ndarray, lookahead: float, clamp_reverse: bool = False
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """The unicycle command that moves the look-ahead point by ``w`` (Lemma 7), for ``R`` robots.

    ``v = w·h(θ)``, ``ω = w·h^⊥(θ)/λ``: then ``ṗ = v h + λ ω h^⊥ = w`` exactly. With
    ``clamp_reverse`` a robot that may not drive backwards gets ``v = max(w·h, 0)``; where the law
    wants ``v < 0`` (``w`` points behind the heading) it turns in place toward ``w`` at the law's
    largest rate ``‖w‖/λ`` instead (``w·h^⊥/λ`` would turn slowest when ``w`` is straight behind).
    Those steps move ``p`` on a circle around the axle, not by ``w``: the certificate does not cover
    them (``clamped``).

    Parameters
    ----------
    w : ndarray, shape (R, 2)
        Wanted velocity of the look-ahead point (map units / s).
    heading : ndarray, shape (R,)
        Headings θ (rad).
    lookahead : float
        λ > 0 (map units).
    clamp_reverse : bool
        The robot may not reverse.

    Returns
    -------
    forward : ndarray, shape (R,)
        ``v`` (map units / s).
    turn : ndarray, shape (R,)
        ``ω`` (rad / s).
    clamped : ndarray of bool, shape (R,)
        Where the clamp changed the command (``w·h < 0``; all False without ``clamp_reverse``).
    """
    if not (math.isfinite(lookahead) and lookahead > 0):
        raise ValueError(f"the look-ahead law needs λ > 0, got {lookahead}")
    w = np.asarray(w, float).reshape(-1, 2)
    theta = np.asarray(heading, float).reshape(len(w))
    c, s = np.cos(theta), np.sin(theta)
    forward = w[:, 0] * c + w[:, 1] * s  # w·h
    across = -w[:, 0] * s + w[:, 1] * c  # w·h^⊥, h^⊥ = (−sin θ, cos θ)
    turn = across / lookahead
    clamped = np.zeros(len(w), bool)
    if clamp_reverse:
        clamped = forward < 0.0
        speed = np.hypot(w[:, 0], w[:, 1])
        turn = np.where(clamped, np.where(across < 0.0, -1.0, 1.0) * speed / lookahead, turn)
        forward = np.where(clamped, 0.0, forward)
    return forward, turn, clamped
