# %% [markdown]
# # The free tyre: load → fit → posterior → report
#
# A newcomer's walk through ringfit on the source study's own data: the natural
# frequencies of a 205/55R16 tyre fixed at the rim, identified by covariance SSI
# (Table 2 of the thesis), and Gong's flexible ring, eq. 18 (docs/physics.md §2.1).
#
# Importing `ringfit` switches JAX to float64 for the whole process.

# %%
import os
from pathlib import Path

import numpy as np

import ringfit
from ringfit.data import path
from ringfit.fit.source_procedure import source_study_fit

OUT = Path(os.environ.get("RINGFIT_NOTEBOOK_OUT", "."))

# %% [markdown]
# ## 1. Load the tyre and the mode table
# `table9.tyre.toml` holds the geometry, the pressure and the thesis's parameters
# (used here only as starting values); the mode table has nine structural modes
# n = 1…9 and one acoustic (cavity) mode, which the ring fit leaves out.

# %%
tyre = ringfit.read_tyre(path("table9.tyre.toml"))
table = ringfit.read_mode_table(path("free-ssi.modes.csv"))
print(tyre.geometry)
for row in table.to_rows():
    print(row["n"], row["kind"], row["freq_hz"])

# %% [markdown]
# ## 2. The model
# eq. 18 with the thesis's Table 9 parameters reproduces its Table 10.

# %%
n = np.arange(0, 11)
print(np.round(ringfit.natural_frequencies(tyre.ring, tyre.geometry, n), 2))

# %% [markdown]
# ## 3. Least squares — and why it needs a prior
# Without a prior, EI runs towards zero: the bending term is a small correction
# to the pressure term for n ≤ 9. ringfit says so instead of returning a number.

# %%
free_fit = ringfit.fit_natural_frequencies(table, tyre.geometry, tyre.ring, prior="none")
print(free_fit.summary())
print(ringfit.identifiability(free_fit).summary())

# %% [markdown]
# With the physically based belt-plate prior on EI (see `ringfit.fit.priors`)
# the problem is well posed; EI is still mostly prior, and the report says so.

# %%
fit = ringfit.fit_natural_frequencies(table, tyre.geometry, tyre.ring, prior="physical")
print(fit.summary())
assert fit.converged

# %% [markdown]
# The thesis's own procedure (three modes solved exactly, ρA stepped) returns its Table 9:

# %%
src = source_study_fit(table, tyre.geometry)
print(src.ring)

# %% [markdown]
# ## 4. Posterior
# emcee with a jitted, vmapped log-probability; it runs until the chain is
# longer than 50 autocorrelation times.

# %%
post = ringfit.sample_posterior(table, tyre.geometry, tyre.ring, prior="physical", progress=False)
for row in post.summary_table():
    print(f"{row['name']:6s} {row['median']:.4g}  [{row['lo']:.4g}, {row['hi']:.4g}]")
print(post.diagnostics()["verdict"])
post.save(OUT / "free_tyre_posterior.h5", overwrite=True)

# %% [markdown]
# ## 5. Report
# A single self-contained HTML file; rebuild it any time from the saved posterior.

# %%
report = ringfit.write_report(OUT / "free_tyre_posterior.h5", OUT / "free_tyre_report.html", overwrite=True)
print("report:", report)

# %% [markdown]
# The report's first figure, drawn from the saved posterior alone: each measured frequency with its σ,
# the least-squares model, and the 95 % posterior predictive band (where a new measurement should fall);
# below, each against the posterior median.

# %%
from ringfit.fit.posterior import natural_frequency_predictive
from ringfit.report.free_plots import modes_figure

saved = ringfit.load_posterior(OUT / "free_tyre_posterior.h5")
n_data, f_data, sigma = (np.asarray(saved.meta["data"][k], dtype=float) for k in ("n", "freq_hz", "sigma_hz"))
band = natural_frequency_predictive(saved, np.arange(max(0, n_data.min() - 1), n_data.max() + 2))
modes_figure(n_data, f_data, sigma, lsq_hz=np.asarray(saved.meta["lsq"]["model_hz"]),
             predictive=band).savefig(OUT / "free_fit.png", dpi=110)
