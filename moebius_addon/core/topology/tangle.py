"""Tangled starts: a knot or link drawn far from its relaxed shape, its type kept.

Two ways, both seeded and reproducible:

* :func:`tangle_braid` changes a braid word by moves that keep the closure's link type —
  conjugation by generators, Markov stabilizations (a new strand and one crossing with it),
  and cancelling pairs ``σᵢ σᵢ⁻¹`` — so that its closure (:func:`.knots.braid_closure`) has
  two to three times the crossings, on more strands, in a layout that must be undone;
* :func:`crumple` moves a polygon by a sequence of random smooth fields, each step cut short
  before two strands come within half an edge length of each other (continuous collision
  detection, :func:`.collision.max_collision_free_step`), the edges made equal again after it
  with the straight path to the equalized polygon checked too: a random isotopy.

:func:`tangled` combines them for a knot or link of the table by name. The untangling
benchmark (``bench/untangle.py``) relaxes such starts and checks that each reaches the
table's energy.
"""

from __future__ import annotations

import numpy as np

from ..geometry.collision import max_collision_free_step
from ..geometry.polygon import equalize
from . import knots, pd, table


def tangle_braid(word, strands: int | None = None, seed: int = 0, *, conjugations: int = 2,
                 stabilizations: int = 2, pairs: int | None = None) -> tuple[list[int], int]:
    """A longer braid word with the same closure (up to isotopy), and its strand count.

    Parameters
    ----------
    word : sequence of nonzero int
        ``σᵢ`` as ``i``, ``σᵢ⁻¹`` as ``-i`` (:func:`.knots.braid_closure`).
    strands : int, optional
        Strands of ``word`` (default ``max|i| + 1``).
    seed : int
        Seed of the random choices.
    conjugations : int
        Times the word is conjugated, ``w → g w g⁻¹`` for a random generator ``g``.
    stabilizations : int
        Markov stabilizations: a new last strand ``m + 1`` and ``σₘ^±1`` appended.
    pairs : int, optional
        Cancelling pairs ``g g⁻¹`` inserted at random places (default: a third of the
        word's crossings, at least 1).

    Returns
    -------
    (word, strands)
    """
    word, strands = pd.braid_word(word, strands)
    for name, v in (("conjugations", conjugations), ("stabilizations", stabilizations)):
        if int(v) != v or v < 0:
            raise ValueError(f"{name} must be a whole number >= 0, got {v!r}")
    rng = np.random.default_rng(seed)
    w, m = list(word), strands

    def generator():
        return int(rng.integers(1, m)) * int(rng.choice((-1, 1)))

    for _ in range(int(conjugations)):
        g = generator()
        w = [g, *w, -g]
    for _ in range(int(stabilizations)):
        w.append(m * int(rng.choice((-1, 1))))
        m += 1
    pairs = max(1, len(word) // 3) if pairs is None else int(pairs)
    if pairs < 0:
        raise ValueError(f"pairs must be a whole number >= 0, got {pairs!r}")
    for _ in range(pairs):
        i = int(rng.integers(0, len(w) + 1))
        g = generator()
        w[i:i] = [g, -g]
    return w, m


def _smooth_field(rng: np.random.Generator, X: np.ndarray, radius: float,
                  modes: int = 4) -> np.ndarray:
    """A random smooth vector field at the points X (rows): a sum of ``modes`` plane waves
    of wavelengths between a third of and one ``radius``, its mean (a translation) removed."""
    V = np.zeros_like(X)
    for _ in range(modes):
        k = rng.normal(size=3)
        k *= rng.uniform(2.0, 6.0) * np.pi / radius / np.linalg.norm(k)
        V += rng.normal(size=3)[None, :] * np.sin(X @ k + rng.uniform(0, 2 * np.pi))[:, None]
    return V - V.mean(axis=0)


def _mean_edge(parts) -> float:
    return float(np.mean(np.concatenate([np.linalg.norm(np.roll(p, -1, 0) - p, axis=1)
                                         for p in parts])))


def crumple(P, seed: int = 0, steps: int = 100, move: float = 0.5):
    """``P`` moved by ``steps`` random smooth fields without ever touching itself.

    Every step draws a field (:func:`_smooth_field`), moves the vertices by at most ``move``
    mean edge lengths along it — less where two strands would come within half an edge
    length (:func:`.collision.max_collision_free_step`) — and makes the edges equal again
    (:func:`.polygon.equalize`), the straight path from the old polygon to the new one checked
    for contact as well (halved until clear). The result is isotopic to ``P`` (a knot keeps
    its type, a link its type and components), equilateral per component, and no two strands
    are closer than half an edge length — a start the coarseness check may still refuse
    (that needs one edge length): ``relax`` refines such a start.

    Parameters
    ----------
    P : (N, 3) array or list of arrays
        Equilateral closed polygon or link.
    seed, steps : int
        Seed of the fields, and how many steps.
    move : float
        Largest move of a vertex per step, in mean edge lengths.
    """
    is_link = isinstance(P, (list, tuple))
    parts = [np.array(p, dtype=np.float64) for p in (P if is_link else [P])]
    rng = np.random.default_rng(seed)
    X = np.concatenate(parts)
    cuts = np.cumsum([len(p) for p in parts])[:-1]
    h = _mean_edge(parts)
    for _ in range(int(steps)):
        radius = float(np.linalg.norm(X - X.mean(axis=0), axis=1).max())
        V = _smooth_field(rng, X, radius)
        tau = move * h / float(np.abs(V).max())
        split = np.split(X, cuts)
        tau = min(tau, 2.0 / 3.0 * max_collision_free_step(
            split if is_link else X, np.split(V, cuts) if is_link else V, tau, 0.5 * h))
        for _ in range(20):
            Y = np.concatenate([equalize(q) for q in np.split(X - tau * V, cuts)])
            # equalize makes the edges their mean, which creeps up step by step (2 % in 60):
            # scaled back, "half an edge length" keeps meaning the same length
            c = Y.mean(axis=0)
            Y = c + (Y - c) * (h / _mean_edge(np.split(Y, cuts)))
            D = X - Y
            path = max_collision_free_step(split if is_link else X,
                                           np.split(D, cuts) if is_link else D, 1.0, 0.5 * h)
            if path >= 1.0:
                X = Y
                break
            tau *= 0.5
    out = np.split(X, cuts)
    return out if is_link else out[0]


def _faithful_closure(word, strands, n, name):
    """The closure of the braid at ``n`` vertices, or at the fewest above (10 % steps) whose
    polygon is ``name``: the invariants of ``identify`` name it and it touches nothing."""
    from .identify import identify

    curves = knots._braid_curves(word, strands)  # the smooth curve, resampled below as is
    while True:
        P = knots._finish(curves, n)  # no coarseness refusal: a coarse start is the point
        try:
            if name in identify(P).names:
                return P
        except ValueError:  # touches itself at this count, or too tangled to read
            pass
        n = int(np.ceil(1.1 * n))


def tangled(name: str, n: int | None = None, seed: int = 0, how: str = "braid", **moves):
    """A knot or link of the table (by name, alias or mirror: :func:`.table.lookup`) drawn
    tangled: its braid word tangled by :func:`tangle_braid` and closed with ``n`` vertices
    (``how="braid"``), or its usual curve crumpled by :func:`crumple` (``how="crumple"``), or
    both (``how="both"``); ``moves`` go to those functions. ``n``: the default of
    :func:`.knots.named` for that knot. The tangled closure is longer, so it is coarser at
    the same count — often too coarse for the start check, which ``relax`` refines — and a
    polygon that coarse need not be the knot of the smooth curve it is drawn from (a chord can
    cut across another strand): it is drawn at the fewest vertices from ``n`` on, in steps of
    10 %, at which :func:`.identify.identify` names the entry (the length of the result says
    how many)."""
    if how not in ("braid", "crumple", "both"):
        raise ValueError(f"how must be 'braid', 'crumple' or 'both', got {how!r}")
    e = table.entry(name)
    if e.crossings == 0:
        raise ValueError("the unknot has no braid word to tangle: use knots.random_unknot")
    if e.reverse:  # its braid closes to another orientation; tangled, which component is which?
        raise ValueError(f"{e.name} is drawn with components reversed after closing its braid "
                         f"word; it has no tangled drawing")
    if n is None:
        P = knots.named(name)
        n = sum(len(p) for p in P) if isinstance(P, list) else len(P)
    crumple_moves = {k: moves.pop(k) for k in ("steps", "move") if k in moves}
    if how == "crumple":
        P = knots.named(name, n)
    else:
        word, strands = tangle_braid(e.braid, e.strands, seed, **moves)
        P = _faithful_closure(word, strands, n, e.name)
    if how != "braid":
        P = crumple(P, seed, **crumple_moves)
    return P
