"""Timing faults (issue 34): stalled streams, drift, one sensor angle, a mode found twice.

The detectors are checked against hand-made signals whose truth is known by construction (repeats inserted or
held at chosen samples, a ramp added to a decay), and for false alarms on many random clean records, quantised
ones included.
"""

import numpy as np
import pytest

from ringfit.errors import InputError
from ringfit.params import table9
from ringfit.synth.records import degrade, impact_records, ring_modes
from ringfit.targets.faults import (chance_repeats, repair_stalls, repair_timing,
                                    stall_verdict, stalled_frames)
from ringfit.targets.identify import classify_rows, found_twice
from ringfit.targets.preprocessing import check_angles
from ringfit.targets.quality import remove_drift


def _decay(fs=3200.0, seconds=0.4, seed=0, axes=2):
    rng = np.random.default_rng(seed)
    t = np.arange(int(fs * seconds)) / fs
    x = np.stack([np.exp(-8 * t) * (np.sin(2 * np.pi * 120 * t + k) + 0.5 * np.sin(2 * np.pi * 210 * t + 2 * k))
                  for k in range(axes)])
    return x + 0.002 * rng.standard_normal(x.shape)


def _insert(x, at, length):
    """Repeats of the frames ``at`` (``length`` copies each) inserted, cut back to the length."""
    idx = []
    for k in range(x.shape[-1]):
        idx.append(k)
        if k in at:
            idx += [k] * length
    return x[:, np.array(idx[:x.shape[-1]])]


def test_stalled_frames_finds_exactly_the_inserted_repeats():
    x = _decay()
    at = [100, 400, 401 + 7, 900]
    y = _insert(x, set(at), 2)
    found = np.flatnonzero(stalled_frames(y))
    want, shift = [], 0
    for k in at:  # each inserted run sits right after its frame, the later ones shifted by the earlier runs
        want += [k + shift + 1, k + shift + 2]
        shift += 2
    assert found.tolist() == want


def test_stalled_frames_ignore_one_axis_repeating_and_a_zero_pre_trigger():
    x = _decay()
    y = x.copy()
    y[0, 500] = y[0, 499]  # one axis only: not a frame repeat
    y[:, :50] = 0.0  # a noise-free pre-trigger
    assert not stalled_frames(y).any()


def test_verdict_and_repair_inserted_repeats_restore_the_time_base():
    x = _decay()
    rng = np.random.default_rng(1)
    at = set(rng.choice(np.arange(10, 1200), 60, replace=False).tolist())
    y = _insert(x, at, 2)
    acc = np.stack([y, y])  # two records
    stalls = np.stack([stalled_frames(a) for a in acc])
    u, spread = stall_verdict(acc, stalls)
    assert u < 0.35 and spread > 1.2
    fixed, _, notes, credible = repair_stalls(acc, None, 3200.0)
    assert credible and "repeats deleted" in notes[0]
    n = fixed.shape[-1]
    np.testing.assert_array_equal(fixed[0], x[:, :n])  # exactly the samples before the stall


def test_verdict_and_repair_held_samples_bridged():
    x = _decay()
    y = x.copy()
    rng = np.random.default_rng(2)
    held = np.sort(rng.choice(np.arange(20, 1200, 5), 80, replace=False))
    y[:, held] = y[:, held - 1]  # one-sample holds: the sample lost
    acc = np.stack([y, y])
    u, _ = stall_verdict(acc, np.stack([stalled_frames(a) for a in acc]))
    assert u > 0.65
    fixed, _, notes, credible = repair_stalls(acc, None, 3200.0)
    assert credible and "bridged" in notes[0] and fixed.shape == acc.shape
    mid = 0.5 * (x[:, held - 1] + x[:, held + 1])  # the straight line between the neighbours, by hand
    np.testing.assert_allclose(fixed[0][:, held], mid, atol=1e-12)


def test_ruined_stream_is_not_credible():
    x = _decay()
    y = _insert(x, set(range(10, 1200, 2)), 1)  # a third of the samples repeated
    _, _, notes, credible = repair_stalls(np.stack([y, y]), None, 3200.0)
    assert not credible and "not credible" in notes[0]


def test_no_stall_on_random_clean_records_float_or_quantised():
    """24 random clean record sets (3 rates, 1 or 2 axes, float or 12/16-bit): no stall said."""
    geometry, ring = table9()
    said = 0
    for seed in range(24):
        truth = ring_modes(ring, geometry, n_values=range(1, 7), seed=seed)
        rec = impact_records(truth, np.arange(8) * 45.0, impacts_per_angle=2, fs_hz=(3200.0, 6400.0, 25600.0)[seed % 3],
                             duration_s=0.3, noise=0.005 + 0.01 * (seed % 3), seed=200 + seed)
        acc = rec.acc[:, : 1 + seed % 2]
        bits = (None, 12, 16)[(seed // 2) % 3]
        if bits:
            q = 2 * np.abs(acc).max() / 2**bits
            acc = np.round(acc / q) * q
        said += bool(repair_stalls(acc, rec.force, rec.fs_hz)[2])
    assert said == 0


def test_stall_found_on_random_degraded_records():
    """12 random draws of each stall kind: found every time, repaired the right way."""
    geometry, ring = table9()
    truth = ring_modes(ring, geometry, n_values=range(1, 7), seed=0)
    base = impact_records(truth, np.arange(8) * 45.0, impacts_per_angle=2, fs_hz=3200.0, duration_s=0.3, seed=5)
    for seed in range(12):
        for how, word in (("stalled", "repeats deleted"), ("held", "bridged")):
            _, notes, credible = repair_timing(degrade(base, how, seed=seed))
            assert credible and notes and word in notes[0], (seed, how, notes)


def test_chance_repeats_of_a_coarse_converter():
    """A 1-LSB-noise signal repeats about as often as the closed form for a rounded Gaussian step says."""
    rng = np.random.default_rng(3)
    x = np.round(3.0 * rng.standard_normal((1, 20000)))  # steps of spread 3√2 LSB
    observed = int(np.sum(np.diff(x[0]) == 0))
    assert chance_repeats(x) == pytest.approx(observed, rel=0.35)


def test_drift_removed_and_said_clean_untouched():
    x = _decay()[None]  # (1 record, 2 axes, samples)
    t = np.linspace(0, 1, x.shape[-1])
    ramp = 0.8 * t + 0.3 * t**2
    out, note = remove_drift(x + ramp)
    assert note is not None and "drift in 2 of 2 channels" in note
    resid = out - x
    # what is left of the ramp (and what the fit took of the decay): a few % of the ramp's 1.1 rise
    assert np.ptp(resid, axis=-1).max() < 0.05 * 1.1
    same, none = remove_drift(x)
    assert none is None and same is x


def test_no_drift_said_on_random_clean_records():
    geometry, ring = table9()
    for seed in range(12):
        truth = ring_modes(ring, geometry, n_values=range(1, 8), seed=seed)
        rec = impact_records(truth, np.arange(8) * 45.0, impacts_per_angle=2, fs_hz=(3200.0, 6400.0, 25600.0)[seed % 3],
                             duration_s=0.4, noise=0.01 + 0.01 * (seed % 4), seed=100 + seed)
        assert remove_drift(rec.acc)[1] is None, seed


@pytest.mark.parametrize("angles", [[30.0] * 4, [30.0, 390.0, -330.0, 30.0]])
def test_one_sensor_angle_refused(angles):
    with pytest.raises(InputError, match="one sensor angle 30°.*cannot be told"):
        check_angles(np.array(angles))


def test_two_angles_refused_three_pass():
    with pytest.raises(InputError, match="only two sensor angles, 0° and 45°"):
        check_angles(np.array([0.0, 360.0, 45.0]))
    check_angles(np.array([0.0, 0.0, 45.0, 90.0]))


def test_found_twice_pairs_a_non_structural_row_with_its_structural_twin():
    freq = np.array([218.75, 227.70, 227.91, 258.98])
    kind = np.array(["acoustic", "acoustic", "structural", "structural"], dtype=object)
    assert found_twice(freq, kind) == [(1, 2)]  # 0.09 % apart; the cavity 4 % away is its own row
    assert found_twice(freq, kind, skip=np.array([False, True, False, False])) == []  # a hum residue is not the mode


def test_acoustic_rows_say_why():
    kind, reason = classify_rows(np.array([1, 6]), np.array([0.9, 0.95]), np.array([219.0, 227.9]),
                                 np.array([True, False]), 218.75)
    assert list(kind) == ["acoustic", "structural"]
    assert "cavity" in reason[0] and "+0.1 %" in reason[0] and reason[1] == ""


def _drum_frames(idx, seconds=3.0):
    from bad_input_cases import _drum_record
    from ringfit.io.continuous import ContinuousRecord

    rec = _drum_record(seconds=seconds)
    return ContinuousRecord(acc=rec.acc[:, idx], axes=rec.axes, fs_hz=rec.fs_hz,
                            encoder_angle_deg=rec.encoder_angle_deg[idx], hall=rec.hall[idx],
                            hall_delay_s=rec.hall_delay_s, condition=rec.condition), rec.samples


@pytest.mark.parametrize("how", ["clean", "inserted", "held", "dropped"])
def test_profile_counts_the_time_a_faulty_stream_covers(how):
    """A drum recording turning at 10 Hz (stated rotation_hz 10): stalls and dropped samples are said, the
    rotation rate stays 10 Hz (not a false sampling-rate contradiction)."""
    import warnings

    from ringfit.targets.rolling_profile import rolling_profile

    s = 6000
    rng = np.random.default_rng(7)
    if how == "inserted":
        idx, k = [], 0
        while len(idx) < s:
            idx.append(k)
            if rng.random() < 0.1 / 3:
                idx += [k] * int(rng.integers(1, 6))
            k += 1
        idx = np.array(idx[:s])
    elif how == "held":
        idx, k = np.arange(s), 1
        while k < s:
            if rng.random() < 0.05:
                run = int(rng.integers(1, 4))
                idx[k:k + run] = idx[k - 1]
                k += run
            k += 1
    elif how == "dropped":
        idx = np.sort(rng.choice(s, int(0.95 * s), replace=False))
    else:
        idx = np.arange(s)
    rec, n = _drum_frames(idx)
    assert n == s
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        p = rolling_profile(rec, points=64)
    said = [str(w.message) for w in caught]
    assert p.rotation_hz == pytest.approx(10.0, rel=0.005)
    assert not any("contradicts" in m for m in said)
    if how == "clean":
        assert not said
    else:
        word = {"inserted": "stalled stream", "held": "dropped", "dropped": "dropped"}[how]
        assert len(said) == 1 and "timing faults" in said[0] and word in said[0]


def _twin_case(twin_n, twin_hz=227.70, half_hz=228.16, orders=(10, 12, 14, 16), twin_zeta=0.025):
    """Hand-made SSI poles at 16 radial angles: ring modes n = 1…5 (109.9…198.3 Hz), 6 and 7 (259.0 Hz), the
    cavity (an n = 1 pattern at 218.75 Hz, lightly damped), and the n = 6 double pole resolved at every order
    into a half with the n = 6 shape at ``half_hz`` and a half whose shape reads as n = ``twin_n`` (what a
    notch or noise left of it) at ``twin_hz``, damped ``twin_zeta``: the pair's centre is their mean."""
    from ringfit.targets.clustering import summarize
    from ringfit.targets.ssi import PoleSet

    th = np.arange(16) * 2 * np.pi / 16
    axis = np.full(16, "radial", dtype=object)
    rng = np.random.default_rng(5)

    def shape(k, weak6=0.0):
        v = np.cos(k * th + 0.3) + weak6 * np.cos(6 * th) + 0.02 * rng.standard_normal(16)
        return v / np.linalg.norm(v)

    members = [(109.9, 0.025, 1, 0.0), (125.2, 0.025, 2, 0.0), (145.9, 0.025, 3, 0.0), (170.8, 0.025, 4, 0.0),
               (198.3, 0.025, 5, 0.0), (218.75, 0.007, 1, 0.0), (half_hz, 0.025, 6, 0.0),
               (twin_hz, twin_zeta, twin_n, 0.35), (259.0, 0.025, 7, 0.0)]
    order, f, z, phi, group = [], [], [], [], []
    for g, (fm, zm, k, weak6) in enumerate(members):
        for o in orders:
            order.append(o), f.append(fm * (1 + 1e-5 * rng.standard_normal())), z.append(zm)
            phi.append(shape(k, weak6).astype(complex)), group.append(g)
    f, z = np.array(f), np.array(z)
    lam = -z * 2 * np.pi * f + 1j * 2 * np.pi * f * np.sqrt(1 - z**2)
    poles = PoleSet(order=np.array(order), freq_hz=f, damping=z, lam=lam, shape=np.array(phi),
                    orders=np.array(orders), singular_values=np.ones(4))
    group = np.array(group)
    modes = [summarize(poles, np.flatnonzero(group == g)) for g in range(len(members))]
    return poles, modes, th, axis


@pytest.mark.parametrize("twin_n", [1, 6, 7])
def test_a_double_pole_is_one_row_whatever_n_its_twin_reads(twin_n):
    """Issue 34 item 7: the two halves of the n = 6 double pole, one read as n = 1 (near the cavity frequency:
    it passed for the cavity), as n = 7 (a tie in the ring's order with n = 6 itself) or as n = 6, make one structural row at the pair's centre with its split; the
    cavity 4 % away stays its own acoustic row."""
    from ringfit.targets.identify import mode_table

    poles, modes, th, axis = _twin_case(twin_n)
    notes = []
    table, _ = mode_table(modes, th, axis, "ssi-cov", poles=poles, cavity_hz=218.75, notes=notes)
    near = np.flatnonzero(np.abs(table.freq_hz / 227.93 - 1) < 0.01)
    assert near.size == 1, list(zip(table.kind, table.freq_hz))
    i = int(near[0])
    assert table.kind[i] == "structural" and table.n[i] == 6
    assert abs(table.freq_hz[i] - (227.70 + 228.16) / 2) < 0.01  # the pair's centre, not one half
    assert abs(float(table.extra["split_hz"][i]) - 0.46) < 0.01
    assert list(table.n[table.kind == "structural"]) == [1, 2, 3, 4, 5, 6, 7]
    cav = np.flatnonzero(table.kind == "acoustic")
    assert cav.size == 1 and abs(table.freq_hz[cav[0]] - 218.75) < 0.01
    assert any("found twice" in s and "227.70" in s for s in notes) == (twin_n != 6)


def test_a_twin_outside_the_fixed_tolerance_but_within_the_modes_spread_is_merged():
    """A twin 0.7 % from its half (beyond TWICE_TOL) whose own frequencies spread over the orders by more than
    that is still the same double pole (the pole's own uncertainty), never a second row."""
    from ringfit.targets.identify import mode_table

    poles, modes, th, axis = _twin_case(1, twin_hz=226.55, half_hz=228.16)
    twin = modes[7].pole_index
    poles.freq_hz[twin] += np.array([-0.8, 0.8, -0.8, 0.8])  # σ over the orders ≈ 0.9 Hz
    from ringfit.targets.clustering import summarize

    modes[7] = summarize(poles, twin)
    table, _ = mode_table(modes, th, axis, "ssi-cov", poles=poles, cavity_hz=218.75, notes=[])
    near = np.flatnonzero(np.abs(table.freq_hz / 227.4 - 1) < 0.01)
    assert near.size == 1 and table.kind[near[0]] == "structural" and table.n[near[0]] == 6


def test_a_lightly_damped_row_beside_a_mode_is_dropped_not_averaged_in():
    """A not-ring-like row at 0.1 % of the n = 6 mode but damped 0.4 % against its 2.5 % (what a notch leaves of
    a hum line, not the pair's other half) is still no second row, and its poles do not move the mode."""
    from ringfit.targets.identify import mode_table

    poles, modes, th, axis = _twin_case(1, twin_zeta=0.004)
    table, _ = mode_table(modes, th, axis, "ssi-cov", poles=poles, cavity_hz=218.75, notes=[])
    near = np.flatnonzero(np.abs(table.freq_hz / 228.0 - 1) < 0.01)
    assert near.size == 1 and table.n[near[0]] == 6
    assert abs(table.freq_hz[near[0]] - 228.16) < 0.01 and abs(table.damping_pct[near[0]] - 2.5) < 0.01


def test_a_ring_mode_read_as_n1_near_the_cavity_is_not_called_acoustic():
    """The n = 6 mode whose only row reads n = 1 (the hum left its shape so) 4 % from eq. 22's cavity frequency:
    damped like the ring (2.5 %), it is not the air (the cavity row, 0.7 %, stays acoustic); it is unclassified
    and says why."""
    from ringfit.targets.identify import mode_table

    poles, modes, th, axis = _twin_case(1)
    del modes[6]  # the half with the n = 6 shape: never clustered
    table, _ = mode_table(modes, th, axis, "ssi-cov", poles=poles, cavity_hz=218.75, notes=[])
    i = int(np.argmin(np.abs(table.freq_hz - 227.70)))
    assert abs(table.freq_hz[i] - 227.70) < 0.01 and table.kind[i] == "unclassified"
    assert "damped like the ring (2.50 %" in table.extra["reason"][i]
    assert list(table.freq_hz[table.kind == "acoustic"].round(2)) == [218.75]
