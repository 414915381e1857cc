"""The calibrated null decides where only the acceptance rule's heuristic bars refuse (issue 21).

The shrink bar (19 % of the SS) and its bootstrap bound are fixed heuristics; a candidate that fails
only them, with a held-out shrink above the 5 % floor and every physical check met, is put to its
null (ringfit/gap/verdict.py ``null_decides``, docs/physics.md §6.4). Here the bar is raised above
any shrink a real effect can reach, on generated mode tables whose injected effect is known: with
the null the effect is still accepted (and says which bar it overruled); with the rule alone
(``null_draws=0``) it is refused; on a noise-only case nothing is accepted either way.
"""

from __future__ import annotations

import pytest

from ringfit.gap import diagnose
from ringfit.gap import verdict as V
from ringfit.synth.cases import make_case

pytestmark = pytest.mark.slow  # three diagnoses of generated mode tables (~10 s warm, ~30 s with compilation)


def _accepted(content):
    return [e for e in content["verdict"]["effects"] if e not in ("none", "unexplained")]


def test_an_injected_effect_below_a_raised_bar_is_accepted_by_its_null(tmp_path, monkeypatch):
    label = make_case(tmp_path / "contact", "ground_contact", seed=1000)
    monkeypatch.setattr(V, "MIN_HELDOUT_SHRINK_PCT", 99.99)  # no model reaches it
    d = diagnose(tmp_path / "contact", progress=False)
    assert _accepted(d.content) == [label.expected_verdict]
    best = next(c for c in d.content["candidates"] if c.get("accepted"))
    assert best["p_value"] < d.content["verdict"]["alpha"]
    assert any("heldout shrink" in w and "99.99" in w for w in best["null_overruled"])
    assert V.MIN_HELDOUT_SHRINK_FLOOR_PCT <= best["heldout_shrink_pct"] < 99.99
    rule_alone = diagnose(tmp_path / "contact", progress=False, null_draws=0)
    assert _accepted(rule_alone.content) == []


def test_noise_only_tables_get_nothing_below_a_raised_bar(tmp_path, monkeypatch):
    make_case(tmp_path / "none", "none", seed=1003)
    monkeypatch.setattr(V, "MIN_HELDOUT_SHRINK_PCT", 99.99)
    d = diagnose(tmp_path / "none", progress=False)
    assert _accepted(d.content) == []
