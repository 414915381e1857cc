"""Synthetic records with known modes -> SSI / FRF mode tables -> ring fit (issue 3, items 8 and 10)."""

import numpy as np
import pytest

from ringfit.params import table9
from ringfit.synth.records import impact_records, ring_modes

ANGLES = np.arange(24) * 15.0


@pytest.fixture(scope="module")
def truth():
    geometry, ring = table9()
    return geometry, ring, ring_modes(ring, geometry, seed=1)


@pytest.fixture(scope="module")
def records(truth):
    return impact_records(truth[2], ANGLES, impacts_per_angle=3, sensor_delay_s=0.4e-3, seed=2)


def _check_table(table, modes, damping_tol=0.15):
    struct = modes.structural()
    for n, f, z in zip(modes.n[struct], modes.freq_hz[struct], modes.damping[struct]):
        rows = np.flatnonzero((table.n == n) & (table.kind == "structural"))
        assert rows.size == 1, f"n={n}: {rows.size} rows"
        i = rows[0]
        assert abs(table.freq_hz[i] - f) / f < 0.003, (n, table.freq_hz[i], f)
        assert abs(table.damping_pct[i] / 100 - z) / z < damping_tol, (n, table.damping_pct[i], z)
    assert set(table.n[table.kind == "structural"]) == set(modes.n[struct])


def test_ssi_recovers_modes_and_flags_cavity(truth, records):
    from ringfit.targets.identify import ssi_modes

    from ringfit.physics.natural import cavity_frequency

    res = ssi_modes(records, delay_s=0.4e-3, cavity_hz=float(cavity_frequency(1)))
    _check_table(res.table, truth[2])
    cav = truth[2].freq_hz[truth[2].kind == "acoustic"][0]
    ac = np.flatnonzero(res.table.kind == "acoustic")
    assert ac.size == 1 and abs(res.table.freq_hz[ac[0]] - cav) / cav < 0.003
    assert np.all(res.table.freq_std_hz > 0)
    # pair-aware shape check keeps at least the poles the plain MAC keeps
    st = res.stability
    assert np.sum(st.label == 2) >= np.sum((st.source_label == 2) & (st.plain_mac >= 0.9))


def test_frf_recovers_modes_and_rejects_bad_impact(truth, records):
    from ringfit.targets.frf import frf_modes

    bad = records.acc.copy()
    bad[4] += 30 * bad[4].std() * np.random.default_rng(5).standard_normal(bad[4].shape)
    from ringfit.io.records import Records

    rec = Records(acc=bad, axes=records.axes, sensor_angle_deg=records.sensor_angle_deg, fs_hz=records.fs_hz,
                  force=records.force)
    res = frf_modes(rec, delay_s=0.4e-3)
    assert not res.frf.kept[4] and res.frf.kept.sum() >= rec.n_records - 3
    _check_table(res.table, truth[2])


def test_travelling_pairs_and_n():
    """Pure counter-rotating waves: measure near 1; standing: near 0 (shape-level truth)."""
    from ringfit.targets.shapes import mode_number, travelling_measure

    th = np.deg2rad(np.repeat(ANGLES, 2))
    axis = np.tile(np.array(["radial", "tangential"], dtype=object), ANGLES.size)
    for n in (1, 4, 9):
        wave = np.where(axis == "radial", np.exp(1j * n * th), 1j * np.exp(1j * n * th) / n)
        stand = np.where(axis == "radial", np.cos(n * th), -np.sin(n * th) / n)
        assert travelling_measure(wave, th, axis, n) > 0.99
        assert travelling_measure(stand, th, axis, n) < 1e-9
        k, conf = mode_number(np.stack([stand, np.roll(stand, 3)], 1), th, axis)
        assert k == n and conf > 0.99


def test_real_shape_rules():
    from ringfit.targets.shapes import real_shape_principal, real_shape_source

    th = np.deg2rad(ANGLES)
    v = np.cos(3 * th) * np.exp(1j * 0.7)  # a standing wave with an arbitrary phase
    assert np.allclose(np.abs(real_shape_principal(v)), np.abs(np.cos(3 * th)), atol=1e-12)
    r = real_shape_source(v)
    assert np.allclose(np.abs(r), np.abs(v)) and np.all(np.sign(r) == np.sign(np.cos(3 * th)) * np.sign(np.sin(0.7)))


def test_acoustic_candidates_order_rule():
    from ringfit.targets.shapes import acoustic_candidates

    n = np.array([1, 2, 3, 1, 4, 5])
    f = np.array([100, 120, 140, 150, 165, 190.0])
    flag = acoustic_candidates(n, np.full(6, 0.9), f)
    assert flag.tolist() == [False, False, False, True, False, False]
    assert acoustic_candidates(n, np.array([0.9, 0.9, 0.3, 0.9, 0.9, 0.9]), f)[2]


def test_align_removes_delay_and_finds_impact(truth):
    from ringfit.targets.preprocessing import align_on_impact

    rec = impact_records(truth[2], [0.0, 90.0], fs_hz=25600, duration_s=0.3, sensor_delay_s=1e-3,
                         noise=0.0, force_noise=0.0, trigger_jitter_s=0.01, seed=3)
    ref = impact_records(truth[2], [0.0, 90.0], fs_hz=25600, duration_s=0.3, sensor_delay_s=0.0,
                         noise=0.0, force_noise=0.0, trigger_jitter_s=0.0, seed=3)
    a, _ = align_on_impact(rec, delay_s=1e-3)
    b, _ = align_on_impact(ref)
    m = min(a.shape[-1], b.shape[-1]) - 2000
    # same free decay after alignment (the jitter is sub-sample, so compare with a loose tolerance)
    assert np.max(np.abs(a[..., 400:m] - b[..., 400:m])) < 0.05 * np.max(np.abs(b[..., 400:m]))


def test_group_velocity_sync_on_pulse_train():
    """Non-dispersive pulses running both ways round a ring: sync recovers the impact time."""
    from ringfit.io.records import Records
    from ringfit.targets.preprocessing import group_velocity, round_trip_time, sync_by_group_velocity

    fs, radius, t_cycle = 20000.0, 0.3, 0.012
    v = group_velocity(radius, t_cycle)
    assert v == pytest.approx(2 * np.pi * 0.3 / 0.012)
    t = np.arange(int(0.2 * fs)) / fs
    angles = np.array([0.0, 40.0, 100.0, -150.0])
    t0 = np.array([0.010, 0.017, 0.023, 0.031])  # unknown impact time in each record
    acc = np.zeros((4, 1, t.size))
    for r, (a, s) in enumerate(zip(np.deg2rad(angles), t0)):
        for k in range(12):
            for arc in (abs(a) + 2 * np.pi * k, 2 * np.pi * (k + 1) - abs(a)):
                acc[r, 0] += np.exp(-0.5 * ((t - s - radius * arc / v) / 2e-4) ** 2) * np.exp(-arc / 20)
    rec = Records(acc=acc, axes=("radial",), sensor_angle_deg=angles, fs_hz=fs)
    assert round_trip_time(acc[0], fs) == pytest.approx(t_cycle, rel=0.01)
    out, tc = sync_by_group_velocity(rec, radius)
    # after sync every record starts at its own impact time: the first pulse sits at R|θ|/v
    first = np.argmax(out[:, 0, :], axis=1) / fs
    assert np.allclose(first, radius * np.abs(np.deg2rad(angles)) / v, atol=2 / fs)


def test_decimation_rejects_alias():
    from ringfit.targets.decimation import decimate, decimation_factor

    assert decimation_factor(25600, 400) == 16
    fs = 25600.0
    t = np.arange(25600) / fs
    x = np.sin(2 * np.pi * 200 * t) + np.sin(2 * np.pi * 1500 * t)  # 1500 Hz would alias to 100 Hz at 1.6 kHz
    y, fs2 = decimate(x, fs, 16)
    assert fs2 == 1600.0
    spec = np.abs(np.fft.rfft(y[200:-200] * np.hanning(y.size - 400)))
    f = np.fft.rfftfreq(y.size - 400, 1 / fs2)
    assert spec[np.argmin(np.abs(f - 100))] < 1e-3 * spec[np.argmin(np.abs(f - 200))]


def test_half_power_damping_on_sdof():
    from ringfit.targets.frf import half_power_damping

    f = np.linspace(50, 150, 20001)
    fn, z = 100.0, 0.02
    power = 1 / ((fn**2 - f**2) ** 2 + (2 * z * fn * f) ** 2)
    assert half_power_damping(f, power, fn) == pytest.approx(z, rel=0.01)


def test_cli_ssi_chain_feeds_the_fit(tmp_path, truth):
    """records.npz -> `ringfit ssi` -> mode table -> fit_natural_frequencies recovers the ring."""
    from ringfit.cli import main
    from ringfit.fit.least_squares import fit_natural_frequencies
    from ringfit.io.modes import read_mode_table
    from ringfit.io.records import write_records

    geometry, ring, modes = truth
    rec = impact_records(modes, ANGLES, seed=7)
    write_records(rec, tmp_path / "t.records.npz")
    out = tmp_path / "t.modes.csv"
    assert main(["ssi", str(tmp_path / "t.records.npz"), "--out", str(out), "--orders", "2:160:2",
                 "--block-rows", "30", "--workers", "2", "--plot", str(tmp_path / "stab.png"), "--no-progress"]) == 0
    assert (tmp_path / "stab.png").stat().st_size > 0
    table = read_mode_table(out)
    method = table.condition.pop("method")
    from ringfit.physics.natural import cavity_frequency

    assert table.condition == {"state": "free", "frame": "fixed", "credible": True,
                               "cavity_hz": float(cavity_frequency(1))}  # what `acoustic` was judged against
    assert method.startswith("ssi-cov; σ: leave-one-group-out jackknife over 12 groups of sensor angles")
    assert np.all(np.isfinite(table.freq_std_hz) & (table.freq_std_hz > 0))
    assert sorted(table.n[table.kind == "structural"]) == list(range(1, 10))
    start = ring.replace(ei=1.3 * ring.ei, kw=0.8 * ring.kw, kv=1.2 * ring.kv)
    fit = fit_natural_frequencies(table, geometry, start, free=("ei", "kw", "kv"))
    assert fit.converged
    for name in ("ei", "kw", "kv"):
        true = float(getattr(ring, name))
        assert abs(fit.values[name] - true) <= 3 * fit.stderr[name] + 0.02 * true, (name, fit.values[name], true)
    # the same command refuses to overwrite its output
    assert main(["ssi", str(tmp_path / "t.records.npz"), "--out", str(out), "--no-progress"]) == 2
