"""The discrete Möbius energy's pair kernels (docs/design.md, "Energy"; docs/api.md, "Open
curves"), the only place its integrand is written.

Three kinds of pairs of disjoint edges ``I, J`` (``d = m_I − m_J``, ``r2 = |d|²``):

* :func:`pair`, two edges of one closed component: the Ishizeki–Nagasawa integrand with the
  midpoint rule, ``f = ((l_I l_J + <e_I, e_J>) − 2 <d, e_I><d, e_J>/|d|²)/|d|²``;
* :func:`link_pair`, two edges of different components: O'Hara's ``l_I l_J/|d|²``;
* :func:`open_pair`, two edges of one open polyline: O'Hara's regularized
  ``l_I l_J (1/|d|² − 1/D²)``, ``D`` the arc length between the midpoints.

Each returns the pair's value and the partial derivatives the sums need, in one of three
forms (a constant argument: inlined, the other branches compile away):

* ``VALUE``: the value alone, in the order the dense energy sum (``core.moebius_energy``)
  has always used (for :func:`pair` one multiplication fewer than the gradient's order; the
  two give different last bits, and the energies of every earlier release are kept bit for
  bit, so both orders stay);
* ``FOLDED``: the dense gradient's form, the length term of ``∂f/∂e`` folded into the edge
  vector's partial (``∂l_I/∂e_I = e_I/l_I``);
* ``SPLIT``: the tree engine's form, ``∂f/∂e`` without the length term and ``∂f/∂l`` apart
  (a sum over many partners adds ``e_I/l_I`` times it once per edge; the far field, whose
  clusters have a total length and a summed edge vector, needs them apart).

A sum that masks a pair out (the near field's edge itself and its neighbours) passes
``r2 = inf``: every partial is then exactly 0, as ``1/inf = 0``.

These kernels are inlined (``inline="always"``) and so compiled with their caller's options
(fast-math in the dense sums, none in the tree engine's). Keep the order of the floating-point
operations: the energies, gradients and iterate histories are pinned bit for bit
(tests/core/data/unchanged_runs.json). Under fast-math even the callers' order of loads counts
(LLVM's reassociation ranks values by it; moebius_dense.py loads ``e_J`` and ``l_J`` before
the midpoint, as it always did). numba's cache is keyed on the caller's file alone: after
editing this one, delete the callers' cached kernels (``__pycache__/*.nbi``, ``*.nbc`` of
moebius_dense.py, open_energy.py, _near_field.py, _far_field.py), or they keep the old code.

The far field expands ``pair`` around the clusters' centres: its zeroth order is :func:`pair`
itself with the clusters' total lengths and summed edge vectors; the higher orders are the
derivatives of the kernel ``∇² log|d|`` in :mod:`.._far_field`.
"""

from __future__ import annotations

import numba as nb

from .record import Energy

#: The name of the energy (``energies.ENERGIES``).
NAME = "moebius"
#: Open polylines are supported (O'Hara's regularized form, :func:`open_pair`).
OPEN_CURVES = True
#: Links are supported (O'Hara's kernel between components, :func:`link_pair`).
LINKS = True
#: ``E(cP) = c^SCALING E(P)``: scale-invariant, so the gradient scales as ``1/c``.
SCALING = 0
#: Added per closed component (the constant of the Ishizeki–Nagasawa decomposition).
CLOSED_CONSTANT = 4.0

# the forms of the kernels' results (module docstring)
VALUE = 0
FOLDED = 1
SPLIT = 2


@nb.njit(cache=True, inline="always")
def pair(dx, dy, dz, ax, ay, az, bx, by, bz, li, lj, r2, form):
    """Two edges of one closed component: ``e_I = a``, ``e_J = b``, lengths ``li``, ``lj``,
    ``d = m_I − m_J`` with ``r2 = |d|²``.

    Returns ``(f, ∂f/∂e_I (3), ∂f/∂e_J (3), ∂f/∂d (3), wi, wj)``: with ``FOLDED`` the
    ``∂f/∂e`` include their length terms, with ``SPLIT`` not and ``wi = ∂f/∂l_I = l_J/|d|²``,
    ``wj = l_I/|d|²``; with ``VALUE`` only ``f`` (the rest 0)."""
    inv = 1.0 / r2
    ab = ax * bx + ay * by + az * bz
    da = dx * ax + dy * ay + dz * az
    db = dx * bx + dy * by + dz * bz
    if form == VALUE:
        return (((li * lj + ab) - 2.0 * da * db * inv) * inv,
                0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0)
    sv = (li * lj + ab) * inv
    q = da * db * inv * inv
    f = sv - 2.0 * q
    if form == FOLDED:
        ci = lj / li
        cj = li / lj
        tb = 2.0 * db * inv
        ta = 2.0 * da * inv
        fax = (ci * ax + bx - tb * dx) * inv
        fay = (ci * ay + by - tb * dy) * inv
        faz = (ci * az + bz - tb * dz) * inv
        fbx = (cj * bx + ax - ta * dx) * inv
        fby = (cj * by + ay - ta * dy) * inv
        fbz = (cj * bz + az - ta * dz) * inv
        wi = wj = 0.0
    else:
        tb = 2.0 * db * inv
        ta = 2.0 * da * inv
        wi = lj * inv
        wj = li * inv
        fax = (bx - tb * dx) * inv
        fay = (by - tb * dy) * inv
        faz = (bz - tb * dz) * inv
        fbx = (ax - ta * dx) * inv
        fby = (ay - ta * dy) * inv
        fbz = (az - ta * dz) * inv
    cd = 8.0 * q - 2.0 * sv
    fdx = (cd * dx - tb * ax - ta * bx) * inv
    fdy = (cd * dy - tb * ay - ta * by) * inv
    fdz = (cd * dz - tb * az - ta * bz) * inv
    return f, fax, fay, faz, fbx, fby, fbz, fdx, fdy, fdz, wi, wj


@nb.njit(cache=True, inline="always")
def link_pair(li, lj, r2, form):
    """Two edges of different components: ``f = l_I l_J / r2``.

    Returns ``(f, ci, cj, cd, wi, wj)``: ``∂f/∂e_I = ci e_I``, ``∂f/∂e_J = cj e_J`` (length
    terms, ``FOLDED``), ``∂f/∂d = cd d``, ``∂f/∂l_I = wi``, ``∂f/∂l_J = wj`` (``SPLIT``);
    with ``VALUE`` only ``f``."""
    if form == VALUE:
        return li * lj / r2, 0.0, 0.0, 0.0, 0.0, 0.0
    inv = 1.0 / r2
    f = li * lj * inv
    cd = -2.0 * f * inv
    if form == FOLDED:
        return f, lj * inv / li, li * inv / lj, cd, 0.0, 0.0
    return f, 0.0, 0.0, cd, lj * inv, li * inv


@nb.njit(cache=True, inline="always")
def open_pair(li, lj, r2, arc, form):
    """Two edges of one open polyline, ``arc`` (``D``) the arc length between their
    midpoints: ``f = l_I l_J (1/r2 − 1/D²)``.

    Returns ``(f, cd, wi, wj, h)``: ``∂f/∂d = cd d``, ``∂f/∂l_I = wi`` and ``∂f/∂l_J = wj``
    at fixed ``D``, and ``∂f/∂D = 2h`` (``D`` grows with the length of every edge from I to J:
    ``∂D/∂l_K = 1``, ``½`` for I and J; ``wi``, ``wj`` include their ``h``); with ``VALUE``
    only ``f``. (``SPLIT`` and ``FOLDED`` are the same here: no edge vector.)"""
    inv = 1.0 / r2
    id2 = 1.0 / (arc * arc)
    f = li * lj * (inv - id2)
    if form == VALUE:
        return f, 0.0, 0.0, 0.0, 0.0
    h = li * lj * id2 / arc  # ∂(−l_I l_J / D²)/∂D = 2h
    cd = -2.0 * (li * lj * inv) * inv
    return f, cd, lj * (inv - id2) + h, li * (inv - id2) + h, h


# -- the record (energies.record): sums and tree imported when first used, as they import the
# kernels above


def _exact(X, layout):
    from .moebius_dense import energy_x

    return energy_x(X, layout)  # open curves: O'Hara's regularized sum


def _exact_gradient(X, layout):
    from .moebius_dense import energy_gradient_x

    return energy_gradient_x(X, layout)


def _frame(X, layout, theta):
    from ..tree.moebius import Frame

    return Frame(X, layout, theta)


#: The admissibility of the Möbius tree when none is given: the largest of 0.15, 0.175, 0.2,
#: 0.25 whose relative errors stay, with a margin, below 1e-4 (energy) and 1e-3 (gradient) on
#: 7_2, FHW, a link and a non-equilateral polygon at 3 000 to 20 000 edges (worst measured with
#: full leaves of 8: 8.2e-6 and 5.0e-4, FHW's gradient at 5 000 edges; 0.2 gave 8.8e-4 there,
#: 0.25 1.5e-3).
THETA = 0.175

RECORD = Energy(
    name=NAME,
    short='Energy',
    label="Möbius",
    help="The paper's Möbius energy: scale-invariant, keeps tight clasps where strands meet",
    exact=_exact,
    exact_gradient=_exact_gradient,
    scaling=lambda: float(SCALING),
    metric_order=lambda: 1.5,  # the paper's W^{3/2,2}
    default_theta=THETA,
    frame=_frame,
    words=lambda: "Möbius energy of the curve at this frame (scale-invariant)",
)
