"""Degraded records (issue 14 item 4): offsets, a junk channel, a dead axis, noise ten times the signal.

Each is either handled — the mode table still holds the true modes, and the
sidecar and a warning say what was done — or called out as not credible.
Truth from the synthetic ring (ringfit/synth/records.py), n = 1…6 and the cavity.
"""

import warnings

import numpy as np
import pytest

from ringfit.errors import InputError
from ringfit.io.records import Records
from ringfit.params import table9
from ringfit.synth.records import impact_records, ring_modes
from ringfit.targets.quality import screen_channels

ANGLES = np.arange(16) * 22.5
BAND = (20.0, 300.0)


@pytest.fixture(scope="module")
def truth():
    geometry, ring = table9()
    return ring_modes(ring, geometry, n_values=range(1, 7), seed=1)


@pytest.fixture(scope="module")
def clean(truth):
    return impact_records(truth, ANGLES, fs_hz=6400.0, duration_s=0.5, seed=2)


def _with(rec, acc):
    return Records(acc=acc, axes=rec.axes, sensor_angle_deg=rec.sensor_angle_deg, fs_hz=rec.fs_hz, force=rec.force)


def _rms(rec):
    return float(np.sqrt(np.mean(rec.acc**2)))


def _degrade(rec, how):
    acc, rms = rec.acc.copy(), _rms(rec)
    rng = np.random.default_rng(7)
    if how == "offset":  # 100x the signal on every channel (today: half the shapes become n = 0)
        acc += 100 * rms
    elif how == "junk":  # one channel records noise instead of the tyre
        acc[3, 0] = 3 * rms * rng.standard_normal(acc.shape[-1])
    elif how == "dead-axis":
        acc[:, 1] = 0.0
    elif how == "noise":  # noise ten times the signal
        acc += 10 * rms * rng.standard_normal(acc.shape)
    return _with(rec, acc)


def _identify(method, rec):
    from ringfit.targets.frf import frf_modes
    from ringfit.targets.identify import ssi_modes

    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        res = (ssi_modes(rec, f_range=BAND, orders=range(2, 81, 2)) if method == "ssi"
               else frf_modes(rec, f_range=BAND))
    return res, [str(w.message) for w in caught]


def _assert_true_modes(table, truth):
    for n, f in zip(truth.n[truth.structural()], truth.freq_hz[truth.structural()]):
        rows = np.flatnonzero((table.n == n) & (table.kind == "structural"))
        assert rows.size == 1, (n, table.n, table.freq_hz)
        assert abs(table.freq_hz[rows[0]] - f) / f < 0.003


@pytest.mark.parametrize("method", ["ssi", "frf"])
@pytest.mark.parametrize("how, said", [
    ("offset", "offset removed from 32 of 32 channels"),
    ("junk", "67.5° radial"),
    ("dead-axis", "axis 'tangential' flat on every record"),
])
def test_degraded_records_handled_and_said(truth, clean, method, how, said):
    res, warned = _identify(method, _degrade(clean, how))
    _assert_true_modes(res.table, truth)
    notes = res.table.condition["preprocessing"]
    assert any(said in n for n in notes), notes
    assert any(said in w for w in warned), warned
    assert res.table.condition["credible"] is True


@pytest.mark.parametrize("method", ["ssi", "frf"])
def test_noise_ten_times_the_signal_is_not_credible(clean, method):
    res, warned = _identify(method, _degrade(clean, "noise"))
    assert res.table.condition["credible"] is False
    assert any("not credible" in n for n in res.table.condition["preprocessing"])
    assert any("nothing credible" in w for w in warned)


def test_clean_records_no_notes(truth, clean):
    res, warned = _identify("ssi", clean)
    _assert_true_modes(res.table, truth)
    assert res.table.condition["credible"] is True and "preprocessing" not in res.table.condition
    assert warned == []


def test_frf_says_acoustic_modes_are_out_of_its_reach(clean):
    res, _ = _identify("frf", clean)
    assert not (res.table.kind == "acoustic").any()  # the cavity is in the records ...
    assert any("acoustic" in lim and "ringfit ssi" in lim for lim in res.table.condition["limits"])  # ... said so


@pytest.mark.parametrize("method", ["ssi", "frf"])
def test_all_zero_records_refused(clean, method):
    with pytest.raises(InputError, match="every acceleration channel is flat"):
        _identify(method, _with(clean, np.zeros_like(clean.acc)))


def test_screen_channels_classifies():
    t = np.arange(4000) / 1000.0
    decay = np.exp(-3 * t) * np.sin(2 * np.pi * 50 * t)
    rng = np.random.default_rng(0)
    y = np.stack([decay * (1 + 0.1 * k) + 1e-3 * rng.standard_normal(t.size) for k in range(8)])
    y[2] = 0.0  # flat
    y[5] = 0.5 * rng.standard_normal(t.size)  # junk: no decay
    y[6] = 100 * decay  # wrong gain
    y[7] = 0.01 * decay  # weak (a sensor near a node): kept
    s = screen_channels(y)
    assert s.reason.tolist() == ["", "", "flat", "", "", "junk", "scale", ""]
    assert s.credible and s.keep.sum() == 5
    noisy = screen_channels(rng.standard_normal((6, 4000)))
    assert not noisy.credible and noisy.keep.all()  # nothing dropped, but not credible
