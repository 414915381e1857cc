"""Figures for the rolling tyre: measured vs model profiles, deformed ring with the patch, contact pressure.

Each function returns a matplotlib Figure (Agg backend via
:func:`ringfit.report.figures.new_figure`); save it with ``fig.savefig(path)``.
Angles in degrees from the patch centre (docs/formats.md §3), accelerations in g.
"""

from __future__ import annotations

import numpy as np

from ringfit.report.figures import new_figure

from ringfit.units import GRAVITY as G
CHANNELS = ("radial (toward centre +)", "tangential (along travel +)")


def profiles_figure(angle_deg, model, speeds_kmh, measured=None, *, title: str = ""):
    """Measured vs model sensor profile per channel (columns) and speed (rows), like the source's figs 30/38.

    **Arguments:** ``angle_deg`` ``(M,)``; ``model`` ``(P, 2, M)`` [m/s²];
    ``speeds_kmh`` ``(P,)``; ``measured`` ``(P, 2, M)`` [m/s²] or None.
    """
    model = np.asarray(model)
    P = model.shape[0]
    fig, axes = new_figure(P, 2, figsize=(10, 2.3 * P + 0.6), sharex=True, squeeze=False)
    for i in range(P):
        for c in range(2):
            ax = axes[i, c]
            if measured is not None:
                ax.plot(angle_deg, np.asarray(measured)[i, c] / G, color="C1", lw=0.8, label="measured")
            ax.plot(angle_deg, model[i, c] / G, color="C0", lw=1.0, label="model")
            ax.grid(alpha=0.3)
            ax.set_ylabel(f"{speeds_kmh[i]:g} km/h\n[g]" if c == 0 else "[g]")
            if i == 0:
                ax.set_title(CHANNELS[c], fontsize=9)
            if i == P - 1:
                ax.set_xlabel("sensor angle from patch centre [deg]")
    axes[0, 0].legend(fontsize=8)
    if title:
        fig.suptitle(title)
    fig.tight_layout()
    return fig


def draw_deformed_ring(ax, solution, geometry, *, scale: float = 5.0):
    """Ring centreline and tread surface, displacements × ``scale``, with the road and the contact patch marked.

    The road is drawn where the scaled deflection puts it, so the tread tips in the patch lie on it.
    """
    phi = np.asarray(solution.phi)
    w, v = np.asarray(solution.w), np.asarray(solution.v)
    R, tau = float(geometry.radius), float(geometry.tread_thickness)
    # axle frame: x̂ rearward, ẑ up; e_r = (sin φ, −cos φ), e_θ = (cos φ, sin φ)
    er = np.stack([np.sin(phi), -np.cos(phi)])
    et = np.stack([np.cos(phi), np.sin(phi)])
    ring = (R + scale * w) * er + scale * v * et
    free = R * er
    squeeze = np.maximum(np.nan_to_num(np.asarray(solution.penetration), neginf=0.0), 0.0)  # tread compression
    tread = (R + tau + scale * (w - squeeze)) * er + scale * v * et  # tips on the road inside the patch
    close = lambda a: np.concatenate([a, a[:, :1]], axis=1)  # noqa: E731
    ax.plot(*close(free), color="0.7", lw=0.8, ls="--", label="undeformed")
    ax.plot(*close(ring), color="C0", lw=1.4, label=f"belt (×{scale:g})")
    ax.plot(*close(tread), color="C2", lw=0.8, label="tread surface")
    contact = np.asarray(solution.pressure) > 0
    ax.plot(*tread[:, contact], color="C3", lw=3, label="contact patch")
    # road: s(φ) = R + τ + w − δ along each ray, drawn with the same displacement scale
    delta = np.asarray(solution.penetration)
    near = np.isfinite(delta) & (np.abs(phi) < np.radians(40.0))
    near &= scale * np.where(near, w - delta, np.inf) < 0.03  # only the stretch near the patch
    road = (R + tau + scale * (w - delta))[near] * er[:, near]
    ax.plot(*road, color="k", lw=1, label="road / drum")
    ax.set_aspect("equal")
    ax.set_xlabel("x rearward [m]")
    ax.set_ylabel("z up [m]")
    ax.legend(fontsize=7, loc="upper right")
    return ax


def deformed_ring_figure(solution, geometry, *, scale: float = 5.0):
    """The deformed ring with the contact patch (:func:`draw_deformed_ring`)."""
    fig, ax = new_figure(figsize=(5.5, 5.5))
    draw_deformed_ring(ax, solution, geometry, scale=scale)
    fig.tight_layout()
    return fig


def draw_contact_pressure(ax, solution, *, window_deg: float = 25.0):
    """Contact pressure p(φ) [kN/m] around the patch."""
    phi = np.degrees(np.asarray(solution.phi))
    sel = np.abs(phi) <= window_deg
    ax.plot(phi[sel], np.asarray(solution.pressure)[sel] / 1e3, color="C3")
    ax.axvline(0, color="0.6", lw=0.8)
    ax.set_xlabel("angle from patch centre [deg] (leading edge < 0)")
    ax.set_ylabel("contact pressure [kN/m]")
    ax.set_title(f"Fz = {float(solution.fz):.0f} N, Fx = {float(solution.fx):+.1f} N (rearward +)", fontsize=9)
    ax.grid(alpha=0.3)
    return ax


def contact_pressure_figure(solution):
    """Contact pressure over the patch (:func:`draw_contact_pressure`)."""
    fig, ax = new_figure(figsize=(6, 3.5))
    draw_contact_pressure(ax, solution)
    fig.tight_layout()
    return fig


def rolling_solution_figure(solution, geometry, channels, *, speed_kmh: float | None = None, scale: float = 5.0):
    """One-page summary of a simulation: deformed ring, contact pressure, the two sensor channels ``(2, M)`` [m/s²]."""
    fig, axes = new_figure(2, 2, figsize=(11, 8.5))
    draw_deformed_ring(axes[0, 0], solution, geometry, scale=scale)
    draw_contact_pressure(axes[0, 1], solution)
    phi = np.degrees(np.asarray(solution.phi))
    for c in range(2):
        ax = axes[1, c]
        ax.plot(phi, np.asarray(channels)[c] / G, color="C0")
        ax.set_title(CHANNELS[c], fontsize=9)
        ax.set_xlabel("sensor angle from patch centre [deg]")
        ax.set_ylabel("[g]")
        ax.grid(alpha=0.3)
    if speed_kmh is not None:
        fig.suptitle(f"steady rolling at {speed_kmh:g} km/h, deflection {1e3 * float(solution.deflection):.2f} mm")
    fig.tight_layout()
    return fig


__all__ = ["profiles_figure", "deformed_ring_figure", "contact_pressure_figure", "rolling_solution_figure",
           "draw_deformed_ring", "draw_contact_pressure"]
