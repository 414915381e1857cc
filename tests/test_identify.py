"""ringfit identify (issue 22): the joint identification of the ring over every measured state.

The joint fits (a synthetic case's fine-grid truth and a cold compile take minutes on a shared core) are
`slow`; the default run checks the compiled programs' shape that once hung (no batched LAPACK call).

Truth from the synthetic generator (ringfit.synth.identify: a finer contact grid and more loaded-mode
harmonics than the identification uses, coloured profile noise, a random gain and angle offset);
refusals checked by their one line; the tyre file's covariance by a round trip.
"""

import json
import math
import re
import shutil

import jax
import jax.numpy as jnp
import numpy as np
import pytest

from ringfit.cli import main
from ringfit.errors import InputError
from ringfit.fit.identify import identification_report, identify, read_identify_folder
from ringfit.io.tyre import read_tyre, write_tyre
from ringfit.synth.identify import make_identify_case



def batched_lapack_calls(lowered_text: str) -> list[tuple[str, str]]:
    """LAPACK custom calls of a lowered program whose first operand holds more than one matrix.

    jaxlib 0.10.2 runs such a call in chunks on XLA's intra-op pool and blocks a pool thread until they finish;
    two at once on a two-thread pool hang the program (ringfit.fit.identify.serial_map)."""
    out = []
    for m in re.finditer(r"custom_call @(lapack_\w+)\(.*?\) .*?: \((tensor<[^>]*>)", lowered_text):
        dims = [int(d) for d in re.findall(r"(\d+)x", m.group(2))]
        if int(np.prod(dims[:-2])) > 1:
            out.append((m.group(1), m.group(2)))
    return out


def test_the_check_finds_a_batched_lapack_call():
    """The check below is not vacuous: a vmapped solve lowers to one batched LU call, a mapped one to single ones."""
    a, b = jnp.ones((3, 40, 40)) + 40 * jnp.eye(40), jnp.ones((3, 40, 1))
    vmapped = jax.jit(jax.vmap(jnp.linalg.solve)).lower(a, b).as_text()
    mapped = jax.jit(lambda a, b: jax.lax.map(lambda ab: jnp.linalg.solve(*ab), (a, b))).lower(a, b).as_text()
    assert any(name == "lapack_dgetrf_ffi" for name, _ in batched_lapack_calls(vmapped))
    assert "lapack_dgetrf_ffi" in mapped and batched_lapack_calls(mapped) == []


def _small_joint_problem(T: int = 2, P: int = 3):
    """The joint problem of free modes, T loaded tables and P profiles, on made-up rows (for its programs' shape)."""
    from ringfit.fit import identify as im
    from ringfit.fit.engine import Problem
    from ringfit.fit.least_squares import ring_vector
    from ringfit.params import table9
    from ringfit.physics.contact import ContactSolver
    from ringfit.physics.profile import ProfileModel

    geometry, ring = table9()
    solver = ContactSolver()
    M = solver.n_grid
    from ringfit.fit.profile_block import PROFILE_K_MIN

    H = M // 2 - PROFILE_K_MIN
    n = np.arange(1, 6)
    rows = im._Rows(
        free=dict(n=n.astype(float), freq=100.0 * n, sigma=np.ones(5)),
        damping=dict(zeta=np.full(5, 0.02), sigma=np.full(5, 0.001)),
        loaded=dict(n=np.tile(n - 1, T), sin=np.zeros(5 * T, int), table=np.repeat(np.arange(T), 5),
                    freq=np.tile(100.0 * n, T), sigma=np.ones(5 * T), load=np.linspace(3000.0, 5000.0, T),
                    drum=np.full(T, np.nan)),
        profiles=dict(measured=np.zeros((P, 2, 2 * H)), sigma=np.ones((P, 2, 2 * H)), omega=np.full(P, 30.0),
                      load=np.linspace(3000.0, 5000.0, P), drum=np.full(P, np.nan), P=P))
    problem = Problem(im.JointResiduals(P, solver, ProfileModel()), im._arrays(geometry, rows, solver),
                      im.joint_coords(P))
    theta = np.concatenate([ring_vector(ring), np.tile([0.0, 1.0], P)])
    return problem, theta, tuple(problem.names)[:6]


@pytest.mark.slow
def test_the_joint_jacobian_in_two_stages_is_the_one_stage_jacobian():
    """identify's model in two stages (the contact solves, then each run's gain and angle offset on the reading):
    its linearisation passes the 2P nuisances' tangents through the reading only — and gives the one-stage
    Jacobian, whose nuisance columns are checked against central differences of the residuals written here."""
    from ringfit.fit import engine
    from ringfit.fit import identify as im

    problem, theta, ring_free = _small_joint_problem(T=1, P=2)
    theta = theta.copy()
    theta[len(theta) - 4 :] = [0.01, 1.05, -0.02, 0.97]  # offsets [rad] and gains away from their start

    class OneStage(im.JointResiduals):
        @property
        def readout(self):
            return ()

    one = engine.Problem(OneStage(2, problem.model.solver, problem.model.profile_model), problem.data, problem.coords)
    from ringfit.fit.least_squares import RING_FIELDS

    r = len(RING_FIELDS)
    assert problem.model.readout == (r, r + 1, r + 2, r + 3) and one.model.readout == ()
    free = ring_free + ("angle_offset_1", "gain_1", "angle_offset_2", "gain_2")
    two_lin = engine.linearize(problem, theta, free)
    one_lin = engine.linearize(one, theta, free)
    scale = np.abs(one_lin.jacobian).max(axis=0)
    np.testing.assert_allclose(two_lin.residuals, one_lin.residuals, rtol=0, atol=1e-12)
    np.testing.assert_allclose(two_lin.jacobian / scale, one_lin.jacobian / scale, rtol=0, atol=1e-10)
    h = 1e-6
    for j, name in enumerate(free[6:], start=6):
        i = problem.names.index(name)
        step = np.zeros_like(theta)
        if name.startswith("gain"):  # log coordinate: d/d ln g
            step[i] = h
            hi, lo = theta * np.exp(step), theta * np.exp(-step)
        else:  # linear coordinate: (θ − center)/scale, scale 1°
            step[i] = h * problem.coords[i].scale
            hi, lo = theta + step, theta - step
        fd = (engine.residuals(problem, hi)[0] - engine.residuals(problem, lo)[0]) / (2 * h)
        np.testing.assert_allclose(two_lin.jacobian[:, j], fd, rtol=0, atol=1e-6 * max(np.abs(fd).max(), 1.0))


def test_the_joint_programs_hold_no_batched_lapack_call():
    """The hang of `ringfit identify` (jaxlib 0.10.2: concurrent batched LAPACK calls wait for each other on XLA's
    CPU pool): neither the joint least-squares solve nor the posterior's log-probability over a chunk of walkers
    may hold one (both traced only, not compiled)."""
    from ringfit.fit import engine

    problem, theta, free = _small_joint_problem()
    fs = engine.free_set(problem, free)
    z0 = engine._start(problem, fs.index, fs.size, fs.arrays, theta[None])[0]
    leaves, treedef = jax.tree.flatten(problem.data)
    solve = engine._solve.lower(leaves, z0, np.append(theta, 0.0), fs.arrays, fs.prior_w, fs.prior_mean,
                                np.int64(8), model=problem.model, treedef=treedef, rtol=1e-8, atol=1e-8,
                                method="levenberg_marquardt").as_text()
    assert "lapack_dgetrf_ffi" in solve  # the contact solves are in it
    assert batched_lapack_calls(solve) == []
    walkers = np.tile(z0[: len(free)], (6, 1))
    kernel, consts = engine.log_density(problem, theta, free)
    logp = engine._batched_log_probability.lower(walkers, consts, kernel=kernel).as_text()
    assert "lapack_dgetrf_ffi" in logp
    assert batched_lapack_calls(logp) == []


@pytest.mark.slow
def test_the_posterior_window_gives_the_fits_density_and_refuses_a_clipped_patch():
    """identify's posterior solves the contacts on a window narrowed to the patches at the optimum, strict and
    without the derivative step (docs/physics.md §12.3, §12.5): its log density equals the fit window's to
    rounding at random points around θ, and is −inf (not a clipped patch) where a much softer tread widens the
    patch past the narrowed edge. The patch's extent checked against a standing solve written here."""
    import dataclasses

    from ringfit.fit import engine
    from ringfit.fit import identify as im
    from ringfit.physics.contact import solve_rolling_jit
    from ringfit.physics.operating import OperatingPoint

    problem, theta, free = _small_joint_problem()
    wide_solver = problem.model.solver
    solver = im.posterior_solver(problem.model, theta, problem.data)
    assert solver.strict_window and not solver.differentiable and solver.n_grid == wide_solver.n_grid
    ring = im.ring_from_vector(jnp.asarray(theta))
    sol = solve_rolling_jit(ring, problem.data.geometry, OperatingPoint(0.0, 5000.0), solver=wide_solver)
    phi = np.degrees(np.asarray(sol.phi))[np.asarray(sol.pressure) > 0]
    extent = max(-phi.min(), phi.max())  # the 5 kN standing patch, the widest of the problem's conditions
    assert im.POSTERIOR_WINDOW_MARGIN * extent <= solver.window_deg < 0.8 * wide_solver.window_deg
    narrow = engine.Problem(dataclasses.replace(problem.model, solver=solver), problem.data, problem.coords)
    u0 = np.array([problem.coordinate(n).to_u(theta[problem.names.index(n)]) for n in free])
    u = u0 + 0.02 * np.random.default_rng(5).standard_normal((6, len(free)))
    j = free.index("k_tread")
    u[-1, j] = u0[j] - 2.5  # k_tread / 12: a deflection and a patch far past the narrowed window
    kw, cw = engine.log_density(problem, theta, free)
    kn, cn = engine.log_density(narrow, theta, free)
    lw = np.asarray(engine._batched_log_probability(jnp.asarray(u), cw, kernel=kw))
    ln = np.asarray(engine._batched_log_probability(jnp.asarray(u), cn, kernel=kn))
    assert np.all(np.isfinite(lw)) and np.all(np.isfinite(ln[:-1]))
    np.testing.assert_allclose(ln[:-1], lw[:-1], rtol=1e-11)
    assert ln[-1] == -np.inf


@pytest.fixture(scope="module")
def joint_case(tmp_path_factory):
    folder = tmp_path_factory.mktemp("joint") / "case"
    truth = make_identify_case(folder, seed=3)
    return folder, truth


@pytest.fixture(scope="module")
def joint(joint_case):
    folder, truth = joint_case
    return identify(read_identify_folder(folder)), truth


def _z(ident, truth, name):
    p = ident.parameters()[name]
    return math.log(p["value"] / truth["ring"][name]) / p["sd_ln"]


@pytest.mark.slow
def test_joint_fit_recovers_the_truth_within_its_intervals(joint):
    ident, truth = joint
    assert ident.converged
    for name in ("rho_a", "ei", "kw", "kv", "k_tread", "damping_ratio"):
        assert abs(_z(ident, truth, name)) < 3.5, (name, _z(ident, truth, name))
    # with profiles at known load EI is identified to a few per cent (free modes alone: ~100 %)
    assert ident.parameters()["ei"]["sd_ln"] < 0.10
    assert ident.parameters()["k_tread"]["sd_ln"] < 0.05
    for got, want in zip(ident.nuisances, truth["profiles"]):
        assert abs(got["gain"] / want["gain"] - 1) < 0.02
        assert abs(got["angle_offset_deg"] - want["angle_offset_deg"]) < 0.1


@pytest.mark.slow
def test_report_has_fisher_shares_that_sum_to_one_and_a_correlation(joint):
    ident, _ = joint
    doc = identification_report(ident)
    json.dumps(doc, allow_nan=False)
    assert set(doc["blocks"]) == {"free modes", "free damping", "loaded modes", "profiles"}
    for name in doc["parameters"]:
        total = sum(b["fisher_share"][name] for b in doc["blocks"].values())
        assert total == pytest.approx(1.0, abs=1e-9)  # no prior rows: the blocks hold all the information
    # EI is pinned by the profiles, the damping by the profiles and the damping rows, not by the free modes
    assert doc["blocks"]["profiles"]["fisher_share"]["ei"] > 0.5
    assert doc["blocks"]["free modes"]["fisher_share"]["damping_ratio"] == 0.0
    corr = np.array(doc["correlation"]["matrix"])
    np.testing.assert_allclose(np.diag(corr), 1.0)
    np.testing.assert_allclose(corr, corr.T, atol=1e-12)


@pytest.mark.slow
def test_free_and_loaded_tables_alone_identify_k_tread(tmp_path):
    truth = make_identify_case(tmp_path / "c", seed=5, profiles=False)
    ident = identify(read_identify_folder(tmp_path / "c"))
    assert ident.converged
    assert "profiles" not in ident.blocks
    assert abs(_z(ident, truth, "k_tread")) < 3.5
    assert ident.blocks["loaded modes"]["fisher_share"]["k_tread"] == pytest.approx(1.0)


@pytest.mark.slow
def test_a_loaded_table_without_load_is_refused_naming_the_key(joint_case, tmp_path):
    folder, _ = joint_case
    bad = tmp_path / "bad"
    shutil.copytree(folder, bad)
    side = bad / "loaded3000.modes.json"
    cond = json.loads(side.read_text())
    cond.pop("load_n")
    side.write_text(json.dumps(cond))
    with pytest.raises(InputError, match=r"loaded3000\.modes\.json.*load_n"):
        read_identify_folder(bad)
    assert main(["identify", str(bad), "--out", str(tmp_path / "x.tyre.toml")]) == 2
    assert not (tmp_path / "x.tyre.toml").exists() and not (tmp_path / "x.identify.json").exists()


@pytest.mark.slow
def test_tyre_covariance_round_trips_and_bad_ones_are_refused(tmp_path, joint):
    ident, _ = joint
    from ringfit.io.tyre import Tyre
    from ringfit.params import table9

    geometry, _ = table9()
    tyre = Tyre(geometry, {}).with_ring(ident.ring, covariance=ident.covariance)
    write_tyre(tyre, tmp_path / "t.tyre.toml")
    back = read_tyre(tmp_path / "t.tyre.toml")
    assert back.covariance.names == ident.covariance.names
    np.testing.assert_array_equal(back.covariance.ln, ident.covariance.ln)
    text = (tmp_path / "t.tyre.toml").read_text()
    for old, new, message in [('"ei"', '"eii"', "did you mean 'ei'"), ("ln = [", "lnn = [", "did you mean 'ln'")]:
        (tmp_path / "b.toml").write_text(text.replace(old, new, 1))
        with pytest.raises(InputError, match=message):
            read_tyre(tmp_path / "b.toml")
    # a negative variance is not a covariance
    doc = text.replace("ln = [\n    [\n        ", "ln = [\n    [\n        -", 1)
    (tmp_path / "c.toml").write_text(doc)
    with pytest.raises(InputError, match="ring.covariance"):
        read_tyre(tmp_path / "c.toml")


@pytest.mark.slow
def test_cli_writes_tyre_and_report_beside_it(joint_case, tmp_path, capsys):
    folder, truth = joint_case
    out = tmp_path / "id.tyre.toml"
    assert main(["identify", str(folder), "--out", str(out), "--quiet"]) == 0
    tyre = read_tyre(out)
    doc = json.loads((tmp_path / "id.identify.json").read_text())
    assert doc["converged"] and doc["format"] == "ringfit-identify/1"
    for name, p in doc["parameters"].items():
        assert tyre.ring_values[name] == pytest.approx(p["value"], rel=1e-12)
        assert tyre.covariance.sd_ln(name) == pytest.approx(p["sd_ln"], rel=1e-12)
        assert p["lo95"] < p["value"] < p["hi95"]
    assert "Fisher information share" in capsys.readouterr().out
    # outputs are not replaced without --force
    assert main(["identify", str(folder), "--out", str(out), "--quiet"]) == 2


@pytest.mark.slow
def test_diagnose_with_the_fitted_tyre_as_baseline_gives_the_same_diagnosis(tmp_path):
    """One ring per tyre: `diagnose --tyre` with `ringfit fit`'s tyre file (the same ring the default path fits
    to free.modes.csv) evaluates that ring instead of refitting it — the diagnosis is the same."""
    assert main(["example", "case", "--out", str(tmp_path / "ex"), "--quiet"]) == 0
    case = tmp_path / "ex" / "case"
    fitted = tmp_path / "fitted.tyre.toml"
    assert main(["fit", str(case / "free.modes.csv"), "--tyre", str(case / "tyre.toml"), "--out", str(fitted)]) == 0
    a, b = tmp_path / "a.diagnosis.json", tmp_path / "b.diagnosis.json"
    assert main(["diagnose", str(case), "--out", str(a), "--quiet"]) == 0
    assert main(["diagnose", str(case), "--out", str(b), "--tyre", str(fitted), "--quiet"]) == 0
    da, db = json.loads(a.read_text()), json.loads(b.read_text())
    assert db["baseline_tyre"].endswith("fitted.tyre.toml") and "baseline_tyre" not in da
    assert da["verdict"]["effects"] == db["verdict"]["effects"]
    for key in ("rms", "reduced_chi2", "noise_rms"):
        assert db["baseline"][key] == pytest.approx(da["baseline"][key], rel=1e-3)
    ref_a = da["parts"][0]["baseline"]["reference_fit"]
    ref_b = db["parts"][0]["baseline"]["reference_fit"]
    assert ref_b["status"] == "evaluated" and ref_a["status"] == "converged"
    for name, value in ref_a["values"].items():
        assert ref_b["values"][name] == pytest.approx(value, rel=1e-9)
        assert ref_b["stderr"][name] == pytest.approx(ref_a["stderr"][name], rel=1e-4)
    # a tyre without [ring] is refused as a baseline
    bare = tmp_path / "bare.toml"
    bare.write_text('[tyre]\nradius_m = 0.296\nwidth_m = 0.152\npressure_bar = 2.2\n')
    assert main(["diagnose", str(case), "--out", str(tmp_path / "c.diagnosis.json"), "--tyre", str(bare)]) == 2


@pytest.fixture(scope="module")
def identified_tyre(joint_case, tmp_path_factory):
    """``ringfit identify`` of the joint case: the tyre file and its report."""
    folder, _ = joint_case
    tyre_path = tmp_path_factory.mktemp("identified") / "identified.tyre.toml"
    assert main(["identify", str(folder), "--out", str(tyre_path), "--quiet"]) == 0
    return tyre_path, json.loads(tyre_path.with_name("identified.identify.json").read_text())


@pytest.mark.slow
def test_the_diagnosis_reads_identifys_profiles_as_identify_does(joint_case, identified_tyre):
    """Same data, same answer (issue 31): `identify` then `diagnose --tyre` on the same case folder, with no hidden
    effect. The diagnosis's profile baseline reads each profile through the profile block's gain and angle offset
    (ringfit.fit.profile_block), as identify does, so it finds no structure in the profiles, keeps the identified
    ring inside its covariance, and recovers each profile's true gain and offset — as identify does. (With one
    offset for all profiles and no gain it rated them at reduced χ² ≈ 28 with the ring pulled ≈ 18 σ.)"""
    from ringfit.gap import diagnose

    folder, truth = joint_case
    tyre_path, report = identified_tyre
    d = diagnose(folder, effects=(), progress=False, null_draws=0, tyre=read_tyre(tyre_path))
    part = next(p for p in d.parts if p.problem.domain == "profiles")
    base = part.summary["baseline"]
    assert not base["structured"] and base["reduced_chi2"] < 2.0, base["reduced_chi2"]
    assert base["drift"]["max_abs_sigma"] < 3.0 and not base["drift"]["prior_distance"]["outside"]
    labels = part.problem.labels
    speed_of = {int(i): float(labels["speed_kmh"][labels["profile"] == i][0]) for i in np.unique(labels["profile"])}
    values = base["parameters"]
    for i, speed in speed_of.items():
        want = next(t for t in truth["profiles"] if abs(t["speed_kmh"] - speed) < 1e-6)
        ident = next(n for n in report["nuisances"] if abs(n["speed_kmh"] - speed) < 1e-6)
        gain, offset_deg = values[f"gain_{i + 1}"], math.degrees(values[f"angle_offset_{i + 1}"])
        assert abs(gain / want["gain"] - 1) < 0.02 and abs(offset_deg - want["angle_offset_deg"]) < 0.1
        assert abs(gain - ident["gain"]) < 3 * ident["gain_sd"] + 1e-3, (gain, ident)
        assert abs(offset_deg - ident["angle_offset_deg"]) < 3 * ident["angle_offset_sd_deg"] + 0.02, (offset_deg, ident)


@pytest.mark.slow
def test_estimate_with_the_identified_tyre_gives_back_each_profiles_stated_load(joint_case, identified_tyre, tmp_path):
    """Same data, same answer (issue 31): identify read each profile at its stated load; `ringfit estimate` of the
    same profile with the identified tyre file finds that load again, inside its 95 % interval and within 1 %."""
    folder, truth = joint_case
    tyre_path, _ = identified_tyre
    for i, want in enumerate(truth["profiles"]):
        prof = sorted(folder.glob("*.profile.csv"))[i]
        stated = json.loads(prof.with_suffix(".json").read_text())["load_n"]
        assert stated == pytest.approx(want["load_n"])
        out = tmp_path / f"{prof.stem}.estimate.json"
        assert main(["estimate", str(prof), "--tyre", str(tyre_path), "--out", str(out), "--quiet"]) == 0
        load = json.loads(out.read_text())["load_n"]
        assert load["lo"] <= stated <= load["hi"], (prof.name, stated, load)
        assert abs(load["value"] / stated - 1) < 0.01


@pytest.mark.slow
def test_roll_states_the_ring_band_from_the_covariance(tmp_path, capsys):
    """The tyre's [ring.covariance] propagated into the standing deflection: a band around the nominal value that
    grows with the covariance (k_trd ±20 % must move the deflection more than ±2 %)."""
    import re

    from ringfit.data import path as data_path
    from ringfit.io.tyre import RingCovariance

    tyre = read_tyre(data_path("table9.tyre.toml"))
    widths = []
    for sd in (0.02, 0.2):
        tyre.covariance = RingCovariance(("k_tread", "kw"), np.diag([sd, 0.01]) ** 2)
        path = tmp_path / f"t{sd}.toml"
        write_tyre(tyre, path)
        assert main(["roll", "--tyre", str(path), "--speed", "40", "--load", "4000", "--out",
                     str(tmp_path / f"p{sd}.profile.csv")]) == 0
        out = capsys.readouterr().out
        nominal = float(re.search(r"deflection ([0-9.]+) mm, patch", out).group(1))
        lo, hi = map(float, re.search(r"deflection ([0-9.]+) … ([0-9.]+) mm", out).groups())
        assert lo < nominal < hi
        widths.append(hi - lo)
    assert widths[1] > 3 * widths[0]


@pytest.mark.slow
def test_cli_posterior_of_the_joint_fit(tmp_path):
    """--posterior: emcee on the same joint problem; its medians sit inside the least-squares 95 % intervals."""
    make_identify_case(tmp_path / "c", seed=8, profiles=False)
    out, h5 = tmp_path / "p.tyre.toml", tmp_path / "p.h5"
    assert main(["identify", str(tmp_path / "c"), "--out", str(out), "--posterior", str(h5), "--min-steps", "200",
                 "--max-steps", "200", "--quiet"]) == 0
    assert h5.stat().st_size > 0
    doc = json.loads((tmp_path / "p.identify.json").read_text())
    post = doc["posterior"]["parameters"]
    for name, p in doc["parameters"].items():
        assert p["lo95"] < post[name]["median"] < p["hi95"], name


# ----------------------------------------------------------------------------- coverage pieces (fast, no fit)


def _noise_rows(colour, rng, points=720, M=512):
    from ringfit.synth.cases import coloured_noise

    x = coloured_noise(rng, points, 1.0, colour)
    spec = np.fft.rfft(x)[2 : M // 2] * math.sqrt(2.0 / points)
    return spec


def test_profile_noise_spectrum_is_calibrated_for_coloured_noise():
    """On pure noise of each colour, a row over its estimated σ has E[z²] = ν/(ν − 2) (σ̂² from ν independent
    neighbouring parts, the row left out) in every band, the lowest harmonics of red noise included (to 5 %; a
    resonance band only errs wide at k = 2 … 4); a plain
    ±4 moving average of the power (the negative control) reads the σ of k = 2 … 4 of red noise low."""
    from ringfit.fit.profile_block import NOISE_SMOOTHING, noise_spectrum

    rng = np.random.default_rng(11)
    for colour in ("white", "pink", "red", "band"):
        z2, plain = [], []
        for _ in range(300):
            spec = _noise_rows(colour, rng)
            power = 0.5 * np.abs(spec) ** 2
            noise, dof = noise_spectrum(power[None])
            z2.append(np.abs(spec) ** 2 / 2 / noise[0])  # mean of (Re² + Im²)/2 over σ̂²
            kernel = np.ones(2 * NOISE_SMOOTHING + 1)
            avg = np.convolve(power, kernel, mode="same") / np.convolve(np.ones(power.size), kernel, mode="same")
            plain.append(np.abs(spec) ** 2 / 2 / avg)
        z2, plain = np.mean(z2, axis=0), np.mean(plain, axis=0)
        expected = dof / (dof - 2.0)
        for lo, hi in ((0, 3), (3, 10), (10, 40), (40, z2.size)):
            ratio = z2[lo:hi].mean() / expected[lo:hi].mean()
            # never anticonservative by more than a few per cent; a bump (band) bends the power law at the lowest
            # harmonics, where σ² then reads up to ~15 % high (intervals a little wide, not narrow)
            assert 0.85 < ratio < 1.05, (colour, lo, hi, ratio)
            if colour != "band":
                assert abs(ratio - 1.0) < 0.05, (colour, lo, hi, ratio)
        if colour == "red":
            assert plain[:3].mean() > 1.25  # σ of the lowest harmonics read ≥ 10 % low by the plain average


def test_t_widening_is_students_quantile_over_the_normals():
    from ringfit.fit.identify import Z95, t_widening

    # closed forms: ν = 1 (Cauchy) tan(0.475π), ν = 2 (2p − 1)/√(2p(1 − p)), ν = ∞ the normal
    assert t_widening(1.0) == pytest.approx(math.tan(0.475 * math.pi) / Z95, rel=1e-10)
    assert t_widening(2.0) == pytest.approx(0.95 / math.sqrt(2 * 0.975 * 0.025) / Z95, rel=1e-10)
    assert t_widening(math.inf) == 1.0
    assert 1.0 < t_widening(200.0) < 1.01


def test_rows_of_a_finer_grid_are_the_same_band_limited_rows():
    """The grid check compares a 2M-point model with M-point data: the rows of the same revolution agree."""
    from ringfit.fit.profile_block import harmonic_rows

    def signal(M):
        phi = -np.pi + 2 * np.pi * np.arange(M) / M
        return np.cos(3 * phi) + 0.5 * np.sin(17 * phi + 0.3) + 0.1 * np.cos(200 * phi)

    coarse = np.asarray(harmonic_rows(jnp.asarray(signal(512))))
    fine = np.asarray(harmonic_rows(jnp.asarray(signal(1024)), rows_grid=512))
    assert fine.shape == coarse.shape
    np.testing.assert_allclose(fine, coarse, atol=1e-12)
    # and the rows are those of the stated normalisation: cos(3φ) has amplitude √(M/2) at k = 3 on M points
    H = coarse.size // 2
    assert abs(coarse[3 - 2] + 1j * coarse[H + 3 - 2]) == pytest.approx(math.sqrt(512 / 2), rel=1e-12)


@pytest.mark.slow
def test_posterior_samples_the_noise_model_of_the_intervals(tmp_path):
    """identify --posterior samples the likelihood of the tyre file's intervals (issue 32): each block's Student-t
    widening on its rows and the grid check's direction convolved into the draws. On a free + loaded case the
    posterior's 95 % interval of every ring parameter agrees with the least-squares one (centre and log-width)
    within 4 Monte-Carlo standard errors of the sampled quantiles (2.67 σ/√ESS each, Gaussian) plus 5 % of the
    width for the model's curvature; and the widening the sampler uses is the one the intervals used."""
    from ringfit.fit.posterior import sample

    make_identify_case(tmp_path / "c", seed=8, profiles=False)
    ident = identify(read_identify_folder(tmp_path / "c"))
    like = ident.posterior_likelihood()
    for block, sl in ident.slices.items():
        b = ident.blocks[block]
        assert np.allclose(like["row_scale"][sl], b["t_widening"] * math.sqrt(1.0 + b["discrepancy"]), rtol=1e-12)
    assert any(b["t_widening"] > 1.05 for b in ident.blocks.values())  # the case exercises the widening
    k = len(ident.fit.names)
    fit = ident.posterior_fit()  # carries the likelihood that sample() reads (no arguments to forget)
    assert np.array_equal(fit.extra["row_scale"], like["row_scale"]) and fit.extra["tables"] == like["tables"]
    post = sample(fit, walkers=2 * k, chains=2, min_steps=1000, max_steps=1000, check_every=500,
                  seed=2, progress=False, spread=0.25)
    ess = dict(zip(post.names, post.ess()))
    lsq = ident.parameters()
    for row in post.summary_table(0.95):
        name = row["name"]
        if name not in lsq:
            continue
        p, sd = lsq[name], lsq[name]["sd_ln"]
        se_q = 2.67 * sd / np.sqrt(ess[name])
        width_p, width = np.log(row["hi"] / row["lo"]), np.log(p["hi95"] / p["lo95"])
        assert abs(width_p - width) < 4 * np.sqrt(2) * se_q + 0.05 * width, (name, width_p, width)
        centre_p, centre = 0.5 * np.log(row["hi"] * row["lo"]), 0.5 * np.log(p["hi95"] * p["lo95"])
        assert abs(centre_p - centre) < 4 * se_q + 0.05 * width, (name, centre_p, centre)
    assert set(post.meta["predictive_check"]) >= {"free.modes.csv"}
