"""Blind-validation case folders (docs/formats.md §6) with one hidden effect, none, or an effect outside the library.

:func:`make_case` writes ``tyre.toml``, ``free.modes.csv/.json`` and test
mode tables (a loaded table with ``extr``/``0`` tags, a spinning table with
backward/forward branches) for a ring drawn around the bundled Table 9 tyre,
then injects one effect at a random plausible magnitude and adds noise of
random level and colour. The label is returned, never written into the
folder. The synthetic truth is computed with code independent of the
diagnosis where the package has it (eq. 25 from
:func:`ringfit.physics.natural.rotating_natural_frequencies`, the extensible
2×2 eigenproblem from :func:`~ringfit.physics.natural.extensible_natural_frequencies`,
the loaded modes with a different basis size than the diagnosis uses, the
cavity as a 2×2 eigenproblem in NumPy).

Injected (mode tables): ``ground_contact``, ``rotation``, ``cavity_mode``,
``wave_damping``, ``ring_extensibility``, ``wheel_suspension`` (an extra table
``suspended.modes.csv``: the free tyre on the bench's suspension, its sidecar stating the
fixture, n ≤ 1 truth from the lumped model :func:`lumped_wheel_modes`), ``damping_growth`` (η(n) = 2ζ0 n^b
on the free table's damping, ζ from the complex-stiffness eigenvalue); ``none``; and the out-of-library
``tread_pitch`` (a construction non-uniformity that shifts a few neighbouring
harmonics and splits the loaded/spinning pairs), whose expected verdict is ``unexplained``.
``sensor_mass`` is not injected: on mode tables it is almost a uniform
relative shift that a refit of ρA absorbs (docs/physics.md §6: negligible).
``cavity_mode`` can be injected but is left out of the benchmark: its mark on
the structural modes is a near-uniform shift of n = 1 that the baseline's
k_w + k_v absorbs, so only an acoustic row could show it (not modelled yet).
``ring_extensibility`` likewise: for a plausible EA (≥ 1e5 N) the flexural
modes move by < 0.3 Hz (docs/physics.md §2.2), below the noise; the tangential
branch that would show it has no label in a docs/formats.md §2 table.
"""

from __future__ import annotations

import json
import math
import os
from dataclasses import dataclass
from pathlib import Path

import equinox as eqx
import jax.numpy as jnp
import numpy as np

from ringfit.units import KMH

#: Effects the generator injects in mode-table cases, with the verdict the diagnosis should give.
MODAL_INJECTIONS = ("none", "ground_contact", "rotation", "wave_damping", "tread_pitch", "wheel_suspension",
                    "damping_growth")
#: Injectable but not part of the blind benchmark (see the module docstring).
EXTRA_INJECTIONS = ("cavity_mode", "ring_extensibility")
EXPECTED = {"none": "none", "tread_pitch": "unexplained"}


@dataclass
class CaseLabel:
    """What was injected (kept away from the diagnosis)."""

    effect: str
    expected_verdict: str
    magnitude: dict
    noise: dict
    ring: dict
    seed: int


def _new_case_folder(folder) -> Path:
    """``folder`` created if absent; it must be empty (a generator never mixes two cases)."""
    folder = Path(folder)
    folder.mkdir(parents=True, exist_ok=True)
    if any(folder.iterdir()):
        raise FileExistsError(f"{folder} is not empty")
    return folder


def _ring(rng):
    from ringfit.params import table9

    geometry, ring = table9()
    f = lambda: float(np.exp(rng.normal(0.0, 0.06)))  # noqa: E731
    ring = ring.replace(rho_a=ring.rho_a * f(), ei=ring.ei * f(), kw=ring.kw * f(), kv=ring.kv * f(),
                        k_tread=ring.k_tread * f())
    return geometry, ring


def joint_ring(rng):
    """The truth of a joint identify case: :func:`_ring`, a damping ratio ζ ~ U(0.015, 0.035) and k_trd jittered
    once more (σ 0.15 of its log). **Returns:** ``(geometry, ring, ζ)``."""
    geometry, ring = _ring(rng)
    zeta = float(rng.uniform(0.015, 0.035))
    ring = ring.replace(damping_ratio=zeta, k_tread=float(ring.k_tread * np.exp(rng.normal(0.0, 0.15))))
    return geometry, ring, zeta


@dataclass
class TableWriter:
    """Writes structural mode tables of a joint case into ``folder``: each frequency with relative noise
    ``sigma_rel`` (drawn from ``rng``), ``freq_std_hz`` stated when ``with_std``."""

    folder: Path
    rng: object
    sigma_rel: float
    with_std: bool

    def __call__(self, name, f, n, tag, damping, condition) -> None:
        from ringfit.io.modes import ModeTable, write_mode_table

        f = np.asarray(f)
        noisy = f * (1.0 + self.sigma_rel * self.rng.standard_normal(f.size))
        t = ModeTable(freq_hz=noisy, n=np.asarray(n), tag=np.asarray(tag, object),
                      kind=np.array(["structural"] * f.size, object), branch=np.array([""] * f.size, object),
                      damping_pct=np.asarray(damping), freq_std_hz=(self.sigma_rel * noisy) if self.with_std else None,
                      condition=condition)
        write_mode_table(t, Path(self.folder) / name)


def _noise(rng, freq, sigma_rel, colour):
    """White or coloured (white + a random walk along the rows) relative frequency noise."""
    white = rng.normal(0.0, 1.0, freq.size)
    if colour == "white":
        e = white
    else:
        walk = np.cumsum(rng.normal(0.0, 1.0, freq.size))
        walk = (walk - walk.mean()) / max(walk.std(), 1e-9)
        e = (white + 0.5 * walk) / math.sqrt(1.25)
    return freq * (1.0 + sigma_rel * e)


def _write_table(folder: Path, name: str, rows: list[dict], condition: dict, with_std: bool, sigma_rel: float):
    from ringfit.io.modes import ModeTable, write_mode_table

    f = np.array([r["freq_hz"] for r in rows])
    table = ModeTable(
        freq_hz=f, n=np.array([r.get("n", -1) for r in rows]), tag=np.array([r.get("tag", "") for r in rows], object),
        kind=np.array([r.get("kind", "structural") for r in rows], object),
        branch=np.array([r.get("branch", "") for r in rows], object),
        damping_pct=np.array([r.get("damping_pct", np.nan) for r in rows]),
        freq_std_hz=(sigma_rel * f) if with_std else None, condition=condition,
    )
    write_mode_table(table, folder / name)


def make_case(folder: str | os.PathLike, effect: str | None = None, seed: int = 0) -> CaseLabel:
    """Write a blind mode-table case into ``folder`` (created; must be empty or absent).

    **Arguments:** ``effect`` — one of :data:`MODAL_INJECTIONS` (``None`` = drawn at random);
    ``seed`` — everything random (ring, magnitude, noise level and colour) follows it.

    **Returns:** the hidden :class:`CaseLabel`.
    """
    import jax.numpy as jnp

    from ringfit.io.tyre import Tyre, write_tyre
    from ringfit.physics.loaded import loaded_natural_frequencies
    from ringfit.physics.natural import (CAVITY_LENGTH, SOUND_SPEED, cavity_coupled_shift, cavity_coupling,
                                         extensible_natural_frequencies, natural_frequencies,
                                         rotating_natural_frequencies)

    rng = np.random.default_rng(seed)
    effect = effect or str(rng.choice(MODAL_INJECTIONS))
    folder = _new_case_folder(folder)
    geometry, ring = _ring(rng)
    sigma_rel = float(rng.uniform(0.0005, 0.002))
    colour = str(rng.choice(["white", "coloured"]))
    with_std = bool(rng.random() < 0.3)
    zeta0 = float(rng.uniform(0.015, 0.035))
    zeta_sd = float(rng.uniform(0.05, 0.12))  # relative damping scatter
    magnitude: dict = {}

    n_free = np.arange(1, int(rng.integers(8, 11)) + 1)
    free = np.asarray(natural_frequencies(ring, geometry, jnp.asarray(n_free, float)))
    n_load = np.arange(1, int(rng.integers(6, 9)) + 1)
    load_cos = np.asarray(natural_frequencies(ring, geometry, jnp.asarray(n_load, float)))
    load_sin = load_cos.copy()
    speed_kmh = float(rng.uniform(40.0, 90.0))
    omega = speed_kmh * KMH / geometry.outer_radius
    n_rot = np.arange(2, int(rng.integers(6, 9)) + 1)
    rot_b = np.asarray(natural_frequencies(ring, geometry, jnp.asarray(n_rot, float)))
    rot_f = rot_b.copy()

    def damping(f):
        return 100.0 * zeta0 * np.exp(rng.normal(0.0, zeta_sd, f.size))

    damp_free = damping(free)
    if effect == "ground_contact":
        a = float(rng.uniform(8.0, 14.0))
        magnitude["half_angle_deg"] = a
        c, s = loaded_natural_frequencies(ring, geometry, math.radians(a), n_max=int(rng.integers(24, 60)))
        load_cos, load_sin = np.asarray(c)[n_load - 1], np.asarray(s)[n_load - 1]
    elif effect == "rotation":
        r = np.asarray(rotating_natural_frequencies(ring, geometry, jnp.asarray(n_rot, float), omega))
        rot_b, rot_f = np.abs(r[:, 0]), np.abs(r[:, 1])
        magnitude["speed_kmh"] = speed_kmh
    elif effect == "ring_extensibility":
        ea = float(np.exp(rng.uniform(np.log(1.0e4), np.log(2.5e4))))
        magnitude["ea_n"] = ea
        fl = lambda n: np.asarray(extensible_natural_frequencies(ring.replace(ea=ea), geometry,  # noqa: E731
                                                                  jnp.asarray(n, float)))[..., 0]
        free, load_cos, rot_b = fl(n_free), fl(n_load), fl(n_rot)
        load_sin, rot_f = load_cos.copy(), rot_b.copy()
    elif effect == "cavity_mode":
        area = float(rng.uniform(0.008, 0.02))
        magnitude["cavity_area_m2"] = area
        f_cav = float(rng.uniform(215.0, 232.0))
        magnitude["cavity_hz"] = f_cav

        def couple(n, f):  # the structural root of the ring–air pencil (docs/physics.md §6 cavity_mode)
            n, w0 = np.asarray(n, dtype=np.float64), 2 * np.pi * np.asarray(f, dtype=np.float64)
            k = cavity_coupling(ring, geometry, n, 1.0 / area)
            return np.sqrt(w0**2 + np.asarray(cavity_coupled_shift(w0, 2 * np.pi * f_cav * n, k))) / (2 * np.pi)

        free, load_cos, rot_b = couple(n_free, free), couple(n_load, load_cos), couple(n_rot, rot_b)
        load_sin, rot_f = load_cos.copy(), rot_b.copy()
    elif effect == "wave_damping":
        slope = float(rng.uniform(0.02, 0.06))
        magnitude["eta_slope"] = slope
        damp_free = 100.0 * (zeta0 + 0.5 * slope * free / 100.0) * np.exp(rng.normal(0.0, zeta_sd, free.size))
    elif effect == "damping_growth":
        # η(n) = 2ζ0 n^b rising ×6…×12 over n = 1…9; truth from the complex-stiffness eigenvalue of each
        # mode, ω² ∝ 1 + iη: ζ = sin(½ atan η) (the effect fits ζ0 n^b, the first-order form)
        b = float(rng.uniform(0.8, 1.15))
        magnitude["exponent"] = b
        eta = 2.0 * zeta0 * n_free.astype(float) ** b
        growth_truth = 100.0 * np.sin(0.5 * np.arctan(eta))
        damp_free = growth_truth * np.exp(rng.normal(0.0, zeta_sd, free.size))
    elif effect == "tread_pitch":
        amp = float(rng.uniform(0.01, 0.02))
        magnitude["relative_amplitude"] = amp
        n0 = float(rng.uniform(3.0, 7.0))
        magnitude["centre_n"] = n0
        pattern = lambda n: amp * np.exp(-((n - n0) ** 2) / 4.5)  # noqa: E731 - a bump over a few n
        free = free * (1 + pattern(n_free))
        load_cos, load_sin = load_cos * (1 + pattern(n_load)), load_sin * (1 - pattern(n_load))
        rot_b, rot_f = rot_b * (1 + pattern(n_rot)), rot_f * (1 - pattern(n_rot))
    elif effect not in ("none", "wheel_suspension"):  # wheel_suspension: its own table, written below
        raise ValueError(f"effect {effect!r} not injectable; choose from {MODAL_INJECTIONS + EXTRA_INJECTIONS}")

    write_tyre(Tyre(geometry, {"rho_a": 2.715, "ei": 0.9426, "kw": 1.294e6, "kv": 1.161e6,
                               "k_tread": 19e6, "damping_ratio": 0.025}), folder / "tyre.toml")
    noisy = lambda f: _noise(rng, f, sigma_rel, colour)  # noqa: E731
    free_noisy = noisy(free)
    rows = [{"n": int(n), "freq_hz": float(f), "damping_pct": float(d)}
            for n, f, d in zip(n_free, free_noisy, damp_free)]
    damp_truth = 100.0 * (zeta0 + 0.5 * magnitude.get("eta_slope", 0.0) * free / 100.0)
    if effect == "damping_growth":
        damp_truth = growth_truth
    # realised noise of every observation, in the order the diagnosis reads them (free: frequency then
    # damping per mode; then loaded.modes.csv, spinning.modes.csv): for the ideal shrink of the benchmark
    row_noise = []
    for f, ft, d, dt in zip(free_noisy, free, damp_free, damp_truth):
        row_noise += [("freq", float(f - ft)), ("ln_damping", float(np.log(d / dt)))]
    if effect == "cavity_mode" or rng.random() < 0.5:
        rows.append({"kind": "acoustic", "freq_hz": float(magnitude.get("cavity_hz", SOUND_SPEED / CAVITY_LENGTH) * (1 + 0.01 * rng.random()))})
    _write_table(folder, "free.modes.csv", rows, {"state": "free", "speed_kmh": 0, "pressure_bar": 2.2,
                                                   "frame": "fixed"}, with_std, sigma_rel)
    lrows = []
    for n, fc, fs, tc, ts in zip(n_load, noisy(load_cos), noisy(load_sin), load_cos, load_sin):
        lrows.append({"n": int(n), "tag": "vert" if n == 1 else "extr", "freq_hz": float(fc)})
        lrows.append({"n": int(n), "tag": "hort" if n == 1 else "0", "freq_hz": float(fs)})
        row_noise += [("freq", float(fc - tc)), ("freq", float(fs - ts))]
    _write_table(folder, "loaded.modes.csv", lrows, {"state": "loaded", "load_n": 4000.0, "speed_kmh": 0,
                                                      "pressure_bar": 2.2, "frame": "fixed"}, with_std, sigma_rel)
    rrows = []
    for n, fb, ff, tb, tf in zip(n_rot, noisy(rot_b), noisy(rot_f), rot_b, rot_f):
        rrows.append({"n": int(n), "branch": "backward", "freq_hz": float(fb)})
        rrows.append({"n": int(n), "branch": "forward", "freq_hz": float(ff)})
        row_noise += [("freq", float(fb - tb)), ("freq", float(ff - tf))]
    _write_table(folder, "spinning.modes.csv", rrows, {"state": "free", "speed_kmh": round(speed_kmh, 2),
                                                        "pressure_bar": 2.2, "frame": "rotating"}, with_std, sigma_rel)
    if effect == "wheel_suspension":
        # the free tyre standing on the bench's suspension: truth from the lumped discretisation below
        # (not the diagnosis's two-body root), its own random stream so the other draws stay as they were
        wrng = np.random.default_rng([seed, 21])
        body = dict(wheel_mass_kg=float(wrng.uniform(10.0, 40.0)), wheel_inertia_kg_m2=float(wrng.uniform(0.3, 1.0)),
                    suspension_stiffness_n_m=[float(np.exp(wrng.uniform(np.log(5e4), np.log(5e5)))),
                                              float(np.exp(wrng.uniform(np.log(3e5), np.log(3e6))))],
                    suspension_torsion_n_m_rad=float(np.exp(wrng.uniform(np.log(3e4), np.log(3e5)))))
        magnitude.update(body)
        truth = lumped_wheel_modes(ring, geometry, body["wheel_mass_kg"], body["wheel_inertia_kg_m2"],
                                   *body["suspension_stiffness_n_m"], body["suspension_torsion_n_m_rad"])
        n_hi = np.arange(2, 6)
        srows_t = [(0, "", truth["torsion"]), (1, "vert", truth["vertical"]), (1, "hort", truth["fore_aft"])]
        srows_t += [(int(n), "", float(f)) for n, f in
                    zip(n_hi, np.asarray(natural_frequencies(ring, geometry, jnp.asarray(n_hi, float))))]
        ft = np.array([f for _, _, f in srows_t])
        fn = noisy(ft)
        srows = [{"n": n, "tag": tag, "freq_hz": float(f)} for (n, tag, _), f in zip(srows_t, fn)]
        row_noise += [("freq", float(a - b)) for a, b in zip(fn, ft)]
        _write_table(folder, "suspended.modes.csv", srows,
                     {"state": "free", "speed_kmh": 0, "pressure_bar": 2.2, "frame": "fixed", "fixture": "suspension",
                      **body}, with_std, sigma_rel)
    return CaseLabel(effect=effect, expected_verdict=EXPECTED.get(effect, effect), magnitude=magnitude,
                     noise={"relative": sigma_rel, "colour": colour, "freq_std_given": with_std,
                            "damping_relative": zeta_sd, "rows": row_noise},
                     ring=ring.as_dict(), seed=seed)


def lumped_wheel_modes(ring, geometry, mass, inertia, k_vertical, k_fore_aft, k_torsion, nodes: int = 64) -> dict:
    """The n ≤ 1 modes of a free tyre on a wheel on its suspension, from a lumped model [Hz] (synthetic truth).

    An independent discretisation of docs/physics.md §6 ``wheel_suspension`` (the diagnosis solves the
    two-body root): ``nodes`` point masses ρA·R·dθ on a circle, each tied to a rigid hub by a radial spring
    k_w·R·dθ and a tangential one k_v·R·dθ (the latter's root moves by Rβ with the hub's rotation),
    neighbours by stiff axial links; the hub (mass, inertia) on springs k_vertical, k_fore_aft, k_torsion.
    Cartesian coordinates, one dense generalised eigenproblem. Each mode is classed by where its kinetic
    energy is (vertical or fore-aft translation, rotation); of the two modes of a class the belt's is the
    one with the smaller share of its strain energy in the support spring (the other is the wheel on its
    suspension). **Returns:** ``{"vertical", "fore_aft", "torsion"}`` [Hz].
    """
    import scipy.linalg

    R = float(geometry.radius)
    dth = 2 * math.pi / nodes
    th = np.arange(nodes) * dth
    ndof = 2 * nodes + 3
    hub = 2 * nodes
    K = np.zeros((ndof, ndof))
    mdiag = np.concatenate([np.full(2 * nodes, float(ring.rho_a) * R * dth), [mass, mass, inertia]])
    kw, kv = float(ring.kw) * R * dth, float(ring.kv) * R * dth
    for i, t in enumerate(th):
        er, et = np.array([math.cos(t), math.sin(t)]), np.array([-math.sin(t), math.cos(t)])
        for e, k, rot in ((er, kw, 0.0), (et, kv, -R)):
            v = np.zeros(ndof)
            v[2 * i:2 * i + 2], v[hub:hub + 2], v[hub + 2] = e, -e, rot
            K += k * np.outer(v, v)
        j = (i + 1) % nodes
        d = np.array([math.cos(th[j]) - math.cos(t), math.sin(th[j]) - math.sin(t)])
        d /= np.linalg.norm(d)
        v = np.zeros(ndof)
        v[2 * j:2 * j + 2], v[2 * i:2 * i + 2] = d, -d
        K += 1e3 * kw * np.outer(v, v)
    support = {"fore_aft": (hub, k_fore_aft), "vertical": (hub + 1, k_vertical), "torsion": (hub + 2, k_torsion)}
    for idx, k in support.values():
        K[idx, idx] += k
    lam, vec = scipy.linalg.eigh(K, np.diag(mdiag))
    xs, ys = slice(0, 2 * nodes, 2), slice(1, 2 * nodes, 2)
    out = {}
    for name, (idx, k) in support.items():
        best = None
        for j in range(ndof):
            x = vec[:, j]
            td = x[xs] * -np.sin(th) + x[ys] * np.cos(th)  # tangential displacement of each node
            # the belt moves as a whole: a mean displacement (translation) or a mean tangential one (torsion)
            mean = {"fore_aft": abs(np.mean(x[xs])), "vertical": abs(np.mean(x[ys])), "torsion": abs(np.mean(td))}
            cls = max(mean, key=mean.get)
            if mean[cls] < 0.3 * np.sqrt(np.mean(x[xs] ** 2 + x[ys] ** 2)):
                cls = None
            if cls != name:
                continue
            share = k * x[idx] ** 2 / (x @ K @ x)
            if best is None or share < best[0]:
                best = (share, math.sqrt(max(lam[j], 0.0)) / (2 * math.pi))
        out[name] = best[1]
    return out


#: Road speeds [km/h] and load [N] of the rolling tables of :func:`make_rolling_case` (the source study's cleat tests).
ROLLING_SPEEDS = (20.0, 40.0, 60.0)
ROLLING_LOAD_N = 4000.0


def _sensor_view(ring, geometry, contact: bool):
    """What the co-rotating sensor sees of each mode at :data:`ROLLING_SPEEDS` (docs/physics.md §3.7), from
    the physics layer alone (not the diagnosis's matching): the strongest radial-acceleration line
    ``|ω + kΩ|/2π`` [Hz], the dominant order and the tag of standing modes (|travel| < 3: ``extr``/``0``,
    ``vert``/``hort`` for n = 1; "" otherwise), each ``(speeds, modes)``. K = 40 harmonics."""
    import jax

    from ringfit.physics.campbell import acceleration_labels
    from ringfit.physics.contact import solve_rolling_jit
    from ringfit.physics.operating import KMH, OperatingPoint, rolling_radius
    from ringfit.physics.rolling_modes import campbell_modes_jit

    # the tyre rolls under its load either way: Ω = V/R_e (R_e = R_out − δ/3 of the standing tyre at the load)
    standing = solve_rolling_jit(ring, geometry, OperatingPoint(0.0, ROLLING_LOAD_N))
    r_e = float(rolling_radius(geometry.outer_radius, float(standing.deflection)))
    omegas = np.asarray(ROLLING_SPEEDS) * KMH / r_e
    cm = campbell_modes_jit(ring, geometry, ROLLING_LOAD_N, omegas, speed_unit="rad/s", contact=contact, harmonics=40)
    # the labels and lines of the Campbell diagram (radial acceleration; a mode without radial content, the
    # inextensible ring's n = 0, read on the tangential axis with its displacement order)
    order, travel, sym, f, weight = (np.asarray(x) for x in jax.device_get(acceleration_labels(cm.modes)))
    best = np.argmax(np.nan_to_num(weight, nan=-1.0), axis=-1)
    hz = np.abs(np.take_along_axis(f, best[..., None], -1)[..., 0])
    hz = np.where(np.all(np.isnan(weight), axis=-1), np.nan, hz)
    standing = (np.abs(travel) < 3.0) & np.isfinite(sym) & contact
    cos_type = np.nan_to_num(sym) >= 0.5
    tag = np.where(order == 1, np.where(cos_type, "vert", "hort"), np.where(cos_type, "extr", "0"))
    return hz, order, np.where(standing, tag, "")


def make_rolling_case(folder: str | os.PathLike, contact: bool = True, seed: int = 0) -> CaseLabel:
    """Write a case folder (docs/formats.md §6) with rolling mode tables at 20/40/60 km/h and 4 kN.

    ``tyre.toml`` (bundled Table 9 values, not the truth), ``free.modes.csv`` (eq. 18 of the true
    ring, noisy, with damping) and ``roll20/40/60.modes.csv`` + sidecars (``state = rolling``,
    ``load_n``, ``speed_kmh``, ``frame = rotating``): what the co-rotating sensor sees of the
    rolling tyre's modes — the strongest line ω + kΩ of each branch of n = 1 … 6–8 of the model of
    docs/physics.md §3.7 (:func:`ringfit.physics.rolling_modes.campbell_modes` of the true ring with K = 40
    harmonics, not the diagnosis's basis; lines and labels read here, not by the diagnosis's matching),
    with ``contact=False`` the free spinning ring (the control: eq. 25 lines, no patch; Ω = V/R_e of the
    loaded tyre in both). Made to look like identified tables: relative noise of
    0.05–0.2 % (the same identification as the free table, up to 1.3× its level), one or two
    modes missing per table, ``extr``/``0`` (``vert``/``hort``) tags on the modes the model calls
    standing and no ``branch`` anywhere, one row per table without n, scattered damping, no
    ``freq_std_hz``.

    **Returns:** the hidden :class:`CaseLabel`: ``effect`` / ``expected_verdict``
    ``"rotation+ground_contact"`` (``"rotation"`` for the control; the order of the chain is
    free), ``noise["rows"]`` the realised noise of every observation in the order the diagnosis
    reads them (docs/formats.md §15).
    """
    from ringfit.io.tyre import Tyre, write_tyre
    from ringfit.physics.natural import natural_frequencies

    rng = np.random.default_rng(seed)
    folder = _new_case_folder(folder)
    geometry, ring = _ring(rng)
    sigma_rel = float(rng.uniform(0.0005, 0.002))
    sigma_roll = sigma_rel * float(rng.uniform(1.0, 1.3))
    zeta0 = float(rng.uniform(0.015, 0.035))
    n_free = np.arange(1, int(rng.integers(8, 11)) + 1)
    free = np.asarray(natural_frequencies(ring, geometry, jnp.asarray(n_free, float)))
    free_noisy = free * (1.0 + sigma_rel * rng.normal(0.0, 1.0, free.size))
    damp = 100.0 * zeta0 * np.exp(rng.normal(0.0, 0.1, free.size))
    row_noise = []
    for f, ft, d in zip(free_noisy, free, damp):
        row_noise += [("freq", float(f - ft)), ("ln_damping", float(np.log(d / 100.0 / zeta0)))]
    write_tyre(Tyre(geometry, {"rho_a": 2.715, "ei": 0.9426, "kw": 1.294e6, "kv": 1.161e6,
                               "k_tread": 19e6, "damping_ratio": 0.025}), folder / "tyre.toml")
    _write_table(folder, "free.modes.csv",
                 [{"n": int(n), "freq_hz": float(f), "damping_pct": float(d)} for n, f, d in zip(n_free, free_noisy, damp)],
                 {"state": "free", "speed_kmh": 0, "pressure_bar": 2.2, "frame": "fixed"}, False, 0.0)
    n_top = int(rng.integers(6, 9))
    hz, order, tags = _sensor_view(ring, geometry, contact)
    truth = {}
    for s, speed in enumerate(ROLLING_SPEEDS):
        keep = [b for b in range(order.shape[1]) if 1 <= order[s, b] <= n_top and np.isfinite(hz[s, b])]
        keep = sorted(keep, key=lambda b: hz[s, b])
        drop = set(rng.choice(len(keep), size=int(rng.integers(1, 3)), replace=False).tolist())
        keep = [b for j, b in enumerate(keep) if j not in drop]
        no_n = int(rng.integers(0, len(keep)))
        rows, true_hz = [], []
        for j, b in enumerate(keep):
            f = float(hz[s, b])
            noisy = f * (1.0 + sigma_roll * float(rng.normal()))
            rows.append({"n": -1 if j == no_n else int(order[s, b]), "tag": str(tags[s, b]), "freq_hz": noisy,
                         "damping_pct": float(100.0 * zeta0 * np.exp(rng.normal(0.3, 0.4)))})
            row_noise.append(("freq", noisy - f))
            true_hz.append(f)
        name = f"roll{int(speed)}.modes.csv"
        truth[name] = true_hz
        _write_table(folder, name, rows, {"state": "rolling", "load_n": ROLLING_LOAD_N, "speed_kmh": speed,
                                          "pressure_bar": 2.2, "frame": "rotating"}, False, 0.0)
    effect = "rotation+ground_contact" if contact else "rotation"
    return CaseLabel(effect=effect, expected_verdict=effect,
                     magnitude={"load_n": ROLLING_LOAD_N, "speeds_kmh": list(ROLLING_SPEEDS), "contact": contact,
                                "true_hz": truth},
                     noise={"relative": sigma_rel, "relative_rolling": sigma_roll, "colour": "white",
                            "freq_std_given": False, "rows": row_noise},
                     ring=ring.as_dict(), seed=seed)


def relabel_rolling_tables(folder: str | os.PathLike, order) -> None:
    """Move the labels (``n``, ``tag``, ``branch``) among the structural rows of every rolling table of a case
    folder (every ``*.modes.csv`` but ``free.modes.csv``), frequencies kept: row i gets the labels of row
    ``order(m)[i]`` of its table's m structural rows (a permutation: shuffled, reversed, …). For the
    diagnosis's label tests (labels that carry no information, or that are all wrong)."""
    for p in sorted(Path(folder).glob("*.modes.csv")):
        if p.name == "free.modes.csv":
            continue
        lines = p.read_text().splitlines()
        head = lines[0].split(",")
        rows = [line.split(",") for line in lines[1:] if line.strip()]
        cols = [head.index(c) for c in ("n", "tag", "branch") if c in head]
        struct = [i for i, r in enumerate(rows) if r[head.index("kind")] == "structural"]
        labels = [[rows[i][c] for c in cols] for i in struct]
        for i, j in zip(struct, order(len(struct))):
            for c, v in zip(cols, labels[j]):
                rows[i][c] = v
        p.write_text("\n".join([lines[0]] + [",".join(r) for r in rows]) + "\n")


def write_label(label: CaseLabel, path: str | os.PathLike) -> None:
    """Write a label as JSON (keep it outside the case folder)."""
    Path(path).write_text(json.dumps(label.__dict__, indent=1))


# ============================================================================ rolling-profile cases
#: Effects the generator injects in profile cases (expected verdict = the name, except as in EXPECTED).
#: ``tread_shear`` is the brush *with the lever* (the tread element's tip force acting on the belt through
#: its height τ), simulated by :class:`LeverShearTruth`, a discretisation independent of the diagnosis's
#: :class:`ringfit.physics.contact.BrushShearLoad`; without the lever the shear would move the readings of a
#: centreline sensor on an inextensible belt by < 0.1 m/s² (docs/physics.md §6 tread_shear).
PROFILE_INJECTIONS = ("none", "sensor_tilt", "gravity", "iepe_highpass", "wave_damping", "rotation", "tread_pitch",
                      "tread_shear")
#: Injectable in profiles but not in the blind benchmark.
PROFILE_EXTRA_INJECTIONS = ()
#: Speeds of a profile case [km/h] (each jittered by up to ±2 km/h).
PROFILE_SPEEDS = (20.0, 30.0, 40.0, 60.0)
NOISE_COLOURS = ("white", "pink", "red", "band")


def coloured_noise(rng, n_points: int, sigma: float, colour: str) -> np.ndarray:
    """Periodic noise on ``n_points`` with per-sample σ [m/s²] and a spectrum of the given colour.

    ``white`` flat; ``pink`` ∝ 1/k; ``red`` ∝ 1/k^1.5 (power); ``band``: white plus a
    resonance bump over a random band of revolution harmonics (a structural mode the
    averaging did not remove).
    """
    spec = np.fft.rfft(rng.normal(0.0, 1.0, n_points))
    k = np.arange(spec.size, dtype=float)
    k[0] = 1.0
    if colour == "pink":
        spec = spec / np.sqrt(k)
    elif colour == "red":
        spec = spec / k**0.75
    elif colour == "band":
        centre, width = rng.uniform(15.0, 80.0), rng.uniform(3.0, 12.0)
        spec = spec * np.sqrt(1.0 + 6.0 * np.exp(-0.5 * ((k - centre) / width) ** 2))
    spec[0] = 0.0
    x = np.fft.irfft(spec, n_points)
    return sigma * x / np.std(x)


def _free_rows(rng, ring, geometry, zeta0, sigma_rel):
    import jax.numpy as jnp

    from ringfit.physics.natural import natural_frequencies

    n_free = np.arange(1, int(rng.integers(8, 11)) + 1)
    free = np.asarray(natural_frequencies(ring, geometry, jnp.asarray(n_free, float)))
    free = free * (1.0 + sigma_rel * rng.normal(0.0, 1.0, free.size))
    damp = 100.0 * zeta0 * np.exp(rng.normal(0.0, 0.05, free.size))
    return [{"n": int(n), "freq_hz": float(f), "damping_pct": float(d)} for n, f, d in zip(n_free, free, damp)]


class PitchModulation(eqx.Module):
    """Out-of-library ``tread_pitch`` truth: the contact pressure modulated by the tread pitch, as a load hook
    ``−depth·p(φ)·cos(pitches·φ + phase)`` on the radial load (:class:`ringfit.physics.profile.ProfileModel`)."""

    pitches: int = eqx.field(static=True)
    depth: float
    phase: float

    def __call__(self, sol, ring, geometry):
        q_w = -self.depth * sol.pressure * jnp.cos(self.pitches * sol.phi + self.phase)
        return q_w, jnp.zeros_like(q_w)


class LeverShearTruth(eqx.Module):
    """Blind-case truth of ``tread_shear`` with the lever, written independently of
    :class:`ringfit.physics.contact.BrushShearLoad` (which the diagnosis uses) as a load hook
    ``(solution, ring, geometry) -> (q_w, q_v)``.

    Different discretisation and kinematics on purpose: the tread element stays normal to the
    belt *exactly*, its tip at ``(R + w) sin φ + v cos φ + τ sin(φ − ψ)`` (not the linearised
    ``−τψ cos φ``); the belt slope ψ = (w′ − v)/R takes w′ by central differences (not spectrally);
    the tip sticks at the leading edge interpolated from the penetration's zero crossing (not the
    first grid point); the rolling radius R_e is set by bisection so that the *clipped* tip forces
    drive no torque (not the unclipped least-squares formula); and the belt loads are the
    work-conjugate forces of the tip force through the tip kinematics, taken by reverse-mode
    differentiation of ``Σ q_x x_tip`` with q_x held fixed (not the hand-derived moment pair
    ``−m′/R``, ``−m/R``).
    """

    k_x: float
    mu: float

    def __call__(self, sol, ring, geometry):
        import jax

        phi, p = sol.phi, sol.pressure
        R, tau = geometry.radius, geometry.outer_radius - geometry.radius
        dphi = phi[1] - phi[0]
        inside = p > 0

        def x_tip(w, v, at=phi):
            wp = (jnp.roll(w, -1) - jnp.roll(w, 1)) / (2.0 * dphi)
            psi = (wp - v) / R
            return (R + w) * jnp.sin(at) + v * jnp.cos(at) + tau * jnp.sin(at - psi)

        x = x_tip(sol.w, sol.v)
        pen = sol.penetration
        i0 = jnp.argmax(inside)
        t = (0.0 - pen[i0 - 1]) / (pen[i0] - pen[i0 - 1])  # leading edge between grid points i0−1 and i0
        phi_l = phi[i0 - 1] + t * dphi
        x_l = x[i0 - 1] + t * (x[i0] - x[i0 - 1])
        s = phi - phi_l

        def forces(r_e):
            q = -self.k_x * (x - x_l - r_e * s)
            return jnp.where(inside, jnp.clip(q, -self.mu * p, self.mu * p), 0.0)

        def torque(r_e):  # the tips' tangential force about the axle; increasing in r_e (s > 0 in the patch)
            return jnp.sum(forces(r_e) * jnp.cos(phi))

        def bisect(_, ab):
            a, b = ab
            m = 0.5 * (a + b)
            above = torque(m) > 0  # the root lies below m
            return jnp.where(above, a, m), jnp.where(above, m, b)

        lo, hi = jax.lax.fori_loop(0, 80, bisect, (0.8 * R, 1.2 * (R + tau)))
        q_x = jax.lax.stop_gradient(forces(0.5 * (lo + hi)))
        q_w, q_v = jax.grad(lambda w, v: jnp.sum(q_x * x_tip(w, v)), argnums=(0, 1))(sol.w, sol.v)
        return q_w, q_v


def add_patch_noise(folder: str | os.PathLike, sigma: float, amplitude: float, width_deg: float, rng) -> None:
    """Add white noise concentrated at the contact patch to every ``*.profile.csv`` of a case ``folder``, in place:
    std ``amplitude·sigma·exp(−½(φ/width_deg)²)`` per channel [m/s²] — what an averaged profile keeps where the
    patch's impacts excite each revolution differently, a noise the diagnosis's stationary far-side model does not
    have (docs/physics.md §6.4 *noise the model does not have*)."""
    from ringfit.io.profiles import Profile, read_profile, write_profile

    for path in sorted(Path(folder).glob("*.profile.csv")):
        prof = read_profile(path)
        env = amplitude * sigma * np.exp(-0.5 * (prof.angle_deg / width_deg) ** 2)
        ch = [c + env * rng.standard_normal(len(prof)) for c in (prof.acc_radial_ms2, prof.acc_tangential_ms2)]
        write_profile(Profile(prof.angle_deg, ch[0], ch[1], condition=prof.condition), path, overwrite=True)


def add_heavy_tailed_errors(folder: str | os.PathLike, scale: float, rng, dof: float = 2.0) -> None:
    """Scatter every frequency of every ``*.modes.csv`` of a case ``folder`` by ``1 + scale·t`` (t Student's with
    ``dof`` degrees of freedom), in place: most rows move by about the tables' noise, a few far out (a row taken
    from the wrong peak, a mode fitted through its neighbour) — a noise the diagnosis's normal row model does not
    have (docs/physics.md §6.4 *noise the model does not have*). The rows' stated ``freq_std_hz`` are kept."""
    for path in sorted(Path(folder).glob("*.modes.csv")):
        lines = path.read_text().splitlines()
        j = lines[0].split(",").index("freq_hz")
        rows = [lines[0]]
        for line in lines[1:]:
            cells = line.split(",")
            if cells[j]:
                cells[j] = f"{float(cells[j]) * (1.0 + scale * rng.standard_t(dof)):.5f}"
            rows.append(",".join(cells))
        path.write_text("\n".join(rows) + "\n")


def make_profile_case(folder: str | os.PathLike, effect: str | None = None, seed: int = 0) -> CaseLabel:
    """Write a blind rolling-profile case (docs/formats.md §6) into ``folder`` (created; must be empty or absent).

    ``tyre.toml`` (bundled Table 9 values, not the truth), ``free.modes.csv`` (eq. 18 of the true
    ring, noisy, with damping) and one ``*.profile.csv`` + ``.json`` per speed (about 20/30/40/60
    km/h). Deliberately unlike the diagnosis: the truth is solved on a finer grid (M = 1024 or
    2048) and written at 360 … 2048 angles; the angle origin is offset by up to ±1.5°; Ω is in the
    sidecar only sometimes; the road is sometimes the 1.2192 m drum; noise is white, pink, red or
    band-coloured with a level (0.05 … 3 m/s² at 40 km/h) that varies with speed and channel. ``wave_damping`` is injected as
    *viscous* material damping (docs/physics.md §4.2), not the diagnosis's growing hysteretic loss; the
    out-of-library ``tread_pitch`` modulates the contact pressure with the tread pitch (a ripple of
    40–70 pitches per revolution): expected verdict ``unexplained``.

    **Returns:** the hidden :class:`CaseLabel` (``noise["grid_rms_ms2"]`` is the noise RMS on the
    diagnosis's 512-point grid, ``noise["grid_rms_by_run_ms2"]`` the same per run as [radial,
    tangential], for the ideal shrink).
    """
    from ringfit.io.profiles import Profile, grid_angles_deg, resample_profile, write_profile
    from ringfit.io.tyre import Tyre, write_tyre
    from ringfit.physics.contact import ContactSolver
    from ringfit.physics.operating import KMH
    from ringfit.physics.profile import ProfileModel, effective_rolling_radius, simulate_profile
    from ringfit.physics.rolling import Hysteretic, RingModel, Viscous
    from ringfit.physics.sensor import STANDARD_GRAVITY, SensorModel
    from ringfit.synth.profiles import SAMPLE_RATE_HZ

    rng = np.random.default_rng(seed)
    effect = effect or str(rng.choice(PROFILE_INJECTIONS))
    if effect not in PROFILE_INJECTIONS + PROFILE_EXTRA_INJECTIONS:
        raise ValueError(f"effect {effect!r} not injectable in profiles; "
                         f"choose from {PROFILE_INJECTIONS + PROFILE_EXTRA_INJECTIONS}")
    folder = _new_case_folder(folder)
    geometry, ring = _ring(rng)
    zeta0 = float(rng.uniform(0.015, 0.035))
    ring = ring.replace(damping_ratio=zeta0, k_tread=float(ring.k_tread * np.exp(rng.normal(0.0, 0.15))))
    load = float(rng.uniform(3500.0, 4500.0))
    drum = 1.2192 if rng.random() < 0.3 else None
    solver = ContactSolver(n_grid=int(rng.choice([768, 1024, 2048])), window_deg=40.0)
    n_points = int(rng.choice([360, 720, 1000, 1024, 2048]))
    offset = math.radians(float(rng.uniform(-1.5, 1.5)))
    write_encoder = bool(rng.random() < 0.7)
    colour = str(rng.choice(NOISE_COLOURS))
    sigma40 = float(np.exp(rng.uniform(np.log(0.05), np.log(3.0))))
    speed_power = float(rng.uniform(0.0, 1.0))
    tangential_factor = float(rng.uniform(0.5, 1.5))
    speeds = [s + float(rng.uniform(-2.0, 2.0)) for s in PROFILE_SPEEDS]

    model, sensor, magnitude, pitch = RingModel(), SensorModel(), {}, None
    shear = None
    if effect == "sensor_tilt":
        magnitude.update(tilt_gain=float(rng.uniform(0.5, 1.0)), offset_mm=float(rng.uniform(0.0, 6.0)))
        sensor = SensorModel(tilt_gain=magnitude["tilt_gain"], offset=magnitude["offset_mm"] * 1e-3)
    elif effect == "gravity":
        magnitude["gravity_gain"] = float(rng.uniform(0.95, 1.05))
        sensor = SensorModel(gravity=magnitude["gravity_gain"] * STANDARD_GRAVITY)
    elif effect == "iepe_highpass":
        magnitude["corner_hz"] = float(rng.uniform(0.8, 3.0))
        magnitude["order"] = int(rng.choice([1, 1, 2]))
        sensor = SensorModel(corner_hz=magnitude["corner_hz"], highpass_order=magnitude["order"])
    elif effect == "wave_damping":
        c_w = float(rng.uniform(400.0, 1200.0))
        magnitude.update(c_w=c_w, c_v=c_w * ring.kv / ring.kw)
        model = RingModel(damping=Hysteretic(), terms=(Viscous(c_w=c_w, c_v=magnitude["c_v"]),))
    elif effect == "tread_shear":
        magnitude.update(k_x=float(rng.uniform(8e6, 40e6)), mu=float(rng.uniform(0.7, 1.2)))
        shear = LeverShearTruth(magnitude["k_x"], magnitude["mu"])
    elif effect == "rotation":
        magnitude["chi"] = float(rng.uniform(0.1, 0.6))
        ring = ring.replace(chi=magnitude["chi"])
    elif effect == "tread_pitch":
        magnitude.update(pitches=int(rng.integers(40, 71)), depth=float(rng.uniform(0.15, 0.35)),
                         phase=float(rng.uniform(0, 2 * np.pi)))
        pitch = magnitude

    write_tyre(Tyre(geometry, {"rho_a": 2.715, "ei": 0.9426, "kw": 1.294e6, "kv": 1.161e6,
                               "k_tread": 19e6, "damping_ratio": 0.025}), folder / "tyre.toml")
    _write_table(folder, "free.modes.csv", _free_rows(rng, ring, geometry, zeta0, float(rng.uniform(5e-4, 2e-3))),
                 {"state": "free", "speed_kmh": 0, "pressure_bar": 2.2, "frame": "fixed"}, False, 0.0)
    hooks = (shear,) if shear is not None else (PitchModulation(**pitch),) if pitch is not None else ()
    truth = ProfileModel(ring_model=model, sensor=sensor, load_hooks=hooks)
    r_e = effective_rolling_radius(ring, geometry, load, drum, model=ProfileModel(ring_model=model), solver=solver)
    grid_noise, grid_by_run = [], []
    for i, speed in enumerate(speeds):
        omega = speed * KMH / r_e
        values = simulate_profile(ring, geometry, speed_kmh=speed, load_n=load, rotation_hz=omega / (2.0 * np.pi),
                                  drum_diameter_m=drum, model=truth, solver=solver, n_points=n_points,
                                  offset_rad=offset).channels
        level = sigma40 * (speed / 40.0) ** speed_power
        noise = np.stack([coloured_noise(rng, n_points, level, colour),
                          coloured_noise(rng, n_points, level * tangential_factor, colour)])
        angle = grid_angles_deg(n_points)
        condition = {"speed_kmh": round(speed, 3), "load_n": round(load, 1), "pressure_bar": 2.2,
                     "revolutions": int(rng.integers(20, 60)), "sample_rate_hz": SAMPLE_RATE_HZ}
        if write_encoder:
            condition["rotation_hz"] = omega / (2.0 * np.pi)
        if drum is not None:
            condition["drum_diameter_m"] = drum
        data = values + noise
        write_profile(Profile(angle, data[0], data[1], condition=condition), folder / f"run{i + 1}.profile.csv")
        on_grid = resample_profile(Profile(angle, noise[0], noise[1]), 512)
        ms = np.mean((on_grid - on_grid.mean(-1, keepdims=True)) ** 2, -1)  # per channel
        grid_noise.append(float(ms.mean()))
        grid_by_run.append(np.sqrt(ms).tolist())
    return CaseLabel(
        effect=effect, expected_verdict=EXPECTED.get(effect, effect), magnitude=magnitude,
        noise={"colour": colour, "sigma40_ms2": sigma40, "speed_power": speed_power,
               "tangential_factor": tangential_factor, "grid_rms_ms2": float(np.sqrt(np.mean(grid_noise))),
               "grid_rms_by_run_ms2": grid_by_run},
        ring={**ring.as_dict(), "load_n": load, "drum_diameter_m": drum, "grid": solver.n_grid,
              "n_points": n_points, "angle_offset_deg": math.degrees(offset), "encoder": write_encoder},
        seed=seed)
