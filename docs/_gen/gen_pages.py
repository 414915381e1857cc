"""Pages of the documentation site that are generated at build time (mkdocs-gen-files).

- ``tutorials/NN_name.md``: one per notebook (``notebooks/*.py``, jupytext percent
  format), markdown cells as text and code cells as code; the notebooks are not executed
  here: each figure a code cell saves (``OUT / "name.png"``) is shown under it from
  ``docs/figures/<notebook>/`` (rendered by ``docs/_gen/render_figures.py``; a figure
  saved there but not rendered is a warning, a failure under ``--strict``).
- ``cli.md``: every ``ringfit`` command and option, from the argparse parser that
  ``ringfit.cli.build_parser`` builds (so it cannot drift from ``--help``).
- ``api/``: one page per top-level module or subpackage of ``ringfit`` (found by
  walking the package, so a new module appears without configuration), each module
  rendered by mkdocstrings from its docstrings; ``api/index.md`` lists the top-level
  names. A page shows a module's public surface only (mkdocs.yml ``filters: public``): the
  names in its ``__all__`` where it has one (a constant documented by ``#:`` included, through
  ``comment_docstrings.py``), else its names without a leading underscore; an internal
  constant or helper left out of ``__all__`` is not on the page. Every public function and
  class the reference shows must have a docstring (a public method may inherit its base
  class's): a missing one is a warning, which ``mkdocs build --strict`` turns into a failure.
"""

from __future__ import annotations

import argparse
import logging
import os
import sys
from pathlib import Path

import mkdocs_gen_files

ROOT = Path(__file__).resolve().parents[2]
PACKAGE = ROOT / "ringfit"
#: Modules of ringfit that the API reference leaves out: the command line has its own page.
NOT_IN_API = ("ringfit.cli", "ringfit.__main__")
#: Top-level names that come first in the API reference, then the rest alphabetically.
API_ORDER = ("params", "io", "targets", "physics", "fit", "gap", "batch", "report", "demo", "synth", "errors",
             "data")

log = logging.getLogger("mkdocs.plugins.ringfit_docs")  # warnings here fail `mkdocs build --strict`

if str(ROOT) not in sys.path:
    sys.path.insert(0, str(ROOT))
if str(Path(__file__).resolve().parent) not in sys.path:
    sys.path.insert(0, str(Path(__file__).resolve().parent))

from render_figures import FIGURES, saved_figures  # noqa: E402  (docs/_gen, beside this file)


# ----------------------------------------------------------------------------- tutorials


def notebook_markdown(path: Path, figures: Path = FIGURES) -> str:
    """Markdown of one jupytext percent-format notebook: markdown cells as text, code cells fenced, each figure a
    code cell saves shown under it from ``figures/<notebook stem>/``."""
    import jupytext

    nb = jupytext.read(path, fmt="py:percent")
    rel = path.relative_to(ROOT).as_posix() if path.is_relative_to(ROOT) else path.name
    parts = []
    for cell in nb.cells:
        text = cell.source.strip("\n")
        if not text.strip():
            continue
        if cell.cell_type == "markdown":
            parts.append(text)
        else:
            parts.append(f"```python\n{text}\n```")
            for name in saved_figures(text):  # the figure this cell saves, as the notebook last rendered it
                if (figures / path.stem / name).is_file():
                    parts.append(f"![{name}](../figures/{path.stem}/{name})")
                else:
                    log.warning("tutorial %s: the figure %s it saves is not rendered in docs/figures/%s/ "
                                "(run python docs/_gen/render_figures.py %s)", rel, name, path.stem, path.stem[:2])
    head = parts[0] if parts and parts[0].startswith("# ") else f"# {path.stem}"
    body = parts[1:] if parts and parts[0].startswith("# ") else parts
    note = (f'!!! note "Run it"\n    This page is `{rel}`, a plain Python file in jupytext\'s percent format. '
            f"Run it with\n    `MPLBACKEND=Agg RINGFIT_NOTEBOOK_OUT=/tmp/nb python {rel}`, or open it as a "
            f"notebook with\n    `jupytext --to notebook {rel}`. The figures below are the notebook's own, saved "
            f"when it last ran\n    (`python docs/_gen/render_figures.py`); printed outputs are not shown.")
    return "\n\n".join([head, note, *body]) + "\n"


def write_tutorials() -> None:
    for path in sorted((ROOT / "notebooks").glob("*.py")):
        with mkdocs_gen_files.open(f"tutorials/{path.stem}.md", "w") as fh:
            fh.write(notebook_markdown(path))
        mkdocs_gen_files.set_edit_path(f"tutorials/{path.stem}.md", os.path.relpath(path, ROOT / "docs"))


# ----------------------------------------------------------------------------- CLI reference


def _escape(text: str) -> str:
    return text.replace("|", r"\|").replace("<", "&lt;").replace(">", "&gt;").replace("*", r"\*")


def _subcommands(parser: argparse.ArgumentParser) -> dict[str, argparse.ArgumentParser]:
    for action in parser._actions:
        if isinstance(action, argparse._SubParsersAction):
            return dict(action.choices)
    return {}


def _option_rows(parser: argparse.ArgumentParser) -> list[str]:
    rows = []
    for action in parser._actions:
        if action.help == argparse.SUPPRESS or isinstance(action, argparse._SubParsersAction):
            continue
        if action.option_strings:
            names = ", ".join(action.option_strings)
            if action.nargs != 0:
                names += " " + (action.metavar if isinstance(action.metavar, str) else action.dest.upper())
        else:
            names = action.metavar if isinstance(action.metavar, str) else action.dest
        help_text = (action.help or "").replace("%(default)s", str(action.default)).replace("%%", "%")
        if action.choices and not isinstance(action.choices, dict):
            help_text += f" (one of: {', '.join(map(str, action.choices))})"
        rows.append(f"| `{names}` | {_escape(' '.join(help_text.split()))} |")
    return rows


def cli_markdown() -> str:
    """The CLI reference: usage, description and an option table for every command."""
    os.environ["COLUMNS"] = "100"  # argparse wraps usage lines to the terminal's width
    from ringfit.cli import build_parser

    parser = build_parser()
    lines = ["# Command line", "",
             "Generated from the `ringfit` command's own parser (what `ringfit COMMAND --help` prints). "
             "Exit status: 0 success, 1 the job ran but did not succeed (e.g. a fit that did not converge), "
             "2 bad input (one line naming the file, row, field or option).", ""]
    lines += ["| command | what it does |", "|---|---|"]
    subs = _subcommands(parser)
    helps = {}
    for action in parser._actions:
        if isinstance(action, argparse._SubParsersAction):
            helps = {a.dest: a.help for a in action._choices_actions}
    for name in subs:
        lines.append(f"| [`ringfit {name}`](#ringfit-{name}) | {_escape(helps.get(name) or '')} |")
    for name, sub in subs.items():
        lines += ["", f"## ringfit {name}", ""]
        if sub.description:
            lines += [_escape(" ".join(sub.description.split())), ""]
        lines += ["```text", sub.format_usage().strip(), "```", ""]
        nested = _subcommands(sub)
        if nested:
            lines += [f"Kinds: {', '.join(f'`{k}`' for k in nested)}.", ""]
        rows = _option_rows(sub)
        if rows:
            lines += ["| argument | meaning |", "|---|---|", *rows]
        if sub.epilog:
            lines += ["", "```text", sub.epilog.strip(), "```"]
    return "\n".join(lines) + "\n"


def write_cli() -> None:
    with mkdocs_gen_files.open("cli.md", "w") as fh:
        fh.write(cli_markdown())


# ----------------------------------------------------------------------------- API reference


def _modules(directory: Path, dotted: str) -> list[str]:
    """``dotted`` and every public module below it, depth first, in file order."""
    out = [dotted]
    if not directory.is_dir():
        return out
    for child in sorted(directory.iterdir()):
        if child.name.startswith("_") or child.name.startswith("."):
            continue
        if child.is_dir() and (child / "__init__.py").exists():
            out += _modules(child, f"{dotted}.{child.name}")
        elif child.suffix == ".py":
            out.append(f"{dotted}.{child.stem}")
    return [m for m in out if not m.startswith(NOT_IN_API)]


def api_sections() -> list[tuple[str, list[str]]]:
    """``(name, modules)`` for each page of the API reference: one per top-level module or subpackage."""
    names = []
    for child in PACKAGE.iterdir():
        if child.name.startswith(("_", ".")):
            continue
        if (child.is_dir() and (child / "__init__.py").exists()) or child.suffix == ".py":
            names.append(child.stem if child.suffix == ".py" else child.name)
    names = [n for n in names if f"ringfit.{n}" not in NOT_IN_API]
    names.sort(key=lambda n: (API_ORDER.index(n) if n in API_ORDER else len(API_ORDER), n))
    return [(n, _modules(PACKAGE / n, f"ringfit.{n}")) for n in names]


def check_documented(modules: list[str], package: str = "ringfit", root: Path = ROOT) -> list[str]:
    """Public functions and classes (and their public methods) of ``modules`` without a docstring.

    Read from the source (griffe, as mkdocstrings does), nothing imported. A public method
    without a docstring passes when a base class documents the method of that name.
    """
    import griffe

    loaded = griffe.load(package, search_paths=[str(root)], docstring_parser="numpy", allow_inspection=False)
    missing = []
    for dotted in modules:
        module = loaded if dotted == package else loaded[dotted[len(package) + 1:]]
        for name, obj in module.members.items():
            if obj.is_alias or obj.is_module or name.startswith("_") or not (obj.is_function or obj.is_class):
                continue
            if not obj.docstring:
                missing.append(obj.path)
            if obj.is_class:
                for mname, member in obj.members.items():
                    if mname.startswith("_") or member.is_alias or not member.is_function or member.docstring:
                        continue
                    inherited = False
                    try:
                        for base in obj.resolved_bases:
                            if mname in base.all_members and base.all_members[mname].docstring:
                                inherited = True
                    except Exception:  # an unresolvable base (a third-party class): the method must say
                        pass
                    if not inherited:
                        missing.append(member.path)
    return missing


def api_page(name: str, modules: list[str]) -> str:
    lines = [f"# ringfit.{name}", ""]
    for i, dotted in enumerate(modules):
        if i:
            lines += ["", f"## `{dotted}`", ""]
        # the package's own docstring under the page title; each module under its own heading
        lines += [f"::: {dotted}", "    options:", "      show_root_heading: false",
                  f"      heading_level: {2 if i == 0 else 3}", ""]
    return "\n".join(lines) + "\n"


def api_index() -> str:
    import ringfit

    lines = ["# API reference", "",
             "`import ringfit` gives the names users call most (below); everything else is imported from the "
             "module that defines it. One page per part of the package, lowest layer first; each page renders "
             "its modules' docstrings (NumPy style). Layers import downward only: "
             "errors/data → params → io → targets → physics → fit → gap → batch → report → demo → cli.", "",
             "| name | defined in |", "|---|---|"]
    private = []
    for name in ringfit.__all__:
        module = ringfit._EXPORTS[name]
        lines.append(f"| [`ringfit.{name}`][{module}.{name}] | `{module}` |")
        if any(part.startswith("_") for part in module.split(".")):
            private.append(f"{module}.{name}")  # no page of its own: rendered here
    for dotted in private:
        lines += ["", f"::: {dotted}", "    options:", "      show_root_heading: true", "      heading_level: 2"]
    return "\n".join(lines) + "\n"


def write_api() -> None:
    sections = api_sections()
    summary = ["* [Overview](index.md)"]
    for name, modules in sections:
        with mkdocs_gen_files.open(f"api/{name}.md", "w") as fh:
            fh.write(api_page(name, modules))
        summary.append(f"* [ringfit.{name}]({name}.md)")
    with mkdocs_gen_files.open("api/index.md", "w") as fh:
        fh.write(api_index())
    with mkdocs_gen_files.open("api/SUMMARY.md", "w") as fh:
        fh.write("\n".join(summary) + "\n")
    missing = check_documented([m for _, modules in sections for m in modules])
    for path in missing:
        log.warning("API reference: public name %s has no docstring (document it, or make it private with _)",
                    path)


def main() -> None:
    write_tutorials()
    write_cli()
    write_api()


if __name__ == "<run_path>":  # run by mkdocs-gen-files (runpy.run_path); tests import the functions
    main()
