"""The new (unworn) tread's depth as the bound on the estimated tread depth (docs/physics.md §13.3–13.4 *the new
tread's bound*; docs/formats.md §1 ``tread_depth_new_mm``): the tyre file's key, its checks, the example's tyre
files, and the estimate held within it.
"""

from __future__ import annotations

import math

import numpy as np
import pytest

from ringfit.errors import InputError
from ringfit.fit.estimate.state import TREAD, estimate_state, new_tread_depth
from ringfit.io.profiles import Profile, grid_angles_deg
from ringfit.io.tyre import read_tyre, write_tyre
from ringfit.params import TyreLaws, table9
from ringfit.physics.profile import ProfileModel
from ringfit.physics.sensor import STANDARD_GRAVITY
from ringfit.physics.state import TyreState, solve_state

GEO, RING = table9()
OMEGA = 2 * math.pi * 12.0
SENSOR = ProfileModel().with_sensor(gravity=STANDARD_GRAVITY, tilt_gain=0.8, corner_hz=0.5)

TYRE = """[tyre]
radius_m = 0.296
width_m = 0.152
pressure_bar = 2.2
{extra}
[ring]
kx_n_per_m2 = 15e6
"""


def _write(tmp_path, extra):
    p = tmp_path / "t.toml"
    p.write_text(TYRE.format(extra=extra))
    return p


def test_the_tyre_file_states_the_new_tread_depth(tmp_path):
    t = read_tyre(_write(tmp_path, "tread_depth_mm = 6.0\ntread_depth_new_mm = 8.5"))
    assert t.laws.tread_depth_new == pytest.approx(8.5e-3, rel=1e-15)
    assert t.laws.tread_depth_ref == pytest.approx(6.0e-3, rel=1e-15)
    assert new_tread_depth(t.laws) == pytest.approx(8.5e-3, rel=1e-15)
    back = read_tyre(write_tyre(t, tmp_path / "back.toml"))  # round trip
    assert back.laws.tread_depth_new == pytest.approx(8.5e-3, rel=1e-15)
    # absent: no bound
    plain = read_tyre(_write(tmp_path, "tread_depth_mm = 6.0"))
    assert plain.laws.tread_depth_new is None and new_tread_depth(plain.laws) is None
    assert new_tread_depth(TyreLaws(tread_depth_new=0.008)) is None  # no tread law: the depth is not estimated


@pytest.mark.parametrize("extra, match", [
    ("tread_depth_mm = 8.0\ntread_depth_new_mm = 7.0", "tread_depth_new_mm = 7 is below tread_depth_mm = 8"),
    ("tread_depth_new_mm = 8.0", "tread_depth_new_mm needs tread_depth_mm"),
    ("tread_depth_mm = 8.0\ntread_depth_new_mm = 60.0", "tread_depth_new_mm"),
    ("tread_depth_mm = 8.0\ntread_depth_new_mm = 0.0", "tread_depth_new_mm"),
])
def test_a_new_tread_depth_that_cannot_be_is_refused(tmp_path, extra, match):
    with pytest.raises(InputError, match=match):
        read_tyre(_write(tmp_path, extra))


def test_the_examples_tyre_files_state_the_new_tread(tmp_path):
    """`ringfit example state`'s tyre files (nominal and true) say 8 mm: the blind depths are drawn from 2–8 mm."""
    from ringfit.synth.state import jittered_tyre, nominal_tyre

    for tyre in (nominal_tyre(), jittered_tyre(np.random.default_rng(5))):
        t = read_tyre(write_tyre(tyre.tyre_file("x"), tmp_path / "x.toml", overwrite=True))
        assert t.laws.tread_depth_new == pytest.approx(0.008, rel=1e-12)


def test_a_stated_depth_deeper_than_the_new_tread_is_refused():
    laws = TyreLaws(tread_depth_ref=0.008, tread_depth_new=0.008, k_x=15e6, has_tread_depth=True, has_brush=True)
    ch = np.ones((2, 64))
    prof = Profile(grid_angles_deg(64), ch[0], ch[1], condition={"rotation_hz": 12.0}, source="x")
    with pytest.raises(InputError, match="deeper than the tyre file's new tread"):
        estimate_state(prof, GEO, RING, laws, fixed={TREAD: 0.0085})


@pytest.mark.slow
def test_a_fit_that_goes_deeper_than_the_new_tread_is_held_within_it():
    """The forward model at a 10 mm tread on a tyre file whose new tread is 8 mm (the bound made active on
    purpose): without the key the estimate's depth is near 10 mm; with it the depth is 8 mm, on the bound, its
    95 % interval below it, and the estimate says so."""
    laws = TyreLaws(tread_depth_ref=0.008, k_x=15e6, kw_share=0.5, kv_share=0.3, has_tread_depth=True,
                    has_brush=True)
    truth = TyreState(4000.0, 2.2e5, 0.010, 0.004, OMEGA)
    _, ch, _ = solve_state(GEO, RING, laws, truth, model=SENSOR)
    rng = np.random.default_rng(11)
    ch = ch + np.array([[0.2], [0.03]]) * rng.standard_normal(ch.shape)
    prof = Profile(grid_angles_deg(ch.shape[-1]), ch[0], ch[1],
                   condition={"speed_kmh": 50.0, "rotation_hz": OMEGA / (2 * math.pi)}, source="synthetic")
    free = estimate_state(prof, GEO, RING, laws)
    assert free.value("tread_depth_mm") == pytest.approx(10.0, abs=0.5)  # the premise: the data say 10 mm
    bounded = estimate_state(prof, GEO, RING, laws.replace(tread_depth_new=0.008), load=free.load)
    Q = bounded.quantities["tread_depth_mm"]
    assert Q["value"] == pytest.approx(8.0, rel=1e-9)
    assert Q["hi"] <= 8.0 * (1 + 1e-9) and Q["lo"] < Q["hi"]
    assert Q["status"] == "estimated"
    assert any("tread_depth_new_mm" in f for f in bounded.flags)
    assert bounded.ridge.depth.max() == pytest.approx(0.008, rel=1e-9)  # the slices end at the new tread
    # every revolution keeps the depth's uncertainty below the bound (held on it, the depth is no parameter of the
    # fit: its revolutions' interval had collapsed to [8, 8] mm)
    from ringfit.fit.estimate.state import profile_rows, state_revolutions
    from ringfit.fit.estimate.problem import EstimateSettings

    rows = np.stack([profile_rows(Profile(prof.angle_deg, *(ch + np.array([[0.5], [0.08]]) * rng.standard_normal(
        ch.shape))), EstimateSettings().n_grid, bounded.k_max) for _ in range(6)])  # six revolutions about it
    revs = state_revolutions(rows, np.full(6, OMEGA / (2 * math.pi)), bounded)
    assert np.all(revs.hi["tread_depth_mm"] <= 8.0 * (1 + 1e-9))
    assert np.all(revs.lo["tread_depth_mm"] < revs.hi["tread_depth_mm"])
    assert revs.lo["tread_depth_mm"] == pytest.approx(np.full(6, Q["lo"]), rel=1e-12)  # the averaged marginal
    assert np.all(revs.hi["load_n"] > revs.lo["load_n"])


def test_the_cli_refuses_a_fixed_depth_deeper_than_the_new_tread(tmp_path, capsys):
    from ringfit.cli import main
    from ringfit.io.profiles import write_profile

    from ringfit.data import path as data_path

    tyre = write_tyre(read_tyre(data_path("table9.tyre.toml")).with_state_values(
        tread_depth_mm=7.0, tread_depth_new_mm=8.0, kx_n_per_m2=15e6), tmp_path / "t9.toml")
    angle = grid_angles_deg(64)
    write_profile(Profile(angle, np.cos(np.radians(angle)), np.sin(np.radians(angle)), condition={"speed_kmh": 50.0}),
                  tmp_path / "p.profile.csv")
    out = tmp_path / "p.estimate.json"
    code = main(["estimate", str(tmp_path / "p.profile.csv"), "--tyre", str(tyre), "--out", str(out), "--state",
                 "--fix", "tread_depth_mm=8.5"])
    assert code == 2
    err = capsys.readouterr().err
    assert "deeper than the tyre file's new tread (tread_depth_new_mm = 8)" in err
    assert len(err.strip().splitlines()) == 1
    assert not out.exists()


def test_tyre_files_differing_only_in_the_new_tread_share_one_compilation():
    """``TyreLaws.tread_depth_new`` is traced like the other laws (issue 31: no recompile per tyre file): a jitted
    function of the laws traces once for three new-tread depths, and a second time only for a file without one
    (another structure)."""
    import equinox as eqx

    from ringfit.physics.contact import as_traced

    @eqx.filter_jit
    @eqx.debug.assert_max_traces(max_traces=2)
    def twice(laws):
        return 2.0 * laws.tread_depth_ref

    for d_new in (0.008, 0.009, 0.010, None, None):
        twice(as_traced(TyreLaws(tread_depth_ref=0.007, has_tread_depth=True, tread_depth_new=d_new)))
