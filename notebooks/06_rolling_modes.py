# %% [markdown]
# # 06 — The rolling, loaded tyre's modes: Campbell diagram, what the sensor sees, matching measured tables
#
# A tyre that rolls **and** touches the ground is neither the free ring of eq. 18, nor the spinning ring of
# eq. 25/26, nor the standing loaded tyre: the contact patch stays where it is while the belt runs through it.
# In the space-fixed frame that system is time-invariant, and its modes (docs/physics.md §3.7) are what a
# cleat test identifies. Each of them is a mixture of circumferential harmonics `k`, because the patch couples
# them; a fixed observer sees one frequency ω, the co-rotating sensor sees lines at ω + kΩ.
#
# This notebook goes the way a test engineer would:
#
# 1. the model's **Campbell diagram** of the Table 9 tyre at 4 kN on the 1.2192 m drum, in both frames;
# 2. synthetic **cleat tests** at 30 and 50 km/h whose waves are the modes of that model (known answer);
# 3. angle × time field → **SSI** → mode tables (fixed frame), labelled with (n, direction) by the model;
# 4. the tables **matched** to the branches, and what the matcher says about a row that does not fit.

# %%
import os
from pathlib import Path

import numpy as np

import ringfit  # noqa: F401  (float64)
from ringfit.gap.campbell import label_identified_modes, match_tables
from ringfit.io.modes import ModeTable
from ringfit.params import table9
from ringfit.physics.campbell import campbell_diagram
from ringfit.report.campbell_plots import plot_campbell
from ringfit.synth.cleat import CleatBench
from ringfit.targets.cleat import angle_time_field
from ringfit.targets.rolling_modes import identify_rolling_modes

OUT = Path(os.environ.get("RINGFIT_NOTEBOOK_OUT", "."))
GEOMETRY, RING = table9()
DRUM, LOAD = 1.2192, 4000.0

# %% [markdown]
# ## 1. The Campbell diagram of the model
# Modes with dominant order n ≤ 15 at 0–80 km/h (one jit, vmapped over speeds), tracked into branches by the
# continuity of their harmonic content. At standstill every order splits into a contact-symmetric (`extr`) and a
# contact-antisymmetric (`0`) mode; with speed, rotation turns them into backward and forward travelling waves.
# In the fixed frame the backward waves fall (Doppler, −nΩ) and the forward ones rise.

# %%
speeds = np.arange(0.0, 80.1, 10.0)
diagram = campbell_diagram(RING, GEOMETRY, LOAD, speeds, drum_diameter_m=DRUM)
print(f"{diagram.branches} branches; R_e = {diagram.rolling_radius_m * 1e3:.1f} mm; patch "
      f"{diagram.leading_deg[0]:+.2f}° … {diagram.trailing_deg[0]:+.2f}° on the drum; all solves converged: "
      f"{bool(diagram.ok.all())}")
direction, tag = diagram.direction(), diagram.tag()
print("branch   0 km/h              40 km/h                80 km/h")
for b in range(10):
    cells = [f"{diagram.fixed_hz[s, b]:6.1f} Hz n={diagram.order[s, b]:<2d} {direction[s, b]:8s} {tag[s, b]:4s}"
             for s in (0, 4, 8)]
    print(f"{b + 1:4d}   " + "  ".join(cells))
plot_campbell(diagram, OUT / "campbell_fixed.png", frame="fixed")
plot_campbell(diagram, OUT / "campbell_sensor.png", frame="sensor")

# %% [markdown]
# **Reading it.** `campbell_fixed.png` is what a fixed observer (or SSI of a cleat field sampled at fixed
# angles) sees; `campbell_sensor.png` what the co-rotating accelerometer sees: each branch at its strongest
# line ω + kΩ, with its weaker lines as grey dots. The same mode shows up roughly nΩ/2π apart in the two
# frames (8–9 Hz per order at 50 km/h), and its secondary lines can land on another mode's main line: a
# shape-based n label of a single sensor is therefore fragile. Labels can change along a branch where the
# contact mixes neighbouring harmonics.

# %% [markdown]
# ## 2–3. Cleat tests whose waves are the model's modes, identified by SSI
# `CleatBench(modes="loaded")` excites the modes of the same model (patch of the drum solve) with an impulse at
# the leading edge of the patch; the recording goes through the same chain as a real one (encoder, hall,
# noise, IEPE high-pass). The field is rebuilt from the passes and SSI gives a fixed-frame mode table; the
# model adds its (n, direction) labels and flags labels it cannot support.

# %%
half = 0.5 * (diagram.trailing_deg[0] - diagram.leading_deg[0])
tables, truths = [], {}
for v in (30.0, 50.0):
    bench = CleatBench(steady="analytic", fs_hz=6400.0, noise_ms2=5.0, modes="loaded", speed_kmh=v,
                       contact_half_angle_deg=half, orders=(1, 2, 3, 4, 5, 6, 7), axes=("radial",))
    truths[v] = bench.generating_modes()
    field = angle_time_field(bench.record(60.0), sectors=128, duration_s=0.12)
    table = identify_rolling_modes(field, channels=32).table
    table.source = f"cleat{v:g}.modes.csv"
    labelled, flags = label_identified_modes(table, RING, GEOMETRY, channels=32, drum_diameter_m=DRUM, speeds_kmh=speeds)
    tables.append(labelled)
    print(f"\n{v:g} km/h: {len(table)} modes identified, {len(truths[v]['n'])} generated; {sum(map(bool, flags))} flagged")
    for i in range(len(table)):
        x = labelled.extra
        print(f"  {table.freq_hz[i]:7.2f} Hz  SSI n={table.n[i]:<2d} {table.branch[i] or table.tag[i]:9s} "
              f"model n={x['model_n'][i] or '-':<2s} {x['model_direction'][i] or '-':9s}"
              + (f"  FLAG: {flags[i]}" if flags[i] else ""))

# %% [markdown]
# ## 4. Both tables matched to the branches
# Each row is compared with the branches at its own speed (from the sidecar's `rotation_hz`) in its frame
# (`fixed`), with σ = √(freq_std² + (τ · f_model)²), τ the model's relative σ taken from the data (the robust
# scale of the matched rows' residuals beyond their freq_std; 2 % in a first pass). Labels that contradict a
# branch cost as much as 2σ of frequency, so a row is matched by frequency first and by its labels among the
# branches near it.

# %%
res = match_tables(tables, RING, GEOMETRY, drum_diameter_m=DRUM, speeds_kmh=speeds)
print(res.summary() + "; " + res.tolerance_note)
print(" speed   f [Hz]  SSI label      branch  model [Hz]  model label        error     z   status")
for r in res.rows:
    lab = f"n={r['n']} {r['branch'] or r['tag']}"
    model = f"n={r['model_n']} {r['model_direction']}" if r["model_n"] is not None else "-"
    print(f"{r['speed_kmh']:5.1f}  {r['freq_hz']:7.2f}  {lab:14s} {str(r['model_branch']):>6s}  {r['model_hz']:9.2f}  "
          f"{model:17s} {r['error_pct']:+5.2f} % {r['z']:+5.2f}  {r['status']}")
hits = 0
for v, table in zip((30.0, 50.0), tables):
    t = truths[v]
    for j in range(len(t["n"])):
        f = t["fixed_hz"][j]
        rows = [r for r in res.rows if r["source"] == table.source and abs(r["freq_hz"] - f) < 0.005 * f]
        if rows and rows[0]["status"] == "matched":
            assert rows[0]["model_n"] == t["n"][j], (v, rows[0], t["n"][j])
            hits += 1
print(f"\n{hits} of {sum(len(t['n']) for t in truths.values())} generating modes found by SSI and matched with the "
      "right n")
plot_campbell(diagram, OUT / "campbell_matched.png", frame="fixed", match=res)

# %% [markdown]
# **Reading it.** Every identified row sits on a branch within a fraction of a percent, with the model's n and
# direction equal to the SSI's shape-based ones: the identification and the model agree on what each mode is.
# Rows that are no mode of the model (noise poles with random shapes, an order the 32 channels cannot resolve)
# are flagged rather than silently labelled.
#
# ## A row that does not fit: the frame mix-up
# The source study doubted its rolling tables because they changed non-monotonically with speed. Here is how
# such a row reads: at 50 km/h we add a row carrying the label of a 30 km/h row, but at the frequency the
# co-rotating sensor would show for that branch — as if one table had been written in the other frame.

# %%
first = next(r for r in res.rows if abs(r["speed_kmh"] - 30.0) < 0.5 and r["status"] == "matched" and r["branch"])
b = first["model_branch"] - 1
s50 = int(np.argmin(np.abs(diagram.speed_kmh - 50.0)))
sensor_hz = float(diagram.sensor_line()[0][s50, b])
t50 = tables[1]
doctored = ModeTable(freq_hz=[sensor_hz], n=[first["n"]], branch=[first["branch"]], condition=dict(t50.condition),
                     source="doctored50.modes.csv")
res2 = match_tables([tables[0], doctored], RING, GEOMETRY, drum_diameter_m=DRUM, speeds_kmh=speeds)
row = res2.rows[-1]
print(f"{row['freq_hz']:.1f} Hz at 50 km/h labelled n={row['n']} {row['branch']}: {row['status']}\n  {row['note']}")
assert row["status"] != "matched" and "frame mix-up" in row["note"]

# %% [markdown]
# The matcher does not just say "unexplained": it follows the branch through the 30 km/h row to 50 km/h,
# says where it goes, and finds that the row is that branch **seen in the rotating frame**. The same test
# tries a secondary line ω + kΩ of another mode and a different n. On real tables (the thesis's 20/40/60 km/h
# at 4 kN) this is the first thing to run before trusting a non-monotonic trend:
# `ringfit campbell --tyre FITTED.toml --load 4000 --drum 1.2192 --speeds 0:80:5 --modes t20.modes.csv
# t40.modes.csv t60.modes.csv --out rolling.campbell.csv --plot rolling.png`.
