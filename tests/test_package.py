"""Package-level promises: float64 on import, a cheap import, every public name is its module's own
object, documented and listed by task in help(ringfit), bundled data present."""

import importlib
import re
import subprocess
import sys

import pytest

import ringfit


def test_import_enables_x64_in_a_fresh_process():
    code = "import ringfit, jax.numpy as jnp; print(jnp.asarray(1.0).dtype)"
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True).stdout
    assert out.strip() == "float64"


def _public_names_in_docstring() -> set[str]:
    """The names the module docstring lists under its tasks (indented lines of comma-separated names)."""
    names = set()
    for line in ringfit.__doc__.splitlines():
        if line.startswith("    ") and re.fullmatch(r"[A-Za-z_0-9, ]+,?", line.strip()):
            names.update(n.strip() for n in line.split(",") if n.strip())
    return names


def test_every_public_name_is_the_object_its_module_defines():
    exports = ringfit._EXPORTS
    assert ringfit.__all__ == sorted(exports)  # __all__ lists exactly the exported names
    assert len(exports) == len(set(exports))
    for name, module_name in exports.items():
        obj = getattr(ringfit, name)
        module = importlib.import_module(module_name)
        assert obj is getattr(module, name), name
        # defined there, not re-exported from elsewhere (the map names the defining module)
        assert getattr(obj, "__module__", None) == module_name, (name, getattr(obj, "__module__", None))
        assert module_name.split(".")[-1] != "__init__" and not hasattr(obj, "__path__"), name  # not a package


def test_every_public_name_is_documented():
    for name in ringfit.__all__:
        doc = getattr(ringfit, name).__doc__ or ""
        # its own text: a dataclass without a docstring gets an auto-generated "Name(field: type, ...)"
        assert doc.strip() and not doc.startswith(f"{name}("), name


def test_help_lists_every_entry_point_by_task():
    assert _public_names_in_docstring() == set(ringfit.__all__)
    for task in ("Free tyre", "Targets from recordings", "Rolling tyre", "Sim-to-real gap", "State estimation"):
        assert task in ringfit.__doc__, task
    for where in ("ringfit.fit.engine", "ringfit.params", "ringfit.batch"):  # what is not top level, and where
        assert where in ringfit.__doc__, where
    assert set(ringfit.__all__) <= set(dir(ringfit))
    with pytest.raises(AttributeError, match="no attribute 'fit_everything'"):
        ringfit.fit_everything  # noqa: B018


def test_import_ringfit_stays_cheap():
    code = "import sys, ringfit; print(sorted(m for m in ('jax', 'numpy', 'scipy', 'matplotlib') if m in sys.modules))"
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True).stdout
    assert out.strip() == "[]"


def test_bundled_seed_data():
    from ringfit.data import path

    for name in ("free-ssi.modes.csv", "free-ssi.modes.json", "free-frf.modes.csv", "table9.tyre.toml",
                 "table10.csv"):
        assert path(name).stat().st_size > 0


def test_top_level_namespace_is_trimmed_and_the_rest_stays_importable():
    # issue 24: what users call (emcee exports 7 names); the rest from its own module
    assert 10 <= len(ringfit.__all__) <= 25, len(ringfit.__all__)
    assert not set(ringfit.__all__) & set(ringfit._ELSEWHERE)
    for name, module_name in ringfit._ELSEWHERE.items():
        obj = getattr(importlib.import_module(module_name), name)
        assert getattr(obj, "__module__", module_name) == module_name, name  # defined where we say
        with pytest.raises(AttributeError, match=re.escape(f"from {module_name} import {name}")):
            getattr(ringfit, name)


def test_the_first_names_a_newcomer_meets_are_top_level():
    """identify (one ring from a case folder), RingParams and TyreGeometry — a newcomer's first names — are in
    __all__ and are the very objects their modules define (spelt out here, not read from ringfit._EXPORTS)."""
    fit_identify = importlib.import_module("ringfit.fit.identify")
    params = importlib.import_module("ringfit.params")
    assert {"identify", "RingParams", "TyreGeometry"} <= set(ringfit.__all__)
    assert ringfit.identify is fit_identify.identify
    assert ringfit.RingParams is params.RingParams
    assert ringfit.TyreGeometry is params.TyreGeometry


def test_an_option_outside_its_literal_is_refused_by_name():
    """Options typed as Literals are checked at run time too: a misspelt one is refused with its name and the
    allowed values, not silently taken for a default."""
    import pytest

    from ringfit.errors import InputError
    from ringfit.io.conditions import check_stated
    from ringfit.params import table9
    from ringfit.report.targets_plots import plot_mode_shapes
    from ringfit.synth.independent import make_independent_case

    geometry, _ = table9()
    with pytest.raises(InputError, match="other_pressure = 'warning'"):
        check_stated(object(), geometry, source="x.csv", other_pressure="warning")
    with pytest.raises(ValueError, match="real = 'principle'"):
        plot_mode_shapes(None, real="principle")
    with pytest.raises(ValueError, match="resolution = 'coarser'"):
        make_independent_case("/nonexistent-never-written", resolution="coarser")
