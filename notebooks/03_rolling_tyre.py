# %% [markdown]
# # 03 — The rolling tyre: contact patch, sensor profiles and the tread stiffness
#
# Gong's flexible ring rolling steadily on a drum under 4 kN (docs/physics.md §4): we solve the
# contact with the tread springs, look at the deformed ring and the contact pressure, read the
# co-rotating accelerometer at several speeds (§4.6, §5), and fit the tread stiffness to
# synthetic "measured" profiles with a known truth — least squares and an emcee posterior.

# %%
import math
import os
import time
from pathlib import Path

import numpy as np

import ringfit  # float64
from ringfit.fit.rolling import fit_rolling, sample_rolling_posterior
from ringfit.params import table9
from ringfit.physics.contact import contact_length, patch_edges
from ringfit.report.rolling_plots import contact_pressure_figure, deformed_ring_figure, profiles_figure
from ringfit.physics.profile import simulate_profile
from ringfit.synth.profiles import synthetic_profile

OUT = Path(os.environ.get("RINGFIT_NOTEBOOK_OUT", "."))
ringfit.enable_compilation_cache()  # compiled solves and fits go to disk: a second run skips XLA compilation
geometry, ring = table9()
DRUM = 1.2192  # m, the source study's test drum

# %% [markdown]
# ## One operating point: 30 km/h on the drum
# The load is imposed; the axle height is solved for together with the contact patch.

# %%
prof, sol = simulate_profile(ring, geometry, speed_kmh=30.0, load_n=4000.0, drum_diameter_m=DRUM, with_solution=True)
omega = 2 * np.pi * prof.condition["rotation_hz"]
lead, trail = np.degrees(patch_edges(sol))
print(f"Ω = {omega:.2f} rad/s, deflection {1e3 * float(sol.deflection):.2f} mm, "
      f"patch {lead:+.2f}° … {trail:+.2f}° ({1e3 * float(contact_length(sol)):.1f} mm), "
      f"p_max {float(sol.pressure.max()):.4g} N/m, Fx {float(sol.fx):+.1f} N (rearward: hysteresis)")
deformed_ring_figure(sol, geometry, scale=5).savefig(OUT / "03_deformed_ring.png")
contact_pressure_figure(sol).savefig(OUT / "03_contact_pressure.png")

# %% [markdown]
# ## The sensor at several speeds
# With χ = 1 and an inextensible ring the deformation does not depend on speed, so the
# baseline accelerations scale exactly with Ω² (docs/physics.md §4.1).

# %%
speeds = (10.0, 30.0, 50.0, 60.0)
sims = [simulate_profile(ring, geometry, speed_kmh=v, load_n=4000.0, drum_diameter_m=DRUM) for v in speeds]
model = np.stack([p.channels for p in sims])
angle = sims[0].angle_deg
profiles_figure(angle, model, speeds, title="baseline sensor (mean removed)").savefig(OUT / "03_profiles.png")
scaled = [p.channels / (2 * np.pi * p.condition["rotation_hz"]) ** 2 for p in sims]
print("max |profile/Ω² − profile(10 km/h)/Ω²| =", max(np.abs(s - scaled[0]).max() for s in scaled), "m")

# %% [markdown]
# ## Fit the tread stiffness
# Synthetic measurements: truth k_trd = 25 MN/m², 2 m/s² white noise, four speeds.
# The ring's stiffness and density are those of the natural-frequency fit (Table 9).
# The profiles are read as `ringfit identify` reads them (the profile block, docs/physics.md §11):
# revolution-harmonic rows, each run's gain and angle offset (one sensor's prior), each run's sensor nuisances
# (tilt, IEPE corner, liner offset, tangential gain, under their priors), and the noise per profile, channel and
# harmonic estimated from the fit's own residual.

# %%
truth = ring.replace(k_tread=25e6)
measured = [synthetic_profile(truth, geometry, v, drum_diameter_m=DRUM, noise_ms2=2.0, seed=i)
            for i, v in enumerate((20.0, 30.0, 40.0, 50.0))]
t0 = time.perf_counter()
result = fit_rolling(measured, geometry, ring)
print(f"(first call includes compilation: {time.perf_counter() - t0:.1f} s)")
print(result.summary())
print("gains", np.round(result.extra["gain"], 4), "angle offsets [deg]", np.round(result.extra["angle_offset_deg"], 3))
profiles_figure(result.extra["angle_deg"], result.extra["model"], result.extra["speed_kmh"],
                result.extra["measured"], title="measured vs fitted").savefig(OUT / "03_fit.png")

# %% [markdown]
# ## Posterior (emcee, vectorised over walkers)

# %%
post = sample_rolling_posterior(result, steps=150, seed=0)  # k_trd and the 24 nuisances: 50 walkers
row = next(r for r in post.summary_table(level=0.6827) if r["name"] == "k_tread")
lo, med, hi = row["lo"], row["median"], row["hi"]
print(f"k_trd posterior: {med:.5g} (68 %: {lo:.5g} … {hi:.5g}); least squares {result.values['k_tread']:.5g} "
      f"± {result.stderr['k_tread']:.2g}; acceptance {np.mean(post.acceptance):.2f}; "
      f"chain {post.chain.shape[0]} steps, τ ≈ {np.nanmax(post.tau):.1f} "
      f"({'converged' if post.converged else 'short chain: more steps for a converged posterior'})")

# %% [markdown]
# The source study instead swept k_trd over a grid at 50 km/h and kept the lowest error;
# `benchmarks/bench_rolling.py` and `tests/test_rolling_fit.py` compare the two: the fit reaches
# the same k_trd (within the grid step and its error) with a few model-evaluation equivalents against 301 sweep
# runs.

# %%
assert math.isclose(result.values["k_tread"], 25e6, rel_tol=0.01)
