"""The rule that chooses the rolling rows' model structure (issue 20; docs/physics.md §6.4):
``ringfit.gap.rolling_rows.structure_loglik``, a mixture over each structure's lines with the line prior
normalised over the lines within the table's span.

Expected values come from outside the rule: rows placed on one structure's lines must choose it, and extra
lines away from the rows cost their density in closed form (2 ln(L'/L) per row), which the naive total
nearest-line cost cannot see. (On uniformly random tables a proper likelihood prefers the structure whose
mixture is nearer uniform, i.e. the denser one; the random-line null repeats the choice per draw, so that
preference is inside the null — tests/test_gap_calibration.py, benchmarks/bench_gap_calibration.py.)"""

import numpy as np

from ringfit.gap.rolling_rows import TOLERANCE_GRID, structure_loglik

LO, HI = 80.0, 480.0


def _cost(f, hz, pen=None):
    """−2 max_τ ln L of rows ``f`` (B, r) on lines ``hz`` (no labels, unit weights, no measurement σ)."""
    r = f.shape[-1]
    pen = np.zeros((r, hz.size)) if pen is None else pen
    return -2.0 * np.max(structure_loglik(f, np.zeros(r), hz, np.ones(hz.size), pen, LO, HI), axis=-1)


def _structures(rng):
    sparse = np.sort(rng.uniform(LO, HI, 20))
    dense = np.sort(rng.uniform(LO, HI, 80))
    return sparse, dense


def test_rows_on_a_structures_lines_choose_it():
    rng = np.random.default_rng(0)
    for _ in range(20):
        sparse, dense = _structures(rng)
        for own, other in ((sparse, dense), (dense, sparse)):
            f = rng.choice(own, 12, replace=False) * (1 + 0.001 * rng.standard_normal(12))
            assert _cost(f[None], own)[0] < _cost(f[None], other)[0]


def test_extra_lines_away_from_the_rows_cost_their_density():
    """Rows on lines two structures share: the structure with 3 extra lines per gap (4× the lines, none near
    a row) pays 2 ln 4 per row — the line prior normalised over the span — whereas the naive total
    nearest-line cost cannot tell the two apart (every row's nearest line is the same)."""
    rng = np.random.default_rng(1)
    sparse = np.linspace(100.0, 460.0, 20)
    gaps = np.diff(sparse)
    extra = np.concatenate([sparse[:-1] + q * gaps for q in (0.25, 0.5, 0.75)])
    dense = np.sort(np.concatenate([sparse, extra, [470.0, 475.0, 478.0]]))  # 80 lines
    assert dense.size == 4 * sparse.size
    f = rng.choice(sparse, 12, replace=False) * (1 + 0.0005 * rng.standard_normal(12))
    diff = _cost(f[None], dense)[0] - _cost(f[None], sparse)[0]
    expected = 2 * 12 * np.log(4.0)
    assert 0.9 * expected < diff < 1.01 * expected, (diff, expected)
    def naive(hz):
        return np.sum(np.min(((f[:, None] - hz) / (0.02 * hz)) ** 2, axis=-1))
    assert abs(naive(dense) - naive(sparse)) < 1e-9


def test_a_contradicted_label_costs_its_penalty():
    """A row labelled with an n that no line near it has: the label penalty (exp(−P/2) on every near line)
    moves the cost by P when one line dominates."""
    hz = np.array([100.0, 200.0, 300.0])
    f = np.array([[200.0]])
    c0 = _cost(f, hz)
    c4 = _cost(f, hz, pen=np.array([[0.0, 4.0, 0.0]]))
    # the row is 100 Hz from the other lines: only the background and the penalised line remain
    assert c4[0] > c0[0] + 3.0
    assert TOLERANCE_GRID[0] < TOLERANCE_GRID[-1]
