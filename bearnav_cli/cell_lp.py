"""The LP (P) of one cell, in solver form, independent of any artifact (ALGORITHMS §5.1, §5.2).

In cell ``X = {x : A x ≤ b}`` with vertices ``v_1 … v_p`` the controller ``u = K y``,
``y = stack(l_k − x)``, is the affine field ``u(x) = a − M x`` with ``a = Kℓ`` and
``M = K𝟙`` (§5.1). The LP (P) of §5.2 maximises the worst-case CBF and CLF margins
over the cell under the input box ``|u_i| ≤ u_max``.

Every condition of (P) is a *group* ``g`` with a direction ``d_g``, a constant vector
``ρ_g`` and a scalar ``r_g``: ``d_gᵀu(x) + ρ_gᵀx ≤ S_g + r_g`` for all ``x ∈ X``::

    CBF k:    d = −n_k,  ρ = c_h·d,   r = c_h·q_k          (slack S_h,k)
    CLF:      d = z,     ρ = c_v·z,   r = c_v·zᵀx_j        (slack S_V)
    input r:  d = e_r,   ρ = 0,       r = u_max            (no slack)

The vertex form states the group at every vertex (the box as two ranged rows per
vertex); the dual form introduces ``λ_g ≥ 0`` with ``A_xᵀλ_g + Mᵀd_g = ρ_g`` and
``b_xᵀλ_g + d_gᵀa − S_g ≤ r_g``. The variables ``θ`` are either the field
``F = [M, a]`` (field space, 6 numbers) or the gain entries allowed by the gain
structure; a fixed linear map ``L`` gives ``F = L θ`` (:func:`field_map`), so one
builder serves every combination. Only the row bounds depend on ``c_h`` and ``c_v``
(:class:`LpTemplate`), so a κ halving re-solves without rebuilding the matrix.

Also here: the cell data (:class:`CellProblem`), the landmark matrix ``G`` of Lemma 3 and
the minimum-norm gain that realises a field (:func:`min_norm_gain`, §5.1, §5.6). Solving
the LP, the κ loop and the certificates are in :mod:`bearnav_cli.stages.synthesize`.
"""

from __future__ import annotations

import functools
import logging
from dataclasses import dataclass

import numpy as np

from bearnav_cli.errors import ArtifactError
from bearnav_cli.lp import INF, LpResult, LpSolver, dense_to_csr

__all__ = [
    "BOX_DIRECTIONS",
    "CellLp",
    "CellProblem",
    "COND_WARNING",
    "dual_lp",
    "dual_template",
    "FIELD_MAP",
    "field_map",
    "field_vertex_templates",
    "FieldTemplates",
    "gain_from_theta",
    "landmark_matrix",
    "LpTemplate",
    "min_norm_gain",
    "min_norm_gains",
    "theta_from_gain",
    "vertex_lp",
    "vertex_lp_field",
    "vertex_lp_gain",
    "vertex_template",
]

log = logging.getLogger(__name__)

#: Warn when ``cond(GᵀG)`` exceeds this (nearly coincident landmarks, §5.6).
COND_WARNING = 1e12
#: Input-box directions ``e_r``.
BOX_DIRECTIONS = np.array([[1.0, 0.0], [-1.0, 0.0], [0.0, 1.0], [0.0, -1.0]])
#: ``L`` of the field space (:func:`field_map`): ``θ = vec([M, a])`` row-major.
FIELD_MAP = np.eye(6).reshape(2, 3, 6)
FIELD_MAP.setflags(write=False)
_EYE2 = np.eye(2)
_EYE2.setflags(write=False)
BOX_DIRECTIONS.setflags(write=False)


# --------------------------------------------------------------------------- cell data and the field map


@dataclass(frozen=True)
class CellProblem:
    """The data of one cell's LP, independent of any artifact.

    Attributes
    ----------
    vertices : ndarray, shape (p, 2)
        CCW vertices of the convex cell (map units).
    A, b : ndarray, shapes (p, 2), (p,)
        The same cell as ``{x : A x ≤ b}`` (used by the dual form).
    z : ndarray, shape (2,)
        Unit exit direction into the cell; ``V(x) = zᵀ(x − x_j)``.
    x_j : ndarray, shape (2,)
        Exit point (the parent node).
    cbf_n, cbf_q : ndarray, shapes (h, 2), (h,)
        Barrier rows ``h_k(x) = n_kᵀx + q_k``, safe where ``h_k ≥ 0``; there may be none.
    landmarks : ndarray, shape (n, 2)
        Positions of the landmarks the controller uses, ``n ≥ 2``.
    """

    vertices: np.ndarray
    A: np.ndarray
    b: np.ndarray
    z: np.ndarray
    x_j: np.ndarray
    cbf_n: np.ndarray
    cbf_q: np.ndarray
    landmarks: np.ndarray

    def __post_init__(self) -> None:
        for name, shape, ndim in _PROBLEM_SHAPES:
            value = getattr(self, name)
            # a float64 array's dtype is (almost always) the one native instance: ``is`` first,
            # the cheap test for the arrays run() slices from Cells
            if type(value) is not np.ndarray or value.ndim != ndim or (value.dtype is not _F64 and value.dtype != _F64):
                object.__setattr__(self, name, np.asarray(value, dtype=float).reshape(shape))


_F64 = np.dtype(np.float64)
_PROBLEM_SHAPES = tuple((name, shape, len(shape)) for name, shape in (
    ("vertices", (-1, 2)), ("A", (-1, 2)), ("b", (-1,)), ("z", (2,)), ("x_j", (2,)), ("cbf_n", (-1, 2)),
    ("cbf_q", (-1,)), ("landmarks", (-1, 2))))  # fmt: skip


def landmark_matrix(landmarks: np.ndarray) -> np.ndarray:
    """``G = [𝟙, ℓ]`` of Lemma 3, with ``𝟙 = 1_n ⊗ I_2`` and ``ℓ = stack(l_k)``.

    Parameters
    ----------
    landmarks : ndarray, shape (n, 2)
        Landmark positions ``l_k`` (map units).

    Returns
    -------
    ndarray, shape (2n, 3)
        ``K G = [M, a]`` for any gain ``K`` of shape (2, 2n).
    """
    n = len(landmarks)
    G = np.empty((2 * n, 3))
    G[:, :2] = np.tile(np.eye(2), (n, 1))
    G[:, 2] = np.ravel(landmarks)
    return G


def field_map(space: str, landmarks: np.ndarray) -> np.ndarray:
    """The linear map ``θ ↦ F = [M, a]`` of a variable space, as an array ``L`` with ``F = L @ θ``.

    Parameters
    ----------
    space : {"field", "full", "diag", "scalar"}
        ``field``: ``θ = vec(F)`` row-major (6 numbers). ``full``: ``θ = vec(K)`` row-major
        (4n). ``diag``: ``θ = (K[0, 2k] for k, K[1, 2k+1] for k)`` (2n). ``scalar``:
        ``K_k = θ_k I`` (n).
    landmarks : ndarray, shape (n, 2)
        Landmark positions (map units); they enter ``L`` through ``G`` (:func:`landmark_matrix`)
        in the gain spaces, and only their number matters for the size.

    Returns
    -------
    ndarray, shape (2, 3, n_θ)
        ``F[i, c] = L[i, c] @ θ``.
    """
    n = len(landmarks)
    if space == "field":
        return FIELD_MAP
    G = landmark_matrix(landmarks)
    if space == "full":
        L = np.zeros((2, 3, 4 * n))
        L[0, :, : 2 * n] = G.T
        L[1, :, 2 * n :] = G.T
    elif space == "diag":
        L = np.zeros((2, 3, 2 * n))
        L[0, :, :n] = G[0::2].T
        L[1, :, n:] = G[1::2].T
    elif space == "scalar":
        L = np.stack([G[0::2].T, G[1::2].T])
    else:
        raise ValueError(f"unknown variable space {space!r}")
    return L


def gain_from_theta(space: str, theta: np.ndarray, landmarks: np.ndarray) -> np.ndarray:
    """The gain ``K`` (2, 2n) of the LP variables ``θ`` (see :func:`field_map`); field space uses Lemma 3.

    Parameters
    ----------
    space : {"field", "full", "diag", "scalar"}
        The variable space ``θ`` lives in (:func:`field_map`). In field space ``θ = vec([M, a])``
        and the gain is the minimum-norm one that realises the field (:func:`min_norm_gain`).
    theta : ndarray, shape (n_θ,)
        The LP variables: 6 numbers in field space, 4n, 2n or n in the gain spaces.
    landmarks : ndarray, shape (n, 2)
        Positions of the cell's landmarks (map units); only their number matters in the gain
        spaces.

    Returns
    -------
    ndarray, shape (2, 2n)
        ``K``, with ``u = K y`` and ``y = stack(l_k − x)``; block ``k`` is columns ``2k, 2k + 1``.

    Raises
    ------
    ValueError
        If ``space`` is none of the four.
    ArtifactError
        In field space, if all landmarks coincide (:func:`min_norm_gain`).
    """
    n = len(landmarks)
    if space == "field":
        F = theta.reshape(2, 3)
        return min_norm_gain(F[:, :2], F[:, 2], landmarks)
    if space == "full":
        return theta.reshape(2, 2 * n).copy()
    K = np.zeros((2, 2 * n))
    if space == "diag":
        K[0, 0::2], K[1, 1::2] = theta[:n], theta[n:]
    elif space == "scalar":
        K[0, 0::2], K[1, 1::2] = theta, theta
    else:
        raise ValueError(f"unknown variable space {space!r}")
    return K


def theta_from_gain(space: str, K: np.ndarray) -> np.ndarray:
    """The gain-space variables ``θ`` of a structured gain ``K`` (2, 2n); inverse of :func:`gain_from_theta`."""
    if space == "full":
        return K.ravel()
    if space == "diag":
        return np.concatenate([K[0, 0::2], K[1, 1::2]])
    if space == "scalar":
        return K[0, 0::2].copy()
    raise ValueError(f"no gain-space variables for {space!r}")


def min_norm_gain(M: np.ndarray, a: np.ndarray, landmarks: np.ndarray) -> np.ndarray:
    """The minimum-Frobenius-norm gain realising the field ``u = a − M x`` (Lemma 3).

    ``K* = [M, a] (GᵀG)⁻¹Gᵀ``, in closed form: with ``l̄`` the landmarks' mean,
    ``δ_k = l_k − l̄`` and ``σ = Σ‖δ_k‖²``, block ``k`` is ``K_k = M/n + (a − M l̄) δ_kᵀ/σ``
    (so ``Σ K_k = M`` and ``Σ K_k l_k = a``). Logs a warning when ``cond(GᵀG) > 1e12``
    (nearly coincident landmarks). One field of :func:`min_norm_gains`.

    Parameters
    ----------
    M : ndarray, shape (2, 2)
        The field's linear part (1/s).
    a : ndarray, shape (2,)
        The field's constant part (map units/s).
    landmarks : ndarray, shape (n, 2)
        Positions of the landmarks the gain reads (map units), ``n ≥ 2``.

    Returns
    -------
    ndarray, shape (2, 2n)
        ``K* = [K_1 … K_n]``, with ``u = K* y`` and ``y = stack(l_k − x)``.

    Raises
    ------
    ArtifactError
        If all landmarks coincide (``G`` loses rank; map landmarks are distinct).
    """
    landmarks = np.asarray(landmarks, float)
    return min_norm_gains(np.reshape(M, (1, 2, 2)), np.reshape(a, (1, 2)), landmarks[None])[0]


def min_norm_gains(M: np.ndarray, a: np.ndarray, landmarks: np.ndarray) -> np.ndarray:
    """:func:`min_norm_gain` of ``g`` fields at once, each over its own ``n`` landmarks.

    Every number is computed as for one field alone (elementwise operations in the same order,
    the means summed landmark by landmark from 0), so a gain does not depend on the fields it
    is computed with.

    Parameters
    ----------
    M : ndarray, shape (g, 2, 2)
        The fields' linear parts (1/s).
    a : ndarray, shape (g, 2)
        The fields' constant parts (map units/s).
    landmarks : ndarray, shape (g, n, 2)
        Positions of each field's landmarks (map units), ``n ≥ 2``.

    Returns
    -------
    ndarray, shape (g, 2, 2n)
        The gains ``K*``.

    Raises
    ------
    ArtifactError
        If all landmarks of a field coincide.
    """
    M, a = np.asarray(M, float), np.asarray(a, float)
    landmarks = np.asarray(landmarks, float)
    g, n = landmarks.shape[:2]
    mean = np.zeros((g, 2))
    for k in range(n):
        mean += landmarks[:, k]
    mean /= n
    delta = landmarks - mean[:, None, :]  # δ_k, (g, n, 2)
    sigma = []
    for offsets in delta.tolist():
        # Python's ** (the C library's pow), which does not always round as numpy's x·x does
        s = 0.0
        for ex, ey in offsets:
            s += ex**2 + ey**2
        if not s > 0:
            raise ArtifactError("the cell's landmarks coincide: no gain realises a general field", field="landmarks")
        sigma.append(s)
    sigma = np.array(sigma)
    cond = _gram_conditions(n, mean, sigma)
    for value in cond[~(cond <= COND_WARNING)].tolist():
        log.warning("nearly coincident landmarks: cond(GᵀG) = %.3g", value)
    offset = (a - M[:, :, 0] * mean[:, :1] - M[:, :, 1] * mean[:, 1:]) / sigma[:, None]  # (a − M l̄)/σ, (g, 2)
    K = M[:, :, None, :] / n + offset[:, :, None, None] * delta[:, None, :, :]  # K_k = M/n + (a − M l̄) δ_kᵀ/σ
    return K.reshape(g, 2, 2 * n)


def _gram_conditions(n: int, mean: np.ndarray, sigma: np.ndarray) -> np.ndarray:
    """``cond(GᵀG)`` of ``g`` landmark sets of ``n`` landmarks each: ``mean`` (g, 2), ``σ`` (g,) as in
    :func:`min_norm_gains`; shape (g,).

    ``GᵀG = [[nI, s], [sᵀ, t]]`` (``s = n·mean``, ``t = σ + n‖mean‖²``) has the eigenvalue ``n``
    and the two of ``[[n, ‖s‖], [‖s‖, t]]``: ``λ₊`` and ``λ₋ = nσ/λ₊``.
    """
    norm_s = n * np.hypot(mean[:, 0], mean[:, 1])
    t = sigma + norm_s * norm_s / n
    big = 0.5 * (n + t) + np.hypot(0.5 * (n - t), norm_s)
    small = np.minimum(float(n), n * sigma / big)
    with np.errstate(divide="ignore"):
        return np.where(small > 0, big / small, np.inf)


# --------------------------------------------------------------------------- the LPs


@dataclass(frozen=True)
class CellLp:
    """One LP in solver form plus where its variables are.

    ``x[:n_theta]`` are the variables ``θ``; ``x[n_theta:n_theta + n_h]`` the CBF slacks
    ``S_h``; ``x[n_theta + n_h]`` the CLF slack ``S_V``; further columns are multipliers
    (dual form) or the least-violation variables ``t``. The LP reads: minimise ``cost @ x``
    subject to ``row_lower <= A x <= row_upper`` and ``col_lower <= x <= col_upper``.

    Attributes
    ----------
    cost : ndarray, shape (n,)
        Objective coefficients of the ``n`` columns (the weights ``w_h``, ``w_v`` on the slacks
        or on ``t``, zero elsewhere).
    A_indptr, A_indices, A_values : ndarray, shapes (m + 1,), (nnz,), (nnz,)
        The constraint matrix ``A`` (m, n) in CSR form (:func:`~bearnav_cli.lp.dense_to_csr`).
    row_lower, row_upper : ndarray, shape (m,)
        Row bounds; ``-INF`` / ``INF`` where a row is one-sided, equal on equality rows.
    col_lower, col_upper : ndarray, shape (n,)
        Column bounds (``θ`` free, slacks ``<= 0`` unless least violation, multipliers ``>= 0``).
    n_theta : int
        Number of variables ``θ`` (the first columns).
    n_h : int
        Number of barrier rows, hence of CBF slacks after ``θ``.
    """

    cost: np.ndarray
    A_indptr: np.ndarray
    A_indices: np.ndarray
    A_values: np.ndarray
    row_lower: np.ndarray
    row_upper: np.ndarray
    col_lower: np.ndarray
    col_upper: np.ndarray
    n_theta: int
    n_h: int

    def arrays(self) -> tuple[np.ndarray, ...]:
        """The arguments of :meth:`LpSolver.solve`, in order."""
        return (self.cost, self.A_indptr, self.A_indices, self.A_values, self.row_lower, self.row_upper,
                self.col_lower, self.col_upper)  # fmt: skip

    def solve(self, solver: LpSolver) -> LpResult:
        return solver.solve(*self.arrays())

    def slacks(self, x: np.ndarray) -> tuple[np.ndarray, float]:
        """``(S_h, S_V)`` from a solution vector."""
        return x[self.n_theta : self.n_theta + self.n_h], float(x[self.n_theta + self.n_h])


@dataclass(frozen=True)
class LpTemplate:
    """A cell's LP with the constants left open: only the row bounds depend on ``c_h`` and ``c_v``.

    Rows come in three blocks: those scaled by ``c_h``, those scaled by ``c_v``, then
    constant ones, so ``row_upper = [c_h·rhs_h, c_v·rhs_v, rhs_const]``. ``row_lower`` equals
    ``row_upper`` on the equality rows and ``lower`` elsewhere. The matrix, costs and column
    bounds are shared by every :meth:`instantiate` call, so κ halvings cost a few vector
    operations. ``vertex_rows`` (vertex form only), shape ``((n_h + 1)·p, n_θ)``, is the dense
    ``θ`` block of the barrier and CLF rows, used to re-check a gain at the vertices.

    Attributes
    ----------
    cost : ndarray, shape (n,)
        Objective coefficients of the ``n`` columns, as in :class:`CellLp`.
    A_indptr, A_indices, A_values : ndarray, shapes (m + 1,), (nnz,), (nnz,)
        The constraint matrix (m, n) in CSR form, shared by every instance.
    col_lower, col_upper : ndarray, shape (n,)
        Column bounds, shared by every instance.
    lower : ndarray, shape (m,)
        Lower row bounds of the inequality rows (``-INF`` for one-sided rows, ``-u_max`` on the
        box rows of the vertex form).
    equality : ndarray of bool, shape (m,) or None
        Rows whose lower bound equals their upper bound (the dual form's equalities); None when
        there are none (vertex form).
    rhs_h : ndarray
        Upper bounds of the ``c_h``-scaled block, before scaling (``h_k(v_q)`` in the vertex
        form; ``(−n_k, q_k)`` per barrier in the dual form).
    rhs_v : ndarray
        Upper bounds of the ``c_v``-scaled block, before scaling (``−V(v_q)`` per vertex in the
        vertex form; ``(z, zᵀx_j)`` in the dual form).
    rhs_const : ndarray
        Upper bounds of the remaining rows (``u_max`` on the box rows, ``INF`` on the
        least-violation rows).
    n_theta : int
        Number of variables ``θ`` (the first columns).
    n_h : int
        Number of barrier rows; with none the ``c_h`` block is empty and ``c_h`` is ignored.
    vertex_rows : ndarray, shape ((n_h + 1)·p, n_θ) or None
        Dense ``θ`` block of the barrier and CLF rows (vertex form only).
    """

    cost: np.ndarray
    A_indptr: np.ndarray
    A_indices: np.ndarray
    A_values: np.ndarray
    col_lower: np.ndarray
    col_upper: np.ndarray
    lower: np.ndarray
    equality: np.ndarray | None
    rhs_h: np.ndarray
    rhs_v: np.ndarray
    rhs_const: np.ndarray
    n_theta: int
    n_h: int
    vertex_rows: np.ndarray | None = None

    def row_upper(self, c_h: float, c_v: float) -> np.ndarray:
        """Upper row bounds for the constants ``c_h`` (ignored without barrier rows) and ``c_v``."""
        if self.n_h:
            return np.concatenate((self.rhs_h * c_h, self.rhs_v * c_v, self.rhs_const))
        return np.concatenate((self.rhs_v * c_v, self.rhs_const))

    def row_bounds(self, c_h: float, c_v: float) -> tuple[np.ndarray, np.ndarray]:
        """``(row_lower, row_upper)`` for the constants ``c_h`` and ``c_v``, each of shape (m,)."""
        upper = self.row_upper(c_h, c_v)
        return (self.lower if self.equality is None else np.where(self.equality, upper, self.lower)), upper

    def instantiate(self, c_h: float, c_v: float) -> CellLp:
        """The LP with the constants ``c_h`` and ``c_v``."""
        lower, upper = self.row_bounds(c_h, c_v)
        return CellLp(self.cost, self.A_indptr, self.A_indices, self.A_values, lower, upper, self.col_lower,
                      self.col_upper, self.n_theta, self.n_h)  # fmt: skip


def _filled(n: int, value: float) -> np.ndarray:
    out = np.empty(n)
    out.fill(value)
    return out


def _frozen(*arrays: np.ndarray) -> tuple[np.ndarray, ...]:
    for array in arrays:
        array.setflags(write=False)
    return arrays


@functools.lru_cache(maxsize=256)
def _slack_columns(n_theta: int, n_h: int, w_h: float, w_v: float) -> tuple[np.ndarray, ...]:
    """Bounds and costs of the columns ``(θ, S_h, S_V)``: θ free, ``S ≤ 0``, cost ``w`` on the slacks."""
    n_cols = n_theta + n_h + 1
    col_upper = _filled(n_cols, INF)
    col_upper[n_theta:] = 0.0
    cost = np.zeros(n_cols)
    cost[n_theta:-1] = w_h
    cost[-1] = w_v
    return _frozen(_filled(n_cols, -INF), col_upper, cost)


@functools.lru_cache(maxsize=256)
def _vertex_row_bounds(slack_rows: int, box_rows: int, u_max: float) -> tuple[np.ndarray, ...]:
    """``lower`` of the vertex rows (−∞, then −u_max on the box rows) and the box rows' ``rhs_const``."""
    lower = _filled(slack_rows + box_rows, -INF)
    lower[slack_rows:] = -u_max
    return _frozen(lower, _filled(box_rows, u_max))


@functools.lru_cache(maxsize=256)
def _slack_block(n_slack: int, p: int, rows: int) -> np.ndarray:
    """``−1`` in column ``g`` of the ``p`` rows of group ``g``, zero below row ``n_slack·p``: shape (rows, n_slack)."""
    block = np.zeros((rows, n_slack))
    block[: n_slack * p] = np.repeat(-np.eye(n_slack), p, axis=0)
    return _frozen(block)[0]


def _box_pattern(L: np.ndarray) -> tuple[tuple[int, ...], tuple[int, ...]]:
    """The θ each field row can move: ``(columns of u_1, columns of u_2)``."""
    moves = np.any(L != 0, axis=1)  # (2, n_θ)
    return tuple(np.flatnonzero(moves[0]).tolist()), tuple(np.flatnonzero(moves[1]).tolist())


_FIELD_PATTERN = ((0, 1, 2), (3, 4, 5))


@functools.lru_cache(maxsize=512)
def _vertex_sparsity(pattern, n_theta: int, n_h: int, p: int, box: int) -> tuple[np.ndarray, ...]:
    """CSR ``indptr``, ``indices`` and the positions in the dense ``(rows, n_θ + h + 1)`` block.

    Rows of the barrier and CLF groups hold every θ a field row can move plus their slack;
    the box rows of ``u_i`` hold the θ of ``pattern[i]`` only.
    """
    n_slack = n_h + 1
    n_cols = n_theta + n_slack
    both = sorted(set(pattern[0]) | set(pattern[1]))
    row_cols = [both + [n_theta + g] for g in range(n_slack) for _ in range(p)]
    row_cols += [list(pattern[i]) for i in range(box) for _ in range(p)]
    counts = [len(c) for c in row_cols]
    indptr = np.zeros(len(row_cols) + 1, np.int32)
    indptr[1:] = np.cumsum(counts)
    indices = np.array([c for cols in row_cols for c in cols], np.int32)
    gather = np.repeat(np.arange(len(row_cols)) * n_cols, counts) + indices
    return _frozen(indptr, indices, gather)


def vertex_template(problem: CellProblem, L: np.ndarray, u_max: float | None, w_h: float = 1.0, w_v: float = 1.0,
                    least_violation: bool = False) -> LpTemplate:  # fmt: skip
    """The vertex form of (P) with open constants (see :func:`vertex_lp`).

    Groups ``g`` in order: the ``h`` barrier rows (``d = −n_k``), the CLF (``d = z``), then
    the box as two ranged groups ``−u_max ≤ e_iᵀu ≤ u_max``. Row ``g·p + q`` reads
    ``d_gᵀu(v_q) − S_g ≤ r_g − ρ_gᵀv_q``, that is ``c_h·h_k(v_q)``, ``−c_v·V(v_q)`` or ``u_max``.

    Parameters
    ----------
    problem : CellProblem
        The cell: vertices ``v_q``, barrier rows, exit direction ``z`` and point ``x_j``.
    L : ndarray, shape (2, 3, n_θ)
        The variable map ``[M, a] = L θ`` (:func:`field_map`); :data:`FIELD_MAP` itself takes
        the batched field-space builder (:func:`field_vertex_templates`).
    u_max : float or None
        Input bound ``|u_i| ≤ u_max`` (map units/s); None drops the box rows.
    w_h, w_v : float
        Objective weights of the CBF slacks ``S_h`` and of the CLF slack ``S_V``.
    least_violation : bool
        Free slacks and minimise ``Σ w·max(S, 0)`` instead (§5.3).

    Returns
    -------
    LpTemplate
        With ``vertex_rows`` set, for re-checking a gain at the vertices.
    """
    if L is FIELD_MAP and not least_violation:
        return _field_vertex_template(problem, u_max, w_h, w_v)
    V = problem.vertices
    p, n_theta = len(V), L.shape[2]
    n_h = len(problem.cbf_q)
    n_slack = n_h + 1
    box = 2 if u_max is not None else 0
    n_groups = n_slack + box
    D = np.empty((n_groups, 2))
    np.negative(problem.cbf_n, out=D[:n_h])
    D[n_h] = problem.z
    D[n_slack:] = _EYE2[:box]
    W = np.empty((p, 3))  # u(v_q) = [M, a] @ W[q]
    np.negative(V, out=W[:, :2])
    W[:, 2] = 1.0
    # the coefficient of θ_j in d_gᵀu(v_q) is Σ_c W_qc (Σ_i d_gi L_icj)
    DL = (D @ L.reshape(2, 3 * n_theta)).reshape(n_groups, 3, n_theta)
    rows = n_groups * p
    coef = (W @ DL).reshape(rows, n_theta)
    rhs_h = (problem.cbf_n @ V.T + problem.cbf_q[:, None]).ravel()  # h_k(v_q), barrier-major
    rhs_v = (problem.x_j - V) @ problem.z  # −V(v_q)
    lower, rhs_const = _vertex_row_bounds(n_slack * p, box * p, float(u_max) if box else 0.0)
    dense = np.empty((rows, n_theta + n_slack))
    dense[:, :n_theta] = coef
    dense[:, n_theta:] = _slack_block(n_slack, p, rows)
    vertex_rows = coef[: n_slack * p]
    if least_violation:
        return _template(dense, lower, None, rhs_h, rhs_v, rhs_const, n_theta, n_h, 0, w_h, w_v, True, vertex_rows)
    # The sparsity pattern depends only on the sizes and on which θ each box side can move.
    # Exact zeros inside it (a vertex on x = 0, say) are passed on explicitly; HiGHS drops them.
    pattern = _FIELD_PATTERN if L is FIELD_MAP else _box_pattern(L)
    indptr, indices, gather = _vertex_sparsity(pattern, n_theta, n_h, p, box)
    col_lower, col_upper, cost = _slack_columns(n_theta, n_h, float(w_h), float(w_v))
    return LpTemplate(cost, indptr, indices, dense.ravel()[gather], col_lower, col_upper, lower, None, rhs_h, rhs_v,
                      rhs_const, n_theta, n_h, vertex_rows)  # fmt: skip


def _field_vertex_template(problem: CellProblem, u_max: float | None, w_h: float, w_v: float) -> LpTemplate:
    """:func:`vertex_template` in field space (``L`` = :data:`FIELD_MAP`), the default LP of every cell:
    :func:`field_vertex_templates` of this one cell (one builder for both)."""
    p, n_h = len(problem.vertices), len(problem.cbf_q)
    built = field_vertex_templates(problem.vertices, np.array([0, p]), np.asarray(problem.cbf_n, float).reshape(-1, 2),
                                   np.asarray(problem.cbf_q, float), np.array([0, n_h]), problem.z[None, :],
                                   problem.x_j[None, :], [0], u_max, w_h, w_v)  # fmt: skip
    return built.templates[0]


@dataclass(frozen=True)
class FieldTemplates:
    """The field-space vertex templates of many cells, from :func:`field_vertex_templates`.

    Attributes
    ----------
    templates : dict of int to LpTemplate
        One per requested cell, each equal (same bytes) to ``vertex_template(problem, FIELD_MAP, …)``.
    h_values : ndarray, shape (Σ_c h_c·p_c,)
        ``h_k(v_q)`` of every cell, cell after cell (barrier-major within a cell); the
        templates' ``rhs_h`` are views into it. Cells not requested hold ``q_k`` only.
    h_value_offsets : ndarray of int64, shape (C + 1,)
        Cell ``c`` owns ``h_values[h_value_offsets[c]:h_value_offsets[c + 1]]``.
    minus_v : ndarray, shape (P,)
        ``−V(v_q)`` of every vertex, in vertex order; the templates' ``rhs_v`` are views into it
        (zero for cells not requested).
    """

    templates: dict
    h_values: np.ndarray
    h_value_offsets: np.ndarray
    minus_v: np.ndarray


def field_vertex_templates(vertices: np.ndarray, vertex_offsets: np.ndarray, cbf_n: np.ndarray, cbf_q: np.ndarray,
                           cbf_offsets: np.ndarray, z: np.ndarray, x_j: np.ndarray, cells, u_max: float | None,
                           w_h: float = 1.0, w_v: float = 1.0) -> FieldTemplates:  # fmt: skip
    """:func:`vertex_template` in field space for many cells at once, from flat arrays (the ``Cells`` layout).

    The coefficients ``d_g ⊗ w_q`` of every row of every cell come from one numpy pass (the
    single products ``d_g ⊗ w_q``, with ``w_q = (−v_q, 1)``), as do the ``+ q_k`` of the barrier
    right-hand sides. What stays per cell is slicing, one concatenation of the CSR values and
    the two small matrix products ``n @ Vᵀ`` and ``(x_j − V) @ z``: those are the very BLAS calls
    of the per-cell builder, on the same views, so that the right-hand sides round the same way
    (a batched product could fuse multiply and add differently).

    Parameters
    ----------
    vertices : ndarray, shape (P, 2)
        Every cell's CCW vertices; cell ``c`` owns rows ``vertex_offsets[c]:vertex_offsets[c + 1]``.
    vertex_offsets : ndarray of int, shape (C + 1,)
        Start of each cell's vertices in ``vertices``, and their total ``P`` last.
    cbf_n, cbf_q : ndarray, shapes (H, 2), (H,)
        Barrier rows ``h = n @ x + q``; cell ``c`` owns rows ``cbf_offsets[c]:cbf_offsets[c + 1]``.
    cbf_offsets : ndarray of int, shape (C + 1,)
        Start of each cell's barrier rows in ``cbf_n``, ``cbf_q``, and their total ``H`` last.
    z, x_j : ndarray, shape (C, 2)
        Exit direction and exit point per cell.
    cells : sequence of int
        The cells to build templates for (rows of every cell are computed, which is cheaper
        than gathering a subset; cells not listed may hold any finite or NaN data).
    u_max, w_h, w_v : float
        As in :func:`vertex_template` (``u_max`` None drops the box rows).

    Returns
    -------
    FieldTemplates
    """
    n_cells = len(z)
    vo, ho = np.asarray(vertex_offsets, np.int64), np.asarray(cbf_offsets, np.int64)
    p, h = np.diff(vo), np.diff(ho)
    box = 2 if u_max is not None else 0
    W = np.empty((len(vertices), 3))  # as in _field_vertex_template, with zeros +0
    np.subtract(0.0, vertices, out=W[:, :2])
    W[:, 2] = 1.0
    # Groups with a slack, cell after cell: the cell's barrier rows (d = −n), then its CLF (d = z).
    go = ho + np.arange(n_cells + 1)
    D = np.empty((go[-1], 2))
    D[go[1:] - 1] = z
    D[np.arange(len(cbf_q)) + np.repeat(np.arange(n_cells), h)] = -cbf_n
    # Slack rows: group g of cell c has one row per vertex of c.
    group_rows = np.repeat(p, h + 1)
    ro = np.zeros(len(group_rows) + 1, np.int64)
    np.cumsum(group_rows, out=ro[1:])
    row_group = np.repeat(np.arange(len(group_rows)), group_rows)
    row_vertex = np.arange(ro[-1]) + np.repeat(np.repeat(vo[:-1], h + 1) - ro[:-1], group_rows)
    # Column by column: a broadcast (R, 2, 1) × (R, 1, 3) product runs numpy's slow tiny-inner-loop path.
    d, w = np.take(D, row_group, axis=0), np.take(W, row_vertex, axis=0)
    coef = np.empty((len(row_group), 6))
    for i in range(2):
        for k in range(3):
            np.multiply(d[:, i], w[:, k], out=coef[:, 3 * i + k])
    coef += 0.0
    slack_values = np.empty((len(coef), 7))
    slack_values[:, :6] = coef
    slack_values[:, 6] = -1.0
    # Right-hand sides: the per-cell products into flat buffers, then the offsets q_k at once.
    hvo = np.zeros(n_cells + 1, np.int64)
    np.cumsum(h * p, out=hvo[1:])
    h_values = np.zeros(hvo[-1])
    minus_v = np.zeros(len(vertices))
    exit_minus_vertex = np.repeat(x_j, p, axis=0) - vertices  # x_j − v_q, elementwise as per cell
    v_off, h_off, hv_off, r_off = vo.tolist(), ho.tolist(), hvo.tolist(), ro[go].tolist()
    cells = list(cells)
    for c in cells:
        v0, v1, h0, h1 = v_off[c], v_off[c + 1], h_off[c], h_off[c + 1]
        np.matmul(cbf_n[h0:h1], vertices[v0:v1].T, out=h_values[hv_off[c] : hv_off[c + 1]].reshape(h1 - h0, v1 - v0))
        np.matmul(exit_minus_vertex[v0:v1], z[c], out=minus_v[v0:v1])
    h_values += np.repeat(cbf_q, np.repeat(p, h))
    _frozen(h_values, minus_v, coef)
    templates = {}
    for c in cells:
        v0, v1, n_h = v_off[c], v_off[c + 1], h_off[c + 1] - h_off[c]
        n = v1 - v0
        r0, r1 = r_off[c], r_off[c + 1]
        w_cell = W[v0:v1].ravel()  # the box rows of u_1, then of u_2
        values = np.concatenate((slack_values[r0:r1].ravel(),) + (w_cell,) * box)
        lower, rhs_const = _vertex_row_bounds(r1 - r0, box * n, float(u_max) if box else 0.0)
        indptr, indices, _ = _vertex_sparsity(_FIELD_PATTERN, 6, n_h, n, box)
        col_lower, col_upper, cost = _slack_columns(6, n_h, float(w_h), float(w_v))
        templates[c] = LpTemplate(cost, indptr, indices, values, col_lower, col_upper, lower, None,
                                  h_values[hv_off[c] : hv_off[c + 1]], minus_v[v0:v1], rhs_const, 6, n_h,
                                  coef[r0:r1])  # fmt: skip
    return FieldTemplates(templates, h_values, hvo, minus_v)


def dual_template(problem: CellProblem, L: np.ndarray, u_max: float | None, w_h: float = 1.0, w_v: float = 1.0,
                  least_violation: bool = False) -> LpTemplate:  # fmt: skip
    """The dual form of (P) with open constants (see :func:`dual_lp`).

    Groups: the ``h`` barrier rows (``d = −n_k``), the CLF (``d = z``), then the four box
    sides ``e_r``, each with its own multipliers ``λ_g ≥ 0`` (``m`` each).

    Parameters
    ----------
    problem : CellProblem
        The cell; the dual form uses its half-planes ``A x ≤ b`` instead of its vertices.
    L : ndarray, shape (2, 3, n_θ)
        The variable map ``[M, a] = L θ`` (:func:`field_map`).
    u_max : float or None
        Input bound ``|u_i| ≤ u_max`` (map units/s); None drops the four box groups.
    w_h, w_v : float
        Objective weights of the CBF slacks ``S_h`` and of the CLF slack ``S_V``.
    least_violation : bool
        Free slacks and minimise ``Σ w·max(S, 0)`` instead (§5.3).

    Returns
    -------
    LpTemplate
        Three rows per group (two equalities, one inequality), ``vertex_rows`` None.
    """
    A, b = problem.A, problem.b
    m = len(b)
    n_theta = L.shape[2]
    n_h = len(problem.cbf_q)
    n_slack = n_h + 1
    D = np.concatenate([-problem.cbf_n, problem.z[None, :]] + ([BOX_DIRECTIONS] if u_max is not None else []))
    n_groups = len(D)
    n_mult = n_groups * m
    head = np.zeros((n_groups, 3, n_theta + n_slack))
    head[:, :, :n_theta] = (D @ L.reshape(2, 3 * n_theta)).reshape(n_groups, 3, n_theta)  # Mᵀd and dᵀa
    head[range(n_slack), 2, range(n_theta, n_theta + n_slack)] = -1.0
    lam = np.zeros((n_groups, 3, n_groups, m))
    g = np.arange(n_groups)
    lam[g, :2, g, :] = A.T
    lam[g, 2, g, :] = b
    dense = np.concatenate([head, lam.reshape(n_groups, 3, n_mult)], axis=2).reshape(3 * n_groups, -1)
    # per group: equalities A_xᵀλ_g + Mᵀd_g = ρ_g (ρ = c_h·d for CBF, c_v·z for CLF, 0 for the box)
    # and b_xᵀλ_g + d_gᵀa − S_g ≤ r_g (r = c_h·q_k, c_v·zᵀx_j, u_max)
    rhs_h = np.column_stack([D[:n_h], problem.cbf_q]).ravel()
    rhs_v = np.array([problem.z[0], problem.z[1], problem.z @ problem.x_j])
    rhs_const = np.zeros((n_groups - n_slack, 3))
    rhs_const[:, 2] = u_max if u_max is not None else 0.0
    equality = np.ones((n_groups, 3), bool)
    equality[:, 2] = False
    return _template(dense, _filled(3 * n_groups, -INF), equality.ravel(), rhs_h, rhs_v, rhs_const.ravel(),
                     n_theta, n_h, n_mult, w_h, w_v, least_violation)  # fmt: skip


def _template(dense, lower, equality, rhs_h, rhs_v, rhs_const, n_theta, n_h, n_extra, w_h, w_v, least_violation,
              vertex_rows=None) -> LpTemplate:  # fmt: skip
    """Add column bounds, the objective and (for least violation) the ``t`` variables; compress the matrix."""
    n_slack = n_h + 1
    n_rows, n_cols = dense.shape
    col_lower = _filled(n_cols, -INF)
    col_upper = _filled(n_cols, INF)
    col_lower[n_theta + n_slack : n_theta + n_slack + n_extra] = 0.0  # multipliers λ, μ, ν ≥ 0
    cost = np.zeros(n_cols)
    if least_violation:  # slacks free, t ≥ S, t ≥ 0, minimise Σ w t
        extra = np.zeros((n_rows + n_slack, n_cols + n_slack))
        extra[:n_rows, :n_cols] = dense
        extra[n_rows:, n_theta : n_theta + n_slack] = -np.eye(n_slack)
        extra[n_rows:, n_cols:] = np.eye(n_slack)
        dense = extra
        lower = np.concatenate([lower, np.zeros(n_slack)])
        if equality is not None:
            equality = np.concatenate([equality, np.zeros(n_slack, bool)])
        rhs_const = np.concatenate([rhs_const, _filled(n_slack, INF)])
        col_lower = np.concatenate([col_lower, np.zeros(n_slack)])
        col_upper = np.concatenate([col_upper, _filled(n_slack, INF)])
        cost = np.concatenate([cost, np.zeros(n_slack)])
        first = n_cols
    else:
        col_upper[n_theta : n_theta + n_slack] = 0.0
        first = n_theta
    cost[first : first + n_h] = w_h
    cost[first + n_h] = w_v
    indptr, indices, values = dense_to_csr(dense)
    return LpTemplate(cost, indptr, indices, values, col_lower, col_upper, lower, equality, rhs_h, rhs_v, rhs_const,
                      n_theta, n_h, vertex_rows)  # fmt: skip


def vertex_lp(problem: CellProblem, L: np.ndarray, c_h: float, c_v: float, u_max: float | None,
              w_h: float = 1.0, w_v: float = 1.0, least_violation: bool = False) -> CellLp:  # fmt: skip
    """The vertex form of (P) in the variables ``θ`` with ``[M, a] = L θ`` (ALGORITHMS §5.2).

    Parameters
    ----------
    problem : CellProblem
        The cell's data.
    L : ndarray, shape (2, 3, n_θ)
        From :func:`field_map`.
    c_h, c_v : float
        Barrier and Lyapunov constants (1/s); ``c_h`` is unused without barrier rows.
    u_max : float or None
        Input box; ``None`` drops the input rows (Appendix A, T1).
    w_h, w_v : float
        Objective weights.
    least_violation : bool
        Free slacks and minimise ``Σ w·max(S, 0)`` instead (§5.3).

    Returns
    -------
    CellLp
        Rows (see :func:`vertex_template`): per group one row per vertex; the box as
        ranged rows ``−u_max ≤ u_i(v_q) ≤ u_max``.
    """
    return vertex_template(problem, L, u_max, w_h, w_v, least_violation).instantiate(c_h, c_v)


def dual_lp(problem: CellProblem, L: np.ndarray, c_h: float, c_v: float, u_max: float | None,
            w_h: float = 1.0, w_v: float = 1.0, least_violation: bool = False) -> CellLp:  # fmt: skip
    """The dual form of (P): multipliers ``λ_g ≥ 0`` per group instead of vertex rows (§5.2).

    Rows per group ``g``: ``A_xᵀλ_g + Mᵀd_g = ρ_g`` (two equalities) and
    ``b_xᵀλ_g + d_gᵀa − S_g ≤ r_g``. Columns after the slacks: ``λ_g`` (m each, ``m`` =
    number of cell rows), group by group.

    Parameters
    ----------
    problem : CellProblem
        The cell's data; its half-planes ``A x ≤ b`` give the multipliers' rows.
    L : ndarray, shape (2, 3, n_θ)
        From :func:`field_map`.
    c_h, c_v : float
        Barrier and Lyapunov constants (1/s); ``c_h`` is unused without barrier rows.
    u_max : float or None
        Input box (map units/s); ``None`` drops the four box groups.
    w_h, w_v : float
        Objective weights of the CBF and CLF slacks.
    least_violation : bool
        Free slacks and minimise ``Σ w·max(S, 0)`` instead (§5.3).

    Returns
    -------
    CellLp
    """
    return dual_template(problem, L, u_max, w_h, w_v, least_violation).instantiate(c_h, c_v)


def vertex_lp_field(problem: CellProblem, c_h: float, c_v: float, u_max: float | None, **kw) -> CellLp:
    """Field-space vertex form: ``θ = vec([M, a])`` (row-major), 6 + n_h + 1 variables.

    Parameters
    ----------
    problem : CellProblem
        The cell's data.
    c_h, c_v : float
        Barrier and Lyapunov constants (1/s).
    u_max : float or None
        Input box (map units/s); ``None`` drops the input rows.
    **kw
        ``w_h``, ``w_v`` and ``least_violation`` of :func:`vertex_lp`.

    Returns
    -------
    CellLp
    """
    return vertex_lp(problem, FIELD_MAP, c_h, c_v, u_max, **kw)


def vertex_lp_gain(problem: CellProblem, c_h: float, c_v: float, u_max: float | None, structure: str = "full",
                   **kw) -> CellLp:  # fmt: skip
    """Gain-space vertex form for a gain structure (``full``, ``diag`` or ``scalar``).

    Parameters
    ----------
    problem : CellProblem
        The cell's data; its landmarks fix the gain's size (2, 2n).
    c_h, c_v : float
        Barrier and Lyapunov constants (1/s).
    u_max : float or None
        Input box (map units/s); ``None`` drops the input rows.
    structure : {"full", "diag", "scalar"}
        Which gain entries are variables (:func:`field_map`).
    **kw
        ``w_h``, ``w_v`` and ``least_violation`` of :func:`vertex_lp`.

    Returns
    -------
    CellLp
    """
    return vertex_lp(problem, field_map(structure, problem.landmarks), c_h, c_v, u_max, **kw)
