# %% [markdown]
# # 08 — Identify the tyre once, then estimate its load
#
# The source study's use case in two commands: identify the ring from everything measured on the
# tyre whose condition is known (free modes, standing loaded tables at their load, rolling
# profiles at their load and speed; docs/physics.md §11), and use that one ring — with its
# uncertainty — to estimate the load of a profile whose load is unknown (§10).
#
# The data are `ringfit example identify`: a synthetic tyre with a known truth (its README).

# %%
import json
import math
import os
from pathlib import Path

import numpy as np

import ringfit  # float64
from ringfit.cli import main

OUT = Path(os.environ.get("RINGFIT_NOTEBOOK_OUT", "."))
ringfit.enable_compilation_cache()
example = OUT / "identify-example"
main(["example", "identify", "--out", str(example), "--force", "--quiet"])
print((example / "README.md").read_text().split("## Try")[0])

# %% [markdown]
# ## One joint fit over every state
# Each kind of measurement is a block of residuals on the one engine; each block's noise comes
# from its own residual (profiles: per revolution harmonic, so coloured noise counts as the fewer
# independent rows it is). The table of Fisher shares says which data pin which parameter.

# %%
tyre_file = OUT / "identified.tyre.toml"
assert main(["identify", str(example / "case"), "--out", str(tyre_file), "--force", "--quiet"]) == 0
report = json.loads((OUT / "identified.identify.json").read_text())
truth = (example / "README.md").read_text()
for name, p in report["parameters"].items():
    print(f"{name:14s} {p['value']:.5g}  (95 %: {p['lo95']:.5g} … {p['hi95']:.5g}, σ ln {p['sd_ln']:.3g})")

# %% [markdown]
# EI is pinned by the profiles (the bending length near the patch), k_tread by the profiles and
# the loaded tables together, ρA by the free and loaded modes:

# %%
shares = {b: v["fisher_share"] for b, v in report["blocks"].items()}
for b, row in shares.items():
    print(f"{b:14s} " + " ".join(f"{k}={v:.2f}" for k, v in row.items()))

# %% [markdown]
# The same from the saved report as a figure: per parameter, each block's share of its Fisher information
# (a bar sums to 1), and in the legend each block's rows and weighted residual RMS (≈ 1: the block's noise
# scale fits its residual).

# %%
import matplotlib.pyplot as plt  # noqa: E402

names = [k for k in report["parameters"] if any(k in row for row in shares.values())]
fig, ax = plt.subplots(figsize=(7, 0.45 * len(names) + 1.6), layout="constrained")
left = np.zeros(len(names))
for b, v in report["blocks"].items():
    share = np.array([shares[b].get(k, 0.0) for k in names])
    ax.barh(names, share, left=left, label=f"{b}: {v['rows']} rows, RMS {v['rms']:.2f}")
    left += share
ax.invert_yaxis()
ax.set_xlabel("share of the parameter's Fisher information")
ax.legend(fontsize=7, loc="upper left", bbox_to_anchor=(1.01, 1.0))
fig.savefig(OUT / "identify_blocks.png", dpi=110)

# %% [markdown]
# ## Free modes alone tell EI poorly
# The same identification from the free table alone: the bending term is a small part of eq. 18 for
# n ≤ 9, so EI's σ is many times larger than with the profiles (how many depends on the table's
# noise: ~100 % on the source study's real table, a few per cent on this clean synthetic one).

# %%
import shutil  # noqa: E402

bare = OUT / "identify-no-profiles"
shutil.rmtree(bare, ignore_errors=True)
shutil.copytree(example / "case", bare, ignore=shutil.ignore_patterns("*.profile.*", "loaded*"))
from ringfit.fit.identify import identify, read_identify_folder  # noqa: E402

free_only = identify(read_identify_folder(bare))
print(f"EI σ(ln): free modes alone {free_only.parameters()['ei']['sd_ln']:.2f}, "
      f"every state {report['parameters']['ei']['sd_ln']:.3f}")

# %% [markdown]
# ## The load of a profile whose load is unknown
# `estimate` reads the identified tyre file; its `[ring.covariance]` carries σ(ln k_trd), which it
# propagates into the load interval (the load and k_trd are ~99 % correlated in one profile).

# %%
est_file = OUT / "unknown.estimate.json"
assert main(["estimate", str(example / "unknown-load.profile.csv"), "--tyre", str(tyre_file), "--out",
             str(est_file), "--force", "--quiet"]) == 0
est = json.loads(est_file.read_text())["load_n"]
print(f"load {est['value']:.0f} N (95 %: {est['lo']:.0f} … {est['hi']:.0f} N); truth 4500 N")
assert est["lo"] < 4500.0 < est["hi"]
