"""Identify the tyre once, from everything measured on it: one joint weighted least squares (docs/physics.md §11).

A case folder (docs/formats.md §6) is read by the one case-folder reader (:func:`read_identify_folder`,
:mod:`ringfit.io.case`). Each kind of measurement is a residual block on the one engine (:mod:`ringfit.fit.engine`)
sharing the ring, each run keeping its own nuisances: free modes and free damping
(:mod:`ringfit.fit.free_block`), standing loaded modes (the patch from the static contact solve at the stated
load), rolling profiles (:mod:`ringfit.fit.profile_block`: harmonic rows, gain, angle offset and the sensor's own
nuisances). Across states (two or more pressures, a known torque) the ring's pressure law and the tread's
longitudinal stiffness are identified too. §11 gives the method: the blocks, each block's noise model and its
Student-t widening, the model's own discretisation checked at the optimum (:func:`grid_check`), the discrepancy
ratio per block (:func:`discrepancy_ratio`), what each block tells (Fisher shares), the active set on bounds and
friction held, carried or read. Stated conditions are checked on reading and each loaded table's load after the
fit (:func:`load_check`). :func:`identify` returns an :class:`Identification` and never raises on
non-convergence (check ``converged``).

Example (``ringfit example identify --out ex``: free, loaded at 3 and 5 kN, three profiles; about 30 s CPU)::

    from ringfit.fit.identify import identify, read_identify_folder
    ident = identify(read_identify_folder("ex/case"))
    ident.converged, ident.ring.ei, ident.ring.k_tread   # True, 1.026 N m² (truth 1.023), 2.0325e7 (2.0328e7)
    ident.covariance.sd_ln("ei")                         # σ of ln EI, carried into the tyre file
    list(ident.blocks)                                   # ['free modes', 'free damping', 'loaded modes', 'profiles']
"""

from __future__ import annotations

import dataclasses
import math
import os
import warnings
from dataclasses import dataclass, field
from pathlib import Path
from typing import ClassVar

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np

from ringfit.errors import InputError
from ringfit.fit.engine import LINEAR, LOG, AbstractResiduals, Coordinate, Problem, least_squares, residuals
from ringfit.fit.free_block import (DISCREPANCY_FOLDS, FOLD_LEVERAGE_MAX, SCALE_PASSES,  # noqa: F401 (re-exported)
                                    SCALE_TOLERANCE, Z95, block_scale, discrepancy_ratio, frequency_folds,
                                    hat_diagonal, noise_passes, t_widening)
from ringfit.fit.least_squares import (DEFAULT_RELATIVE_STD, RING_COORDS, RING_FIELDS, frequency_data,
                                      ring_from_vector, ring_vector)
from ringfit.fit.priors import BOUNDS
from ringfit.fit.profile_block import (PROFILE_K_MAX, SENSOR_FIELDS, decrement_tol, harmonic_rows, noise_from_residual, nuisance_coords,
                                       nuisance_names, nuisance_prior, nuisance_start, profile_basis, profile_rows,
                                       read_through, sensor_basis, sensor_coords, sensor_names, sensor_prior,
                                       sensor_reading, sensor_start)
from ringfit.fit.result import FitResult, covariance_from_jacobian, grid_moves
from ringfit.io.case import CaseFolder, read_case_folder, sidecar_number
from ringfit.io.conditions import pressure_conflict
from ringfit.io.modes import ModeTable
from ringfit.io.tyre import LINEAR_COVARIANCE, RingCovariance, Tyre
from ringfit.params import RingParams, TyreGeometry, TyreLaws
from ringfit.physics.contact import ContactSolver, as_traced, patch_edges, solve_rolling
from ringfit.physics.loaded import loaded_natural_frequencies
from ringfit.physics.natural import natural_frequencies
from ringfit.physics.operating import OperatingPoint
from ringfit.physics.profile import (FlatOrDrum, ProfileModel, flat_or_drum, full_band, profile_channels,
                                     rolling_state, spectral_stage)
from ringfit.physics.state import TyreState, state_profile, state_solution, state_tyre

#: Relative σ of a damping ratio row before its block scale is estimated.
DAMPING_RELATIVE_STD = 0.05
#: Harmonics of the loaded-mode basis (docs/physics.md §6; N = 20 is within 0.2 Hz of N = 40).
LOADED_HARMONICS = 24
#: The grid check refines the contact grid and the loaded-mode basis twice, by 2 and by this factor, and
#: extrapolates to the continuum by Richardson's rule, as the state estimate reads (docs/physics.md §11, §13.4).
GRID_CHECK_FACTOR = 4
#: Parameters of the ring the identification can free.
RING_FREE = ("rho_a", "ei", "kw", "kv", "k_tread", "damping_ratio")
BLOCKS = ("free modes", "free damping", "loaded modes", "profiles", "torque")


# ----------------------------------------------------------------------------- inputs


@dataclass
class IdentifyInputs(CaseFolder):
    """What a case folder holds for the identification (see the module docstring): the reader's
    :class:`~ringfit.io.case.CaseFolder` and how identify uses its tables — ``loaded`` (standing, with their
    ``load_n``), ``skipped`` (why a table is not used), ``free_more`` (free tables at other pressures than
    ``free``'s: identify across states, docs/physics.md §11)."""

    loaded: list[ModeTable] = field(default_factory=list)
    skipped: list[str] = field(default_factory=list)
    free_more: list[ModeTable] = field(default_factory=list)

    @property
    def files(self) -> list[str]:
        return [Path(t.source).name for t in [self.free, *self.free_more, *self.loaded]] + \
            [Path(str(p.source)).name for p in self.profiles]


def read_identify_folder(folder: str | os.PathLike) -> IdentifyInputs:
    """Read a case folder for :func:`identify` with the one case-folder reader
    (:func:`ringfit.io.case.read_case_folder`: its rules and messages), then identify's own use of it: a free table
    at another pressure is a state of its own (identify across states), a rolling table is listed as skipped, any
    other table must be ``loaded`` with its ``load_n`` (one line naming the sidecar and the key); every pressure is
    checked at the end (one: the tyre file's; several: the pressure law)."""
    # the pressure is checked below, over every measurement (one pressure: the tyre file's; several: the law)
    case = read_case_folder(folder, other_pressure="refuse", pressure_law=True)
    tyre, free = case.tyre, case.free
    inputs = IdentifyInputs(case.folder, tyre, free, tables=case.tables, records=case.records)
    free_path = Path(str(free.source))
    stated = [(free.condition, free_path.with_suffix(".json"))]  # every measurement's condition: its pressure
    for table in case.tables:
        p = Path(str(table.source))
        sidecar = p.with_suffix(".json")
        cond = table.condition
        speed = sidecar_number(cond, "speed_kmh") or sidecar_number(cond, "rotation_hz") or 0.0
        if table.state == "free" and not speed:
            # a free table at another pressure is a state of its own (identify across states); at a pressure
            # already measured it is a second copy of that state
            seen = [measured_pressure(t.condition, tyre) for t in [free, *inputs.free_more]]
            here = measured_pressure(cond, tyre)
            if all(not _same_pressure(here, q) for q in seen):
                inputs.free_more.append(table)
                stated.append((cond, sidecar))
                continue
            inputs.skipped.append(f"{p.name}: a second free table at a pressure already measured (only one free "
                                  "table per pressure is used: free.modes.csv at its own)")
            continue
        if speed:
            inputs.skipped.append(f"{p.name}: spinning/rolling table (state {table.state!r}, speed {speed:g}); "
                                  "rolling mode tables are not part of the joint model yet")
            continue
        if table.state != "loaded":
            raise InputError(f"state {table.state!r}: expected \"loaded\" (standing, with load_n) for a table "
                             "the identification uses", source=sidecar)
        load = sidecar_number(cond, "load_n")
        if load is None:
            raise InputError("missing 'load_n': a loaded table's load [N] is needed to identify from it",
                             source=sidecar)
        if not (math.isfinite(load) and load > 0):
            raise InputError(f"load_n = {cond.get('load_n')!r}: expected a positive load [N]", source=sidecar)
        stated.append((cond, sidecar))
        inputs.loaded.append(table)
    for prof in case.profiles:  # sorted by load, then speed; load_n and speed_kmh checked by the reader
        stated.append((prof.condition, Path(str(prof.source)).with_suffix(".json")))
        inputs.profiles.append(prof)
    _check_pressures(stated, tyre)
    return inputs


def _check_pressure(cond: dict, tyre_bar: float, source) -> None:
    """A measurement at another pressure than the tyre file's is refused: the ring identified is the tyre's at
    its pressure, and the pressure changes the stiffness it is identified from (as ``fit-rolling`` refuses)."""
    note = pressure_conflict(cond, tyre_bar)
    if note:
        raise InputError(f"{note}; identify measurements at one pressure, with that pressure in tyre.toml",
                         source=source)


# ----------------------------------------------------------------------------- identify across states: inputs


#: A measurement's stated pressure must lie within this share of the tyre file's p_ref when the measurements span
#: two or more pressures: the pressure law of docs/physics.md §13.1 is linear in p/p_ref, not trusted beyond.
PRESSURE_LAW_SPAN = (0.5, 1.5)
#: Two stated pressures closer than this share are one pressure (io.conditions' tolerance).
PRESSURE_SAME = 0.05
#: A stated tread depth this far [mm] from the tyre file's is another tread state (not read by identify).
TREAD_DEPTH_TOL_MM = 0.05


def measured_pressure(cond: dict, tyre: Tyre) -> float:
    """A measurement's pressure [Pa]: its stated ``pressure_bar``, else the tyre file's p_ref."""
    p = sidecar_number(cond, "pressure_bar")
    return float(tyre.geometry.pressure) if p is None or not (math.isfinite(p) and p > 0) else p * 1e5


def _same_pressure(a: float, b: float) -> bool:
    return abs(a - b) <= PRESSURE_SAME * max(a, b)


def distinct_pressures(pressures) -> list[float]:
    """The distinct pressures among ``pressures`` [Pa] (two within :data:`PRESSURE_SAME` are one), sorted."""
    out: list[float] = []
    for p in sorted(float(x) for x in pressures):
        if not out or not _same_pressure(p, out[-1]):
            out.append(p)
    return out


def _check_pressures(stated: list, tyre: Tyre) -> None:
    """The measurements' pressures, checked together (docs/formats.md §6).

    One pressure (every measurement within :data:`PRESSURE_SAME` of one value): it must be the tyre file's, as
    before — the ring identified is the tyre's at p_ref. Two or more: the ring is carried to each through the
    pressure law (docs/physics.md §13.1), which is trusted within :data:`PRESSURE_LAW_SPAN` × p_ref only. A
    stated tread depth other than the file's is refused (identify reads every measurement at d_ref)."""
    p_ref = float(tyre.geometry.pressure)
    pressures = [measured_pressure(c, tyre) for c, _ in stated]
    if len(distinct_pressures(pressures)) <= 1:
        for cond, source in stated:
            _check_pressure(cond, p_ref / 1e5, source)
    else:
        lo, hi = PRESSURE_LAW_SPAN
        for p, (cond, source) in zip(pressures, stated):
            if not lo * p_ref <= p <= hi * p_ref:
                raise InputError(f"pressure_bar = {p / 1e5:g} is outside {lo:g}–{hi:g} × the tyre file's "
                                 f"{p_ref / 1e5:g} bar, the range the linear pressure law (docs/physics.md §13.1) "
                                 "is identified over; give measurements nearer the tyre file's pressure",
                                 source=source)
    d_ref = tyre.state_values.get("tread_depth_mm")
    for cond, source in stated:
        d = sidecar_number(cond, "tread_depth_mm")
        if d is not None and (d_ref is None or abs(d - d_ref) > TREAD_DEPTH_TOL_MM):
            at = "no tread_depth_mm" if d_ref is None else f"tread_depth_mm = {d_ref:g}"
            raise InputError(f"tread_depth_mm = {d:g}: identify reads every measurement at the tyre file's tread "
                             f"depth ({at} in tyre.toml); give measurements at that depth", source=source)


# ----------------------------------------------------------------------------- the joint residual model


class JointArrays(eqx.Module):
    """Data of the joint model; a block the folder lacks is ``None`` (static: one compile per structure).

    - free: ``f_n``, ``f_freq``, ``f_sigma`` ``(mf,)``; damping: ``d_zeta``, ``d_sigma`` ``(md,)``;
    - loaded: ``l_n`` ``(ml,)`` harmonic − 1, ``l_sin`` ``(ml,)`` 0/1, ``l_table`` ``(ml,)``, ``l_freq``,
      ``l_sigma``; per table ``l_load`` ``(T,)``, ``l_roads``;
    - profiles: ``p_omega``, ``p_load`` ``(P,)``, ``p_roads``, ``p_band``, ``p_measured`` ``(P, 2, H)``
      harmonic rows (real parts then imaginary parts of k = k_min …), ``p_sigma`` ``(P, 2, H)``.
    """

    geometry: TyreGeometry
    f_n: jax.Array
    f_freq: jax.Array
    f_sigma: jax.Array
    d_zeta: jax.Array | None
    d_sigma: jax.Array | None
    l_n: jax.Array | None
    l_sin: jax.Array | None
    l_table: jax.Array | None
    l_freq: jax.Array | None
    l_sigma: jax.Array | None
    l_load: jax.Array | None
    l_roads: FlatOrDrum | None
    p_omega: jax.Array | None
    p_load: jax.Array | None
    p_roads: FlatOrDrum | None
    p_band: jax.Array | None
    p_measured: jax.Array | None
    p_sigma: jax.Array | None
    # identify across states (docs/physics.md §11 *across states*; None without): the tyre file's state laws,
    # each free table's pressure ``f_pressures`` (F,) and its rows' table ``f_table`` (mf,), each loaded table's
    # ``l_pressure`` (T,), each profile's ``p_pressure`` (P,); the torque rows: profile ``t_index`` (D,), stated
    # ``t_torque`` and ``t_sigma`` [N m]
    laws: TyreLaws | None = None
    f_pressures: jax.Array | None = None
    f_table: jax.Array | None = None
    l_pressure: jax.Array | None = None
    p_pressure: jax.Array | None = None
    t_index: jax.Array | None = None
    t_torque: jax.Array | None = None
    t_sigma: jax.Array | None = None


def standing_half_angle(ring: RingParams, geometry: TyreGeometry, load, road, solver: ContactSolver):
    """Contact half-angle [rad] of the standing tyre at ``load`` [N]: the static contact solve (docs/physics.md §4.3–4.4)."""
    sol = solve_rolling(ring, geometry, OperatingPoint(0.0, load, road), solver=solver)
    lead, trail = patch_edges(sol)
    return 0.5 * (trail - lead)


#: The posterior's contact window (docs/physics.md §12.3): this many times the widest patch's half-extent at the
#: optimum (and two grid steps more), when that is narrower than the fit's window.
POSTERIOR_WINDOW_MARGIN = 1.5


@eqx.filter_jit
def contact_extents(model: "JointResiduals", theta, data: "JointArrays"):
    """``(extent (E,) [rad], load (E,) [N])`` over every contact solve of the joint model at θ (the loaded tables'
    standing solves, then the profiles' rolling ones; docs/physics.md §4.4): the largest |φ| of a loaded grid
    point, and the condition's load; one condition after another (:func:`serial_map`). Not for a model across
    states (its solves are the state solution's)."""
    ring = ring_from_vector(theta)
    g = data.geometry
    phi = model.solver.grid()

    def extent(sol):
        return jnp.max(jnp.where(sol.pressure > 0.0, jnp.abs(phi), 0.0))

    ext, loads = [], []
    if data.l_n is not None:
        ext.append(serial_map(
            lambda a: extent(solve_rolling(ring, g, OperatingPoint(0.0, a[0], a[1]), solver=model.solver)),
            (data.l_load, data.l_roads)))
        loads.append(data.l_load)
    if data.p_omega is not None:
        pm = model.profile_model
        ring_p = pm.ring(ring)
        ext.append(serial_map(
            lambda a: extent(rolling_state(pm, ring_p, g, OperatingPoint(a[0], a[1], a[2]), model.solver)[0]),
            (data.p_omega, data.p_load, data.p_roads)))
        loads.append(data.p_load)
    return jnp.concatenate(ext), jnp.concatenate(loads)


def posterior_solver(model: "JointResiduals", theta, data: "JointArrays") -> ContactSolver:
    """The contact solver of identify's posterior (docs/physics.md §12.3, §12.5), from the patches at θ: the fit's,
    its window narrowed to :data:`POSTERIOR_WINDOW_MARGIN` times the widest patch plus two grid steps, strict (a
    walker whose patch reaches the narrowed edge has density 0, never a clipped patch), without the derivative's
    extra solve (``differentiable=False``: the sampler never differentiates), and each active set started at
    the patch the conditions have at θ (``start_compliance``: the mean of (R+τ)(1 − cos a)/Fz over the
    conditions, a their patch extents). The dense bordered solves cost ∝ K³ in the window's K points, times
    the iterations. The fit's solver itself where the narrowed window would not be narrower, or across states."""
    solver = model.solver
    if model.across or (data.l_n is None and data.p_omega is None):
        return solver
    ext, loads = (np.asarray(a, dtype=np.float64) for a in contact_extents(model, jnp.asarray(theta), data))
    step = 360.0 / solver.n_grid
    half = POSTERIOR_WINDOW_MARGIN * math.degrees(float(np.max(ext))) + 2 * step
    if not (half < solver.window_deg - step and np.all(ext > 0) and np.all(loads > 0)):
        return solver
    compliance = float(np.mean(float(data.geometry.outer_radius) * (1.0 - np.cos(ext)) / loads))
    return ContactSolver(n_grid=solver.n_grid, window_deg=half, max_iter=solver.max_iter, strict_window=True,
                         differentiable=False, start_compliance=compliance)


def serial_map(f, xs):
    """``f`` over the leading axis of the pytree ``xs``, one element after another (``jax.lax.map``), not vmapped.

    Why: jaxlib's CPU LAPACK kernels (LU, triangular solve, eigh, …; jaxlib 0.10.2) split a *batched* call
    into chunks, schedule them on XLA's intra-op thread pool and block the calling pool thread until they are
    done. XLA runs independent parts of one program concurrently on that same pool, so when two batched calls
    (the loaded tables' contact solves and the profiles', say) start together on a pool of two threads — a
    2-core machine — every pool thread waits for a chunk no thread is free to run: the program hangs for ever
    with every XLA thread idle. A call with one matrix runs inline and never waits, so mapping the contact
    solves one condition after another removes the hang whatever else runs beside them (the cost is nil: the
    kernel loops over the matrices either way). tests/test_identify.py checks the compiled programs for
    batched LAPACK calls; :attr:`JointResiduals.serial_batches` makes the engine's batches over parameter
    vectors (the posterior's walkers) serial too.
    """
    return jax.lax.map(f, xs)


class JointResiduals(AbstractResiduals):
    """Rows of every block, each divided by its σ; θ = ring fields, then per profile (angle offset, gain).

    aux: ``(free model Hz, loaded model Hz, profile model rows)`` (``None`` for absent blocks).
    """

    #: the posterior's walkers are evaluated one after another (see :func:`serial_map`)
    serial_batches: ClassVar[bool] = True
    n_profiles: int = eqx.field(static=True)
    solver: ContactSolver = eqx.field(static=True)
    profile_model: ProfileModel = eqx.field(static=True)
    n_harmonics: int = eqx.field(static=True, default=LOADED_HARMONICS)
    #: profile rows as on a grid of this many points (0: the solver's grid); the grid check's finer model
    rows_grid: int = eqx.field(static=True, default=0)
    #: highest profile harmonic compared (0: M/2 − 1); :func:`profile_band`
    k_top: int = eqx.field(static=True, default=0)
    #: identify across states (docs/physics.md §11): θ carries the state laws and the profiles' slips
    #: (:func:`state_parameters`), every state is read through :func:`ringfit.physics.state.state_tyre`
    across: bool = eqx.field(static=True, default=False)
    #: each profile read through its sensor's own nuisances (:data:`~ringfit.fit.profile_block.SENSOR_FIELDS`: tilt,
    #: IEPE corner, liner offset, tangential gain), θ's last 4P entries — as the state estimate reads a recording
    sensor: bool = eqx.field(static=True, default=False)

    # two stages (the engine's two-stage model, :class:`ringfit.fit.engine.AbstractResiduals`): the solves (eq. 18,
    # the loaded modes, the rolling profiles), then each run's reading through its gain and angle offset — so a
    # linearisation passes the 2P nuisances' tangents through the reading only, not through the contact solves
    @property
    def readout(self) -> tuple[int, ...]:
        """θ indices of the profiles' nuisances (angle offset, gain per profile; with :attr:`sensor`, each run's sensor
        nuisances): they act after the solves."""
        base = len(RING_FIELDS)
        out = tuple(range(base, base + 2 * self.n_profiles))
        if self.sensor:
            start = self.sensor_start
            out += tuple(range(start, start + len(SENSOR_FIELDS) * self.n_profiles))
        return out

    @property
    def sensor_start(self) -> int:
        """θ index of the first sensor nuisance (after the ring, the runs' gains and offsets, and across states the
        laws and slips)."""
        P = self.n_profiles
        return len(RING_FIELDS) + 2 * P + ((len(LAW_FIELDS) + P) if self.across else 0)

    def __call__(self, theta, data: JointArrays):
        return self.outer(self.inner(theta, data), theta, data)

    def inner(self, theta, data: JointArrays):
        """The expensive stage: every block's model before the profiles' reading — ``(free model Hz, loaded model
        Hz or None, profile channels (P, 2, M) or None, drive torques (P,) or None)``; it does not depend on the
        :attr:`readout` entries of θ."""
        ring = ring_from_vector(theta)
        g = data.geometry
        laws, slips = state_parameters(theta, data, self.n_profiles) if self.across else (None, None)

        def at(pressure):
            """The ring and geometry at a measurement's pressure (docs/physics.md §13.1; at d_ref)."""
            g_p, ring_p, _ = state_tyre(g, ring, laws, pressure, laws.tread_depth_ref)
            return ring_p, g_p

        # free modes: eq. 18 (docs/physics.md §2.1), block "free modes" of §11; across states each free table at
        # its own pressure
        if laws is None:
            f_model = natural_frequencies(ring, g, data.f_n)
        else:
            per = jax.vmap(lambda p: natural_frequencies(*at(p), data.f_n))(data.f_pressures)  # (F, mf)
            f_model = per[data.f_table, jnp.arange(data.f_n.shape[0])]
        l_model = ch = torque = None
        if data.l_n is not None:
            # loaded modes: the patch half-angle from the static contact solve at load_n (docs/physics.md §4.3–4.4),
            # the modes from the patch foundation of §6 ground_contact (§11 "loaded modes"); one table after another
            # (serial_map: no batched LAPACK call, see its docstring)
            def table_freqs(args):
                fz, road, pressure = args
                ring_t, g_t = (ring, g) if laws is None else at(pressure)
                a = standing_half_angle(ring_t, g_t, fz, road, self.solver)
                c, s = loaded_natural_frequencies(ring_t, g_t, a, self.n_harmonics)
                return jnp.stack([c, s])

            pressures = data.l_load if data.l_pressure is None else data.l_pressure  # (unused without laws)
            freqs = serial_map(table_freqs, (data.l_load, data.l_roads, pressures))  # (T, 2, N)
            l_model = freqs[data.l_table, data.l_sin, data.l_n]
        if data.p_omega is not None:
            # profiles: the rolling ring read by the sensor (docs/physics.md §4–§5), one profile after another
            # (serial_map); each run's gain and angle offset are the outer stage's
            def one_profile(args):
                om, fz, road, band = args
                if self.sensor:  # the reading's bilinear basis in (e, γ), read in the outer stage
                    pm = self.profile_model
                    return profile_basis(pm, pm.ring(ring), g, OperatingPoint(om, fz, road), band, self.solver)
                return profile_channels(self.profile_model, ring, g, om[None], fz[None],
                                        jax.tree.map(lambda x: x[None], road), band[None], 0.0, self.solver)[0]

            def one_state(args):
                # across states: the profile at its state — pressure, slip (docs/physics.md §13) — through the one
                # state solution (the lever brush when the tyre has one); its drive torque T = Fx·H for the torque rows
                om, fz, road, pressure, slip = args
                state = TyreState(load=fz, pressure=pressure, tread_depth=laws.tread_depth_ref, slip=slip, omega=om)
                sol, channels, q = state_solution(g, ring, laws, state, model=self.profile_model, solver=self.solver,
                                                  road=road)
                if self.sensor:  # the reading's bilinear basis in (e, γ) at the state's geometry
                    pm, ring_s, g_s = state_profile(g, ring, laws, state, model=self.profile_model)
                    ring_s = pm.ring(ring_s)
                    channels = spectral_stage(pm, sensor_basis(sol, g_s, pm.sensor), ring_s, g_s, jnp.full(4, om),
                                              jnp.asarray(full_band(4, self.solver.n_grid)), 0.0)
                return channels, q.torque

            if laws is None:
                ch = serial_map(one_profile, (data.p_omega, data.p_load, data.p_roads, data.p_band))
            else:
                ch, torque = serial_map(one_state, (data.p_omega, data.p_load, data.p_roads, data.p_pressure, slips))
        return f_model, l_model, ch, torque

    def outer(self, inner, theta, data: JointArrays):
        """The cheap stage: every block's rows, each divided by its σ, from :meth:`inner`'s models — the profiles
        read through each run's gain and angle offset (:func:`ringfit.fit.profile_block.read_through`)."""
        f_model, l_model, ch, torque = inner
        ring = ring_from_vector(theta)
        rows = [(f_model - data.f_freq) / data.f_sigma]
        aux = [f_model, l_model, None]
        if data.d_zeta is not None:  # free damping: one modal ζ (docs/physics.md §11)
            rows.append((ring.damping_ratio - data.d_zeta) / data.d_sigma)
        if l_model is not None:
            rows.append((l_model - data.l_freq) / data.l_sigma)
        if ch is not None:
            P = self.n_profiles
            base = len(RING_FIELDS)
            offset = theta[base : base + 2 * P : 2]
            gain = theta[base + 1 : base + 2 * P : 2]
            if self.sensor:  # each run's sensor: (e, γ) on its basis, its high-pass and tangential gain
                start, F = self.sensor_start, len(SENSOR_FIELDS)
                ch = sensor_reading(ch, data.p_omega, theta[start : start + F * P].reshape(P, F))
            # profiles compared in revolution harmonics (§11 "profiles")
            model = harmonic_rows(read_through(ch, offset, gain), rows_grid=self.rows_grid or None, k_top=self.k_top)
            rows.append(((model - data.p_measured) / data.p_sigma).ravel())
            aux[2] = model
            if data.t_index is not None:
                # torque: the stated axle torque against the brush's T = Fx·H at the profile's slip (§11, §13.2)
                rows.append((torque[data.t_index] - data.t_torque) / data.t_sigma)
        return jnp.concatenate(rows), tuple(aux)


#: The state laws identified across states, in θ after the profiles' nuisances (docs/physics.md §11): the pressure
#: shares (linear, in [0, 1]) and the tread's longitudinal stiffness k_x (log). Then one slip κ per profile.
LAW_FIELDS = ("kw_share", "kv_share", "k_tread_share", "k_x")
#: k_x's plausible range [N/m²]: the bounded coordinate of the fit and the cap of its covariance.
K_X_BOUNDS = (1.0e5, 1.0e9)
#: k_x's start [N/m²] when profiles at a torque identify it and the tyre file has no ``kx_n_per_m2``
#: (docs/formats.md §6): a passenger-car tread's order of magnitude; the data move it.
K_X_START = 15.0e6
#: Bound of a profile's slip κ (the nuisance of a profile at a torque).
SLIP_BOUND = 0.3
#: A stated torque's σ when the sidecar gives no ``torque_std_nm``: this share of |T|, at least the floor [N m].
TORQUE_RELATIVE_STD = 0.02
TORQUE_STD_FLOOR_NM = 2.0


def slip_names(P: int) -> tuple[str, ...]:
    """Names of the profiles' slips across states: ``slip_i`` (i = 1 … P)."""
    return tuple(f"slip_{i + 1}" for i in range(P))


def state_parameters(theta, data: JointArrays, P: int):
    """The state laws at θ (the tyre file's :class:`~ringfit.params.TyreLaws` with :data:`LAW_FIELDS` from θ) and
    the profiles' slips ``(P,)`` — θ's part after the ring and the profiles' nuisances (:func:`state_coords`)."""
    base = len(RING_FIELDS) + 2 * P
    v = theta[base : base + len(LAW_FIELDS)]
    laws = data.laws.replace(**{name: v[j] for j, name in enumerate(LAW_FIELDS)})
    start = base + len(LAW_FIELDS)
    return laws, theta[start : start + P]


def state_coords(P: int) -> tuple[Coordinate, ...]:
    """Coordinates of the state laws and slips (after :func:`joint_coords`' when identifying across states): each
    pressure share linear in [0, 1], k_x log in :data:`K_X_BOUNDS`, each slip linear (scale 0.01) in ±
    :data:`SLIP_BOUND`. Every one of them bounded: a law the data do not bound stops at its range's edge, flagged."""
    coords = [Coordinate(n, LINEAR, lo=0.0, hi=1.0) for n in LAW_FIELDS[:3]]
    coords.append(Coordinate("k_x", LOG, lo=K_X_BOUNDS[0], hi=K_X_BOUNDS[1]))
    coords += [Coordinate(n, LINEAR, scale=0.01, lo=-SLIP_BOUND, hi=SLIP_BOUND) for n in slip_names(P)]
    return tuple(coords)


def joint_coords(P: int) -> tuple[Coordinate, ...]:
    """The joint fit's coordinates: the ring's (log), then per profile its angle offset (linear) and gain (log).

    The ring parameters the identification frees are held inside their plausible range :data:`BOUNDS` (the
    engine's bounded transform): a parameter the data do not bound — k_tread from a loaded table that shows no
    contact, EI from free modes alone — then stops at the range's edge, flagged there with its interval to the
    bound, instead of running off towards 0 or ∞ until the solver's step limit."""
    coords = [Coordinate(c.name, c.kind, c.center, c.scale, lo=BOUNDS[c.name][0], hi=BOUNDS[c.name][1])
              if c.name in RING_FREE and c.name in BOUNDS else c for c in RING_COORDS]
    return tuple(coords) + nuisance_coords(P)  # the profile block's nuisances (ringfit.fit.profile_block)


# ----------------------------------------------------------------------------- rows of each block


@dataclass
class _Rows:
    """Every block's rows (dicts of arrays, ``None`` for a block the folder lacks); σ arrays are rescaled in place."""

    free: dict
    damping: dict | None
    loaded: dict | None
    profiles: dict | None
    #: identify across states: the torque rows (``index``, ``torque``, ``sigma`` per profile at a torque)
    torque: dict | None = None
    #: identify across states: ``laws``, ``f_pressures``, ``l_pressure``, ``p_pressure`` (None: one state)
    states: dict | None = None


def _free_rows(table: ModeTable, more: list[ModeTable] = ()) -> dict:
    """The free tables' rows (``free.modes.csv``, then each free table at another pressure); ``table`` says whose."""
    parts = [frequency_data(t) for t in [table, *more]]
    d = parts[0]
    out = dict(n=d.n, freq=d.freq_hz, sigma=d.sigma_hz, given=d.stated, rows=d.rows)
    if more:
        out.update(n=np.concatenate([q.n for q in parts]), freq=np.concatenate([q.freq_hz for q in parts]),
                   sigma=np.concatenate([q.sigma_hz for q in parts]),
                   given=all(q.stated for q in parts),
                   table=np.concatenate([np.full(q.n.size, j) for j, q in enumerate(parts)]),
                   sources=[t.source for t in [table, *more]])
    return out


def _damping_rows(table: ModeTable) -> dict | None:
    base = table.structural_with_n()
    zeta = table.damping_pct / 100.0
    ok = base & np.isfinite(zeta) & (zeta > 0)
    if ok.sum() < 2:
        return None
    z = zeta[ok]
    return dict(zeta=z, sigma=DAMPING_RELATIVE_STD * np.full(z.size, float(np.median(z))), given=False)


def _loaded_rows(tables: list[ModeTable], ring: RingParams, geometry: TyreGeometry, solver) -> tuple[dict, list]:
    notes = []
    n, sin, tab, freq, sigma, loads, drums, untagged = [], [], [], [], [], [], [], []
    for ti, t in enumerate(tables):
        loads.append(float(t.condition["load_n"]))
        d = sidecar_number(t.condition, "drum_diameter_m")
        drums.append(d if d and math.isfinite(d) and d > 0 else math.nan)
        std = t.freq_std_hz
        for i in range(len(t)):
            if t.kind[i] != "structural" or not t.n[i] >= 1 or int(t.n[i]) > LOADED_HARMONICS:
                continue
            tag = str(t.tag[i])
            s = 1 if tag in ("0", "hort") else 0 if tag in ("extr", "vert") else -1
            f = float(t.freq_hz[i])
            n.append(int(t.n[i]) - 1)
            sin.append(s)
            tab.append(ti)
            freq.append(f)
            sigma.append(float(std[i]) if np.isfinite(std[i]) and std[i] > 0 else DEFAULT_RELATIVE_STD * f)
            if s < 0:
                untagged.append(len(n) - 1)
    if not n:
        return None, notes
    if untagged:
        # untagged rows: the branch (contact-symmetric or -antisymmetric) nearer to the row at the start
        road = flat_or_drum(np.array(drums), len(tables))
        branches = {}  # per table with untagged rows: its (cosine, sine) model frequencies at the start
        for ti in sorted({tab[j] for j in untagged}):
            half = float(standing_half_angle(ring, geometry, loads[ti], jax.tree.map(lambda x: x[ti], road), solver))
            branches[ti] = [np.asarray(x) for x in loaded_natural_frequencies(ring, geometry, half, LOADED_HARMONICS)]
        for j in untagged:
            c, s = branches[tab[j]]
            sin[j] = int(abs(s[n[j]] - freq[j]) < abs(c[n[j]] - freq[j]))
        notes.append(f"{len(untagged)} loaded row(s) without a tag matched to the nearer branch at the start")
    given = all(np.isfinite(t.freq_std_hz).all() for t in tables)
    return dict(n=np.array(n), sin=np.array(sin), table=np.array(tab), freq=np.array(freq), sigma=np.array(sigma),
                sigma0=np.array(sigma), load=np.array(loads), drum=np.array(drums), given=given), notes


def _profile_rows(profiles, geometry, ring, solver, plan: "StatePlan | None" = None) -> dict | None:
    """The profile block's rows (:func:`ringfit.fit.profile_block.profile_rows`); across states, Ω of a profile
    without ``rotation_hz`` at another pressure is V/R_e of the ring at that pressure (§13.1)."""
    if not profiles:
        return None
    from ringfit.fit.profile_block import rolling_data

    rows = profile_rows(profiles, geometry, ring, solver, k_max=PROFILE_K_MAX)
    if plan is not None and plan.active:
        for i, prof in enumerate(profiles):
            if prof.rotation_hz is None and not _same_pressure(plan.p_pressure[i], float(geometry.pressure)):
                g_i, ring_i, _ = state_tyre(geometry, ring, plan.laws, plan.p_pressure[i], plan.laws.tread_depth_ref)
                rows["omega"][i] = rolling_data([prof], g_i, ring_i, solver=solver).omega[0]
    return rows


def _arrays(geometry, rows: _Rows, solver) -> JointArrays:
    fr, dm, ld, pr = rows.free, rows.damping, rows.loaded, rows.profiles
    kw = dict(geometry=geometry, f_n=fr["n"], f_freq=fr["freq"], f_sigma=fr["sigma"],
              d_zeta=None, d_sigma=None, l_n=None, l_sin=None, l_table=None, l_freq=None, l_sigma=None,
              l_load=None, l_roads=None, p_omega=None, p_load=None, p_roads=None, p_band=None, p_measured=None,
              p_sigma=None)
    if dm is not None:
        kw.update(d_zeta=dm["zeta"], d_sigma=dm["sigma"])
    if ld is not None:
        drum = ld["drum"]
        kw.update(l_n=ld["n"].astype(np.int32), l_sin=ld["sin"].astype(np.int32), l_table=ld["table"].astype(np.int32),
                  l_freq=ld["freq"], l_sigma=ld["sigma"], l_load=ld["load"],
                  l_roads=flat_or_drum(None if np.all(np.isnan(drum)) else drum, drum.size))
    if pr is not None:
        kw.update(p_omega=pr["omega"], p_load=pr["load"], p_roads=flat_or_drum(pr["drum"], pr["P"]),
                  p_band=full_band(pr["P"], solver.n_grid), p_measured=pr["measured"], p_sigma=pr["sigma"])
    if rows.states is not None:
        kw.update(_state_arrays(rows))
    return as_traced(JointArrays(**kw))


def _slices(rows: _Rows) -> dict[str, slice]:
    out, start = {}, 0
    for name, block in zip(BLOCKS, (rows.free, rows.damping, rows.loaded, rows.profiles, rows.torque)):
        if block is None:
            continue
        m = block["sigma"].size  # one σ per row, in every block
        out[name] = slice(start, start + m)
        start += m
    return out


# ----------------------------------------------------------------------------- identify across states: setup


@dataclass
class StatePlan:
    """What identify across states does with a folder (docs/physics.md §11 *across states*).

    - ``laws``: the tyre file's :class:`~ringfit.params.TyreLaws` (with the brush switched on at
      :data:`K_X_START` when profiles at a torque need one and the file has none): the start and the held values;
    - ``free``: the laws the data identify (of :data:`LAW_FIELDS`); ``driven``: the profiles at a torque (indices);
    - ``pressures``: each free table's, loaded table's and profile's pressure [Pa]; ``notes``: what is not
      identified and why. ``active`` False: one state (one pressure, no torque, no brush) — today's model exactly.
    """

    laws: TyreLaws
    free: tuple[str, ...]
    driven: tuple[int, ...]
    f_pressures: np.ndarray
    l_pressure: np.ndarray
    p_pressure: np.ndarray
    torque: np.ndarray
    torque_sigma: np.ndarray
    notes: list
    active: bool

    def start(self, P: int) -> np.ndarray:
        """θ's start for :data:`LAW_FIELDS` and the slips: a share the data identify from 0.5 when the file's is 0 (a
        share at a bound of its sine-bounded coordinate could not move), else from the file's (held ones as given);
        every slip 0 (free rolling)."""
        law = []
        for name in LAW_FIELDS:
            v = float(getattr(self.laws, name))
            if name in self.free and name != "k_x":
                v = 0.5 if v == 0.0 else min(max(v, 0.05), 0.95)
            law.append(v)
        return np.concatenate([law, np.zeros(P)])

    def free_names(self, P: int) -> tuple[str, ...]:
        """The engine's free names of the plan: the laws identified, then the slips of the profiles at a torque."""
        return tuple(self.free) + tuple(slip_names(P)[i] for i in self.driven)


def plan_states(inputs: IdentifyInputs) -> StatePlan:
    """Which state laws a folder identifies (docs/physics.md §11 *across states*): kw_share and kv_share from
    measurements at two or more pressures, k_tread_share from loaded tables or profiles at two or more, k_x from
    profiles at a known torque; the rest held at the tyre file's values (0 without), each with a note saying so."""
    tyre = inputs.tyre
    laws = tyre.laws
    p_free = np.array([measured_pressure(t.condition, tyre) for t in [inputs.free, *inputs.free_more]])
    p_loaded = np.array([measured_pressure(t.condition, tyre) for t in inputs.loaded])
    p_prof = np.array([measured_pressure(pr.condition, tyre) for pr in inputs.profiles])
    torque = np.array([sidecar_number(pr.condition, "torque_nm") or 0.0 for pr in inputs.profiles])
    sigma = np.zeros(torque.size)
    for i, pr in enumerate(inputs.profiles):
        given = sidecar_number(pr.condition, "torque_std_nm")
        if given is not None and not (math.isfinite(given) and given > 0):
            raise InputError(f"torque_std_nm = {pr.condition.get('torque_std_nm')!r}: expected a positive σ of the "
                             "stated torque [N m]", source=Path(str(pr.source)).with_suffix(".json"))
        sigma[i] = given if given is not None else max(TORQUE_RELATIVE_STD * abs(torque[i]), TORQUE_STD_FLOOR_NM)
    driven = tuple(int(i) for i in np.flatnonzero(torque != 0.0))
    every = distinct_pressures(np.concatenate([p_free, p_loaded, p_prof]))
    contact = distinct_pressures(np.concatenate([p_loaded, p_prof]))
    held = lambda names: ", ".join(f"{n} = {float(getattr(laws, n)):g}" for n in names)  # noqa: E731
    free, notes = [], []
    if len(every) >= 2:
        free += ["kw_share", "kv_share"]
        if len(contact) >= 2:
            free.append("k_tread_share")
        else:
            notes.append("loaded tables and profiles at one pressure: the pressure law of k_tread is not identified "
                         f"(held at the tyre file's {held(['k_tread_share'])})")
    else:
        notes.append("one pressure: the pressure law is not identified (held at the tyre file's "
                     f"{held(LAW_FIELDS[:3])}); give measurements at two or more pressures to identify it")
    if driven:
        if not laws.has_brush:
            laws = laws.replace(k_x=K_X_START, has_brush=True)
            notes.append(f"the tyre file has no kx_n_per_m2: k_x started from {K_X_START:g} N/m² (the profiles at a "
                         "torque identify it)")
        free.append("k_x")
    else:
        kept = f" (held at the tyre file's {float(laws.k_x):g} N/m²)" if laws.has_brush else ""
        notes.append(f"no profile at a known torque: the tread's longitudinal stiffness k_x is not identified{kept}")
    active = len(every) >= 2 or bool(driven) or laws.has_brush
    return StatePlan(laws, tuple(free), driven, p_free, p_loaded, p_prof, torque, sigma, notes, active)


def _state_rows(plan: StatePlan, inputs: IdentifyInputs) -> tuple[dict, dict | None]:
    """The rows' state data (``_Rows.states``) and the torque rows (``_Rows.torque``) of a plan."""
    states = dict(laws=plan.laws, f_pressures=plan.f_pressures, l_pressure=plan.l_pressure,
                  p_pressure=plan.p_pressure)
    if not plan.driven:
        return states, None
    idx = np.array(plan.driven, dtype=np.int32)
    return states, dict(index=idx, torque=plan.torque[idx], sigma=plan.torque_sigma[idx],
                        sources=[inputs.profiles[i].source for i in plan.driven])


def _state_arrays(rows: _Rows) -> dict:
    st, fr, tq = rows.states, rows.free, rows.torque
    out = dict(laws=st["laws"], f_pressures=np.asarray(st["f_pressures"], dtype=np.float64),
               f_table=np.asarray(fr.get("table", np.zeros(fr["n"].size)), dtype=np.int32))
    if rows.loaded is not None:
        out["l_pressure"] = np.asarray(st["l_pressure"], dtype=np.float64)
    if rows.profiles is not None:
        out["p_pressure"] = np.asarray(st["p_pressure"], dtype=np.float64)
    if tq is not None:
        out.update(t_index=tq["index"], t_torque=tq["torque"], t_sigma=tq["sigma"])
    return out


# ----------------------------------------------------------------------------- the identification


@dataclass
class Identification:
    """The joint identification (see the module docstring).

    - ``fit``: the engine's :class:`~ringfit.fit.result.FitResult` of the last pass;
    - ``ring``: the identified :class:`RingParams`; ``free``: the ring parameters identified;
    - ``blocks``: per block its rows, noise scale, weighted RMS, Fisher share per free parameter;
    - ``correlation``: ``(names, matrix)`` of the ring parameters' posterior correlation;
    - ``covariance``: :class:`~ringfit.io.tyre.RingCovariance` of the ring parameters (ln θ);
    - ``nuisances``: per profile its gain and angle offset (deg) with σ; ``notes``: what was skipped.
    - ``grid_check``: the model's own discretisation (:func:`grid_check`): ``grid``, ``loaded_harmonics`` (coarse
      to finest) and per parameter ``shift`` (the optimum's move to the continuum, applied to the values; solver
      coordinates: ln θ of a positive parameter) and ``beyond`` (its part beyond the first refinement, carried into
      every σ and interval above as a rank-one term ``δu δuᵀ``); None when it was not run.
    """

    fit: FitResult
    ring: RingParams
    free: tuple[str, ...]
    blocks: dict
    correlation: tuple
    covariance: RingCovariance
    nuisances: list
    notes: list
    passes: int
    inputs: IdentifyInputs | None = None
    grid_check: dict | None = None
    #: ``(m,)`` per data row: its block's Student-t widening (:func:`~ringfit.fit.free_block.t_widening`) times √κ_b
    #: (:func:`discrepancy_ratio`), 1 elsewhere
    row_scale: np.ndarray | None = None
    #: ``(k,)`` the grid check's systematic direction δu (its move beyond the first refinement, solver coordinates
    #: of ``fit.names``), None when not run
    shift_u: np.ndarray | None = None
    #: the block of each data row, in order: name → slice of ``fit.residuals``
    slices: dict | None = None
    #: each measured table's rows (file name, with " damping" for the free table's damping rows) → row indices
    tables: dict | None = None

    #: the notes also given as warnings (a table's data contradicting its stated load: :func:`load_check`)
    warned: list = field(default_factory=list)
    #: identify across states (docs/physics.md §11): the state laws identified (of :data:`LAW_FIELDS`), in
    #: ``covariance`` after the ring's, and the laws at the optimum (None: one state, the file's laws untouched)
    laws_free: tuple = ()
    laws: TyreLaws | None = None
    #: what identify held and carried as a consider direction (docs/physics.md §11 *friction*): ``friction`` →
    #: value, ``sd_ln``, ``stated``, per free parameter its ``move`` for +1 σ and its σ ``sd_without``/``sd_with``
    held: dict | None = None
    #: θ at the base grid's optimum, before the grid check's move (the friction's profile reads the rows there)
    at_grid: np.ndarray | None = None

    def law_values(self) -> dict:
        """The identified state laws by tyre-file key (``kw_share`` …, ``kx_n_per_m2``; docs/formats.md §1), for
        :meth:`ringfit.io.tyre.Tyre.with_state_values`; empty when none was identified."""
        if self.laws is None:
            return {}
        out = {("kx_n_per_m2" if n == "k_x" else n): float(getattr(self.laws, n)) for n in self.laws_free}
        if self.held is not None:  # the held μ its covariance row names (docs/formats.md §1.1)
            out["friction"] = float(self.held["friction"]["value"])
        return out

    def posterior_likelihood(self) -> dict:
        """What :func:`ringfit.fit.posterior.sample` needs to sample the noise model of the intervals
        (docs/physics.md §12.3): ``row_scale`` (the t-widening and discrepancy per row) and ``shift_u`` (the grid
        check's systematic direction, and the held friction's consider direction where there is one: ``(d, k)``,
        each convolved into the draws)."""
        shifts = [] if self.shift_u is None else [np.asarray(self.shift_u, dtype=np.float64)]
        if self.held is not None:
            shifts.append(np.array([self.held["friction"]["move"][n] for n in self.fit.names]))
        shift = None if not shifts else (shifts[0] if len(shifts) == 1 else np.stack(shifts))
        return dict(row_scale=self.row_scale, shift_u=shift, tables=self.tables)

    def posterior_fit(self) -> FitResult:
        """The fit whose posterior `identify --posterior` samples: :attr:`fit` with its joint model's contact window
        narrowed to the patches at the optimum (:func:`posterior_solver`; the same density to rounding wherever
        it is not 0, at about half the cost), and :meth:`posterior_likelihood` in its ``extra``, where
        :func:`~ringfit.fit.posterior.sample` reads the noise model it samples."""
        model, data = self.fit.problem.model, self.fit.problem.data
        solver = posterior_solver(model, self.fit.theta, data)
        # the intervals' noise model travels with the fit: sample() reads it (docs/physics.md §12.3)
        extra = {**self.fit.extra, **self.posterior_likelihood()}
        if solver is model.solver:
            return dataclasses.replace(self.fit, extra=extra)
        problem = dataclasses.replace(self.fit.problem, model=dataclasses.replace(model, solver=solver))
        return dataclasses.replace(self.fit, problem=problem, extra=extra)

    @property
    def converged(self) -> bool:
        return self.fit.converged

    def parameters(self) -> dict:
        """Per ring parameter: value, lo95, hi95, sd_ln (log parameters; 95 % interval e^{ln θ ± 1.96 σ},
        :meth:`FitResult.interval <ringfit.fit.result.FitResult.interval>`).

        A barely identified parameter (an interval reaching past the plausible range :data:`BOUNDS`, or no finite
        σ at all) is a finding, not an error: its interval ends at the bound, ``to_bound`` names the end(s)
        cut there (``"lo"``, ``"hi"``), and :meth:`barely_identified` says it in a flag line. Every number is
        finite (``sd_ln`` is None when the data give no finite σ), so the report stays JSON."""
        out = {}
        for name in tuple(self.free) + tuple(self.laws_free):
            value, sd = self.fit.values[name], self.covariance.sd_ln(name)
            if name in LINEAR_COVARIANCE:  # a pressure share: value ± 1.96 σ in [0, 1]
                out[name] = linear_interval(value, sd, PARAMETER_BOUNDS[name])
            else:
                out[name] = log_interval(value, sd, PARAMETER_BOUNDS.get(name))
        return out

    def barely_identified(self) -> list[str]:
        """One flag line per parameter whose 95 % interval reaches a bound of the plausible range."""
        lines = []
        for name, p in self.parameters().items():
            if p.get("to_bound"):
                lo, hi = PARAMETER_BOUNDS[name]
                sd_value = p.get("sd_ln", p.get("sd"))
                sd = "no finite σ" if sd_value is None else f"sd{'' if 'sd' in p else ' ln'} {sd_value:.3g}"
                ends = " and ".join({"lo": f"lower bound {lo:g}", "hi": f"upper bound {hi:g}"}[e] for e in p["to_bound"])
                how = ("measurements at more pressures or profiles at larger torques" if name in PARAMETER_BOUNDS
                       and name not in BOUNDS else "loaded tables, profiles")
                lines.append(f"{name} is barely identified by these measurements ({sd}): its 95 % interval "
                             f"[{p['lo95']:.4g}, {p['hi95']:.4g}] runs to the plausible range's {ends}; "
                             f"add measurements that pin it ({how}) or hold it at a known value")
        return lines


#: Plausible ranges of every parameter identify reports: the ring's (:data:`ringfit.fit.priors.BOUNDS`), k_x's and
#: the pressure shares' (docs/physics.md §11 *across states*).
PARAMETER_BOUNDS = {**BOUNDS, "k_x": K_X_BOUNDS, **{n: (0.0, 1.0) for n in LINEAR_COVARIANCE}}


def linear_interval(value: float, sd, bounds: tuple[float, float]) -> dict:
    """``value ± 1.96 sd`` cut at ``bounds`` (a pressure share: [0, 1]); ``to_bound`` the ends cut, as
    :func:`log_interval`; ``sd`` None when not finite."""
    lo_b, hi_b = bounds
    if sd is None or not math.isfinite(sd) or not math.isfinite(value):
        return dict(value=float(value) if math.isfinite(value) else None, lo95=lo_b, hi95=hi_b, sd=None,
                    to_bound=["lo", "hi"])
    lo, hi, cut = value - Z95 * sd, value + Z95 * sd, []
    if lo <= lo_b + 1e-12:
        lo, cut = min(lo_b, value), cut + ["lo"]
    if hi >= hi_b - 1e-12:
        hi, cut = max(hi_b, value), cut + ["hi"]
    out = dict(value=float(value), lo95=float(lo), hi95=float(hi), sd=float(sd))
    if cut:
        out["to_bound"] = cut
    return out


def log_interval(value: float, sd_ln, bounds: tuple[float, float] | None) -> dict:
    """``value·e^{±1.96 sd_ln}`` computed in log space and cut at ``bounds`` (the plausible range): never an
    overflow, never an infinity. ``to_bound``: the ends cut (``"lo"``, ``"hi"``); ``sd_ln`` None when not finite."""
    lo_b, hi_b = bounds if bounds is not None else (0.0, math.inf)
    finite_sd = sd_ln is not None and math.isfinite(sd_ln)
    if not (finite_sd and value > 0 and math.isfinite(value)):
        return dict(value=float(value) if math.isfinite(value) else None, lo95=lo_b, hi95=hi_b,
                    sd_ln=float(sd_ln) if finite_sd else None, to_bound=["lo", "hi"])
    ln_v, half = math.log(value), Z95 * sd_ln
    lo, hi, cut = ln_v - half, ln_v + half, []
    if bounds is not None and lo <= math.log(lo_b) + 1e-9:
        lo, cut = min(math.log(lo_b), ln_v), cut + ["lo"]
    if bounds is not None and hi >= math.log(hi_b) - 1e-9:
        hi, cut = max(math.log(hi_b), ln_v), cut + ["hi"]
    # an end cut at a bound is that bound exactly (not e^{ln bound})
    lo95 = (lo_b if value >= lo_b else value) if "lo" in cut else math.exp(lo)
    hi95 = (hi_b if value <= hi_b else value) if "hi" in cut else math.exp(hi)
    out = dict(value=value, lo95=lo95, hi95=hi95, sd_ln=float(sd_ln))
    if cut:
        out["to_bound"] = cut
    return out


#: The solver's step budget per noise pass of :func:`identify`. A converging pass takes 5–100 steps; one whose
#: valley is long and flat takes more: the across-states case of seed 6 with μ 0.90 (the file's 1) met its
#: tolerances after 269 steps of its fourth pass (at 128 it was reported ``max_steps_reached``). Steps are a traced
#: argument: a larger budget costs nothing where the pass converges sooner, and a pass creeping to a bound is
#: finished by the engine's active set after :data:`ringfit.fit.engine.ACTIVE_SET_AFTER` steps, not at the budget.
IDENTIFY_MAX_STEPS = 512


def identify(inputs: IdentifyInputs, *, solver: ContactSolver = ContactSolver(), max_steps: int = IDENTIFY_MAX_STEPS,
             rtol: float = 1e-8, atol: float = 1e-8, progress: bool = False, sensor: bool = True) -> Identification:
    """Joint weighted least squares of the ring (and per-run nuisances) over every block of ``inputs``.

    Starts from the tyre file's ``[ring]`` (Table 9 values where it has none). ``sensor`` (default): each profile
    is read through its sensor's own nuisances (:data:`~ringfit.fit.profile_block.SENSOR_FIELDS`: tilt, IEPE corner,
    liner offset, tangential gain, each run its own, the state estimate's priors), as the state estimate reads a
    recording (docs/physics.md §11 *profiles*); ``False``: a gain and an angle offset per run only. Returns
    :class:`Identification`; never raises on non-convergence (check ``converged``).

    Runs with one BLAS thread: the contact solves' small LU factorisations run on XLA's own threads,
    and a threaded LAPACK under them only synchronises — on a busy machine it was seen to deadlock
    (two XLA threads waiting in ``dgetrf``).
    """
    from ringfit._threads import small_matrix_threads

    with small_matrix_threads():
        return _identify(inputs, solver=solver, max_steps=max_steps, rtol=rtol, atol=atol, progress=progress,
                         sensor=sensor)


def _identify(inputs, *, solver, max_steps, rtol, atol, progress, sensor, consider=True,
              start=None, friction=None) -> Identification:
    tyre = inputs.tyre
    geometry, ring0 = tyre.geometry, tyre.ring
    notes = list(inputs.skipped)
    plan = plan_states(inputs)  # identify across states (docs/physics.md §11): which laws, which notes
    notes += plan.notes
    ld, ld_notes = _loaded_rows(inputs.loaded, ring0, geometry, solver) if inputs.loaded else (None, [])
    notes += ld_notes
    rows = _Rows(_free_rows(inputs.free, inputs.free_more), _damping_rows(inputs.free), ld,
                 _profile_rows(inputs.profiles, geometry, ring0, solver, plan))
    if plan.active:
        rows.states, rows.torque = _state_rows(plan, inputs)
    P = 0 if rows.profiles is None else rows.profiles["P"]
    free = ["rho_a", "ei", "kw", "kv"]
    if rows.loaded is not None or rows.profiles is not None:
        free.append("k_tread")
    if rows.damping is not None or rows.profiles is not None:
        free.append("damping_ratio")
    free_ring = tuple(free)
    free = tuple(free) + nuisance_names(P)
    coords = joint_coords(P)
    theta = np.concatenate([ring_vector(ring0), nuisance_start(P)])
    free_laws = plan.free if plan.active else ()
    if plan.active:
        free, coords = free + plan.free_names(P), coords + state_coords(P)
        theta = np.concatenate([theta, plan.start(P)])
    prior = nuisance_prior(P)  # the runs share one sensor: their gains and offsets tied (profile block)
    if sensor and P:  # each run's sensor's own nuisances (tilt, corner, liner offset, tangential gain), last in θ
        free, coords = free + sensor_names(P), coords + sensor_coords(P)
        theta = np.concatenate([theta, sensor_start(P)])
        prior = prior.combine(sensor_prior(P))
    model = JointResiduals(P, solver, ProfileModel(), k_top=0 if rows.profiles is None else rows.profiles["k_top"],
                           across=plan.active, sensor=bool(sensor and P))
    slices = _slices(rows)
    scales = {b: 1.0 for b in slices}
    if rows.loaded is None and rows.profiles is None:
        # a free tyre's frequencies hardly see EI (docs/physics.md §2.1: the bending term is ~10 % of the
        # pressure term): without loaded tables or profiles the fit would chase it to a bound and not converge
        from ringfit.fit.least_squares import log_normal_prior
        from ringfit.fit.priors import PHYSICAL_PRIORS

        prior = log_normal_prior({k: v for k, v in PHYSICAL_PRIORS.items() if k in free_ring})
        notes.append("only free modes: EI is barely pinned by a free tyre's frequencies, so the belt-plate prior on "
                     f"EI ({PHYSICAL_PRIORS['ei'].source}; `ringfit fit --prior physical`, its default) is used; "
                     "add loaded tables or profiles to identify it from data")
    if start is not None and np.shape(start) == np.shape(theta):  # again at another held μ: from the optimum found
        theta = np.array(start, dtype=np.float64)
    state = dict(theta=theta, passes=0)
    block_dof = {}

    def fit_once():
        state["passes"] += 1
        data = _arrays(geometry, rows, solver)
        problem = Problem(model, data, coords, prior=prior, plausible=BOUNDS, data_label="these measurements")
        # the sensor's weakly told nuisances converge only linearly: stop at the decrement (docs/physics.md §11
        # *convergence*); without them, the Cauchy test alone, as every other fit of these blocks (`ringfit fit`)
        fit = least_squares(problem, state["theta"], free, max_steps=max_steps, rtol=rtol, atol=atol,
                            dtol=decrement_tol(bool(sensor and P)))
        if progress:
            print(f"identify: pass {state['passes']}: {fit.status} after {fit.iterations} steps, "
                  f"χ²/m = {fit.extra['chi2_raw'] / fit.residuals.size:.3g}",
                  flush=True)
        if fit.converged:
            state["theta"] = fit.theta.copy()
        return fit

    def renoise(fit):  # every block's noise model from this fit (free_block's scale; the profiles' spectrum)
        r = fit.residuals
        h = hat_diagonal(fit.jacobian)
        change = 0.0
        for name, sl in slices.items():
            if name == "torque":  # the stated torque's σ holds: no scale estimated (one row per slip nuisance)
                block_dof[name] = math.inf
                continue
            block = {"free modes": rows.free, "free damping": rows.damping, "loaded modes": rows.loaded}.get(name)
            if name == "profiles":
                pr = rows.profiles
                pr["sigma"] = noise_from_residual(r[sl].reshape(pr["measured"].shape) * pr["sigma"], h[sl])
                block_dof[name] = max(sl.stop - sl.start - float(h[sl].sum()), 1.0)
                s = 1.0
            else:  # the free-modes block's noise model (free_block): a stated σ only scaled up
                s, block_dof[name] = block_scale(r[sl], h[sl], bool(block is not None and block.get("given")),
                                                 scales[name])
                if block is not None:
                    block["sigma"] = block["sigma"] * s
            change = max(change, abs(s - 1.0))
            scales[name] *= s
        return change, False

    fit, passes = noise_passes(fit_once, renoise)
    # the final weights are those the last fit used: evaluate blocks with them
    # a scale estimated from ν residual degrees of freedom: its parameters follow Student's t_ν, not the normal
    widen = {n: t_widening(d) for n, d in block_dof.items() if n != "profiles"}
    # the model's form error as its held-out rows show it (docs/physics.md §11, model discrepancy)
    folds = {n: block_folds(n, sl, rows) for n, sl in slices.items()}
    ratio = {n: discrepancy_ratio(fit.jacobian, fit.residuals, f) for n, f in folds.items()}
    check = None
    pre = fit  # the base grid's optimum, before the move to the continuum (the friction's profile reads it)
    # (θ holds EA = ∞ of the inextensible ring: only the free parameters need be finite)
    if all(math.isfinite(fit.values[n]) for n in fit.names) and (rows.loaded is not None or rows.profiles is not None):
        check = grid_check(fit, rows, geometry, solver, P)
        if np.all(np.isfinite(check["shift_u"])):
            fit = grid_moved(fit, check["shift_u"])
    if friction is None and consider and plan.active and plan.laws.has_brush and fit.converged:
        # μ, which the brush needs and no row measures alone: the tyre file's value and doubt, then what the data
        # say of it (docs/physics.md §11 *friction*)
        sd_ln = friction_sd_ln(tyre)
        if progress:
            print(f"identify: again at μ·e^(±{sd_ln:.3g}) (the friction's doubt, and its profile)", flush=True)

        def again(other):  # the base identification says its warnings (a table's load): not three times
            with warnings.catch_warnings():
                warnings.simplefilter("ignore")
                return _identify(other, solver=solver, max_steps=max_steps, rtol=rtol, atol=atol, progress=False,
                                 sensor=sensor, consider=False, start=pre.theta)

        ends, how = friction_ends(inputs, fit, sd_ln, again)
        if ends is None:
            notes.append(f"friction μ held at {float(plan.laws.friction):g} without its doubt in the covariance: {how}")
        else:
            row_scale = block_row_scale(fit.residuals.size, slices, widen, ratio)
            friction = friction_read(pre, fit, ends, rows, geometry, solver, P, sd_ln, row_scale,
                                     refined=None if check is None else check["refined"])
            if friction["again"]:  # the tyre is the one identified at the μ the data and the file say
                if progress:
                    print(f"identify: again at μ = {friction['value']:.4g} (read from the data)", flush=True)
                tyre_at = tyre.with_state_values(friction=friction["value"])
                at = _identify(dataclasses.replace(inputs, tyre=tyre_at), solver=solver, max_steps=max_steps,
                               rtol=rtol, atol=atol, progress=progress, sensor=sensor, consider=False,
                               start=pre.theta, friction=friction)
                if at.converged:
                    return at
                # not there: the tyre stays the one at the file's μ, with the file's doubt (said in a note)
                notes.append(f"friction: the data read μ = {friction['value']:.4g}, but the identification there "
                             f"did not converge ({at.fit.status}); μ held at {float(plan.laws.friction):g} with "
                             "the tyre file's doubt")
                friction = friction_held(ends, fit, float(plan.laws.friction), sd_ln)
    warned = []
    # (the identifications at μ·e^{±σ} give only their values: the base identification checks the tables' loads)
    if (consider or friction is not None) and rows.loaded is not None and all(math.isfinite(fit.values[n])
                                                                              for n in fit.names):
        laws = None
        if plan.active:
            laws = plan.laws.replace(**{n: float(fit.values[n]) for n in LAW_FIELDS})
        warned = load_check(ring_from_vector(jnp.asarray(fit.theta)), geometry, rows.loaded,
                            [t.source for t in inputs.loaded], solver, laws=laws,
                            pressures=plan.l_pressure if plan.active else None)
        for note in warned:
            warnings.warn(note, stacklevel=2)
    ident = _finish(fit, rows, slices, scales, free_ring, P, notes + warned, passes, inputs, check, widen, ratio,
                    free_laws=free_laws, friction=friction)
    if plan.active:
        ident.laws = plan.laws.replace(**{n: float(fit.values[n]) for n in LAW_FIELDS})
    ident.warned = warned
    ident.at_grid = np.asarray(pre.theta, dtype=np.float64)
    return ident


#: σ of ln μ, the tread tips' friction, when the tyre file states no ``friction_sd`` (docs/physics.md §11
#: *friction*): identify holds μ at the file's ``friction`` and carries this doubt into the covariance. A road's
#: or a drum's μ is seldom known better than ±20 % (two σ) before it is measured.
FRICTION_LN_SD = 0.1


def friction_sd_ln(tyre: Tyre) -> float:
    """σ of ln μ that identify holds μ with: the tyre file's ``friction_sd`` over its ``friction`` (docs/formats.md
    §1), else :data:`FRICTION_LN_SD`."""
    sd = tyre.state_values.get("friction_sd")
    if sd is None:
        return FRICTION_LN_SD
    return float(sd) / float(tyre.laws.friction)


def friction_ends(inputs: IdentifyInputs, fit: FitResult, sd_ln: float, again) -> tuple[list | None, str]:
    """The folder identified again, whole (noise passes, grid check and its move to the continuum), with the tyre
    file's μ at μ·e^{+σ} and at μ·e^{−σ} (docs/physics.md §11 *friction*). ``again(inputs)`` identifies ``inputs``
    without this step, each from this fit's optimum. Whole identifications, because cheaper moves were measured and
    fall short: the sliding zone near the patch's exit, where μ acts, is resolved only as the contact grid is
    refined, and the noise model follows μ's misfit (on the across-states case, seed 0, the Gauss–Newton step from
    the fit's Jacobian gave 60 % of k_x's move, a refit on the base grid 63 %, refits each moved by its own grid check
    74 %).

    **Returns** ``([at +σ, at −σ], "identified at ±σ")`` (:class:`Identification` each), or ``(None, why)`` where
    either did not converge."""
    mu = float(inputs.tyre.laws.friction)
    ends = []
    for sign in (1.0, -1.0):
        tyre = inputs.tyre.with_state_values(friction=mu * math.exp(sign * sd_ln))
        other = again(dataclasses.replace(inputs, tyre=tyre))
        if not other.converged or tuple(other.fit.names) != tuple(fit.names):
            return None, f"the identification at μ·e^{{{sign * sd_ln:+.3g}}} did not converge ({other.fit.status})"
        if not all(math.isfinite(other.fit.values[n]) for n in fit.names):
            return None, f"the identification at μ·e^{{{sign * sd_ln:+.3g}}} gave no finite answer"
        ends.append(other)
    return ends, "identified at ±σ"


def _answer_u(fit: FitResult, other: FitResult) -> np.ndarray:
    """``other``'s free parameters in ``fit``'s solver coordinates (``fit.names`` order)."""
    coords = {c.name: c for c in fit.coords}
    return np.array([coords[n].to_u(other.values[n]) for n in fit.names], dtype=np.float64)


def friction_held(ends: list, fit: FitResult, mu: float, sd_ln: float) -> dict:
    """μ held at the tyre file's, its doubt a consider direction (docs/physics.md §11 *friction*): δu_μ half the
    difference of the answers at μ·e^{±σ} (:func:`friction_ends`) — the covariance gains δu_μ δu_μᵀ, and σ·δu_μ is the
    parameters' covariance with ln μ."""
    move = 0.5 * (_answer_u(fit, ends[0].fit) - _answer_u(fit, ends[1].fit))
    return dict(value=mu, sd_ln=sd_ln, move_u=move, how="identified at ±σ", prior=dict(value=mu, sd_ln=sd_ln),
                again=False)


#: The model refinements (contact grid and loaded-mode harmonics ×2, ×4) the friction's profile is read on
#: (:func:`friction_read`): the finest gives the estimate, the last halving's change its grid term.
FRICTION_PROFILE_GRIDS = (2, 4)
#: Identify again at the μ the data read only when it is this many of its own σ from the file's (below, θ's move
#: is a tenth of the doubt the covariance carries anyway).
FRICTION_AGAIN_SD = 0.1


def friction_profile(pre: FitResult, thetas: list, rows: _Rows, geometry: TyreGeometry, solver: ContactSolver, P: int,
                     sd_ln: float, row_scale: np.ndarray, factor: int, centre=None) -> dict | None:
    """What the rows say of ln μ at one refinement of the model (docs/physics.md §11 *friction: read from the
    data*): at each of the three answers ``thetas`` (base grid optima at ln μ₀ − σ, ln μ₀, ln μ₀ + σ) the rows, each
    under its μ, under the base identification's weights and block widening (``row_scale``), evaluated on the
    model refined ``factor`` times, less their projection on the base fit's Jacobian (the other parameters'
    linear re-fit). The three costs are a parabola in ln μ: **returns** ``dict(ln, sd)`` of ln(μ/μ₀) at its
    minimum and 1/√curvature, or None where the cost has no positive curvature (the rows cannot tell μ).
    ``centre``: the rows at ``thetas[1]`` under μ₀ on this model where already evaluated (the grid check's)."""
    m = pre.residuals.size
    J = np.asarray(pre.jacobian, dtype=np.float64)[:m] / row_scale[:, None]
    Q, _ = np.linalg.qr(J)
    laws = rows.states["laws"]
    mu0 = float(laws.friction)
    cost = []
    for sign, theta in zip((-1.0, 0.0, 1.0), thetas):
        if sign == 0.0 and centre is not None:
            r = np.asarray(centre, dtype=np.float64) / row_scale
        else:
            at = dataclasses.replace(rows, states={**rows.states,
                                                   "laws": laws.replace(friction=mu0 * math.exp(sign * sd_ln))})
            r = refined_rows(pre, at, geometry, solver, P, factor, theta) / row_scale
        cost.append(float(r @ r - np.sum((Q.T @ r) ** 2)))
    a = (cost[0] + cost[2] - 2.0 * cost[1]) / (2.0 * sd_ln**2)
    b = (cost[2] - cost[0]) / (2.0 * sd_ln)
    if not (math.isfinite(a) and a > 0.0 and math.isfinite(b)):
        return None
    return dict(ln=-b / (2.0 * a), sd=1.0 / math.sqrt(a))


def friction_read(pre: FitResult, fit: FitResult, ends: list, rows: _Rows, geometry: TyreGeometry,
                  solver: ContactSolver, P: int, sd_ln: float, row_scale: np.ndarray, refined=None) -> dict:
    """μ read from the data, the tyre file's μ its prior (docs/physics.md §11 *friction: read from the data*).

    The profile of ln μ (:func:`friction_profile`) on each model of :data:`FRICTION_PROFILE_GRIDS`: the finest its
    estimate x̂ (ln μ/μ₀) and σ, the last halving's change |x̂_4M − x̂_2M| a grid term added in quadrature (the
    profile's own discretisation error). With the file's N(0, σ₀²) as prior the posterior of ln μ/μ₀ is N(m, s²),
    1/s² = 1/σ₀² + 1/σ_x², m = s² x̂/σ_x². The parameters' move with ln μ is the parabola through the three answers
    (at −σ₀, 0, +σ₀; grid-moved, solver coordinates), its slope at m times s the consider direction δu_μ (the
    covariance gains δu_μ δu_μᵀ). Where the rows have no curvature in ln μ, μ stays held (:func:`friction_held`).

    **Returns** the ``friction`` dict of :func:`_finish` (``value`` μ₀·e^m, ``sd_ln`` s, ``move_u``, ``how``,
    ``prior``, ``data``) and ``again``: whether |m| ≥ :data:`FRICTION_AGAIN_SD`·s (identify at μ₀·e^m).
    ``refined``: the grid check's rows at the base optimum per refinement (:func:`grid_check`), not evaluated again."""
    mu0 = float(rows.states["laws"].friction)
    thetas = [ends[1].at_grid, pre.theta, ends[0].at_grid]
    per = {}
    for f in FRICTION_PROFILE_GRIDS:
        per[f] = friction_profile(pre, thetas, rows, geometry, solver, P, sd_ln, row_scale, f,
                                  centre=(refined or {}).get(f))
        if per[f] is None:
            held = friction_held(ends, fit, mu0, sd_ln)
            held["how"] = (f"identified at ±σ; the rows have no curvature in ln μ on the model ×{f}, so μ is held "
                           "at the tyre file's")
            return held
    fine, coarse = per[FRICTION_PROFILE_GRIDS[-1]], per[FRICTION_PROFILE_GRIDS[-2]]
    grid = abs(fine["ln"] - coarse["ln"])
    sd_x = math.hypot(fine["sd"], grid)
    post_var = 1.0 / (1.0 / sd_ln**2 + 1.0 / sd_x**2)
    m, s = post_var * fine["ln"] / sd_x**2, math.sqrt(post_var)
    u0, up, um = _answer_u(fit, fit), _answer_u(fit, ends[0].fit), _answer_u(fit, ends[1].fit)
    slope = (up - um) / (2.0 * sd_ln) + (up + um - 2.0 * u0) / sd_ln**2 * m
    z = fine["ln"] / math.hypot(sd_ln, sd_x)
    data = dict(ln_ratio=fine["ln"], sd=sd_x, sd_profile=fine["sd"], grid=grid, z_against_file=z,
                grids={f"x{f}": dict(ln_ratio=v["ln"], sd=v["sd"]) for f, v in per.items()})
    return dict(value=mu0 * math.exp(m), sd_ln=s, move_u=s * slope, how="read from the data (profile of ln μ)",
                prior=dict(value=mu0, sd_ln=sd_ln), data=data, again=abs(m) >= FRICTION_AGAIN_SD * s)


#: Loads scanned per loaded table for its best-fit load, relative to its stated load_n (:func:`load_check`).
LOAD_SCAN = (0.3, 3.0, 41)
#: A table whose best-fit load differs from its stated load by more than this share, and fits there better by
#: :data:`LOAD_F_RATIO` (the drop of χ² against the table's own residual variance), is said to contradict it.
LOAD_SHARE_TOL = 0.15
LOAD_F_RATIO = 9.0


@eqx.filter_jit
def _scan_loaded(ring, geometry, loads, roads, solver, n_harmonics):
    def one(args):
        fz, road = args
        a = standing_half_angle(ring, geometry, fz, road, solver)
        c, s = loaded_natural_frequencies(ring, geometry, a, n_harmonics)
        return jnp.stack([c, s])

    return serial_map(one, (loads, roads))


def load_check(ring: RingParams, geometry: TyreGeometry, loaded: dict, sources, solver: ContactSolver, *,
               laws: TyreLaws | None = None, pressures=None) -> list[str]:
    """What the loaded tables' own frequencies say of their stated ``load_n`` (one sentence per contradiction).

    With the identified ring, each table's rows are compared with the loaded-mode model (docs/physics.md §6) at
    loads from :data:`LOAD_SCAN` × its stated load; the load of least χ² (σ as stated, or the default relative σ)
    is its best-fit load. A table whose best-fit load is more than :data:`LOAD_SHARE_TOL` off its stated one and
    fits there better by an F ratio of :data:`LOAD_F_RATIO` — (χ²(stated) − χ²(best)) over the table's residual
    variance at its best load — was not measured at the load its sidecar states (a 5000 N table labelled 3000 N
    is absorbed by the block's σ scale otherwise, without a word). Across states (``laws`` and each table's
    ``pressures`` [Pa]) each table is scanned with the ring at its pressure (docs/physics.md §13.1)."""
    stated = np.asarray(loaded["load"], dtype=np.float64)
    T = stated.size
    lo, hi, k = LOAD_SCAN
    rel = np.geomspace(lo, hi, k)
    loads = (stated[:, None] * rel[None, :]).ravel()
    drums = np.repeat(np.asarray(loaded["drum"], dtype=np.float64), k)
    roads = flat_or_drum(drums, loads.size)
    if laws is None:
        freqs = np.asarray(_scan_loaded(ring, geometry, jnp.asarray(loads), roads, solver, LOADED_HARMONICS))
    else:
        parts = []
        for t in range(T):
            g_t, ring_t, _ = as_traced(state_tyre(geometry, ring, laws, float(pressures[t]), laws.tread_depth_ref))
            sl = slice(t * k, (t + 1) * k)
            parts.append(np.asarray(_scan_loaded(ring_t, g_t, jnp.asarray(loads[sl]),
                                                 jax.tree.map(lambda x: x[sl], roads), solver, LOADED_HARMONICS)))
        freqs = np.concatenate(parts)
    freqs = freqs.reshape(T, k, 2, -1)
    sigma0 = loaded.get("sigma0", loaded["sigma"])
    notes = []
    for t in range(T):
        sel = loaded["table"] == t
        m = int(sel.sum())
        if m < 3:
            continue
        model = freqs[t][:, loaded["sin"][sel], loaded["n"][sel]]  # (k, m)
        chi2 = np.sum(((model - loaded["freq"][sel]) / sigma0[sel]) ** 2, axis=1)
        if not np.all(np.isfinite(chi2)):
            continue
        j = int(np.argmin(chi2))
        at = int(np.argmin(np.abs(rel - 1.0)))
        best = float(loads.reshape(T, k)[t, j])
        var = chi2[j] / max(m - 1, 1)
        f_ratio = (chi2[at] - chi2[j]) / max(var, 1e-300)
        if abs(best / stated[t] - 1.0) > LOAD_SHARE_TOL and f_ratio > LOAD_F_RATIO:
            edge = " (the end of the scan)" if j in (0, k - 1) else ""
            notes.append(f"{Path(str(sources[t])).name} states load_n = {stated[t]:g} N, but its frequencies fit the "
                         f"identified ring best at about {best:.0f} N{edge} (χ² {chi2[at]:.3g} at the stated load, "
                         f"{chi2[j]:.3g} there): it was not measured at the stated load — check its sidecar")
    return notes


#: Harmonic bands of the profiles for their discrepancy ratio (a frequency block's folds: free_block.DISCREPANCY_FOLDS).
DISCREPANCY_BANDS = 4


def block_folds(name: str, sl: slice, rows: _Rows) -> list[np.ndarray]:
    """The held-out groups of a block's rows (indices into the residual vector; docs/physics.md §11): a frequency
    block's rows dealt round-robin into :data:`DISCREPANCY_FOLDS` (each fold spans the harmonics n), the profiles'
    rows in :data:`DISCREPANCY_BANDS` contiguous bands of revolution harmonics (every profile, channel and part)."""
    idx = np.arange(sl.start, sl.stop)
    if name == "profiles":
        return band_folds(idx, rows.profiles["measured"].shape[-1] // 2)
    return frequency_folds(idx)


def band_folds(idx: np.ndarray, H: int, bands: int = DISCREPANCY_BANDS) -> list[np.ndarray]:
    """Rows ``idx`` of revolution harmonics laid out in runs of ``H`` (profile, channel, Re k…, Im k…) split into
    ``bands`` contiguous bands of harmonics, each band every run's rows of those harmonics (docs/physics.md §11;
    the state estimate's rows, §13.4, likewise)."""
    idx = np.asarray(idx)
    k = np.tile(np.arange(H), idx.size // H)
    edges = np.linspace(0, H, bands + 1).round().astype(int)
    return [idx[(k >= a) & (k < b)] for a, b in zip(edges[:-1], edges[1:])]


def grid_check(fit: FitResult, rows: _Rows, geometry: TyreGeometry, solver: ContactSolver, P: int,
               factor: int = GRID_CHECK_FACTOR) -> dict:
    """How far the joint optimum moves when the model's discretisation is refined to the continuum (docs/physics.md
    §11 *the model's grid*).

    The contact solve's discrete active set makes the patch (its edges, so the loaded modes' half-angle and
    the profiles' shape around the patch) a fine staircase in the parameters, and the loaded-mode basis is
    truncated at :data:`LOADED_HARMONICS`; both are systematic, the same in every row of a profile, so they
    are not noise the block scales could absorb. The same rows and weights are evaluated at the fit under the
    model refined by 2, 4, … up to ``factor`` (grid ×M, harmonics ×N; the profiles' model rows band-limited to the
    data's harmonics), each halving's move is one Gauss–Newton step with the fit's Jacobian, and the move still to
    come beyond the finest grid is Richardson's on the last two moves (:func:`~ringfit.fit.result.grid_moves`) — the
    rule the state estimate reads a recording by (§13.4), so a tyre is identified and read on the same model. One
    residual evaluation per refinement.

    **Returns** ``dict(grid, loaded_harmonics, shift_u, beyond_u, refined)`` (``(k,)`` in the solver coordinates of
    ``fit.names``): ``shift_u`` the whole move to the continuum, ``beyond_u`` its part beyond the first refinement
    (the last halving's move and the tail: the part a Gauss–Newton step from M and the extrapolation know least);
    ``refined`` the rows at the fit per refinement factor (:func:`refined_rows`; the friction's profile reuses them).
    """
    levels = [2**j for j in range(int(round(math.log2(factor))) + 1)]
    at = [np.asarray(fit.residuals)]
    for f in levels[1:]:
        at.append(refined_rows(fit, rows, geometry, solver, P, f, fit.theta))
    steps, tail = grid_moves(fit, at)
    shift = np.sum(steps, axis=0) + tail
    return dict(grid=[f * solver.n_grid for f in levels], loaded_harmonics=[f * LOADED_HARMONICS for f in levels],
                shift_u=shift, beyond_u=shift - steps[0], refined=dict(zip(levels[1:], at[1:])))


def refined_rows(fit: FitResult, rows: _Rows, geometry: TyreGeometry, solver: ContactSolver, P: int, factor: int,
                 theta) -> np.ndarray:
    """The fit's weighted data rows ``(m,)`` (as ``fit.residuals``: the same rows and σ) at ``theta`` under the model
    refined ``factor`` times: contact grid ×factor, loaded-mode harmonics ×factor, the profiles' model rows
    band-limited to the data's harmonics (:func:`grid_check`, :func:`friction_profile`; docs/physics.md §11 *the
    model's grid*)."""
    fine = ContactSolver(n_grid=factor * solver.n_grid, window_deg=solver.window_deg, max_iter=solver.max_iter)
    model = JointResiduals(P, fine, ProfileModel(), n_harmonics=factor * LOADED_HARMONICS, rows_grid=solver.n_grid,
                           k_top=0 if rows.profiles is None else rows.profiles["k_top"],
                           across=rows.states is not None, sensor=fit.problem.model.sensor)
    problem = Problem(model, _arrays(geometry, rows, fine), fit.coords, data_label="these measurements")
    return np.asarray(residuals(problem, jnp.asarray(theta, dtype=jnp.float64))[0])[:fit.residuals.size]


def grid_moved(fit: FitResult, shift_u) -> FitResult:
    """``fit`` moved by the grid check's move to the continuum (:func:`grid_check`, docs/physics.md §11 *the model's
    grid*): every free parameter at the extrapolated model's optimum, as the state estimate reads a recording on its
    extrapolated model (§13.4) — so a tyre is identified and read by the same discretisation. The move's part beyond
    the first refinement stays in the covariance (``_finish``). A bounded parameter stays inside its range."""
    theta = np.array(fit.theta, dtype=np.float64)
    order = [c.name for c in fit.coords]
    values, stderr = dict(fit.values), dict(fit.stderr)
    for name, du in zip(fit.names, np.asarray(shift_u, dtype=np.float64)):
        i = order.index(name)
        c = fit.coords[i]
        new = float(c.from_u(c.to_u(theta[i]) + du))
        if math.isfinite(c.lo) or math.isfinite(c.hi):
            span = (c.hi - c.lo) if math.isfinite(c.hi - c.lo) else abs(new)
            new = float(np.clip(new, c.lo + 1e-9 * span, c.hi - 1e-9 * span))
        if c.kind == LOG and name in stderr and values[name]:
            stderr[name] = stderr[name] * new / values[name]
        theta[i], values[name] = new, new
    return dataclasses.replace(fit, theta=theta, values=values, stderr=stderr)


def block_row_scale(m: int, slices: dict, widen: dict | None, ratio: dict | None) -> np.ndarray:
    """Each data row's σ factor ``(m,)``: its block's t_ν/z (:func:`t_widening`) times √κ_b (its discrepancy ratio,
    docs/physics.md §11 *model discrepancy*) — the likelihood the covariance, the posterior and the friction's
    profile read the rows with."""
    row_scale = np.ones(m)
    for b, sl in slices.items():
        row_scale[sl] = (widen or {}).get(b, 1.0) * math.sqrt((ratio or {}).get(b, 1.0))
    return row_scale


def _finish(fit, rows, slices, scales, free_ring, P, notes, passes, inputs, check=None, widen=None,
            ratio=None, free_laws=(), friction=None) -> Identification:
    J, r = fit.jacobian, fit.residuals
    names = fit.names
    cov_u = fit.covariance_log
    row_scale = block_row_scale(r.size, slices, widen, ratio)
    if np.any(row_scale > 1.0):
        Jw = J.copy()
        Jw[: r.size] /= row_scale[:, None]
        cov_u = covariance_from_jacobian(Jw)
    grid = None
    shift_u = None
    if check is not None and np.all(np.isfinite(check["shift_u"])):
        du = check["shift_u"]
        # the discretisation's move beyond its first refinement: one systematic direction (grid_check)
        shift_u = np.asarray(check["beyond_u"], dtype=np.float64)
        cov_u = cov_u + np.outer(shift_u, shift_u)
        grid = dict(grid=check["grid"], loaded_harmonics=check["loaded_harmonics"],
                    shift={n: float(x) for n, x in zip(names, du)},
                    beyond={n: float(x) for n, x in zip(names, shift_u)})
    held = move = None
    if friction is not None and np.all(np.isfinite(friction["move_u"])):
        # the held μ's doubt (docs/physics.md §11 *friction*): θ̂ is off by δu_μ·(ln μ − ln μ₀)/σ
        move = np.asarray(friction["move_u"], dtype=np.float64)
        before = np.sqrt(np.clip(np.diag(cov_u), 0.0, None))
        cov_u = cov_u + np.outer(move, move)
        after = np.sqrt(np.clip(np.diag(cov_u), 0.0, None))
        held = dict(friction=dict(value=friction["value"], sd_ln=friction["sd_ln"], how=friction["how"],
                                  stated=bool(inputs is not None and "friction_sd" in inputs.tyre.state_values),
                                  prior=friction.get("prior"), **({"data": friction["data"]} if "data" in friction
                                                                  else {}),
                                  move={n: float(x) for n, x in zip(names, move)},
                                  sd_without={n: float(x) for n, x in zip(names, before)},
                                  sd_with={n: float(x) for n, x in zip(names, after)}))
    fisher = {b: J[sl].T @ J[sl] for b, sl in slices.items()}
    total = np.diag(J.T @ J)  # data and prior rows
    # the covariance's parameters: the ring's, then the state laws identified across states (ln k_x; a share as
    # itself: its coordinate is linear with scale 1, state_coords)
    cov_names = tuple(free_ring) + tuple(free_laws)
    blocks = {}
    for b, sl in slices.items():
        share = np.diag(fisher[b]) / np.where(total > 0, total, 1.0)
        blocks[b] = dict(rows=int(sl.stop - sl.start), sigma_scale=float(scales[b]),
                         t_widening=float((widen or {}).get(b, 1.0)),
                         discrepancy=float((ratio or {}).get(b, 1.0) - 1.0),
                         rms=float(math.sqrt(np.mean(r[sl] ** 2))),
                         fisher_share={n: float(share[j]) for j, n in enumerate(names) if n in cov_names})
    idx = [names.index(n) for n in cov_names]
    cov = cov_u[np.ix_(idx, idx)]
    if held is not None:  # ln μ joins the covariance: its own σ², and σ·δu_μ with the rest
        k = len(idx)
        sd_mu = held["friction"]["sd_ln"]
        full = np.zeros((k + 1, k + 1))
        full[:k, :k] = cov
        full[:k, k] = full[k, :k] = sd_mu * move[idx]
        full[k, k] = sd_mu**2
        cov, cov_names = full, cov_names + ("friction",)
    cov = 0.5 * (cov + cov.T)
    cov = cap_unbounded(cov, cov_names, bounds=PARAMETER_BOUNDS, linear=LINEAR_COVARIANCE)
    sd = np.sqrt(np.clip(np.diag(cov), 0.0, None))
    with np.errstate(invalid="ignore", divide="ignore"):
        corr = cov / np.outer(sd, sd)
    covariance = RingCovariance(cov_names, cov, "ringfit identify")
    nuisances = []
    pr = rows.profiles
    for i in range(P):
        o, g = f"angle_offset_{i + 1}", f"gain_{i + 1}"
        io, ig = names.index(o), names.index(g)
        scale_o = fit.coords[[c.name for c in fit.coords].index(o)].scale
        nuisances.append(dict(source=str(pr["sources"][i]), load_n=float(pr["load"][i]),
                              speed_kmh=float(pr["speed_kmh"][i]),
                              angle_offset_deg=math.degrees(fit.values[o]),
                              angle_offset_sd_deg=math.degrees(scale_o * math.sqrt(max(cov_u[io, io], 0.0))),
                              gain=fit.values[g], gain_sd=fit.values[g] * math.sqrt(max(cov_u[ig, ig], 0.0))))
        for field_ in SENSOR_FIELDS:  # the run's sensor nuisances, where fitted (identify's ``sensor``)
            name = f"{field_}_{i + 1}"
            if name in names:
                j = names.index(name)
                coord = fit.coords[[c.name for c in fit.coords].index(name)]
                sd_u = math.sqrt(max(cov_u[j, j], 0.0))
                nuisances[-1][field_] = float(fit.values[name])
                nuisances[-1][f"{field_}_sd"] = float(fit.values[name] * sd_u if coord.kind == LOG
                                                      else coord.scale * sd_u)
        if rows.states is not None:
            nuisances[-1].update(_state_nuisances(fit, rows, cov_u, i))
    ring = RingParams(**{n: fit.values[n] for n in RING_FIELDS})
    ident = Identification(fit, ring, free_ring, blocks, (cov_names, corr), covariance, nuisances, notes, passes,
                           inputs, grid, row_scale, shift_u, dict(slices), _table_rows(rows, slices, inputs, P))
    ident.laws_free = tuple(free_laws)
    ident.held = held
    if held is not None:
        f = held["friction"]
        grown = ", ".join(f"{n} {100 * f['sd_without'][n]:.2g} → {100 * f['sd_with'][n]:.2g} %"
                          for n in ("ei", "k_tread", "k_x") if n in f["sd_with"])
        file_doubt = ("the tyre file's friction_sd" if f["stated"] else
                      "the default: state friction_sd in the tyre file when μ is known better")
        if "data" in f:
            d, pr = f["data"], f["prior"]
            notes.append(f"friction μ read from the data: {f['value']:.4g} (σ of ln μ {f['sd_ln']:.2g}), the rows' "
                         f"ln μ/μ₀ {d['ln_ratio']:+.3f} ± {d['sd']:.3f} (profile {d['sd_profile']:.3f}, grid "
                         f"{d['grid']:.3f}) with the tyre file's μ₀ = {pr['value']:g} (σ of ln μ {pr['sd_ln']:.3g}, "
                         f"{file_doubt}) as prior; its doubt is carried in the covariance (σ of ln: {grown})")
            if abs(d["ln_ratio"]) > 1.5 * pr["sd_ln"]:
                notes.append(f"friction: the rows' μ lies {abs(d['ln_ratio']) / pr['sd_ln']:.1f} σ of the file's "
                             "doubt from μ₀, beyond the identifications at μ₀·e^(±σ) its profile was read from: "
                             "its value is extrapolated; state a friction nearer it, or a wider friction_sd")
            if abs(d["z_against_file"]) > 3.0:
                notes.append(f"friction: the data and the tyre file disagree on μ ({d['z_against_file']:+.1f} σ)")
        else:
            notes.append(f"friction μ held at {f['value']:g} (σ of ln μ {f['sd_ln']:.3g}, {file_doubt}); its doubt "
                         f"is carried in the covariance (σ of ln: {grown})"
                         + ("" if f["how"] == "identified at ±σ" else f" [{f['how']}]"))
    return ident


def _state_nuisances(fit, rows: _Rows, cov_u: np.ndarray, i: int) -> dict:
    """Across states, a profile's pressure and, at a torque, its stated torque and the slip κ identified with it."""
    out = dict(pressure_bar=float(rows.states["p_pressure"][i]) / 1e5)
    tq = rows.torque
    if tq is not None and i in tq["index"]:
        j = int(np.flatnonzero(tq["index"] == i)[0])
        name = slip_names(i + 1)[i]
        k = fit.names.index(name)
        scale = fit.coords[[c.name for c in fit.coords].index(name)].scale
        out.update(torque_nm=float(tq["torque"][j]), torque_sd_nm=float(tq["sigma"][j]), slip=float(fit.values[name]),
                   slip_sd=scale * math.sqrt(max(float(cov_u[k, k]), 0.0)))
    return out


def _table_rows(rows: _Rows, slices: dict, inputs, P: int) -> dict:
    """Each measured table's row indices (for the posterior predictive check): the free table's frequencies and
    damping, each loaded table, each profile; named after their files."""
    def name(obj, fallback):
        src = getattr(obj, "source", None) if obj is not None else None
        return Path(str(src)).name if src else fallback

    free = None if inputs is None else inputs.free
    out = {name(free, "free.modes.csv"): np.arange(slices["free modes"].start, slices["free modes"].stop)}
    if "table" in rows.free:  # free tables at several pressures (identify across states)
        start = slices["free modes"].start
        out = {Path(str(src)).name or f"free table {t + 1}": start + np.flatnonzero(rows.free["table"] == t)
               for t, src in enumerate(rows.free["sources"])}
    if "free damping" in slices:
        sl = slices["free damping"]
        out[name(free, "free.modes.csv") + " damping"] = np.arange(sl.start, sl.stop)
    if "loaded modes" in slices:
        start = slices["loaded modes"].start
        for t in range(len(rows.loaded["load"])):
            idx = start + np.flatnonzero(rows.loaded["table"] == t)
            if idx.size:
                out[name(inputs.loaded[t] if inputs else None, f"loaded table {t + 1}")] = idx
    if "profiles" in slices:
        sl = slices["profiles"]
        per = (sl.stop - sl.start) // max(P, 1)
        for i in range(P):
            out[Path(str(rows.profiles["sources"][i])).name or f"profile {i + 1}"] = np.arange(sl.start + i * per,
                                                                                              sl.start + (i + 1) * per)
    if "torque" in slices:
        sl = slices["torque"]
        out["torque"] = np.arange(sl.start, sl.stop)
    return out


#: A frequency block whose rows scatter more than this many times their σ (stated, or the default relative σ) is
#: flagged: its σ scale absorbs a misfit — a model that lacks an effect, or a stated condition that is wrong.
SCALE_FLAG = 3.0


def scale_flags(blocks: dict) -> list[str]:
    """One flag per frequency block (free or loaded modes) whose σ scale exceeds :data:`SCALE_FLAG`."""
    out = []
    for name in ("free modes", "loaded modes"):
        b = blocks.get(name)
        if b is not None and b["sigma_scale"] > SCALE_FLAG:
            out.append(f"the {name} scatter {b['sigma_scale']:.3g}× their σ (the block's σ scale): the model lacks "
                       "an effect these data show, or a stated condition (load, speed, rotation, pressure) is "
                       "wrong; the intervals are widened by it, not explained")
    return out


def cap_unbounded(cov: np.ndarray, names, bounds: dict | None = None, linear=()) -> np.ndarray:
    """The ring covariance (ln θ) with each parameter the data do not bound — a variance that is not finite or
    whose 95 % interval is wider than the whole plausible range :data:`BOUNDS` — given that range's spread
    instead: σ_ln = ln(hi/lo)/(2·1.96), uncorrelated with the rest. A parameter barely identified is then a
    finite, readable ``[ring.covariance]`` entry whose interval runs to the bounds (docs/formats.md §18), not
    an infinity that no reader accepts. ``bounds``: the ranges (default :data:`BOUNDS`); a name in ``linear`` (a
    pressure share) has a covariance of the value itself, so its spread is (hi − lo)/(2·1.96)."""
    cov = np.array(cov, dtype=np.float64)
    bounds = BOUNDS if bounds is None else bounds

    def spread(n):
        lo, hi = bounds[n]
        return (hi - lo) if n in linear else math.log(hi / lo)

    caps = {i: spread(n) / (2.0 * Z95) for i, n in enumerate(names) if n in bounds}
    wide = [i for i, c in caps.items() if not (math.isfinite(cov[i, i]) and cov[i, i] <= c**2)]
    for i in wide:
        cov[i, :] = 0.0
        cov[:, i] = 0.0
    for i in caps:  # a correlation the others cannot carry (not finite) leaves them unbounded too
        if i not in wide and not np.all(np.isfinite(cov[i])):
            wide.append(i)
            cov[i, :] = 0.0
            cov[:, i] = 0.0
    for i in wide:
        cov[i, i] = caps[i] ** 2
    return cov


def identification_report(ident: Identification) -> dict:
    """The ``NAME.identify.json`` content (docs/formats.md §18)."""
    fit = ident.fit
    names, corr = ident.correlation
    return _json_safe({
        "format": "ringfit-identify/1",
        "status": fit.status,
        "converged": bool(fit.converged),
        "message": fit.message,
        "iterations": int(fit.iterations),
        "passes": int(ident.passes),
        "flags": list(fit.flags) + ident.barely_identified() + scale_flags(ident.blocks),
        "parameters": ident.parameters(),
        "blocks": ident.blocks,
        "correlation": {"names": list(names), "matrix": [[float(x) for x in row] for row in corr]},
        "nuisances": ident.nuisances,
        **({"grid_check": ident.grid_check} if ident.grid_check is not None else {}),
        **({"held": ident.held} if ident.held is not None else {}),
        "files": [] if ident.inputs is None else ident.inputs.files,
        "notes": ident.notes,
    })


def _json_safe(x):
    """``x`` with every non-finite float (a σ the data do not bound, a correlation of it) as None: strict JSON."""
    if isinstance(x, dict):
        return {k: _json_safe(v) for k, v in x.items()}
    if isinstance(x, (list, tuple)):
        return [_json_safe(v) for v in x]
    if isinstance(x, (float, np.floating)):
        return float(x) if math.isfinite(x) else None
    if isinstance(x, np.ndarray):
        return _json_safe(x.tolist())
    return x


__all__ = ["IDENTIFY_MAX_STEPS", "friction_ends", "friction_profile", "serial_map", "identify", "read_identify_folder", "log_interval", "cap_unbounded", "load_check", "IdentifyInputs",
           "discrepancy_ratio", "block_folds", "band_folds",
           "Identification", "identification_report",
           "JointResiduals", "harmonic_rows", "standing_half_angle", "BLOCKS"]
