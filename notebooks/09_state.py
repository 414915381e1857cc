# %% [markdown]
# # 09 — The tyre's state from the one accelerometer
#
# Load, inflation pressure, drive/brake force (with its slip), speed and tread depth, revolution by
# revolution, each with a 95 % interval (docs/physics.md §13). The recordings come from `ringfit example
# state`: the *independent* simulator (`ringfit.synth.state`, §13.7 — its own finite differences, a brush
# iterated to its fixed point, coloured noise, sensor tilt, the IEPE high-pass in time), a true tyre that is
# the example's nominal `tyre.toml` jittered, and recordings whose state is hidden (`blind/`) with the truth
# kept aside (`truth/`).
#
# The tyre we first read them with is the nominal `tyre.toml`, what a user has before identifying anything; the
# last section identifies the tyre from the example's `calibration/` (`ringfit identify` across pressures and
# torque) and reads the same recording with it.

# %%
import csv
import os
import shutil
import warnings
from pathlib import Path

import matplotlib.pyplot as plt
import numpy as np

import ringfit  # float64
from ringfit.cli import main
from ringfit.fit.estimate import state as st
from ringfit.io.continuous import read_continuous
from ringfit.io.tyre import read_tyre
from ringfit.physics.state import TyreState

OUT = Path(os.environ.get("RINGFIT_NOTEBOOK_OUT", "."))
ringfit.enable_compilation_cache()  # a second run skips XLA compilation
example = OUT / "state-example"
main(["example", "state", "--out", str(example), "--blind", "1", "--seconds", "4", "--force", "--quiet"])
print((example / "README.md").read_text().split("Try:")[0])

# %% [markdown]
# ## What one accelerometer can tell
# Before reading a recording: the Fisher information of one revolution (`state_fisher`, §13.5) at the
# example's noise (0.5 % of Ω²R per sample) says which quantities one revolution pins and which trade off.
# The load trades mostly against the **tread depth** (a worn tread is a stiffer, lower tread: the same
# deflection reads as another load), much less against pressure; the speed V = Ω·r_road is known only as
# well as the rolling radius, i.e. the tread depth.

# %%
tyre = read_tyre(example / "tyre.toml")
geometry, ring, laws = tyre.geometry, tyre.ring, tyre.laws
rout = float(geometry.radius + geometry.tread_thickness)
print(f"{'load':>6s} | σ per revolution:  load %  pressure %  Fx % of load  speed %  depth mm | ρ(load, depth) "
      "ρ(load, pressure)")
for load in (1200.0, 3600.0):
    omega = 60 / 3.6 / rout
    f = st.state_fisher(geometry, ring, laws, TyreState(load, float(geometry.pressure), 0.005, 0.005, omega),
                        0.005 * omega**2 * rout)
    t = f.table()
    print(f"{load:6.0f} | {t['load_n']['sd_pct']:24.2f} {t['pressure_bar']['sd_pct']:11.2f} "
          f"{100 * t['fx_n']['sd'] / load:13.2f} {t['speed_kmh']['sd_pct']:8.3f} {t['tread_depth_mm']['sd']:9.2f} | "
          f"{f.corr('load_n', 'tread_depth_mm'):+14.3f} {f.corr('load_n', 'pressure_bar'):+17.3f}")

# %% [markdown]
# ## The state of a blind recording
# One pass over the recording for every whole revolution's radial and tangential harmonics; the averaged
# profile is fitted fully (θ = load, pressure, slip, tread depth and the sensor's nuisances, §13.4), then every
# revolution is one linearised Gauss–Newton step from it (thousands of revolutions per CPU second).


# %%
def read_state(path, fixed=None):
    """(averaged StateEstimate, StateRevolutions) of a continuous recording, as `ringfit estimate --state`."""
    record = read_continuous(path)
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        _, state, revs = st.estimate_recording_state(record, geometry, ring, laws, fixed=fixed)
    return state, revs


blind = example / "blind" / "blind_01.records.npz"
state, revs = read_state(blind)
for key in ("load_n", "pressure_bar", "fx_n", "slip", "speed_kmh", "tread_depth_mm", "rolling_radius_m"):
    q = state.quantities[key]
    print(f"{key:17s} {q['value']:10.5g}  (95 %: {q['lo']:.5g} … {q['hi']:.5g} {q['unit']})  {q['status']}")
print("\n".join(state.untold))
for flag in state.flags:  # what the estimate warns of: a fall-back band, the new tread's bound, a drifting state
    print(f"flag: {flag}")

# %% [markdown]
# ## Against the truth
# The truth is kept per revolution of the simulator (`truth/blind_01.truth.csv`); the load oscillates by up to
# 4 % and Fx ramps within the recording. Each panel is one quantity per revolution with its 95 % band (blue)
# and the truth (black).

# %%
with open(example / "truth" / "blind_01.truth.csv") as fh:
    rows = list(csv.DictReader(fh))
truth = {k: np.array([float(r[k]) for r in rows]) for k in rows[0]}
t_mid = 0.5 * (truth["t_start_s"] + truth["t_end_s"])
keys = ("load_n", "pressure_bar", "fx_n", "speed_kmh", "tread_depth_mm")
fig, axes = plt.subplots(len(keys), 1, figsize=(7, 11), sharex=True)
for ax, key in zip(axes, keys):
    ax.fill_between(revs.t_s, revs.lo[key], revs.hi[key], color="C0", alpha=0.25, label="95 % (per revolution)")
    ax.plot(revs.t_s, revs.values[key], "C0.-", label="estimate")
    ax.plot(t_mid, truth[key], "k-", label="truth")
    ax.set_ylabel(f"{key}")
axes[0].legend(fontsize=8)
axes[-1].set_xlabel("t [s]")
fig.tight_layout()
fig.savefig(OUT / "state_vs_truth.png", dpi=90)
for key in keys:
    err = np.median(revs.values[key]) - np.median(truth[key])
    print(f"{key:15s} median estimate {np.median(revs.values[key]):9.4g}  truth {np.median(truth[key]):9.4g}  "
          f"({err:+.3g})")

# %% [markdown]
# **Read it honestly.** On this simulator the estimate read with the nominal tyre is *not* at the targets
# (`benchmarks/bench_state.py` measures it over many blind recordings): the load, pressure and tread depth move
# together along the ridge the Fisher table shows, pushed by a model-form difference between the two codes of
# about 2 % in load-equivalent (docs/physics.md §13.6). The per-revolution bands are statistical only: they are
# as wide as the revolution's noise, not as the averaged estimate's model error. A recording whose Fx or load
# drifts by more than 5 % of the load is flagged above ("the state drifted within the recording") and fitted on
# stretches of the recording, each at its own load and slip, sharing pressure, tread depth and sensor: an averaged
# profile over a drifting state smears the patch's trailing edge, and on the independent simulator such a ramp
# pushed the worst misses along the ridge (docs/physics.md §13.4 *a drifting state*, §13.6).
#
# ## What a stated pressure and tread depth buy
# A TPMS reading and a known wear (`ringfit estimate --fix pressure=… --fix tread_depth=…` in the CLI) hold two
# of the ridge's directions; load, Fx and speed are then read much closer.

# %%
fixed = {st.PRESSURE: 1e5 * float(np.mean(truth["pressure_bar"])),
         st.TREAD: 1e-3 * float(np.mean(truth["tread_depth_mm"]))}
held, _ = read_state(blind, fixed=fixed)
for key in ("load_n", "fx_n", "speed_kmh"):
    q, free = held.quantities[key], state.quantities[key]
    print(f"{key:10s} free: {free['value']:9.5g}   p, d held: {q['value']:9.5g} (95 %: {q['lo']:.5g} … "
          f"{q['hi']:.5g})   truth {np.mean(truth[key]):9.5g}")

# %% [markdown]
# ## Identify the tyre first, then read its state
# The nominal `tyre.toml` is what a user has before any measurement; `calibration/` holds what they measure
# once per tyre: recordings at known states (two loads, three pressures, a drive and a brake at a stated axle
# torque) and the free tyre's modes at three pressures. `ringfit identify` reads a case folder (docs/formats.md
# §6): `tyre.toml`, the free table at the tyre file's pressure as `free.modes.csv`, the other pressures' free
# tables beside it, and rolling *profiles* — so each calibration recording is first averaged into one with
# `ringfit profile`, which keeps its stated load, pressure, torque and tread depth in the sidecar. identify reads
# every measurement on one road and at the tyre file's tread depth: the drum and the worn-tread recordings stay
# out (`ringfit.synth.examples.calibration_case` does these steps). identify reads each profile through its sensor's
# own nuisances (tilt, IEPE corner, liner offset, tangential gain; §11 *profiles*) and identifies the ring, how it
# scales with pressure (`[ring.pressure]`) and the tread's k_x, with a covariance (§11, §13).

# %%
from ringfit.synth.examples import calibration_case

case = OUT / "state-case"
shutil.rmtree(case, ignore_errors=True)
left = calibration_case(example, case)  # `ringfit profile` of each recording kept, the free tables, tyre.toml
print(sorted(p.name for p in case.iterdir()), "\nleft out:", left)
identified = OUT / "identified.tyre.toml"
assert main(["identify", str(case), "--out", str(identified), "--force", "--quiet"]) == 0

# %% [markdown]
# The same blind recording read with the identified tyre, beside the nominal read and the truth:

# %%
tyre = read_tyre(identified)
geometry, ring, laws = tyre.geometry, tyre.ring, tyre.laws
known, _ = read_state(blind)
for key in keys:
    q, nominal_q = known.quantities[key], state.quantities[key]
    print(f"{key:15s} nominal tyre {nominal_q['value']:9.5g}   identified {q['value']:9.5g} (95 %: {q['lo']:.5g} … "
          f"{q['hi']:.5g})   truth {np.mean(truth[key]):9.5g}")

# %% [markdown]
# One recording is not a verdict, and the identified tyre can read it worse than the nominal one: its calibration
# here is four seconds per state, and a ring identified from it carries its own errors into every reading (EI,
# on which the load–pressure reading leans, is the least pinned). identify reads the tread's friction μ from the
# profiles at a torque, with the tyre file's value (1 here; the simulator's μ differs) as its prior, σ of ln μ 0.1
# unless the file states `friction_sd`, and carries what is left of its doubt into the covariance it writes, so the
# identified intervals above include it (docs/physics.md §11 *friction*). `benchmarks/bench_state.py --tyre
# identified` measures this path over many recordings (docs/physics.md §13.6): 0.73 % median load error on seeds 0–5
# and 0.83 % on held-out seeds 6–9, against 0.35 % (seeds 0–5) and 0.9 % (seeds 7–9) with the true tyre file.
