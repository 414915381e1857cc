# %% [markdown]
# # 07 — Wheel load and contact patch from the one accelerometer
#
# The reason to identify a tyre model at all: once the ring is known, its steady rolling model
# can be inverted for the tyre's state. Here the radial reading of the co-rotating sensor gives the
# vertical load with a 95 % interval and the contact patch (docs/physics.md §10), for one profile
# and then revolution by revolution along a recording whose load changes. The classic feature
# method (edge-peak spacing → load) runs beside it.

# %%
import json
import math
import os
from pathlib import Path

import numpy as np

import ringfit  # float64
from ringfit.fit.estimate import estimate_load, estimate_recording
from ringfit.io.profiles import Profile
from ringfit.params import table9
from ringfit.physics.contact import ContactSolver, contact_length, patch_edges
from ringfit.physics.profile import ProfileModel, simulate_profile
from ringfit.report.estimate_plots import estimate_figure
from ringfit.synth.cases import coloured_noise
from ringfit.synth.cleat import CleatBench

OUT = Path(os.environ.get("RINGFIT_NOTEBOOK_OUT", "."))
ringfit.enable_compilation_cache()  # a second run skips XLA compilation
geometry, ring = table9()  # in practice: the tyre file written by `ringfit fit` + `ringfit fit-rolling`
rng = np.random.default_rng(7)

# %% [markdown]
# ## A profile whose load we pretend not to know
# The "measurement" is the forward model on a finer grid (2048 points, written at 1000 angles)
# with what a real sensor adds: gravity, a 0.8 Hz IEPE high-pass, axes turning with the belt,
# an angle offset of 0.6°, 1 % pink noise. The sidecar has no `load_n` and its speed is a nominal
# 3 % off; there is no encoder rate.

# %%
TRUE_LOAD = 4600.0
sensor = ProfileModel().with_sensor(gravity=9.81, corner_hz=0.8, tilt_gain=1.0)
truth, sol = simulate_profile(ring, geometry, speed_kmh=45.0, load_n=TRUE_LOAD, model=sensor,
                              solver=ContactSolver(n_grid=2048), n_points=1000, offset_rad=math.radians(0.6),
                              with_solution=True)
sigma = 0.01 * np.abs(truth.acc_radial_ms2).max()
channels = truth.channels + np.stack([coloured_noise(rng, 1000, sigma, "pink") for _ in range(2)])
condition = {"speed_kmh": 45.0 * 1.03, "pressure_bar": 2.2, "revolutions": 1}
measured = Profile(truth.angle_deg, channels[0], channels[1], condition=condition, source="measured.profile.csv")

est = estimate_load(measured, geometry, ring)
record = est.to_record("measured.profile.csv")  # what `ringfit estimate` writes (docs/formats.md §7)
print(json.dumps({k: record[k] for k in ("load_n", "patch", "rotation_hz", "fit")}, indent=1))
lead, trail = np.degrees(patch_edges(sol))
print(f"\ntruth: {TRUE_LOAD:.0f} N, patch {lead:+.2f}° … {trail:+.2f}° ({1e3 * float(contact_length(sol)):.1f} mm)")
print(f"estimate: {est.load_n:.0f} N ({100 * (est.load_n / TRUE_LOAD - 1):+.2f} %), 95 % {est.lo:.0f} … {est.hi:.0f} N; "
      f"feature method {est.feature.load_n:.0f} N ({100 * (est.feature.load_n / TRUE_LOAD - 1):+.2f} %)")
estimate_figure(est, title="synthetic profile, 4.6 kN").savefig(OUT / "07_profile_fit.png")

# %% [markdown]
# The gain absorbed the wrong speed (Ω² is 6 % off, the gain ≈ 1/1.03²): the load comes from the
# shape of the reading around the patch, not from its amplitude. The high-pass corner, the tilt and
# the angle offset were fitted as nuisances; gravity's revolution harmonic k = 1 is not fitted at all.

# %%
for key, entry in est.nuisances.items():
    print(f"{key:18s} {entry['value']:.4g}" + (f" ± {entry['stderr']:.2g}" if "stderr" in entry else " (fixed)"))

# %% [markdown]
# ## Revolution by revolution: a load step on the drum
# A continuous recording (docs/records-continuous.md) at 60 km/h whose load steps from 3.0 to
# 5.2 kN after 0.8 s: the averaged profile mixes two loads (and its fit says so), while every
# revolution is fitted on its own — load, gain and angle offset, warm-started from the previous
# revolution in one compiled chain.

# %%
bench = CleatBench(speed_kmh=60.0, load_n=3000.0, load_steps=((0.8, 5200.0),), fs_hz=8192.0, noise_ms2=4.0,
                   highpass_hz=0.5)
record = bench.record(1.8, cleat=False)
ref, revs = estimate_recording(record, geometry, ring)
print("averaged profile:", f"{ref.load_n:.0f} N;", "; ".join(ref.flags) or "no flags")
truth_load = bench.load_at(revs.t_s)
for i in range(len(revs)):
    print(f"rev {revs.revolution[i]:2d}  t = {revs.t_s[i]:.3f} s  load {revs.load_n[i]:6.0f} N "
          f"[{revs.lo[i]:.0f}, {revs.hi[i]:.0f}]  truth {truth_load[i]:.0f}  patch {revs.length_mm[i]:.1f} mm  "
          f"feature {revs.feature_load_n[i]:.0f} N")
estimate_figure(ref, revs, title="load step on the drum").savefig(OUT / "07_load_per_revolution.png")

# %% [markdown]
# From the command line the same is
#
# ```bash
# ringfit estimate run.profile.csv --tyre fitted.tyre.toml --out run.estimate.json --plot fit.png
# ringfit estimate run.records.npz --tyre fitted.tyre.toml --out run.estimate.json --per-revolution revs.csv
# ```
#
# `benchmarks/bench_estimate.py` measures the accuracy over loads, speeds, roads, noise colours and
# sensor settings, what the estimate does with effects it does not model, and the speed per
# revolution. One caution stands out there: the load is only as good as the tyre file's tread
# stiffness (a 10 % error in k_trd moves the load by several percent), so fit k_trd at a known load
# first (`ringfit fit-rolling`).
