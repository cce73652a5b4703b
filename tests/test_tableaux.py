"""Order conditions of the Butcher tableaux (as scipy tests its own methods' coefficients).

The rooted trees are generated here (every tree of order n + 1 is a tree of order n with one more leaf),
the elementary weights computed from (A, b), and each condition b·Φ(t) = 1/γ(t) checked."""
from __future__ import annotations

import numpy as np
import pytest

from bayes_disc.physics.tableaux import TABLEAUX, get_tableau

Tree = tuple   # a rooted tree: the sorted tuple of its children's subtrees; the leaf is ()


def _grow(tree: Tree) -> set:
    """Every tree obtained by attaching one leaf to one node of ``tree`` (canonical forms)."""
    out = {tuple(sorted(tree + ((),)))}                      # a new child of the root
    for k, child in enumerate(tree):
        rest = tree[:k] + tree[k + 1:]
        for grown in _grow(child):                          # or a leaf somewhere inside a child
            out.add(tuple(sorted(rest + (grown,))))
    return out


def rooted_trees(max_order: int) -> dict[int, list]:
    """{n: all rooted trees with n nodes} for n = 1..max_order."""
    trees = {1: [()]}
    for n in range(2, max_order + 1):
        trees[n] = sorted({g for t in trees[n - 1] for g in _grow(t)})
    return trees


def order(tree: Tree) -> int:
    return 1 + sum(order(c) for c in tree)


def density(tree: Tree) -> int:
    """γ(t) = |t| Π γ(children)."""
    g = order(tree)
    for c in tree:
        g *= density(c)
    return g


def stage_weights(tree: Tree, A: np.ndarray) -> np.ndarray:
    """Φ_i(t) per stage: 1 for the leaf, Π_children (A Φ(child))_i otherwise."""
    out = np.ones(A.shape[0])
    for c in tree:
        out = out * (A @ stage_weights(c, A))
    return out


def violations(tab, n: int, trees) -> np.ndarray:
    """|b·Φ(t) − 1/γ(t)| relative to the size of the terms summed (max of 1/γ and Σ|b_i Φ_i|)."""
    out = []
    for t in trees[n]:
        phi = stage_weights(t, tab.A)
        exact = 1.0 / density(t)
        scale = max(exact, float(np.abs(tab.b * phi).sum()))
        out.append(abs(float(tab.b @ phi) - exact) / scale)
    return np.array(out)


def test_tree_generator_counts_match_cayley_sequence():
    # number of rooted trees with n nodes (OEIS A000081): an independent check of the generator
    assert [len(v) for v in rooted_trees(9).values()] == [1, 1, 2, 4, 9, 20, 48, 115, 286]
    assert all(order(t) == n for n, ts in rooted_trees(6).items() for t in ts)
    assert density(((), ())) == 3 and density((((),),)) == 6


@pytest.mark.parametrize("name", sorted(TABLEAUX))
def test_row_sums_and_explicit(name):
    tab = get_tableau(name)
    assert tab.A.shape == (tab.stages, tab.stages)
    assert np.all(np.triu(tab.A) == 0.0), "explicit methods have a strictly lower-triangular A"
    np.testing.assert_allclose(tab.A.sum(axis=1), tab.c, rtol=1e-12, atol=1e-14)


@pytest.mark.parametrize("name", sorted(TABLEAUX))
def test_order_conditions_hold_up_to_claimed_order(name):
    tab = get_tableau(name)
    trees = rooted_trees(tab.order)
    for n in range(1, tab.order + 1):
        v = violations(tab, n, trees)
        assert v.max() < 1e-12, f"{name}: order-{n} condition violated by {v.max():.2e} (relative)"


@pytest.mark.parametrize("name", sorted(TABLEAUX))
def test_next_order_conditions_fail(name):
    """The claimed order is the order: some condition of order p + 1 does not hold."""
    tab = get_tableau(name)
    v = violations(tab, tab.order + 1, rooted_trees(tab.order + 1))
    assert v.max() > 1e-6, f"{name}: all order-{tab.order + 1} conditions hold; the claimed order is too low"


def test_unknown_method_is_an_error():
    with pytest.raises(ValueError, match="unknown integration method 'rk5'.*known"):
        get_tableau("rk5")
