"""Parameters of the tyre and of Gong's flexible ring, in SI units.

Two frozen PyTrees (``eqx.Module``) carry everything the physics needs:

* :class:`TyreGeometry` — what is known or measured about the tyre (radius,
  width, inflation pressure, tread thickness).
* :class:`RingParams` — what is fitted (mass per length, stiffnesses, damping,
  tread stiffness, and the optional membrane stiffness and centrifugal share).

The symbols and units follow ``docs/physics.md`` §1. Values are stored in natural
(physical) units; the fitters work on their logarithms (``ringfit.fit``).
"""

from __future__ import annotations

import math
from dataclasses import fields, replace

from ringfit._precision import enable_x64

enable_x64()  # before JAX loads: float64 even when ``ringfit`` itself is shadowed (ringfit._precision)

import equinox as eqx

BAR = 1.0e5  # Pa per bar

#: Parameters a fit can free, by short name -> (RingParams field, unit, TOML key).
RING_PARAMETERS: dict[str, tuple[str, str]] = {
    "rho_a": ("kg/m", "rho_a_kg_per_m"),
    "ei": ("N m^2", "ei_n_m2"),
    "kw": ("N/m^2", "kw_n_per_m2"),
    "kv": ("N/m^2", "kv_n_per_m2"),
    "damping_ratio": ("-", "damping_ratio"),
    "k_tread": ("N/m^2", "k_tread_n_per_m2"),
    "ea": ("N", "ea_n"),
    "chi": ("-", "chi"),
}


class TyreGeometry(eqx.Module):
    """Geometry and operating condition of the tyre (docs/physics.md §1).

    **Fields** (scalars, SI):

    - ``radius``: treadband centre radius R [m].
    - ``width``: treadband width b [m].
    - ``pressure``: inflation (gauge) pressure p0 [Pa].
    - ``tread_thickness``: tread / secondary-spring thickness τ [m];
      the outer radius is R + τ.
    - ``tread_rib_width``: width B [m] of the tread's ribs (between circumferential grooves)
      for the incompressible tread layer of the loaded modes (docs/physics.md §6 ``ground_contact``);
      0 (default) = local tread springs (Winkler).
    - ``name``: free text, static.
    """

    radius: float
    width: float
    pressure: float
    tread_thickness: float = 0.020
    # static: a tyre's tread pattern, never fitted; a Python float lets the loaded model leave the layer's
    # sine-series operator out of every program of a tyre without ribs (0, the default), where it cost ~6×
    tread_rib_width: float = eqx.field(static=True, default=0.0)
    name: str = eqx.field(static=True, default="")

    @property
    def hoop_pressure_stiffness(self):
        """p0·b/R [N/m²], the pressure term of eq. 18."""
        return self.pressure * self.width / self.radius

    @property
    def pretension(self):
        """Hoop pretension T0 = p0·b·R [N] (docs/physics.md §1)."""
        return self.pressure * self.width * self.radius

    @property
    def outer_radius(self):
        """R + τ [m]."""
        return self.radius + self.tread_thickness


#: The radial tread spring k_trd [N/m²] where nothing states it: the source thesis's value, fitted there to its
#: 50 km/h profile (docs/physics.md §1, the parameter table; Table 9's ``k_tread_n_per_m2``).
DEFAULT_K_TREAD = 19.0e6


class RingParams(eqx.Module):
    """Fitted parameters of the flexible ring (docs/physics.md §1).

    **Fields** (scalars or arrays of one shape, SI):

    - ``rho_a``: mass per unit circumference ρA [kg/m].
    - ``ei``: bending stiffness EI [N m²].
    - ``kw``: radial foundation stiffness k_w [N/m²].
    - ``kv``: tangential foundation stiffness k_v [N/m²].
    - ``damping_ratio``: modal damping ratio ζ [-] (hysteretic η = 2ζ).
    - ``k_tread``: radial tread (secondary) spring stiffness [N/m²].
    - ``ea``: membrane stiffness EA [N]; ``inf`` = inextensible ring.
    - ``chi``: share of the centrifugal hoop tension carried by the belt [-].
    """

    rho_a: float
    ei: float
    kw: float
    kv: float
    damping_ratio: float = 0.025
    k_tread: float = DEFAULT_K_TREAD
    ea: float = math.inf
    chi: float = 1.0

    def replace(self, **changes) -> "RingParams":
        """A copy with some fields changed (``dataclasses.replace``)."""
        unknown = set(changes) - {f.name for f in fields(self)}
        if unknown:
            raise KeyError(
                f"unknown ring parameter(s) {sorted(unknown)}; known: {sorted(RING_PARAMETERS)}"
            )
        return replace(self, **changes)

    def as_dict(self) -> dict[str, float]:
        """Field name -> float."""
        return {f.name: float(getattr(self, f.name)) for f in fields(self)}


class TyreLaws(eqx.Module):
    """How the reference tyre (its ``TyreGeometry`` and ``RingParams``, which hold at the tyre file's pressure
    p_ref = ``geometry.pressure`` and tread depth d_ref) changes with its state (docs/physics.md §13; the
    tyre file's keys, docs/formats.md §1).

    **Fields** (SI; traced, so that identify can fit them):

    - ``tread_depth_ref``: d_ref [m], the tread depth at which ``[ring]`` and ``tread_thickness`` hold.
    - ``tread_density``: ρ_t [kg/m³] of the tread rubber; ``land_ratio``: λ, the rubber share of the footprint.
    - ``k_x``: the tread's longitudinal (brush) stiffness per unit length [N/m²]; ``friction``: μ of the tips.
    - ``kw_share``, ``kv_share``, ``k_tread_share``: the pressure-proportional shares s of k_w, k_v, k_trd.
    - ``tread_depth_new``: d_new [m], the new (unworn) tread's depth (the data sheet's; None = not stated; traced
      like the rest, so that tyre files differing only in it share one compilation):
      wear only removes tread, so the tread depth never exceeds it — the state estimate's bound on d
      (docs/physics.md §13.3–13.4).

    **Static flags**: ``has_tread_depth`` (the file gives ``tread_depth_mm``: the tread law applies and a
    depth can be estimated), ``has_brush`` (the file gives ``kx_n_per_m2``: drive/brake can be modelled).
    Defaults: no laws (every share 0, no brush, no tread law) — the reference tyre at every state but load.
    """

    tread_depth_ref: float = 0.008
    tread_density: float = 1100.0
    land_ratio: float = 0.7
    k_x: float = 0.0
    friction: float = 1.0
    kw_share: float = 0.0
    kv_share: float = 0.0
    k_tread_share: float = 0.0
    tread_depth_new: float | None = None
    has_tread_depth: bool = eqx.field(static=True, default=False)
    has_brush: bool = eqx.field(static=True, default=False)

    def replace(self, **changes) -> "TyreLaws":
        """A copy with some fields changed (``dataclasses.replace``)."""
        return replace(self, **changes)

    @property
    def has_pressure_law(self) -> bool:
        """Whether any ring parameter scales with pressure (beyond the pretension p·b·R, which always does)."""
        return any(float(getattr(self, k)) != 0.0 for k in ("kw_share", "kv_share", "k_tread_share"))


def table9() -> tuple[TyreGeometry, RingParams]:
    """The source study's Table 9 tyre (docs/physics.md §1), from the bundled ``table9.tyre.toml``.

    Read with ``tomllib`` directly (the bundled file is known good), so that
    this module imports nothing above it (``ringfit.io.tyre`` reads user files).
    """
    import tomllib

    from ringfit.data import path as data_path

    doc = tomllib.loads(data_path("table9.tyre.toml").read_text(encoding="utf-8"))
    t, r = doc["tyre"], doc["ring"]
    field_of = {toml_key: short for short, (_, toml_key) in RING_PARAMETERS.items()}
    geometry = TyreGeometry(radius=float(t["radius_m"]), width=float(t["width_m"]),
                            pressure=float(t["pressure_bar"]) * BAR, name=str(t.get("name", "")))
    return geometry, RingParams(**{field_of[k]: float(v) for k, v in r.items()})
