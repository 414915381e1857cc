"""The `ringfit` command line for the free-tyre workflow: outputs, exit codes, bad input."""

import shutil
import subprocess
import sys

import pytest

from ringfit.cli import main
from ringfit.data import path as data_path

MODES = data_path("free-ssi.modes.csv")
TYRE = data_path("table9.tyre.toml")


def run(*args):
    return main([str(a) for a in args])


@pytest.mark.slow  # end to end, > 7 s: CI runs it with -m slow (issue 24 item 3)
def test_fit_sample_report_chain(tmp_path, capsys):
    fitted = tmp_path / "fitted.toml"
    assert run("fit", MODES, "--tyre", TYRE, "--out", fitted) == 0
    out = capsys.readouterr().out
    assert "converged" in out and "Fisher" in out
    from ringfit.io.tyre import read_tyre

    t = read_tyre(fitted)
    assert set(t.ring_values) >= {"rho_a", "ei", "kw", "kv"} and 2.3 < t.ring_values["rho_a"] < 2.8
    post = tmp_path / "post.h5"
    nc = tmp_path / "post.nc"
    assert run("sample", MODES, "--tyre", fitted, "--out", post, "--walkers", "16", "--min-steps", "1000",
               "--max-steps", "1500", "--no-progress", "--netcdf", nc) == 0
    _check_netcdf_matches_posterior(nc, post)
    report = tmp_path / "r.html"
    assert run("report", post, "--out", report) == 0
    assert report.stat().st_size > 50_000
    # outputs are never overwritten without --force
    assert run("report", post, "--out", report) == 2
    assert run("report", post, "--out", report, "--force") == 0


def _check_netcdf_matches_posterior(nc, h5):
    """arviz reads back the draws of the HDF5 posterior: same values, walkers as chains, natural units."""
    import warnings

    import numpy as np

    from ringfit.fit.posterior import load_posterior

    with warnings.catch_warnings():
        warnings.simplefilter("ignore", FutureWarning)
        import arviz as az
    idata = az.from_netcdf(nc)
    post = load_posterior(h5)
    walkers = post.chain.shape[1]
    kept = post.chain[post.burn :: post.thin]
    assert set(idata.posterior.data_vars) == set(post.names)
    for i, name in enumerate(post.names):
        draws = idata.posterior[name].values  # (chain, draw)
        assert draws.shape == (walkers, kept.shape[0])
        # the h5 stores solver coordinates (log for positive parameters): exp of them is the value
        np.testing.assert_allclose(draws.T, np.exp(kept[:, :, i]), rtol=1e-12)
        assert draws.dtype == np.float64
    np.testing.assert_array_equal(idata.sample_stats["lp"].values.T, post.log_prob[post.burn :: post.thin])
    np.testing.assert_array_equal(idata.observed_data["freq_hz"].values, post.meta["data"]["freq_hz"])
    np.testing.assert_array_equal(idata.observed_data["n"].values, post.meta["data"]["n"])
    assert idata.attrs["burn"] == post.burn and idata.attrs["thin"] == post.thin
    # arviz's own diagnostics run on it and agree with the posterior's (computed on log θ there)
    rhat = az.rhat(np.log(idata.posterior))
    # (not bit-equal: log(exp(u)) moves u by 1 ulp, which breaks the tie of the two middle draws in folded R̂)
    np.testing.assert_allclose([float(rhat[n].values) for n in post.names], post.rhat(), rtol=1e-3)


def test_sample_netcdf_option_refuses_bad_names(tmp_path, capsys):
    fitted = tmp_path / "fitted.toml"
    assert run("fit", MODES, "--tyre", TYRE, "--out", fitted) == 0
    common = ("sample", MODES, "--tyre", fitted, "--walkers", "8", "--min-steps", "100", "--max-steps", "100",
              "--no-progress")
    capsys.readouterr()
    assert run(*common, "--out", tmp_path / "x.nc", "--netcdf", tmp_path / "x.nc") == 2  # the same file as --out
    assert run(*common, "--out", tmp_path / "post.h5", "--netcdf", tmp_path / "draws.h5") == 2  # not .nc
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 2 and "--netcdf" in err[1] and ".nc" in err[1], err
    assert "two outputs" in err[0], err
    assert run(*common, "--out", tmp_path / "post.h5", "--netcdf", tmp_path / "nope" / "x.nc") == 2  # no folder
    assert sorted(p.name for p in tmp_path.iterdir()) == ["fitted.toml"]  # nothing written


def test_unconverged_fit_writes_nothing_and_exits_1(tmp_path, capsys):
    out = tmp_path / "f.toml"
    assert run("fit", MODES, "--tyre", TYRE, "--out", out, "--prior", "none") == 1
    assert not out.exists()
    assert "did not converge" in capsys.readouterr().err


def _bad(tmp_path, name, text):
    p = tmp_path / name
    p.write_text(text)
    return p


@pytest.mark.parametrize("case", ["missing", "column", "nan", "negative", "pascal", "param", "unreadable"])
def test_bad_input_exit_2_one_line(tmp_path, capsys, case):
    modes, tyre, extra = MODES, TYRE, []
    if case == "missing":
        modes = tmp_path / "nope.modes.csv"
    elif case == "column":
        modes = _bad(tmp_path, "c.modes.csv", "n,frequency\n1,100\n")
    elif case == "nan":
        modes = _bad(tmp_path, "c.modes.csv", "n,freq_hz\n1,100\n2,NaN\n")
    elif case == "negative":
        modes = _bad(tmp_path, "c.modes.csv", "n,freq_hz\n1,100\n2,-120\n")
    elif case == "pascal":
        tyre = _bad(tmp_path, "t.toml", "[tyre]\nradius_m = 0.296\nwidth_m = 0.152\npressure_bar = 220000\n")
    elif case == "param":
        extra = ["--free", "ei,stiffness"]
    elif case == "unreadable":
        modes = tmp_path / "bin.modes.csv"
        modes.write_bytes(b"\xff\xfe\x00\x81binary")
    out = tmp_path / "out.toml"
    status = run("fit", modes, "--tyre", tyre, "--out", out, *extra)
    err = capsys.readouterr().err.strip()
    assert status == 2
    assert len(err.splitlines()) == 1 and err.startswith("ringfit fit: error:")
    assert not out.exists()


def test_never_overwrites_an_input(tmp_path):
    modes = tmp_path / "m.modes.csv"
    shutil.copy(MODES, modes)
    before = modes.read_bytes()
    assert run("fit", modes, "--tyre", TYRE, "--out", modes, "--force") == 2
    assert modes.read_bytes() == before


@pytest.mark.parametrize("cmd", ["fit", "sample", "report", "demo"])
def test_help(cmd, capsys):
    assert main([cmd, "--help"]) == 0  # main returns argparse's status instead of exiting
    assert "usage: ringfit" in capsys.readouterr().out


@pytest.mark.slow  # end to end, > 7 s: CI runs it with -m slow (issue 24 item 3)
def test_demo_end_to_end(tmp_path):
    proc = subprocess.run([sys.executable, "-m", "ringfit", "demo", "--out", str(tmp_path / "d")],
                          capture_output=True, text=True, timeout=300)
    assert proc.returncode == 0, proc.stderr[-2000:]
    assert "Table 10" in proc.stdout and "max |error|" in proc.stdout
    for name in ("fitted.tyre.toml", "posterior.h5", "report.html"):
        assert (tmp_path / "d" / name).stat().st_size > 100
    again = subprocess.run([sys.executable, "-m", "ringfit", "demo", "--out", str(tmp_path / "d")],
                           capture_output=True, text=True, timeout=300)
    assert again.returncode == 2 and "refusing to overwrite" in again.stderr
