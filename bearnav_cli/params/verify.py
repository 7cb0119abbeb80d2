"""The parameters of ``bearnav verify``: :class:`Params`, re-exported by :mod:`bearnav_cli.verify`."""

from __future__ import annotations

from dataclasses import dataclass

from bearnav_cli.errors import InvalidParamsError
from bearnav_cli.params import simulate
from bearnav_cli.params.declare import MAX_RUNS, SEED, Range, check, param
from bearnav_cli.runtime.defaults import DYNAMICS

__all__ = ["Params"]


@dataclass(frozen=True)
class Params:
    """Parameters of ``bearnav verify``.

    Attributes
    ----------
    n_starts : int
        Random starts of the Monte-Carlo check (0 skips it).
    seed : int
        Seed of ``numpy.random.default_rng`` for the starts.
    speed : float or None
        Reference speed of the closed loop (map units / s); ``None`` means the map's ``params: simulate:
        speed``, else simulate's default. Both are resolved by :func:`bearnav_cli.verify.loop_speed`.
    dt : float or None
        Euler step (s); ``None`` takes the simulate default.
    min_success : float or None
        Fail when the success rate is below this fraction (``None``: never on that ground).
    dynamics : {"single", "unicycle"}
        Robot of the closed loop: the single integrator the certificate is stated for, or the unicycle
        (``α`` = the loop's speed). On a plan with a look-ahead ``λ > 0`` the unicycle drives the point
        ``p = x + λh`` as a single integrator (ALGORITHMS §12.6, Lemma 7), inside the certificate;
        with ``λ = 0`` it follows §7.1's rules with ``certified_heading`` on (the heading allowance,
        ``runtime.unicycle.heading_allowance``), outside the certificate: its steps count as uncertified
        and the report says so. Both run with displacements and exact motion. A run from ``D``
        **breaches** the certificate when any of its steps is not certified
        (``runtime.ControlOutput.certified``: a funnel cell's field followed, not a straight
        approach, on an exact estimate; not checked for the unicycle without a look-ahead) or when
        its true position (``p`` with a look-ahead) lies outside every cell of ``D`` after a step;
        any breach or collision of a run from ``D`` fails verify.
    bearing_error_deg : float or None
        The bound on every world-frame bearing error of the liveness report (degrees, in (0, 45));
        ``None`` means the map's ``robot: bearing_error_deg`` plus ``compass_error_deg`` (0.2° by default).
    live_fov : float or None
        Measure liveness (ALGORITHMS §12.5) for a camera of this field of view (degrees, in (0, 360]).
        ``None`` skips it. On a grid per cell, ``ε_c^look`` (the worst over the cell of the best one-look
        bound over the headings), the live cells (``ε_c^look < τ_c − κℓ − ν``), the live fraction of ``D``
        and the certified bearing error ``η*``: a measurement at a stated resolution, not a proof, that
        never fails verify (:func:`bearnav_cli.liveness.measure`).
    slip : float or None
        The odometry error bound of the liveness report, a fraction of each step (in [0, 1)) plus a
        floor (``κ`` and ``ν``). ``None`` means the map's ``robot: slip`` (0.03 by default); the
        floor is the map's ``robot: slip_floor``, else ``1e-4·D``.
    live_resolution : float or None
        Grid spacing of the liveness report (map units, > 0). ``None`` means about 25 points in the
        median cell, at most ``0.01·D`` (:func:`bearnav_cli.liveness.default_resolution`).
    """

    n_starts: int = param(200, range=Range(0, MAX_RUNS, integer=True), option="--starts")
    seed: int = param(0, range=SEED)
    speed: float | None = param(None, range=Range(0, 1e3, low_open=True, per_diagonal=True), unit="map units/s")
    dt: float | None = param(None, range=Range(0, 1e3, low_open=True), unit="s", option=None)
    min_success: float | None = param(None, range=Range(0, 1), capped=True)
    dynamics: str = param("single", choices=DYNAMICS)
    bearing_error_deg: float | None = param(
        None, range=Range(0, 45, low_open=True, high_open=True), unit="degrees", capped=True
    )
    live_fov: float | None = param(None, range=Range(0, 360, low_open=True), unit="degrees", capped=True)
    slip: float | None = param(None, range=Range(0, 1, high_open=True), capped=True)
    live_resolution: float | None = param(None, range=Range(0, low_open=True), unit="map units")

    def __post_init__(self) -> None:
        check(self)
        simulate.Params(**({} if self.speed is None else {"speed": self.speed}), dt=self.dt)  # the loop's checks
        for name in ("bearing_error_deg", "slip", "live_resolution"):
            if getattr(self, name) is not None and self.live_fov is None:
                raise InvalidParamsError("only with live_fov (the liveness report it belongs to)", field=name)
