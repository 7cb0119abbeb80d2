"""The unicycle's rules (ALGORITHMS §7.1, §11.2): ``(v, ω)`` toward a command, and the heading allowance.

Numpy only. :func:`unicycle_command` maps a unit command to ``(v, ω)`` (§7.1's law, ``turn_first``,
the reverse clamp, the straight approach's alignment); :func:`heading_allowance` bounds the heading
error at which a unicycle on a funnel plan without a look-ahead stays inside its cell's certificate.
A look-ahead unicycle drives by :func:`~bearnav_cli.runtime.robot.lookahead_command` instead.
"""

from __future__ import annotations

import math

import numpy as np

from bearnav_cli.runtime import bearing
from bearnav_cli.runtime.cell_policy import affine_field
from bearnav_cli.runtime.plan_arrays import PlanArrays
from bearnav_cli.runtime.settings import UnicycleSettings

__all__ = ["APPROACH_ALIGNMENT", "heading_allowance", "unicycle_command"]

#: A unicycle approaching a node drives only when its heading is this close to the segment (rad).
APPROACH_ALIGNMENT = math.radians(10.0)


def unicycle_command(
    s: UnicycleSettings,
    direction: np.ndarray,
    heading: np.ndarray,
    holding: np.ndarray,
    scanning: np.ndarray,
    target: np.ndarray,
    turn: np.ndarray,
    allowed: np.ndarray | None = None,
) -> tuple[np.ndarray, ...]:
    """``(v, ω)`` of the unicycle toward the unit command ``direction`` (ALGORITHMS §7.1).

    §7.1's ``v = α cos e``; ``turn_first`` uses ``α cos³ e``: a unicycle far off its field slows
    down to turn instead of sweeping a wide arc past an obstacle corner. Holding or looking
    around, it turns in place; a straight approach drives only when aligned within
    ``APPROACH_ALIGNMENT``. ``allowed`` (R,), from :func:`heading_allowance`: where it is below
    π the robot drives forward (never back) only while ``|e| < allowed``, else turns in place.

    Parameters
    ----------
    s : UnicycleSettings
        The gains ``alpha`` (map units / s) and ``beta`` (rad / s), ``turn_first`` and
        ``clamp_reverse`` (a :class:`~bearnav_cli.runtime.settings.ControlSettings` is one).
    direction : ndarray, shape (R, 2)
        The unit command (``u``, or ``last_dir`` while holding); a zero row is no command.
    heading : ndarray, shape (R,)
        The unicycle's yaw ``φ`` (rad); ``e`` is the angle from it to ``direction``.
    holding : ndarray of bool, shape (R,)
        No position estimate this step: no forward motion, only the turn toward ``direction``.
    scanning : ndarray of bool, shape (R,)
        Looking around in place: no forward motion, and ``turn`` as given.
    target : ndarray of int, shape (R,)
        Approached node (``-1`` for none): a straight approach drives only within
        ``APPROACH_ALIGNMENT`` of ``direction``.
    turn : ndarray, shape (R,)
        The look-around turn rate (rad / s) of :func:`~bearnav_cli.runtime.looking.look_around`, used where
        ``scanning``.
    allowed : ndarray, shape (R,), optional
        The heading allowance (rad) of :func:`heading_allowance`; ``None``: §7.1's rule alone.

    Returns
    -------
    forward, turn : ndarray, shape (R,)
        ``v`` (map units / s) and ``ω`` (rad / s).
    motion : ndarray, shape (R, 2)
        The world-frame velocity odometry integrates.
    """
    phi = np.asarray(heading, float).reshape(len(direction))
    e = bearing.wrap(np.arctan2(direction[:, 1], direction[:, 0]) - phi)
    e[~np.any(direction != 0.0, axis=1)] = 0.0  # no command: neither turn nor drive for it
    gain = np.cos(e) ** 3 if s.turn_first else np.cos(e)
    idle = ~np.any(direction != 0.0, axis=1) & ~holding & ~scanning
    forward = np.where(holding | scanning | idle, 0.0, s.alpha * gain)
    forward[(target >= 0) & (np.abs(e) > APPROACH_ALIGNMENT)] = 0.0
    if s.clamp_reverse:
        forward = np.maximum(forward, 0.0)
    if allowed is not None:
        bound = allowed < math.pi
        forward[bound] = np.where(np.abs(e[bound]) < allowed[bound], np.maximum(forward[bound], 0.0), 0.0)
    turn = np.where(scanning, turn, s.beta * np.sin(e))
    return forward, turn, forward[:, None] * np.column_stack([np.cos(phi), np.sin(phi)])


def heading_allowance(arrays: PlanArrays, cell: np.ndarray, x: np.ndarray, target: np.ndarray) -> np.ndarray:
    """The largest heading error at which a unicycle may drive forward and stay certified, shape (R,), rad.

    The cell's field ``u`` meets at ``x`` its barrier conditions ``n_k·u + c_h h_k ≥ μ_k`` and its
    progress condition ``−(z·u + c_v V) ≥ μ_v`` with pointwise margins ``μ`` (positive on a
    certified cell, ALGORITHMS §11.2). Driving at any speed ``v > 0`` along a heading ``e`` instead
    of ``d = u/‖u‖`` changes each left side, scaled by ``λ = v/‖u‖``, by at most ``v‖e − d‖``
    (unit normals); so while ``‖e − d‖ = 2 sin(|Δ|/2) < min μ / ‖u‖`` the velocity still meets
    ``ḣ_k ≥ −λ c_h h_k`` and ``V̇ ≤ −λ(c_v V + ε)`` with ``ε > 0``: the robot stays in the cell's safe
    set and keeps progressing to its exit, as the single integrator does (a positive time scaling
    of the certified field). Turning in place (``v = 0``) keeps every ``h`` and ``V``.

    Returns ``π`` (no bound) for robots outside a funnel plan's cells, approaching a node, or where
    a margin is not positive at ``x`` (an estimate off its cell: the certificate says nothing there).

    Parameters
    ----------
    arrays : PlanArrays
        The plan: each cell's affine field, barrier rows, ``c_h``, ``c_v`` and exit (funnel plans).
    cell : ndarray of int, shape (R,)
        Active cell of each robot (``-1`` for none).
    x : ndarray, shape (R, 2)
        The position estimate ``x̂`` the field is evaluated at (map units).
    target : ndarray of int, shape (R,)
        Approached node (``-1`` for none): an approaching robot has no bound.
    """
    p = np.asarray(x, float).reshape(-1, 2)
    cell = np.asarray(cell, np.int64)
    out = np.full(len(p), math.pi)
    on = (cell >= 0) & (np.asarray(target) < 0)
    if not arrays.funnel or not on.any():
        return out
    idx = np.flatnonzero(on)
    c, q = cell[idx], p[idx]
    u = affine_field(arrays, c, q)
    speed = np.hypot(u[:, 0], u[:, 1])
    A, b = arrays.bar_A[c], arrays.bar_b[c]  # padding rows: 0·x + inf
    h = np.einsum("rqi,ri->rq", A, q) + b
    with np.errstate(invalid="ignore"):
        margins = np.einsum("rqi,ri->rq", A, u) + arrays.c_h[c][:, None] * h
    margin = np.min(np.where(np.isfinite(b), margins, math.inf), axis=1, initial=math.inf)
    z, x_j = arrays.exit_dir[c], arrays.exit_point[c]
    edge = arrays.parent_cell[c] >= 0  # the goal cell has no progress condition
    progress = -(np.einsum("ri,ri->r", z, u) + arrays.c_v[c] * np.einsum("ri,ri->r", z, q - x_j))
    margin = np.where(edge, np.minimum(margin, progress), margin)
    with np.errstate(divide="ignore", invalid="ignore"):
        ratio = np.where(speed > 0, margin / speed, -1.0)
    bounded = (ratio > 0) & (ratio < 2.0)  # ‖e − d‖ ≤ 2 always: ratio ≥ 2 allows any heading
    out[idx[bounded]] = 2.0 * np.arcsin(0.5 * ratio[bounded])
    return out
