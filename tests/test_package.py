"""Package-level promises: float64 on import, every public name resolves, bundled data present."""

import subprocess
import sys

import ringfit


def test_import_enables_x64_in_a_fresh_process():
    code = "import ringfit, jax.numpy as jnp; print(jnp.asarray(1.0).dtype)"
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True).stdout
    assert out.strip() == "float64"


def test_every_public_name_resolves():
    for name in ringfit.__all__:
        assert getattr(ringfit, name) is not None, name


def test_bundled_seed_data():
    from ringfit.data import path

    for name in ("free-ssi.modes.csv", "free-ssi.modes.json", "free-frf.modes.csv", "table9.tyre.toml",
                 "table10.csv"):
        assert path(name).stat().st_size > 0
