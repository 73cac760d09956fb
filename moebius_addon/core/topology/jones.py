"""The Jones polynomial of a planar diagram, by the Kauffman bracket summed tangle by tangle.

Kauffman's state sum ``<D> = Σ_s A^(a(s) − b(s)) d^(loops(s))``, ``d = −A² − A⁻²``, over the
2^c smoothings of the c crossings is exponential in c. Summed crossing by crossing instead, a
state is only the way the smoothings so far join the open ends of the part already added (the
edges to crossings not yet added), so the work grows with the number of such pairings, which
stays small when each crossing added shares edges with the part so far (Bar-Natan's order for
tangle computations, "Fast Khovanov homology computations", J. Knot Theory Ramif. 2007, §7,
applied here to the bracket). ``V(t) = (−A³)^(−w) <D> / d`` at ``A = t^(−1/4)``
(Kauffman, *State models and the Jones polynomial*, Topology 1987).

Smoothings: the A-smoothing of ``X[a, b, c, d]`` joins ``a`` to ``b`` and ``c`` to ``d``, so that
a positive kink is ``−A³`` times the strand and ``V`` of KnotInfo's 3_1 (the closure of
``σ_1³``, three positive crossings) is ``t + t³ − t⁴``, as KnotInfo writes it.
"""

from __future__ import annotations

from .pd import PlanarDiagram

#: Pairings a sum may hold at once before it gives up (:class:`TooComplex`); a dozen
#: thousand pairings of 16 open ends still take well under a second.
MAX_STATES = 200_000


class TooComplex(ValueError):
    """The diagram needs more intermediate states than :data:`MAX_STATES`."""


def _mul(p: dict[int, int], q: dict[int, int]) -> dict[int, int]:
    out: dict[int, int] = {}
    for a, x in p.items():
        for b, y in q.items():
            out[a + b] = out.get(a + b, 0) + x * y
    return {e: c for e, c in out.items() if c}


_D = {2: -1, -2: -1}  # d = -A^2 - A^-2


def _d_power(k: int, cache: dict[int, dict[int, int]] = {0: {0: 1}}) -> dict[int, int]:  # noqa: B006 - a cache
    if k not in cache:
        cache[k] = _mul(_d_power(k - 1), _D)
    return cache[k]


def _order(X) -> list[int]:
    """Crossings in an order that keeps the open ends few: each next crossing shares the most
    edges with those already added (ties: the one opening the fewest new ends)."""
    c = len(X)
    labels = [set(int(v) for v in X[m]) for m in range(c)]
    remaining = set(range(c))
    boundary: set[int] = set()
    order = []
    while remaining:
        best = max(remaining, key=lambda m: (len(labels[m] & boundary),
                                             -len(labels[m] - boundary), -m))
        order.append(best)
        remaining.discard(best)
        boundary ^= labels[best]
    return order


def kauffman_bracket(d: PlanarDiagram, max_states: int = MAX_STATES) -> dict[int, int]:
    """The Kauffman bracket ``<D>`` (unnormalized: a diagram without crossings of one circle is
    ``d``) as ``{exponent of A: coefficient}``."""
    states: dict[tuple, dict[int, int]] = {(): {0: 1}}
    for m in _order(d.X):
        a, b, c, e = (int(v) for v in d.X[m])
        smoothings = ((((a, b), (c, e)), 1), (((a, e), (b, c)), -1))
        new: dict[tuple, dict[int, int]] = {}
        for key, poly in states.items():
            base: dict[int, int] = {}
            for u, v in key:
                base[u], base[v] = v, u
            for pairs, power in smoothings:
                partner = dict(base)
                loops = 0
                for u, v in pairs:
                    if u == v:  # both ends of one edge at this crossing: a circle
                        loops += 1
                        continue
                    pu, pv = partner.pop(u, None), partner.pop(v, None)
                    if pu is None and pv is None:
                        partner[u], partner[v] = v, u
                    elif pv is None:
                        partner[pu], partner[v] = v, pu
                    elif pu is None:
                        partner[pv], partner[u] = u, pv
                    elif pu == v:  # the two ends of one open path meet: a circle
                        loops += 1
                    else:
                        partner[pu], partner[pv] = pv, pu
                k = tuple(sorted((u, v) for u, v in partner.items() if u < v))
                term = _mul(poly, _mul({power: 1}, _d_power(loops)))
                acc = new.setdefault(k, {})
                for ex, co in term.items():
                    acc[ex] = acc.get(ex, 0) + co
        states = {k: {ex: co for ex, co in p.items() if co} for k, p in new.items()}
        if len(states) > max_states:
            raise TooComplex(f"the Kauffman bracket of this {d.crossings}-crossing diagram "
                             f"needs more than {max_states} intermediate states")
    poly = states.get((), {})
    return _mul(poly, _d_power(d.loops)) if d.crossings else _d_power(d.loops)


def jones(d: PlanarDiagram, max_states: int = MAX_STATES) -> dict[int, int]:
    """The Jones polynomial as ``{exponent of x: coefficient}`` with ``x = t^(1/2)``, the
    variable LinkInfo writes (knots and links with an odd number of components have even
    exponents only). The unknot is ``{0: 1}``, the positive Hopf link ``{1: -1, 5: -1}``."""
    if d.crossings == 0 and d.loops == 0:
        raise ValueError("an empty diagram has no Jones polynomial")
    br = kauffman_bracket(d, max_states)
    # divide by d = -(A^2 + A^-2): synthetic division from the highest power down
    rem = dict(br)
    quo: dict[int, int] = {}
    low = min(br)
    while rem:
        top = max(rem)
        if top - 2 < low + 2:  # the quotient's lowest term is A^(low + 2)
            raise ArithmeticError("the bracket is not divisible by d")  # pragma: no cover
        q = -rem[top]  # leading term of d is -A^2
        quo[top - 2] = q
        for ex, co in ((top, -1), (top - 4, -1)):
            rem[ex] = rem.get(ex, 0) - q * co
            if rem[ex] == 0:
                del rem[ex]
    w = d.writhe
    # (-A^3)^(-w) = (-1)^w A^(-3w); then A^e = t^(-e/4) = x^(-e/2)
    sign = -1 if w % 2 else 1
    out = {}
    for ex, co in quo.items():
        e = ex - 3 * w
        if e % 2:
            raise ArithmeticError("odd power of A in the normalized bracket")  # pragma: no cover
        out[-e // 2] = sign * co
    return out
