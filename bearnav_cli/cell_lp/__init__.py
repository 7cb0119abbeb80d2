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

Every name is re-exported here; the modules, each with one job:

- :mod:`~bearnav_cli.cell_lp.fields` — the cell data (:class:`CellProblem`), the field map ``L``,
  the landmark matrix ``G`` of Lemma 3 and the minimum-norm gain that realises a field;
- :mod:`~bearnav_cli.cell_lp.form` — the solver form: :class:`CellLp`, :class:`LpTemplate`;
- :mod:`~bearnav_cli.cell_lp.vertex` — the vertex form, one cell or many at once;
- :mod:`~bearnav_cli.cell_lp.dual` — the dual form.
"""

from bearnav_cli.cell_lp.dual import BOX_DIRECTIONS, dual_lp, dual_template
from bearnav_cli.cell_lp.fields import (
    COND_WARNING,
    FIELD_MAP,
    CellProblem,
    field_map,
    gain_from_theta,
    landmark_matrix,
    min_norm_gain,
    min_norm_gains,
    theta_from_gain,
)
from bearnav_cli.cell_lp.form import CellLp, LpTemplate
from bearnav_cli.cell_lp.vertex import (
    FieldTemplates,
    field_vertex_templates,
    vertex_lp,
    vertex_lp_field,
    vertex_lp_gain,
    vertex_template,
)

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
