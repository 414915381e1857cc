"""A joint identification case: every state of one tyre with a known condition, from a known truth.

``make_identify_case`` writes ``tyre.toml`` (Table 9 starting values, not the truth),
``free.modes.csv`` (eq. 18, with damping), two standing loaded tables (the loaded-mode model at
two loads, the patch from a contact solve on a finer grid than ringfit's) and three rolling
profiles at known load and speed (solved on a finer grid, written at other angles, with a random
gain, angle offset and coloured noise), and returns the truth. Deliberately unlike the estimator:
the profile truth uses ``n_grid`` 1024 or 2048 and the loaded truth 48 harmonics.
"""

from __future__ import annotations

import json
import math
import os

import numpy as np

from ringfit.units import KMH

#: Loads [N] of the standing loaded tables and of the three profiles, and the profiles' speeds [km/h].
LOADED_LOADS = (3000.0, 5000.0)
PROFILE_POINTS = ((3000.0, 30.0), (4000.0, 50.0), (5000.0, 70.0))


def make_identify_case(folder: str | os.PathLike, seed: int = 0, *, profiles: bool = True,
                       loaded: bool = True, noise_colour: str | None = None, truth_file: bool = True) -> dict:
    """Write the case into ``folder`` (created; must be empty or absent); returns the truth (also in
    ``truth.json`` there when ``truth_file``; the identification does not read it)."""
    import jax.numpy as jnp

    from ringfit.io.profiles import Profile, write_profile
    from ringfit.io.tyre import Tyre, write_tyre
    from ringfit.physics.contact import ContactSolver, patch_edges, solve_rolling_jit
    from ringfit.physics.loaded import loaded_natural_frequencies
    from ringfit.physics.natural import natural_frequencies
    from ringfit.physics.operating import OperatingPoint
    from ringfit.physics.profile import ProfileModel, simulate_profile
    from ringfit.synth.cases import NOISE_COLOURS, TableWriter, _new_case_folder, coloured_noise, joint_ring

    rng = np.random.default_rng(seed)
    folder = _new_case_folder(folder)
    geometry, ring, zeta = joint_ring(rng)
    sigma_rel = float(rng.uniform(0.001, 0.003))
    with_std = bool(rng.random() < 0.5)
    write_tyre(Tyre(geometry, {}), folder / "tyre.toml")

    table = TableWriter(folder, rng, sigma_rel, with_std)

    n_free = np.arange(1, 10)
    f_free = np.asarray(natural_frequencies(ring, geometry, jnp.asarray(n_free, float)))
    damp = 100.0 * zeta * np.exp(rng.normal(0.0, 0.05, n_free.size))
    table("free.modes.csv", f_free, n_free, [""] * n_free.size, damp, {"state": "free"})
    fine = ContactSolver(n_grid=int(rng.choice([1024, 2048])), window_deg=40.0)
    half_angles = {}
    if loaded:
        for load in LOADED_LOADS:
            sol = solve_rolling_jit(ring, geometry, OperatingPoint(0.0, load), solver=fine)
            lead, trail = (float(x) for x in patch_edges(sol))
            half = 0.5 * (trail - lead)
            half_angles[load] = half
            c, s = (np.asarray(x) for x in loaded_natural_frequencies(ring, geometry, half, 48))
            n = np.arange(1, 8)
            f = np.concatenate([c[n - 1], s[n - 1]])
            tags = ["vert" if k == 1 else "extr" for k in n] + ["hort" if k == 1 else "0" for k in n]
            table(f"loaded{int(load)}.modes.csv", f, np.concatenate([n, n]), tags,
                  np.full(f.size, np.nan), {"state": "loaded", "load_n": load, "speed_kmh": 0.0})
    truth_profiles = []
    if profiles:
        colour = noise_colour or str(rng.choice(NOISE_COLOURS))
        for i, (load, speed) in enumerate(PROFILE_POINTS):
            n_points = int(rng.choice([720, 1000, 1024]))
            prof = simulate_profile(ring, geometry, speed_kmh=speed, load_n=load, model=ProfileModel(), solver=fine,
                                    n_points=n_points)
            gain = float(np.exp(rng.normal(0.0, 0.03)))
            offset_deg = float(rng.uniform(-1.0, 1.0))
            ch = np.asarray(prof.channels) * gain
            # an angle offset: the recorded angle α = φ − offset (docs/physics.md §5 layer 6)
            sigma = float(rng.uniform(0.005, 0.02)) * float(np.std(ch[0]))
            ch = ch + np.stack([coloured_noise(rng, n_points, sigma, colour),
                                coloured_noise(rng, n_points, sigma, colour)])
            angle = (np.asarray(prof.angle_deg) - offset_deg + 180.0) % 360.0 - 180.0
            order = np.argsort(angle)
            cond = {k: v for k, v in dict(prof.condition).items()}
            cond.update(revolutions=50, sample_rate_hz=25600.0)
            write_profile(Profile(angle[order], ch[0][order], ch[1][order], condition=cond, source=""),
                          folder / f"run{i + 1}.profile.csv")
            truth_profiles.append(dict(load_n=load, speed_kmh=speed, gain=gain, angle_offset_deg=offset_deg,
                                       noise_ms2=sigma, noise_colour=colour, n_points=n_points))
    truth = dict(seed=seed, ring={k: float(v) for k, v in ring.as_dict().items() if math.isfinite(v)},
                 sigma_rel=sigma_rel, with_std=with_std, half_angles=half_angles, profiles=truth_profiles,
                 truth_grid=fine.n_grid)
    truth["ring_object"] = ring
    truth["geometry"] = geometry
    if truth_file:
        (folder / "truth.json").write_text(json.dumps({k: v for k, v in truth.items()
                                                       if k not in ("ring_object", "geometry")}, indent=1))
    return truth


#: A case across states (:func:`make_state_identify_case`): the low pressure as a share of the tyre file's p_ref;
#: the loaded tables ``(load, pressure share)``; the profiles ``(load, speed, pressure share, slip κ)`` (κ ≠ 0: at a
#: drive (+) or brake (−) torque, stated as ``torque_nm``).
LOW_PRESSURE = 0.8
STATE_LOADED = ((3000.0, 1.0), (5000.0, 1.0), (4000.0, LOW_PRESSURE))
STATE_PROFILES = ((3000.0, 30.0, 1.0, 0.0), (5000.0, 70.0, 1.0, 0.0), (4000.0, 50.0, LOW_PRESSURE, 0.0),
                  (4000.0, 50.0, 1.0, 0.015), (4000.0, 50.0, LOW_PRESSURE, -0.015))
#: σ of a stated torque, as a share of it (written as the sidecar's torque_std_nm; the stated value carries it).
STATE_TORQUE_STD = 0.02


def make_state_identify_case(folder: str | os.PathLike, seed: int = 0, *, noise_colour: str | None = None,
                             truth_file: bool = True, profiles=STATE_PROFILES, loaded=STATE_LOADED,
                             noise_scale: float = 1.0, friction: float = 1.0) -> dict:
    """A case folder across states (docs/physics.md §11 *across states*): the tyre at two pressures and at a drive
    and a brake torque, from a known ring **and known state laws** (pressure shares, k_x); returns the truth.

    Writes ``tyre.toml`` (geometry at p_ref, no ``[ring]``, no laws: identify starts from Table 9 and its defaults),
    ``free.modes.csv`` at p_ref and ``free_low.modes.csv`` at :data:`LOW_PRESSURE` × p_ref (eq. 18 of the ring at
    each pressure, with damping at p_ref), the loaded tables of :data:`STATE_LOADED` and the profiles of
    :data:`STATE_PROFILES`. Every state is made by :func:`ringfit.physics.state.state_tyre` (the one place the laws
    live) on a finer contact grid (1024 or 2048) and more loaded-mode harmonics (48) than identify's; a profile
    at a slip is the lever brush's (:func:`~ringfit.physics.state.solve_state`), its sidecar stating the torque
    T = Fx·H of the truth plus a draw of its σ (``torque_std_nm``, :data:`STATE_TORQUE_STD` of it), the rotation
    Ω and the speed Ω·r_road. Noise, gains and angle offsets as :func:`make_identify_case`; ``noise_scale``
    multiplies the profiles' noise (a small one isolates the model's own systematic errors). ``friction``: the
    truth's μ of the tread tips (the tyre file says none, so identify holds μ = 1: docs/physics.md §11 *friction*).
    """
    import jax.numpy as jnp

    from ringfit.io.profiles import Profile, band_limited_resample, grid_angles_deg, write_profile
    from ringfit.io.tyre import Tyre, write_tyre
    from ringfit.params import BAR
    from ringfit.physics.contact import ContactSolver, patch_edges, solve_rolling_jit
    from ringfit.physics.loaded import loaded_natural_frequencies
    from ringfit.physics.natural import natural_frequencies
    from ringfit.physics.operating import OperatingPoint
    from ringfit.physics.profile import ProfileModel, effective_rolling_radius
    from ringfit.physics.state import TyreState, solve_state, state_tyre
    from ringfit.synth.cases import NOISE_COLOURS, TableWriter, _new_case_folder, coloured_noise, joint_ring
    from ringfit.params import TyreLaws

    rng = np.random.default_rng(seed)
    folder = _new_case_folder(folder)
    geometry, ring, zeta = joint_ring(rng)
    laws = TyreLaws(kw_share=float(rng.uniform(0.3, 0.7)), kv_share=float(rng.uniform(0.2, 0.6)),
                    k_tread_share=float(rng.uniform(0.1, 0.5)), k_x=float(15e6 * np.exp(rng.normal(0.0, 0.2))),
                    friction=float(friction), has_brush=True)
    sigma_rel = float(rng.uniform(0.001, 0.003))
    with_std = bool(rng.random() < 0.5)
    write_tyre(Tyre(geometry, {}), folder / "tyre.toml")
    p_ref = float(geometry.pressure)

    def at(share):
        g, r, _ = state_tyre(geometry, ring, laws, share * p_ref, laws.tread_depth_ref)
        return g, r

    table = TableWriter(folder, rng, sigma_rel, with_std)

    n_free = np.arange(1, 10)
    for name, share in (("free.modes.csv", 1.0), ("free_low.modes.csv", LOW_PRESSURE)):
        g, r = at(share)
        f_free = np.asarray(natural_frequencies(r, g, jnp.asarray(n_free, float)))
        damp = 100.0 * zeta * np.exp(rng.normal(0.0, 0.05, n_free.size))
        table(name, f_free, n_free, [""] * n_free.size, damp, {"state": "free", "pressure_bar": share * p_ref / BAR})
    fine = ContactSolver(n_grid=int(rng.choice([1024, 2048])), window_deg=40.0)
    for load, share in loaded:
        g, r = at(share)
        sol = solve_rolling_jit(r, g, OperatingPoint(0.0, load), solver=fine)
        lead, trail = (float(x) for x in patch_edges(sol))
        c, s = (np.asarray(x) for x in loaded_natural_frequencies(r, g, 0.5 * (trail - lead), 48))
        n = np.arange(1, 8)
        f = np.concatenate([c[n - 1], s[n - 1]])
        tags = ["vert" if k == 1 else "extr" for k in n] + ["hort" if k == 1 else "0" for k in n]
        table(f"loaded{int(load)}_{int(round(100 * share))}.modes.csv", f, np.concatenate([n, n]), tags,
              np.full(f.size, np.nan), {"state": "loaded", "load_n": load, "speed_kmh": 0.0,
                                        "pressure_bar": share * p_ref / BAR})
    colour = noise_colour or str(rng.choice(NOISE_COLOURS))
    truth_profiles = []
    for i, (load, speed, share, slip) in enumerate(profiles):
        g, r = at(share)
        omega = speed * KMH / effective_rolling_radius(r, g, load, solver=fine)
        state = TyreState(load=load, pressure=share * p_ref, tread_depth=laws.tread_depth_ref, slip=slip, omega=omega)
        _, channels, q = solve_state(geometry, ring, laws, state, model=ProfileModel(), solver=fine)
        n_points = int(rng.choice([720, 1000, 1024]))
        gain = float(np.exp(rng.normal(0.0, 0.03)))
        offset_deg = float(rng.uniform(-1.0, 1.0))
        ch = band_limited_resample(channels, n_points) * gain
        sigma = float(rng.uniform(0.005, 0.02)) * float(np.std(ch[0])) * noise_scale
        ch = ch + np.stack([coloured_noise(rng, n_points, sigma, colour), coloured_noise(rng, n_points, sigma, colour)])
        angle = (grid_angles_deg(n_points) - offset_deg + 180.0) % 360.0 - 180.0
        order = np.argsort(angle)
        cond = {"speed_kmh": omega * q["r_road"] / KMH, "load_n": load, "pressure_bar": share * p_ref / BAR,
                "rotation_hz": omega / (2.0 * np.pi), "revolutions": 50, "sample_rate_hz": 25600.0}
        truth_p = dict(load_n=load, speed_kmh=cond["speed_kmh"], pressure_bar=cond["pressure_bar"], slip=slip,
                       gain=gain, angle_offset_deg=offset_deg, noise_ms2=sigma, noise_colour=colour,
                       n_points=n_points, fx_n=q["fx"], torque_nm=q["torque"])
        if slip != 0.0:
            sd = STATE_TORQUE_STD * abs(q["torque"])
            cond.update(torque_nm=float(q["torque"] + sd * rng.standard_normal()), torque_std_nm=sd)
            truth_p["stated_torque_nm"] = cond["torque_nm"]
        write_profile(Profile(angle[order], ch[0][order], ch[1][order], condition=cond, source=""),
                      folder / f"run{i + 1}.profile.csv")
        truth_profiles.append(truth_p)
    truth = dict(seed=seed, ring={k: float(v) for k, v in ring.as_dict().items() if math.isfinite(v)},
                 laws={k: float(getattr(laws, k)) for k in ("kw_share", "kv_share", "k_tread_share", "k_x")},
                 sigma_rel=sigma_rel, with_std=with_std, profiles=truth_profiles, truth_grid=fine.n_grid,
                 pressures_bar=[p_ref / BAR, LOW_PRESSURE * p_ref / BAR], friction=float(friction))
    if truth_file:
        (folder / "truth.json").write_text(json.dumps(truth, indent=1))
    truth.update(ring_object=ring, geometry=geometry, laws_object=laws)
    return truth


__all__ = ["make_identify_case", "make_state_identify_case", "LOADED_LOADS", "PROFILE_POINTS", "STATE_LOADED",
           "STATE_PROFILES", "LOW_PRESSURE"]
