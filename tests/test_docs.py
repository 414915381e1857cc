"""The documentation site (issue 24 item 4): it builds with ``mkdocs build --strict`` — a broken
link, a section reference to no section or an undocumented public function or class fails —
the CLI reference covers every command and option, and every notebook becomes a tutorial."""

import argparse
import importlib.util
import os
import subprocess
import sys
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]
SITE_PACKAGES = ("mkdocs", "material", "mkdocstrings", "mkdocstrings_handlers.python", "mkdocs_gen_files",
                 "mkdocs_literate_nav", "jupytext")
MISSING = [m for m in SITE_PACKAGES if importlib.util.find_spec(m.split(".")[0]) is None
           or (m == "mkdocstrings_handlers.python" and importlib.util.find_spec(m) is None)]
needs_site = pytest.mark.skipif(bool(MISSING), reason=f"documentation packages not installed ({', '.join(MISSING)}): "
                                                       "pip install -e '.[docs]'")


def _gen_pages():
    spec = importlib.util.spec_from_file_location("gen_pages", ROOT / "docs" / "_gen" / "gen_pages.py")
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)  # defines the functions; generates nothing outside mkdocs
    return module


@pytest.fixture(scope="module")
def built_site(tmp_path_factory):
    """``mkdocs build --strict`` once for the tests that read the built site: ``(process, site folder)``."""
    site = tmp_path_factory.mktemp("docs") / "site"
    env = dict(os.environ, DISABLE_MKDOCS_2_WARNING="true", NO_MKDOCS_2_WARNING="1",
               PYTHONPATH=os.pathsep.join([str(ROOT), os.environ.get("PYTHONPATH", "")]))
    proc = subprocess.run([sys.executable, "-m", "mkdocs", "build", "--strict", "--site-dir", str(site)],
                          cwd=ROOT, env=env, capture_output=True, text=True, timeout=900)
    return proc, site


@needs_site
def test_site_builds_strict(built_site):
    proc, site = built_site
    warnings = [line for line in proc.stderr.splitlines() if "WARNING" in line and "MkDocs may break" not in line]
    assert proc.returncode == 0, "mkdocs build --strict failed:\n" + "\n".join(warnings or [proc.stderr[-4000:]])
    for page in ("index.html", "getting-started.html", "cli.html", "physics.html", "formats.html",
                 "api/index.html", "api/fit.html", "api/gap.html", "tutorials/01_free_tyre.html"):
        assert (site / page).stat().st_size > 2000, page
    api = (site / "api" / "fit.html").read_text()
    assert 'id="ringfit.fit.posterior.Posterior.to_inference_data"' in api  # rendered from its docstring
    assert "Examples" in api and "&gt;&gt;&gt;" in api
    tutorial = (site / "tutorials" / "01_free_tyre.html").read_text()
    assert 'href="../physics.html#21-inextensible-ring-eq-18-s"' in tutorial  # "docs/physics.md §2.1" linked
    index = (site / "api" / "index.html").read_text()
    import ringfit

    for name in ringfit.__all__:  # every top-level name links to where it is documented
        assert f"ringfit.{name}</code></a>" in index, name


@needs_site
def test_api_pages_show_only_what_a_module_exports(built_site):
    """A module with ``__all__``: its page shows the names in it (a ``#:`` constant included) and no other name,
    however documented (an internal constant with its ``#:`` comment stays off the page)."""
    import griffe

    proc, site = built_site
    assert proc.returncode == 0, proc.stderr[-4000:]
    gen = _gen_pages()
    loaded = griffe.load("ringfit", search_paths=[str(ROOT)], allow_inspection=False)
    hidden = shown = 0
    for page, modules in gen.api_sections():
        html = (site / "api" / f"{page}.html").read_text()
        for dotted in modules:
            module = loaded if dotted == "ringfit" else loaded[dotted[len("ringfit."):]]
            if not module.exports:
                continue
            for name, obj in module.members.items():
                if obj.is_alias or not obj.is_attribute or obj.lineno is None:
                    continue
                comment = module.lines[obj.lineno - 2].lstrip().startswith("#:") if obj.lineno > 1 else False
                if not comment:
                    continue
                on_page = f'id="{dotted}.{name}"' in html
                if name in module.exports:
                    assert on_page, f"{dotted}.{name} is in __all__ and documented, but not on api/{page}.html"
                    shown += 1
                else:
                    assert not on_page, f"{dotted}.{name} is not in __all__, but on api/{page}.html"
                    hidden += 1
    assert hidden >= 20 and shown >= 20, (hidden, shown)  # both kinds exist: the test can fail
    gap = (site / "api" / "gap.html").read_text()
    assert 'id="ringfit.gap.modal.OUTLIER_Z"' in gap and 'id="ringfit.gap.modal.CONTACT_BRANCH"' not in gap


@needs_site
def test_undocumented_public_names_are_found(tmp_path):
    gen = _gen_pages()
    pkg = tmp_path / "toypkg"
    pkg.mkdir()
    (pkg / "__init__.py").write_text('"""A toy package."""\n')
    (pkg / "mod.py").write_text(
        '"""A module."""\n\n'
        "class Base:\n"
        '    """A base."""\n\n'
        "    def run(self):\n"
        '        """Run it."""\n\n'
        "class Child(Base):\n"
        '    """A child."""\n\n'
        "    def run(self):  # inherits Base.run's docstring\n"
        "        return 1\n\n"
        "    def extra(self):\n"
        "        return 2\n\n"
        "def documented():\n"
        '    """Yes."""\n\n'
        "def bare():\n"
        "    return 0\n\n"
        "def _private():\n"
        "    return 0\n\n"
        "class Bare:\n"
        "    pass\n"
    )
    missing = gen.check_documented(["toypkg", "toypkg.mod"], package="toypkg", root=tmp_path)
    assert sorted(missing) == ["toypkg.mod.Bare", "toypkg.mod.Child.extra", "toypkg.mod.bare"]


@needs_site
def test_api_reference_has_a_page_for_every_part_of_the_package():
    gen = _gen_pages()
    sections = dict(gen.api_sections())
    parts = {p.stem if p.suffix == ".py" else p.name for p in (ROOT / "ringfit").iterdir()
             if not p.name.startswith(("_", ".")) and (p.suffix == ".py" or (p / "__init__.py").exists())}
    assert set(sections) == parts - {"cli"}  # the CLI has its own page
    modules = {m for ms in sections.values() for m in ms}
    for path in (ROOT / "ringfit").rglob("*.py"):
        rel = path.relative_to(ROOT).with_suffix("")
        dotted = ".".join(rel.parts[:-1] if rel.name == "__init__" else rel.parts)
        if dotted != "ringfit" and not any(p.startswith("_") for p in dotted.split(".")) \
                and not dotted.startswith("ringfit.cli"):
            assert dotted in modules, dotted  # a new module appears without configuration


@needs_site
def test_cli_reference_lists_every_command_and_option():
    gen = _gen_pages()
    text = gen.cli_markdown()
    from ringfit.cli import build_parser

    parser = build_parser()
    subs = gen._subcommands(parser)
    assert len(subs) >= 16
    for name, sub in subs.items():
        assert f"\n## ringfit {name}\n" in text, name
        for action in sub._actions:
            if action.help != argparse.SUPPRESS and action.option_strings:
                assert f"`{action.option_strings[0]}" in text, (name, action.option_strings)
    assert "`--netcdf FILE.nc`" in text


@needs_site
def test_every_notebook_becomes_a_tutorial_page():
    gen = _gen_pages()
    for path in sorted((ROOT / "notebooks").glob("*.py")):
        md = gen.notebook_markdown(path)
        assert md.startswith("# "), path.name
        code = [line for line in path.read_text().splitlines() if line and not line.startswith("#")]
        # every line of code is on the page, inside a python fence
        for line in code:
            assert line in md, (path.name, line)
        assert md.count("```python") == sum(1 for line in path.read_text().splitlines() if line == "# %%")


@needs_site
def test_tutorials_show_the_figures_their_notebooks_save(tmp_path, caplog):
    """Every figure a notebook saves under a literal name is rendered in docs/figures/ and shown under the code
    cell that saves it; one that is not rendered is a warning (a failure under --strict)."""
    gen = _gen_pages()
    shown = 0
    for path in sorted((ROOT / "notebooks").glob("*.py")):
        md = gen.notebook_markdown(path)
        for name in gen.saved_figures(path.read_text()):
            png = ROOT / "docs" / "figures" / path.stem / name
            assert png.is_file() and png.read_bytes()[:8] == b"\x89PNG\r\n\x1a\n", (path.name, name)
            image = f"![{name}](../figures/{path.stem}/{name})"
            assert md.count(image) == 1, (path.name, name)
            # under the cell that saves it: the image follows the fence that holds the saving line
            code, between = md[:md.index(image)].rsplit("```python", 1)[1].split("```", 1)
            assert f'OUT / "{name}"' in code, (path.name, name)
            assert all(line.startswith("![") for line in between.split() if line), (path.name, name, between)
            shown += 1
    assert shown >= 10
    book = tmp_path / "99_toy.py"
    book.write_text('# %% [markdown]\n# # Toy\n\n# %%\nfig.savefig(OUT / "never_rendered.png")\n'
                    '# %%\nfig.savefig(OUT / f"{name}.png")  # an f-string name is not resolved\n')
    with caplog.at_level("WARNING", logger="mkdocs.plugins.ringfit_docs"):
        md = gen.notebook_markdown(book, figures=tmp_path / "figures")
    assert "![never_rendered.png]" not in md  # no image for it
    assert [r.getMessage() for r in caplog.records if "never_rendered.png" in r.getMessage()], caplog.text
    assert gen.saved_figures(book.read_text()) == ["never_rendered.png"]


@needs_site
def test_section_references_become_links_and_a_missing_section_is_a_warning(caplog):
    from types import SimpleNamespace

    spec = importlib.util.spec_from_file_location("docs_hooks", ROOT / "docs" / "_gen" / "hooks.py")
    hooks = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(hooks)
    physics = (ROOT / "docs" / "physics.md").read_text()
    files = SimpleNamespace(get_file_from_path=lambda p: SimpleNamespace(
        content_string=physics if p == "physics.md" else "# formats\n\n## 5. Gap diagnosis — x\n"))
    hooks.on_files(files, None)
    page = SimpleNamespace(url="api/fit.html", file=SimpleNamespace(src_uri="api/fit.md"))
    html = ("<p>eq. 18 (<code>docs/physics.md §2.1</code>), see formats.md §5 and :func:<code>~ringfit.fit.x</code>"
            "</p><pre>docs/physics.md §2.1 stays in code blocks</pre><a href='x'>physics.md §2.1</a>")
    out = hooks.on_page_content(html, page, None, None)
    assert '<a href="../physics.html#21-inextensible-ring-eq-18-s"><code>physics.md §2.1</code></a>' in out
    assert '<a href="../formats.html#5-gap-diagnosis-x"><code>formats.md §5</code></a>' in out
    assert "<pre>docs/physics.md §2.1 stays in code blocks</pre>" in out and "<a href='x'>physics.md §2.1</a>" in out
    assert ":func:" not in out and "<code>x</code>" in out
    with caplog.at_level("INFO", logger="mkdocs.plugins.ringfit_links"):
        out = hooks.on_page_content("<p>see docs/physics.md §99.9 and formats.md §5.7</p>", page, None, None)
    assert any("§99.9" in r.getMessage() and "no such section" in r.getMessage() and r.levelname == "WARNING"
               for r in caplog.records)
    assert '<a href="../formats.html#5-gap-diagnosis-x"><code>formats.md §5.7</code></a>' in out  # its section
    assert not any("§5.7" in r.getMessage() and r.levelname == "WARNING" for r in caplog.records)
