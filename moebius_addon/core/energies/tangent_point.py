"""The discrete tangent-point energy's pair kernel (docs/design.md, "Tangent-point energy"), the
only place its integrand is written.

For an ordered pair of disjoint edges ``I, J`` (``d = m_I − m_J``, ``T_I = e_I / l_I``)::

    f_IJ = l_I l_J |T_I × d|^α / |d|^β = l_I^(1−α) l_J |e_I × d|^α |d|^(−β)

the midpoint rule for ``∫∫ |T(x) × (x − y)|^α / |x − y|^β`` (Buck–Orloff's tangent-point
energy with the exponents of Blair's and Strzelecki–von der Mosel's ``(α, β)`` family, the one
Repulsive Curves and Repulsor minimize). Not symmetric in ``I, J``: only ``I``'s tangent
enters, ``J`` is a point of weight ``l_J``. ``|T × d|`` is the length of a cross product, never
``|d|² − <T, d>²`` (which cancels for nearly parallel ``T`` and ``d``, the pairs along a smooth
strand).

:func:`pair` returns the value and the partials the sums need; a constant ``kind`` (inlined,
the other branches compile away) picks ``α = 2, β = 4`` (no ``pow`` at all), ``α = 2, β = 4.5``
(two square roots), ``α = 2`` (one ``pow``, for ``|d|^−β``) or general exponents. A sum
that masks a pair out passes ``r2 = inf``: every result is then exactly 0.
"""

from __future__ import annotations

import math

import numba as nb

from ..runs.checks import check_number
from .record import Energy, Parameter

#: The name of the energy (``energies.ENERGIES``).
NAME = "tangent_point"
#: Open polylines are supported (the same integrand; the first and last edge are disjoint).
OPEN_CURVES = True
#: Links are supported (every pair of edges of different components counts).
LINKS = True
#: The default exponents ``(α, β)``: β − α > 2, where the energy repels strands strongly
#: enough that relaxed knots come out evenly spread (measured, docs/gallery.md, "Two
#: energies"): from the same 300-edge starts (2, 4.5) converged on all six knots tried at
#: 300 edges in 24–38 iterations, while (2, 4) — scale-invariant, β − α = 2, the borderline
#: of self-avoidance — pulled the crossings into a tangle an edge length wide, jammed and was
#: refined to 1 200 edges on all six (7_4: 6.2 against 59.5 CPU s, stalled).
DEFAULT_ALPHA = 2.0
DEFAULT_BETA = 4.5
#: The largest ``beta``: a run works at total length 1, where points an edge apart are 1/N
#: apart; N^beta must stay far inside float64's 1e308 for N to 10^6 (alpha = 100, beta = 150
#: gave a finite energy of 5.8e19 on the start and NaN in the run).
MAX_BETA = 40.0
#: Default admissibility of the tangent-point tree (with leaves of ``tree.tangent_point.
#: LEAF_SIZE`` edges), Repulsor's default too. Its far field for α = 2 is of second order on
#: both sides: at 0.5 the energy erred at most 6.5e-4 over varied curves (knots, links, a round
#: ring, open cables; 500 to 20 000 edges), under the 1e-3 that docs/api.md gives, and its E+g
#: took 0.84–0.89 of the time at 0.4 from 10⁴ edges on (docs/lab/tangent-point.md, "The default
#: θ 0.5").
THETA = 0.5

# what :func:`pair` computes (a constant argument at every call site)
KIND_2_4 = 0  # α = 2, β = 4: no pow
KIND_2 = 1  # α = 2: |T × d|² exactly, one pow for |d|^−β
KIND_GENERAL = 2
KIND_2_45 = 3  # α = 2, β = 4.5 (the default): |d|^−4.5 by a square root, no pow


def scaling(alpha: float, beta: float) -> float:
    """``s`` with ``E(λP) = λ^s E(P)``: ``2 + α − β`` (each edge length one power, the
    integrand ``α − β``)."""
    return 2.0 + alpha - beta


def check_exponents(alpha, beta) -> tuple[float, float]:
    """``(α, β)`` as floats, or ValueError naming the one at fault: both finite, ``α > 0``
    and ``α + 1 < β < 2α + 1`` (below: the energy does not repel, a curve may pass through
    itself at finite energy; above: it is infinite on every smooth curve). Text (``"2"``,
    ``b"4.5"``) and booleans are refused, as by every numeric option (:func:`.._checks.
    check_number`)."""
    a, b = check_number("alpha", alpha), check_number("beta", beta)
    if a <= 0.0:
        raise ValueError(f"alpha must be > 0, got {alpha!r} (the default is {DEFAULT_ALPHA:g})")
    if b > MAX_BETA:
        raise ValueError(f"beta must be at most {MAX_BETA:g}, got {beta!r}: |x − y|^−beta "
                         "between points an edge apart overflows float64 at the resolutions a "
                         f"run reaches (the default is ({DEFAULT_ALPHA:g}, {DEFAULT_BETA:g}))")
    if not (a + 1.0 < b < 2.0 * a + 1.0):
        raise ValueError(f"beta must lie in (alpha + 1, 2 alpha + 1) = ({a + 1.0:g}, "
                         f"{2.0 * a + 1.0:g}) for alpha = {a:g}, got {beta!r} (below, the energy "
                         f"is no barrier against self-crossing; above, it is infinite on smooth "
                         f"curves; the default is ({DEFAULT_ALPHA:g}, {DEFAULT_BETA:g}))")
    return a, b


def kind_of(alpha: float, beta: float) -> int:
    """The :func:`pair` branch for these exponents."""
    if alpha == 2.0:
        if beta == 4.0:
            return KIND_2_4
        return KIND_2_45 if beta == 4.5 else KIND_2
    return KIND_GENERAL


@nb.njit(cache=True, inline="always")
def radial(r2, beta, kind):
    """``(1 / |d|², |d|^−β)`` from ``r2 = |d|²`` (the only part of :func:`pair` that depends
    on ``kind`` for ``α = 2``): a sum computes it in a small loop per kind and the pairs in one
    loop for every kind (a loop per kind took minutes to compile)."""
    inv = 1.0 / r2
    if kind == KIND_2_4:
        rb = inv * inv  # |d|^−4
    elif kind == KIND_2_45:
        rb = inv * inv * math.sqrt(math.sqrt(inv))  # r2^−2 r2^−¼, no pow
    else:
        rb = r2 ** (-0.5 * beta)
    return inv, rb


@nb.njit(cache=True, inline="always")
def pair(dx, dy, dz, ax, ay, az, li, il, lj, r2, alpha, beta, kind):
    """The ordered pair ``(I, J)``: ``e_I = a``, lengths ``li``, ``lj``, ``il = 1 / li`` (a sum
    divides once per edge, not per pair), ``d = m_I − m_J`` with ``r2 = |d|²``.

    Returns ``(f, ∂f/∂e_I (3), ∂f/∂d (3), ∂f/∂l_J)``: ``∂f/∂e_I`` with its length term (``l_I``
    is ``|e_I|``); ``∂f/∂m_I = ∂f/∂d``, ``∂f/∂m_J = −∂f/∂d``; ``∂f/∂l_J = f/l_J`` (computed
    without the division, so a weight ``l_J = 0`` gives 0)."""
    inv, rb = radial(r2, beta, kind)
    return pair_radial(dx, dy, dz, ax, ay, az, li, il, lj, inv, rb, alpha, beta,
                       kind == KIND_GENERAL)


@nb.njit(cache=True, inline="always")
def pair_radial(dx, dy, dz, ax, ay, az, li, il, lj, inv, rb, alpha, beta, general):
    """:func:`pair` with :func:`radial`'s ``inv``, ``rb`` given; ``general``: ``α ≠ 2``."""
    # c = e_I × d; |c|^α = w |c|², its derivative in c: α w c
    cx = ay * dz - az * dy
    cy = az * dx - ax * dz
    cz = ax * dy - ay * dx
    c2 = cx * cx + cy * cy + cz * cz
    if general:
        w = c2 ** (0.5 * alpha - 1.0) if c2 > 0.0 else 0.0
        pl = li ** (1.0 - alpha)
    else:
        w = 1.0
        pl = il  # l_I^(1−α)
    h = pl * w * rb  # f = lj h |c|²
    fl = h * c2  # ∂f/∂l_J
    f = lj * fl
    # ∂f/∂c = lj h α c; ∂f/∂e = d × ∂f/∂c + (1 − α) f e/l_I²; ∂f/∂d = ∂f/∂c × e − β f d/|d|²
    k = lj * h * alpha
    gx = k * cx
    gy = k * cy
    gz = k * cz
    tl = (1.0 - alpha) * f * il * il
    fax = dy * gz - dz * gy + tl * ax
    fay = dz * gx - dx * gz + tl * ay
    faz = dx * gy - dy * gx + tl * az
    tb = beta * f * inv
    fdx = gy * az - gz * ay - tb * dx
    fdy = gz * ax - gx * az - tb * dy
    fdz = gx * ay - gy * ax - tb * dz
    return f, fax, fay, faz, fdx, fdy, fdz, fl


@nb.njit(cache=True, inline="always")
def pair_both_2(dx, dy, dz, ax, ay, az, li, il, sx, sy, sz, lj, jl, inv, rb, beta):
    """Both orders of a pair for ``α = 2`` with :func:`radial`'s ``inv``, ``rb`` given:
    ``d = m_I − m_J``, ``e_I = a``, ``e_J = s``, lengths ``li``, ``lj`` and their inverses.
    With ``c = e_I × d``, ``u = e_J × d``, ``p_I = ρ l_J/l_I``, ``p_J = ρ l_I/l_J``
    (``ρ = |d|^−β``): ``F = f_IJ + f_JI = p_I |c|² + p_J |u|²``, ``∂F/∂e_I = d × 2 p_I c``,
    ``∂F/∂e_J = d × 2 p_J u``, ``∂F/∂d = 2 p_I c × e_I + 2 p_J u × e_J − β F d/|d|²`` and
    the prefactors' lengths ``∂F/∂l_I = (f_JI − f_IJ)/l_I``, ``∂F/∂l_J = (f_IJ − f_JI)/l_J``
    (the edge-vector derivatives without their length terms). Cross products, not
    ``l²|d|² − (e·d)²``: no cancellation where ``d`` is nearly parallel to an edge. Less
    arithmetic than :func:`pair_radial` twice (one radial term, one ``d``; docs/lab/repulsor.md,
    "The tangent-point near field's pair in one piece, the moments of a leaf in registers").

    Returns ``(F, ∂e_I (3), ∂e_J (3), ∂d (3), ∂l_I, ∂l_J)``."""
    cx = ay * dz - az * dy
    cy = az * dx - ax * dz
    cz = ax * dy - ay * dx
    ux = sy * dz - sz * dy
    uy = sz * dx - sx * dz
    uz = sx * dy - sy * dx
    pi = lj * il * rb
    pj = li * jl * rb
    fi = pi * (cx * cx + cy * cy + cz * cz)
    fj = pj * (ux * ux + uy * uy + uz * uz)
    F = fi + fj
    gi = 2.0 * pi
    gj = 2.0 * pj
    gx = gi * cx
    gy = gi * cy
    gz = gi * cz
    hx = gj * ux
    hy = gj * uy
    hz = gj * uz
    tb = beta * F * inv
    mx = gy * az - gz * ay + hy * sz - hz * sy - tb * dx
    my = gz * ax - gx * az + hz * sx - hx * sz - tb * dy
    mz = gx * ay - gy * ax + hx * sy - hy * sx - tb * dz
    return (F, dy * gz - dz * gy, dz * gx - dx * gz, dx * gy - dy * gx,
            dy * hz - dz * hy, dz * hx - dx * hz, dx * hy - dy * hx,
            mx, my, mz, (fj - fi) * il, (fi - fj) * jl)


# -- the record (energies.record): sums and tree imported when first used, as they import the
# kernels above


def _check(values: dict) -> dict:
    a, b = values.get("alpha"), values.get("beta")
    a, b = check_exponents(DEFAULT_ALPHA if a is None else a, DEFAULT_BETA if b is None else b)
    return {"alpha": a, "beta": b}


def _exact(X, layout, alpha, beta):
    from .tangent_point_dense import tp_energy_x

    return tp_energy_x(X, layout, alpha, beta)


def _exact_gradient(X, layout, alpha, beta):
    from .tangent_point_dense import tp_energy_gradient_x

    return tp_energy_gradient_x(X, layout, alpha, beta)


def _frame(X, layout, theta, alpha, beta):
    from ..tree.tangent_point import TangentPointFrame

    return TangentPointFrame(X, layout, alpha, beta, theta)


RECORD = Energy(
    name=NAME,
    short='TP',
    label="Tangent-Point",
    help="Tangent-point energy with exponents α, β (Advanced; default 2, 4.5): spreads the "
         "strands evenly, opens tight clasps",
    exact=_exact,
    exact_gradient=_exact_gradient,
    parameters=(
        Parameter("alpha", "α", "Tangent-point energy: exponent α of |T × (x − y)| (needs "
                  "α + 1 < β < 2α + 1)", DEFAULT_ALPHA, "tp_alpha", minimum=0.01,
                  soft_max=8.0),
        Parameter("beta", "β", "Tangent-point energy: exponent β of |x − y| (needs α + 1 < β < "
                  "2α + 1; β = α + 2 makes it scale-invariant)", DEFAULT_BETA, "tp_beta",
                  minimum=0.01, soft_max=16.0),
    ),
    check=_check,
    scaling=scaling,
    # Repulsive Curves' order: 7/4 at the default (2, 4.5), 3/2 at (2, 4)
    metric_order=lambda alpha, beta: (beta - 1.0) / alpha,
    default_theta=THETA,
    frame=_frame,
    tag=lambda alpha, beta: f"{NAME}({alpha:g}, {beta:g})",
    words=lambda alpha, beta: (f"Tangent-point energy ({alpha:g}, {beta:g}) (α, β) of the curve "
                               "at this frame, for the curve scaled to total length 1"),
    warmup=({"energy": NAME},),
    warmup_sizes=(100, 3000),
)
