# %% [markdown]
# # 05 — Cleat test: from one co-rotating sensor to the rolling tyre's waves and modes
#
# A tyre rolls on a drum with a cleat; one accelerometer turns with the tyre, a rim encoder gives its
# angle and a hall sensor marks each cleat arrival (the source's §4.2, §4.6). Here the recording is
# synthetic (`ringfit.synth.cleat`), so every step can be checked against the truth:
#
# 1. continuous recording → rolling profile (no-cleat reading by angle),
# 2. hall pulses → cleat arrivals → angle × time field, static pattern subtracted, coverage (figure 23),
# 3. polar snapshots and animation of the radial acceleration (figure 37),
# 4. SSI on the field → modes of the rolling tyre, compared with eq. 25/26 of the ring.

# %%
import os
from pathlib import Path

import numpy as np

import ringfit  # noqa: F401  (float64)
from ringfit.gap.campbell import compare_with_ring
from ringfit.io.continuous import read_continuous
from ringfit.report.cleat_plots import animate_field, plot_coverage, plot_field_map, plot_polar_snapshots
from ringfit.synth.cleat import CleatBench
from ringfit.targets.cleat import angle_time_field, coverage_points, field_error
from ringfit.targets.rolling_modes import identify_rolling_modes
from ringfit.targets.rolling_profile import rolling_profile

OUT = Path(os.environ.get("RINGFIT_NOTEBOOK_OUT", "."))

# %% [markdown]
# ## A synthetic drum test
# Table 9 tyre at 40 km/h, 4 kN on the 1.2192 m drum. The steady reading comes from the rolling ring
# model (contact on the drum, gravity, sensor axes turning with the belt); each cleat hit excites the
# rotating ring's backward and forward waves n = 1…8 (`modes="free"`: the free spinning ring, eq. 25/26, a
# known analytic truth for the signal chain). A tyre loaded on the drum has other modes: the patch turns the
# forward waves into hybrids with the backward ones (docs/physics.md §3.7, notebook 06, `ringfit example
# cleat`). Sampling at 6.4 kHz keeps the notebook quick.

# %%
bench = CleatBench(speed_kmh=40.0, fs_hz=6400.0, steady="ring", noise_ms2=5.0)
print(f"Ω = {bench.omega:.2f} rad/s, drum period {1e3 * bench.drum_period_s:.1f} ms, "
      f"drum/tyre circumference ratio {bench.circumference_ratio:.4f}")
bench.write(OUT / "cleat40.records.npz", 90.0, overwrite=True)
bench.write(OUT / "roll40.records.npz", 20.0, cleat=False, overwrite=True)

# %% [markdown]
# ## Rolling profile (no cleat)

# %%
with read_continuous(OUT / "roll40.records.npz") as rec:
    prof = rolling_profile(rec, points=1024)
truth = bench.profile_truth(prof.angle_deg, "radial")
print(f"{prof.full_revolutions} revolutions; radial rms error vs truth {np.sqrt(np.mean((prof.channel('radial') - truth) ** 2)):.2f} m/s² "
      f"(median revolution spread {np.nanmedian(prof.spread[0]):.2f} m/s²)")

# %% [markdown]
# ## The angle × time field

# %%
rec = read_continuous(OUT / "cleat40.records.npz")
field = angle_time_field(rec, sectors=128, duration_s=0.15, baseline=prof)
cov = field.coverage()
print(cov)
err = field_error(field, lambda p, t: bench.cleat_field(p, t, "radial"), "radial", tau_min_s=bench.envelope_s)
print(f"field vs truth after the enveloping phase: rms {err['rms']:.2f} m/s² = {100 * err['relative']:.1f} % of the truth rms")
pts = {k: coverage_points(rec, field.arrivals, k, 0.15, step=2) for k in (10, 50)}
plot_coverage(pts, OUT / "coverage.png")
plot_field_map(field, OUT / "field.png", tau_max_s=0.08)
rec.close()

# %% [markdown]
# ## Figure 37: radial acceleration around the tyre after the impact

# %%
plot_polar_snapshots(field, [0.0, 0.004, 0.008, 0.012, 0.03, 0.06], OUT / "snapshots.png")
animate_field(field, OUT / "cleat40.gif", tau_max_s=0.06, frames=30)

# %% [markdown]
# ## Modes of the rolling tyre (fixed frame) and the ring's prediction

# %%
modes = identify_rolling_modes(field, channels=32, orders=range(4, 61, 2))
rows = compare_with_ring(modes.table, bench.ring, bench.geometry, field.rotation_hz)
print(" n  branch     tag    f [Hz]  eq.26 [Hz]  eq.25 [Hz]  Doppler nΩ/2π")
for r in rows:
    print(f"{r['n']:2d}  {r['branch']:9s} {r['tag']:5s} {r['freq_hz']:8.2f}  {r['fixed_pred_hz']:9.2f}  "
          f"{r['rotating_pred_hz']:9.2f}  {r['doppler_hz']:8.2f}")
assert max(abs(r["error_hz"]) for r in rows) < 2.0
