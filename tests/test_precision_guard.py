"""float64 everywhere (issue 31 item 7): a shadowing ``ringfit`` folder or a switched-off x64 never runs in float32."""

from __future__ import annotations

import subprocess
import sys
import textwrap


def _run(code: str, cwd) -> subprocess.CompletedProcess:
    return subprocess.run([sys.executable, "-c", textwrap.dedent(code)], cwd=cwd, capture_output=True, text=True,
                          timeout=180, env={"PATH": "/usr/bin:/bin", "JAX_PLATFORMS": "cpu"})


def test_a_folder_named_ringfit_on_the_path_still_computes_in_float64(tmp_path):
    (tmp_path / "ringfit").mkdir()  # what a clone's parent folder looks like to Python run from there
    out = _run("""
        import ringfit
        assert getattr(ringfit, "__file__", None) is None, "the folder did not shadow the package"
        from ringfit.params import RingParams
        from ringfit.physics.natural import natural_frequencies
        import jax, jax.numpy as jnp
        print(jax.config.jax_enable_x64, jnp.zeros(2).dtype)
    """, tmp_path)
    assert out.returncode == 0, out.stderr
    assert out.stdout.split() == ["True", "float64"]


def test_a_fit_refuses_when_x64_was_switched_off(tmp_path):
    out = _run("""
        import ringfit
        from ringfit._precision import PrecisionError
        from ringfit.fit.least_squares import fit_natural_frequencies
        from ringfit.io.modes import read_mode_table
        from ringfit.io.tyre import read_tyre
        from ringfit.data import path
        import jax
        jax.config.update("jax_enable_x64", False)
        try:
            tyre = read_tyre(path("table9.tyre.toml")); fit_natural_frequencies(read_mode_table(path("free-ssi.modes.csv")), tyre.geometry, tyre.ring)
        except PrecisionError as exc:
            print("REFUSED", exc)
        else:
            print("RAN")
    """, tmp_path)
    assert out.returncode == 0, out.stderr
    assert out.stdout.startswith("REFUSED") and "64-bit" in out.stdout


def test_the_command_line_refuses_float32(tmp_path):
    from ringfit.data import path

    env = {"PATH": "/usr/bin:/bin", "JAX_PLATFORMS": "cpu"}
    code = ("import sys; from ringfit.cli import main; import jax; jax.config.update('jax_enable_x64', False); "
            f"sys.exit(main(['fit', {str(path('free-ssi.modes.csv'))!r}, '--tyre', "
            f"{str(path('table9.tyre.toml'))!r}, '--out', {str(tmp_path / 'f.tyre.toml')!r}]))")
    out = subprocess.run([sys.executable, "-c", code], cwd=tmp_path, capture_output=True, text=True, timeout=180,
                         env=env)
    assert out.returncode == 2, out.stderr
    assert "64-bit" in out.stderr and out.stderr.count("\n") == 1
    assert not (tmp_path / "f.tyre.toml").exists()
