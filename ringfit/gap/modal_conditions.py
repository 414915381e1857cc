"""What a mode table's stated condition computes for the diagnosis (docs/physics.md §4.3–4.4, §3.6, §6).

The contact patch at a stated load (:func:`contact_patch`: the rolling model's static contact solve with the
tyre file's k_trd, or Table 9's with :data:`K_TREAD_PRIOR_SD`), the loaded cavity's split lines, the wheel on its
suspension (:func:`wheel_row`), the spin of a rolling table, and each table's rows (:func:`table_rows`).
"""

from __future__ import annotations

import math


from ringfit.io.modes import ModeTable
from ringfit.params import RingParams, TyreGeometry
from ringfit._cache import jit
from ringfit.physics.natural import cavity_frequency_jit
from ringfit.units import KMH


#: log-normal σ of k_trd when the tyre file gives none (its median is then the Table 9 value).
K_TREAD_PRIOR_SD = 0.5


#: log σ of k_trd when the tyre file gives it (a fitted value: ``ringfit fit-rolling``'s typical error).
K_TREAD_FITTED_SD = 0.1


DEFAULT_K_TREAD = 19e6


def table_label(table: ModeTable, index: int) -> str:
    """A short name for a table: its state (and speed, load) for the free table, else its file name."""
    c = table.condition
    state = table.state
    parts = [state]
    sp = c.get("speed_kmh") or 0
    if sp:
        parts.append(f"{sp:g} km/h")
    if state != "free" and c.get("load_n"):
        parts.append(f"{c['load_n']:g} N")
    name = str(table.source).rsplit("/", 1)[-1].removesuffix(".modes.csv")
    return " ".join(parts) if index == 0 else f"{name} ({' '.join(parts)})"


def spin_of(table: ModeTable, outer_radius: float) -> float:
    """Ω [rad/s] of a table's condition: ``rotation_hz`` or ``speed_kmh``/R_out (0 if static)."""
    c = table.condition
    if c.get("rotation_hz"):
        return 2.0 * math.pi * float(c["rotation_hz"])
    if c.get("speed_kmh"):
        return float(c["speed_kmh"]) * KMH / outer_radius
    return 0.0


def is_reference_state(table: ModeTable) -> bool:
    """Whether ``table`` is the reference state the ring is fitted to: static, free, on a bolted rim."""
    c = table.condition
    # a free tyre on a suspended wheel is another state (its n <= 1 modes move: wheel_suspension)
    return (table.state == "free" and not float(c.get("speed_kmh") or 0) and not float(c.get("rotation_hz") or 0)
            and c.get("fixture", "bolted") == "bolted")


def contact_patch(ring: RingParams, geometry: TyreGeometry, load_n: float, drum_diameter_m=None,
                  k_tread_sd: float = K_TREAD_FITTED_SD) -> tuple[float, float]:
    """Contact half-angle [rad] of the standing tyre at ``load_n`` and its σ from the k_trd uncertainty.

    The static contact solve of the rolling model (docs/physics.md §4.3–4.4, Ω = 0): the
    half-angle is half the patch between its edges; σ from k_trd·e^{±k_tread_sd}.
    """
    a, sa, _ = static_contact(ring, geometry, load_n, drum_diameter_m, k_tread_sd)
    return a, sa


def static_contact(ring, geometry, load_n, drum_diameter_m, k_tread_sd):
    """:func:`contact_patch`'s ``(a, σ_a)`` and the nominal static solution (the loaded cavity's split uses it)."""
    from ringfit.physics.contact import ContactSolver, patch_edges, solve_rolling_jit
    from ringfit.physics.operating import OperatingPoint, road_from_drum_diameter

    road = road_from_drum_diameter(drum_diameter_m)
    out, sols = [], []
    for factor in (1.0, math.exp(-k_tread_sd), math.exp(k_tread_sd)):
        r = ring.replace(k_tread=float(ring.k_tread) * factor)
        sol = solve_rolling_jit(r, geometry, OperatingPoint(0.0, float(load_n), road), solver=ContactSolver())
        lead, trail = (float(x) for x in patch_edges(sol))
        out.append(0.5 * (trail - lead))
        sols.append(sol)
    return out[0], 0.5 * abs(out[2] - out[1]), sols[0]


@jit
def _loaded_cavity_lines(f_a, split):
    """The loaded cavity's pair at rest (fore-aft, vertical) [Hz] (docs/physics.md §6), in one compiled program."""
    from ringfit.physics.cavity import loaded_cavity_lines

    return loaded_cavity_lines(f_a, split)


@jit
def cavity_split(solution, geometry):
    """W_2/h_c of a static contact solution (docs/physics.md §6 cavity_mode), in one compiled program."""
    from ringfit.physics.cavity import cavity_height, deflection_cos2

    return deflection_cos2(solution) / cavity_height(geometry)


def wheel_row(condition: dict, source: str = "<condition>") -> list[float]:
    """The 9 numbers of :attr:`ModalRows.wheel` from a table's sidecar (zeros for a bolted rim)."""
    from ringfit.io.modes import wheel_of

    w = wheel_of(condition, source=source)
    if w is None:
        return [0.0] * 9
    inv = [1.0 / w[k] for k in ("k_vertical", "k_fore_aft", "k_torsion")]
    return [1.0, w["mass"], w["inertia"], *inv, w["c_vertical"], w["c_fore_aft"], w["c_torsion"]]


def table_rows(tables, geometry, patches, spins, cavity_split=None):
    """Per structural row: dict of its attributes (before n-matching).

    ``cavity_split``: per table W_2/h_c of the loaded cavity (docs/physics.md §6 cavity_mode), or None."""
    cavity = [float(f) for t in tables for f, k in zip(t.freq_hz, t.kind) if k == "acoustic"]
    f_a = cavity[0] if cavity else float(cavity_frequency_jit(1))  # one program, not one per operation
    rows = []
    damping_std = [t.extra_floats("damping_std_pct") for t in tables]
    wheels = [wheel_row(t.condition, str(t.source)) for t in tables]
    for ti, t in enumerate(tables):
        fixed = t.condition.get("frame", "rotating" if spins[ti] > 0 else "fixed") == "fixed"
        tl = table_label(t, ti)
        for i in range(len(t)):
            if t.kind[i] != "structural":
                continue
            tag, branch = str(t.tag[i]), str(t.branch[i])
            contact = 0
            if t.state != "free":
                contact = 1 if tag in ("extr", "vert") else 2 if tag in ("0", "hort") else 0
            rows.append(dict(
                table=ti, i=i, tlabel=tl, n=int(t.n[i]), tag=tag, branch=branch, contact=contact,
                spin=spins[ti], fixed=fixed, patch=patches[ti][0] if contact else 0.0,
                freq=float(t.freq_hz[i]), std=float(t.freq_std_hz[i]), damping=float(t.damping_pct[i]),
                damping_std=damping_std[ti][i],
                reference=ti == 0, a=int(t.a[i]), joint=0.0, mode_index=0, line_k=0.0, wave="",
                wheel=wheels[ti], cavity=_row_cavity(t, f_a, contact, int(t.n[i]),
                                                     None if cavity_split is None else cavity_split[ti]),
            ))
    return rows, f_a


def _row_cavity(table: ModeTable, f_a: float, contact: int, n: int, split) -> float:
    """The cavity line a row's ring mode meets [Hz] (:attr:`ModalRows.cavity_hz`)."""
    p = table.condition.get("pressure_bar")
    if p is not None and float(p) == 0.0:
        return 0.0  # no air in the cavity: cavity_mode does not act on this table
    if split is None or n != 1 or not contact:
        return f_a

    # the loaded cavity's pair at rest: fore-aft f_a sqrt(1 + e), vertical f_a sqrt(1 - e) (docs/physics.md §6);
    # one compiled program, not one per operation (a cold process compiles each)
    fore_aft, vertical = _loaded_cavity_lines(f_a, split)
    return float(vertical if contact == 1 else fore_aft)


def wheel_note(table: ModeTable) -> str:
    """One line on the table's fixture (empty for a bolted rim); a ``WARNING`` where defaults stand in."""
    import warnings

    from ringfit.io.modes import wheel_of

    w = wheel_of(table.condition, source=str(table.source))
    if w is None:
        return ""
    note = (f"fixture suspension: wheel {w['mass']:g} kg, {w['inertia']:g} kg m^2 on k_z {w['k_vertical']:.3g}, "
            f"k_x {w['k_fore_aft']:.3g} N/m, k_theta {w['k_torsion']:.3g} N m/rad")
    if w["defaults"]:
        msg = (f"{table.source}: fixture 'suspension' without {', '.join(w['defaults'])}: the defaults of "
               "docs/formats.md §2 stand in (the computed wheel_suspension candidate uses them)")
        warnings.warn(msg, stacklevel=2)
        note += f" (defaults for {', '.join(w['defaults'])})"
    return note


__all__ = ["contact_patch", "wheel_row", "spin_of", "table_label", "is_reference_state", "static_contact",
           "cavity_split", "table_rows", "wheel_note", "DEFAULT_K_TREAD", "K_TREAD_PRIOR_SD", "K_TREAD_FITTED_SD"]
