"""The independent simulator of the tyre's state (docs/physics.md §13.7): continuous recordings of a co-rotating
sensor on a tyre at a known, or hidden, load, inflation pressure, speed, drive/brake force and tread depth.

Written separately from the model on purpose: nothing of :mod:`ringfit.physics` or :mod:`ringfit.fit` is used (a
test checks the imports), so a blind estimate checks the model and its inversion against a second discretisation
of the same physics. §13.7 gives the method: the ring by 4th-order periodic finite differences with a membrane
penalty, the pressure and tread-depth laws, hysteretic damping by a Hilbert transform, the road by its own
active-set loop, the memory brush with the lever iterated to a fixed point, and the sensor (liner offset,
gravity, tilt, sensitivity, coloured noise, the IEPE high-pass in time, a quantised encoder); then the checks and
the cross-check of the two codes. The state may drift within a recording: each revolution is solved at its own
state and the truth is kept per revolution. About 0.05 s of CPU per revolution at n = 2048.

Example (half a second at 60 km/h, driving at 500 N)::

    from ringfit.synth.state import State, Sensor, TrueTyre, simulate_state_recording
    rec = simulate_state_recording(TrueTyre(), State(load=4000.0, pressure=2.2e5, fx=500.0, depth=0.007),
                                   speed_kmh=60.0, seconds=0.5, fs=10_000.0, sensor=Sensor(offset=1e-3, tilt=0.5))
    rec.acc.shape                 # (2, 5000): radial, tangential [m/s²]
    rec.revolutions[0]            # the truth: {'load_n': 4000.0, 'rotation_hz': 8.697, 'rolling_radius_m': 0.305,
                                  #  'slip': 0.0044, 'torque_nm': 151.2, 'contact_length_m': 0.1233, …}
"""

from __future__ import annotations

import json
import math
from dataclasses import asdict, dataclass, field, replace
from pathlib import Path

import numpy as np

from ringfit._threads import small_matrix_threads
from ringfit.units import GRAVITY, KMH

BAR = 1e5
#: Relaxation of the brush–contact fixed point (its plain steps alternate with a ratio of about −0.28).
RELAX = 0.88
#: The rated load of the example tyre [N] (Table 9's test load).
RATED_LOAD = 4000.0


# ============================================================================ the true tyre and its state
@dataclass(frozen=True)
class TrueTyre:
    """The true tyre of a simulation, SI. Ring values hold at ``pressure_ref`` and ``depth_ref``; ``depth_new`` is
    the new (unworn) tread's depth, the data sheet's, which the tyre file states (``tread_depth_new_mm``): the
    example's blind tread depths are drawn up to it."""

    radius: float = 0.296
    width: float = 0.152
    pressure_ref: float = 2.2e5
    tread_ref: float = 0.020          # τ_ref at depth_ref
    depth_ref: float = 0.008
    rho_a: float = 2.715
    ei: float = 0.9426
    kw: float = 1.294e6
    kv: float = 1.161e6
    damping_ratio: float = 0.025
    k_tread: float = 19e6
    kx: float = 15e6
    mu: float = 1.0
    kw_share: float = 0.5
    kv_share: float = 0.3
    k_tread_share: float = 0.0
    tread_density: float = 1100.0
    land_ratio: float = 0.7
    depth_new: float = 0.008

    def at(self, pressure: float, depth: float) -> dict:
        """The ring's values at pressure p [Pa] and tread depth d [m] (the laws of the module docstring)."""
        r = pressure / self.pressure_ref
        tau = self.tread_ref + (depth - self.depth_ref)
        if tau <= 0:
            raise ValueError(f"tread depth {depth} m leaves no tread (τ = {tau} m)")
        return dict(
            P=pressure * self.width / self.radius,
            kw=self.kw * (1 - self.kw_share + self.kw_share * r),
            kv=self.kv * (1 - self.kv_share + self.kv_share * r),
            k_tread=self.k_tread * (1 - self.k_tread_share + self.k_tread_share * r) * self.tread_ref / tau,
            kx=self.kx * self.tread_ref / tau,
            rho_a=self.rho_a + self.tread_density * self.width * self.land_ratio * (depth - self.depth_ref),
            tau=tau, ei=self.ei, eta=2.0 * self.damping_ratio, mu=self.mu, R=self.radius,
        )

    def tyre_file(self, name: str = "true tyre"):
        """A :class:`ringfit.io.tyre.Tyre` with the STATE_CONTRACT keys (docs/formats.md §1)."""
        from ringfit.io.tyre import Tyre
        from ringfit.params import TyreGeometry

        geometry = TyreGeometry(radius=self.radius, width=self.width, pressure=self.pressure_ref,
                                tread_thickness=self.tread_ref, name=name)
        values = dict(rho_a=self.rho_a, ei=self.ei, kw=self.kw, kv=self.kv, damping_ratio=self.damping_ratio,
                      k_tread=self.k_tread)
        extra = {"tyre": {"tread_depth_mm": 1e3 * self.depth_ref, "tread_depth_new_mm": 1e3 * self.depth_new,
                          "tread_density_kg_m3": self.tread_density,
                          "tread_land_ratio": self.land_ratio},
                 "ring": {"kx_n_per_m2": self.kx, "friction": self.mu,
                          "pressure": {"kw_share": self.kw_share, "kv_share": self.kv_share,
                                       "k_tread_share": self.k_tread_share}}}
        return Tyre(geometry, {k: float(v) for k, v in values.items()}, extra)


@dataclass(frozen=True)
class State:
    """One operating state: ``load`` Fz [N], ``pressure`` [Pa], ``fx`` [N] (the tips' net force, + driving),
    ``depth`` (tread depth) [m]."""

    load: float
    pressure: float
    fx: float
    depth: float


@dataclass(frozen=True)
class Sensor:
    """The accelerometer: liner offset e [m], tilt gain γ, per-channel sensitivity factors (radial,
    tangential), IEPE corner f_c [Hz], noise σ per channel [m/s²] and colour."""

    offset: float = 0.0
    tilt: float = 0.0
    gain: tuple = (1.0, 1.0)
    corner_hz: float = 0.5
    noise: tuple = (0.0, 0.0)
    colour: str = "white"


# ============================================================================ finite differences
def stencils(n: int, order: int = 4):
    """Periodic central FD matrices d/dφ … d⁴/dφ⁴ on φ_j = −π + 2πj/n (order 2 or 4), sparse CSR."""
    import scipy.sparse as sp

    h = 2 * np.pi / n

    def st(coeffs, scale):
        rows = np.concatenate([np.arange(n)] * len(coeffs))
        cols = np.concatenate([(np.arange(n) + k) % n for k in coeffs])
        vals = np.concatenate([np.full(n, c / scale) for c in coeffs.values()])
        return sp.csr_matrix((vals, (rows, cols)), shape=(n, n))

    if order == 4:
        return (st({-2: 1, -1: -8, 1: 8, 2: -1}, 12 * h), st({-2: -1, -1: 16, 0: -30, 1: 16, 2: -1}, 12 * h**2),
                st({-3: 1, -2: -8, -1: 13, 1: -13, 2: 8, 3: -1}, 8 * h**3),
                st({-3: -1, -2: 12, -1: -39, 0: 56, 1: -39, 2: 12, 3: -1}, 6 * h**4))
    if order == 2:
        return (st({-1: -1, 1: 1}, 2 * h), st({-1: 1, 0: -2, 1: 1}, h**2),
                st({-2: -1, -1: 2, 1: -2, 2: 1}, 2 * h**3), st({-2: 1, -1: -4, 0: 6, 1: -4, 2: 1}, h**4))
    raise ValueError(f"order {order}; expected 2 or 4")


def _hilbert_i_sign(y):
    """Multiply each column's harmonic n by i·sign(n) (n = 0 and the Nyquist harmonic get 0)."""
    n = y.shape[0]
    Y = np.fft.rfft(y, axis=0)
    Y[0] = 0.0
    if n % 2 == 0:
        Y[-1] = 0.0
    return np.fft.irfft(1j * Y, n, axis=0)


@dataclass
class Steady:
    """A solved steady rolling state (SI; fields on the ring's grid φ)."""

    phi: np.ndarray
    w: np.ndarray
    v: np.ndarray
    pressure: np.ndarray      # radial tread force per unit centreline length [N/m] on the grid
    tip: np.ndarray           # road force on the tips along x̂ (rearward) per unit length [N/m]
    axle_height: float
    r_road: float
    r_free: float
    fz: float
    fx: float                 # the tips' net force, + along the direction of travel (driving)
    fx_radial: float          # the radial springs' horizontal force, + along travel (−: rolling resistance)
    leading: float            # patch edges φ [rad]
    trailing: float
    contact_length: float     # along the road between the patch edges [m]
    outer_iterations: int
    brush_loads: np.ndarray = None   # (q_w, q_v) of the tips on the window points: a warm start

    @property
    def slip(self) -> float:
        return self.r_free / self.r_road - 1.0



class RingFD:
    """The ring at one pressure, tread depth and Ω, discretised by FD on ``n`` points, with its influence
    matrix over the contact window; :meth:`solve` finds the steady state for a load and an Fx."""

    def __init__(self, tyre: TrueTyre, pressure: float, depth: float, omega: float, *, n: int = 2048,
                 order: int = 4, ea: float = 1e9, window_deg: float = 30.0, damping: bool = True,
                 drum_diameter: float | None = None):
        import scipy.sparse as sp
        import scipy.sparse.linalg as spla

        self.tyre, self.omega, self.n, self.order = tyre, float(omega), int(n), order
        self.drum = None if drum_diameter is None else 0.5 * float(drum_diameter)  # drum radius R_d [m]
        self.par = par = tyre.at(pressure, depth)
        R = par["R"]
        self.h = 2 * np.pi / n
        self.phi = -np.pi + self.h * np.arange(n)
        self.d = d1, d2, d3, d4 = stencils(n, order)
        eye = sp.identity(n, format="csr")
        b4, P = par["ei"] / R**4, par["P"]
        m = ea / R**2 - par["rho_a"] * self.omega**2
        self.elastic = sp.bmat([[b4 * d4 - P * (d2 + eye) + par["kw"] * eye, -b4 * d3],
                                [b4 * d3, -b4 * d2 + par["kv"] * eye]]).tocsr()
        # the membrane term as the strain ε = w + D1 v and its adjoint D1ᵀ = −D1, so that the discrete
        # inextensible motions (w = −D1 v) carry no penalty at all: with D2 in place of D1·D1 the penalty
        # would stiffen short waves by EA/R²·O(k²(kh)⁴) (2nd order with D2 reads loads 2 % low, §13.7)
        L = (self.elastic + sp.bmat([[m * eye, m * d1], [-m * d1, -m * (d1 @ d1)]])).tocsc()
        self.lu = spla.splu(L)
        self.eta = par["eta"] if damping else 0.0
        self.win = np.flatnonzero(np.abs(self.phi) <= math.radians(window_deg))
        nw = self.win.size
        # the FD operator is circulant (periodic, constant coefficients): the response to a unit load at
        # grid point j is the response to one at point 0 moved by j, so two columns give every column
        rhs = np.zeros((2 * n, 2))
        rhs[0, 0] = rhs[n, 1] = 1.0
        g = self._solve(rhs)
        self._spectra = np.fft.rfft(g.reshape(2, n, 2), axis=1)  # [w or v, harmonic, from q_w or q_v]
        shift = (self.win[:, None] - self.win[None, :]) % n
        gw = np.block([g[:n, 0][shift], g[:n, 1][shift]])     # w on the window from (q_w, q_v) on it
        gv = np.block([g[n:, 0][shift], g[n:, 1][shift]])     # v likewise
        self.Gww = gw[:, :nw]
        d1w = self.d[0][self.win][:, self.win].toarray()  # d/dφ within the window (the patch is inside it)
        self._window = (gw, gv, d1w)

    def response(self, q_w, q_v):
        """(w, v) on the whole grid for the loads ``q_w``, ``q_v`` [N/m] on the window points: the circulant
        operator's columns are the two base responses shifted, summed here as circular convolutions."""
        n = self.n
        Q = np.zeros((2, n))
        Q[0, self.win], Q[1, self.win] = q_w, q_v
        F = np.fft.rfft(Q, axis=1)
        out = np.einsum("akb,bk->ak", self._spectra, F)
        return np.fft.irfft(out, n, axis=1)

    def _solve(self, rhs):
        """(L + η·K_hyst) x = rhs by a Neumann series on L's LU (K_hyst = i·sign(n)·elastic)."""
        x0 = self.lu.solve(rhs)
        if self.eta == 0.0:
            return x0
        n = self.n
        x = x0
        scale = np.max(np.abs(x0))
        prev = np.inf
        for _ in range(80):
            ke = self.elastic @ x
            damp = np.vstack([_hilbert_i_sign(ke[:n]), _hilbert_i_sign(ke[n:])])
            new = x0 - self.lu.solve(self.eta * damp)
            change = np.max(np.abs(new - x)) / scale
            x = new
            # geometric at ratio ~η down to the roundoff floor of the EA penalty (~1e-10 at n = 2048)
            if change <= 1e-12 or (change < 1e-8 and change > 0.5 * prev):
                return x
            prev = change
        raise RuntimeError("the hysteretic Neumann series did not converge")

    # ------------------------------------------------------------------ the road
    def road_distance(self, phi, H):
        """Distance s(φ) from the axle to the road along the ray at φ, and ∂s/∂H (docs/physics.md §4.3): flat,
        H/cos φ; a drum of radius R_d whose top is H below the axle, D cos φ − √(R_d² − D² sin²φ),
        D = H + R_d (+inf where the ray misses it)."""
        if self.drum is None:
            return H / np.cos(phi), 1.0 / np.cos(phi)
        rd, D = self.drum, H + self.drum
        disc = rd**2 - (D * np.sin(phi)) ** 2
        root = np.sqrt(np.maximum(disc, 1e-300))
        s = np.where(disc > 0, D * np.cos(phi) - root, np.inf)
        ds = np.where(disc > 0, np.cos(phi) + D * np.sin(phi) ** 2 / root, 0.0)
        return s, ds

    def _road_x(self, sigma):
        """Horizontal position (x̂, rearward) of the road point at arc length σ from the top of the road."""
        return sigma if self.drum is None else self.drum * math.sin(sigma / self.drum)

    def _road_sigma(self, x):
        return x if self.drum is None else self.drum * math.asin(x / self.drum)

    # ------------------------------------------------------------------ contact
    def _contact(self, load, w_other, k, rout, active, H=None):
        """Radial tread forces p on the window for the load, the ring moved by ``w_other`` (other loads):
        the active set and, on a drum, Newton in H (the road linearised in H at each step)."""
        phik = self.phi[self.win]
        R, h = self.par["R"], self.h
        H = rout - 0.01 if H is None else H
        for _ in range(200):
            idx = np.flatnonzero(active)
            m = idx.size
            s0, ds = self.road_distance(phik[idx], H)
            A = np.zeros((m + 1, m + 1))
            A[:m, :m] = np.eye(m) + k * self.Gww[np.ix_(idx, idx)]
            A[:m, m] = k * ds
            A[m, :m] = R * h * np.cos(phik[idx])
            x = np.linalg.solve(A, np.append(k * (rout + w_other[idx] - s0 + ds * H), load))
            p = np.zeros(self.win.size)
            p[idx] = x[:m]
            moved = abs(x[m] - H)
            H = x[m]
            pen = rout + w_other - self.Gww @ p - self.road_distance(phik, H)[0]
            new = pen > 0
            if np.array_equal(new, active) and (self.drum is None or moved < 1e-13):
                return p, H, pen, active
            active = new
        raise RuntimeError("the contact active set did not settle")

    def _tips(self, x, s, p, x_lead, r, k, mu):
        """Memory brush: tip forces along x̂ (road on tip) for road metres per radian ``r``. Each tip's anchor
        is a road point, at arc length σ along the road; the road carries it r·s after a wheel turn s."""
        anchor = self._road_sigma(x_lead)
        road_x = self._road_x
        q = []
        for xj, sj, pj in zip(x, s, p):
            e = xj - road_x(anchor + r * sj)
            lim = mu * pj / k
            if abs(e) > lim:
                e = math.copysign(lim, e)
                anchor = self._road_sigma(xj - e) - r * sj
            q.append(-k * e)
        return np.asarray(q)

    def solve(self, load: float, fx: float = 0.0, *, tol: float = 1e-9, max_outer: int = 200,
              start: Steady | None = None, steps: int | None = None) -> Steady:
        """The steady state at load Fz [N] with the tips' net force ``fx`` [N] (+ driving); ``start``: a
        nearby solution whose brush loads start the fixed point. ``tol``: the fixed point stops when the
        brush loads move by less than ``tol`` times the largest radial tread force. ``steps``: stop after
        that many evaluations of the brush instead (``steps=1``: the brush loads of the radial-only solution,
        then the contact solved again with them — the two-pass fixed point of a load hook), for studies."""
        n, nw, win = self.n, self.win.size, self.win
        par = self.par
        R, tau, k, kx, mu, h = par["R"], par["tau"], par["k_tread"], par["kx"], par["mu"], self.h
        rout = R + tau
        phik = self.phi[win]
        gw, gv, d1w = self._window
        active = np.abs(phik) < 0.1
        qb = np.zeros(2 * nw) if start is None else start.brush_loads.copy()  # brush loads (q_w, q_v), window
        r_guess = None if start is None else start.r_road
        top = mu * load
        if abs(fx) >= 0.999 * top:
            raise ValueError(f"Fx = {fx:.1f} N is beyond the friction limit μ·Fz = {top:.1f} N")
        H = None
        for it in range(1, max_outer + 1):
            p, H, pen, active = self._contact(load, gw[:, :nw] @ qb[:nw] + gw[:, nw:] @ qb[nw:], k, rout, active, H)
            loads = np.concatenate([qb[:nw] - p, qb[nw:]])
            ww, vw = gw @ loads, gv @ loads     # w, v on the window
            idx = np.flatnonzero(active)
            if idx.size < 3 or np.any(np.diff(idx) != 1):
                raise RuntimeError("the contact patch is not one contiguous run of grid points")
            if idx[0] < 4 or idx[-1] > nw - 5:
                raise RuntimeError("the contact patch reaches the edge of the window; widen window_deg")
            psi = (d1w @ ww - vw) / R
            xt = (R + ww) * np.sin(phik) + vw * np.cos(phik) + tau * np.sin(phik - psi)
            i0 = idx[0]
            t = pen[i0 - 1] / (pen[i0 - 1] - pen[i0])
            phi_l = phik[i0 - 1] + t * h
            x_l = xt[i0 - 1] + t * (xt[i0] - xt[i0 - 1])
            xs, ss, ps = xt[idx].tolist(), (phik[idx] - phi_l).tolist(), p[idx].tolist()

            def net(r, xs=xs, ss=ss, ps=ps, x_l=x_l):
                return float(-np.sum(self._tips(xs, ss, ps, x_l, r, kx, mu)) * R * h)

            r_road = self._root(lambda r: net(r) - fx, r_guess, rout)
            r_guess = r_road
            q = np.zeros(nw)
            q[idx] = self._tips(xs, ss, ps, x_l, r_road, kx, mu)
            c = -tau * q * np.cos(phik - psi) / R
            new = np.concatenate([q * np.sin(phik) + d1w.T @ c, q * np.cos(phik) - c])
            change = np.max(np.abs(new - qb))
            # the plain fixed point alternates with a ratio of about −0.28 (docs/physics.md §13.7):
            # relaxing by 0.88 (between that mode's 1/1.28 and 1 for the slow one) halves the steps
            qb = new if steps is not None else qb + RELAX * (new - qb)
            if change <= tol * max(1.0, np.max(p)) or it == steps:
                break
        else:
            raise RuntimeError("the brush and the contact did not reach a fixed point")
        r_free = r_road if fx == 0.0 else self._root(net, r_road, rout)
        # the final fields with the final brush loads
        p, H, pen, active = self._contact(load, gw[:, :nw] @ qb[:nw] + gw[:, nw:] @ qb[nw:], k, rout, active, H)
        w, v = self.response(qb[:nw] - p, qb[nw:])
        pf = np.zeros(n)
        pf[win] = p
        qf = np.zeros(n)
        qf[win[idx]] = q[idx]
        trailing_i = idx[-1]
        tt = pen[trailing_i] / (pen[trailing_i] - pen[trailing_i + 1])
        phi_t = float(phik[trailing_i] + tt * h)
        if self.drum is None:
            length = H * (math.tan(phi_t) - math.tan(phi_l))
        else:  # the arc of the drum between the road points of the two edges
            edges = np.array([phi_l, phi_t])
            sd = self.road_distance(edges, H)[0]
            beta = np.arctan2(sd * np.sin(edges), H + self.drum - sd * np.cos(edges))
            length = self.drum * (beta[1] - beta[0])
        return Steady(
            phi=self.phi, w=w, v=v, pressure=pf, tip=qf, axle_height=float(H), r_road=float(r_road),
            r_free=float(r_free), fz=float(R * h * np.sum(p * np.cos(phik))), fx=float(-np.sum(qf) * R * h),
            fx_radial=float(R * h * np.sum(p * np.sin(phik))), leading=float(phi_l), trailing=phi_t,
            contact_length=float(length), outer_iterations=it, brush_loads=qb)

    @staticmethod
    def _root(f, guess, rout):
        """The road length per radian where ``f`` (decreasing in it) vanishes: Brent's method, on a bracket
        grown from ``guess`` (or ±20 % of R_out); :class:`ValueError` when the brush cannot carry it."""
        from scipy.optimize import brentq

        if guess is not None:
            for width in (1e-5, 1e-4, 1e-3):
                lo, hi = guess - width * rout, guess + width * rout
                f_lo, f_hi = f(lo), f(hi)
                if f_hi < 0.0 < f_lo:
                    return brentq(f, lo, hi, xtol=1e-14, rtol=1e-14)
        lo, hi = 0.8 * rout, 1.2 * rout
        f_lo, f_hi = f(lo), f(hi)
        if not f_hi < 0.0 < f_lo:
            raise ValueError(f"the brush cannot carry this Fx: its force minus the wanted one runs "
                             f"{f_lo:.1f} … {f_hi:.1f} N over r_road = {lo:.4f} … {hi:.4f} m")
        return brentq(f, lo, hi, xtol=1e-14, rtol=1e-14)

    # ------------------------------------------------------------------ the sensor
    def reading(self, sol: Steady, sensor: Sensor) -> tuple[np.ndarray, np.ndarray]:
        """(radial, tangential) specific force on the grid [m/s²] (docs/physics.md §4.6, §5 layers 1–4; no
        gain, noise or high-pass): radial toward the centre +, tangential along travel +."""
        d1, d2, _, _ = self.d
        R, e, om2 = self.par["R"], sensor.offset, self.omega**2
        w, v, phi = sol.w, sol.v, self.phi
        psi = (d1 @ w - v) / R
        vs = v + e * psi
        rs = R - e
        a_r = om2 * (d2 @ w - 2 * (d1 @ vs) - w) - om2 * rs
        # v″ as D1·D1 v, as in the membrane strain: with D2 the discrete inextensible belt would show a
        # spurious strain rate Ω²(D2 − D1·D1)v at the patch edges in the tangential channel
        a_t = om2 * (d1 @ (d1 @ vs) + 2 * (d1 @ w) - vs)
        f_r, f_t = a_r - GRAVITY * np.cos(phi), a_t + GRAVITY * np.sin(phi)
        f_r0, f_t0 = -om2 * rs - GRAVITY * np.cos(phi), GRAVITY * np.sin(phi)
        return -f_r + sensor.tilt * psi * f_t0, f_t + sensor.tilt * psi * f_r0


def free_frequencies(tyre: TrueTyre, pressure: float, depth: float, modes, *, n: int = 2048, order: int = 4,
                     ea: float = 1e9) -> np.ndarray:
    """Natural frequencies [Hz] of the free, standing tyre (Ω = 0, no contact) for wave numbers ``modes``, from
    the same FD operator as :class:`RingFD`: the operator is circulant, so e^{ikφ} is an eigenvector of each
    stencil; its 2×2 symbol (w, v) against the mass ρA·I gives two frequencies per k, the lower the
    flexural one (docs/physics.md §2.1 in the limit EA → ∞, h → 0)."""
    par = tyre.at(pressure, depth)
    b4, P, m = par["ei"] / par["R"] ** 4, par["P"], ea / par["R"] ** 2
    phi = -np.pi + 2 * np.pi * np.arange(n) / n
    out = []
    for k in modes:
        e = np.exp(1j * k * phi)
        s1, s2, s3, s4 = ((d @ e)[0] / e[0] for d in stencils(n, order))
        K = np.array([[b4 * s4 - P * (s2 + 1) + par["kw"] + m, -b4 * s3 + m * s1],
                      [b4 * s3 - m * s1, -b4 * s2 - m * s1 * s1 + par["kv"]]])
        lam = np.linalg.eigvals(K).real.min() / par["rho_a"]
        out.append(math.sqrt(lam) / (2 * math.pi))
    return np.asarray(out)


# ============================================================================ the time domain
def iepe_highpass(x, corner_hz: float, fs: float, *, zi_level=None):
    """The first-order IEPE high-pass H(s) = s/(s + 2πf_c) in the time domain (bilinear transform,
    ``scipy.signal.lfilter``) along the last axis; ``zi_level`` starts it settled on that constant input."""
    from scipy import signal

    b, a = signal.bilinear([1.0, 0.0], [1.0, 2 * np.pi * corner_hz], fs)
    if zi_level is None:
        return signal.lfilter(b, a, x, axis=-1)
    zi = signal.lfilter_zi(b, a)
    lvl = np.atleast_1d(np.asarray(zi_level, float))
    return signal.lfilter(b, a, x, axis=-1, zi=zi[None, :] * lvl[:, None] if np.ndim(x) > 1 else zi * lvl[0])[0]


def coloured_time_noise(rng, samples: int, fs: float, sigma: float, colour: str) -> np.ndarray:
    """Noise in time with RMS ``sigma``: ``white``; ``pink`` (power ∝ 1/f); ``red`` (∝ 1/f²); ``band`` (white
    plus a resonance bump of ±10 % around a random 300–3000 Hz). Below 2 Hz the 1/f laws are held flat."""
    spec = np.fft.rfft(rng.normal(0.0, 1.0, samples))
    f = np.fft.rfftfreq(samples, 1.0 / fs)
    fl = np.maximum(f, 2.0)
    if colour == "pink":
        spec = spec / np.sqrt(fl)
    elif colour == "red":
        spec = spec / fl
    elif colour == "band":
        centre = rng.uniform(300.0, min(3000.0, 0.4 * fs))
        spec = spec * np.sqrt(1.0 + 20.0 * np.exp(-0.5 * ((f - centre) / (0.1 * centre)) ** 2))
    elif colour != "white":
        raise ValueError(f"noise colour {colour!r}")
    spec[0] = 0.0
    x = np.fft.irfft(spec, samples)
    return sigma * x / np.std(x)


@dataclass
class Recording:
    """A simulated recording: the channels, the encoder and the truth per revolution."""

    acc: np.ndarray                 # (2, samples): radial, tangential [m/s²]
    encoder_deg: np.ndarray         # absolute encoder angle [deg]
    encoder_offset_deg: float
    fs: float
    omega: float
    revolutions: list = field(default_factory=list)   # dicts, one per revolution (the truth)


def simulate_state_recording(tyre: TrueTyre, states, *, speed_kmh: float, seconds: float, fs: float,
                             sensor: Sensor, seed: int = 0, n: int = 2048, encoder_counts: int = 4096,
                             drum_diameter_m: float | None = None, progress=None) -> Recording:
    """A continuous recording of ``seconds`` at ``fs`` [Hz] of the sensor on ``tyre``.

    ``states``: a :class:`State` (held for the whole recording) or a function ``t [s] -> State`` (evaluated
    at each revolution's middle; pressure and tread depth must stay constant). The wheel turns at a constant
    Ω = V/r_road with V = ``speed_kmh`` at the state of t = 0; each revolution (top to top, φ = 180°) is
    solved at its own state; V = Ω·r_road then follows the state. **Returns** a :class:`Recording` whose
    ``revolutions`` hold the truth (``load_n``, ``pressure_bar``, ``speed_kmh``, ``rolling_radius_m``,
    ``free_radius_m``, ``fx_n``, ``slip``, ``torque_nm`` = Fx·H, ``tread_depth_mm``, …). ``drum_diameter_m``:
    on a drum of that diameter instead of a flat road (V is then the drum's surface speed)."""
    with small_matrix_threads():  # small dense solves: BLAS threads only cost here
        return _simulate(tyre, states, speed_kmh, seconds, fs, sensor, seed, n, encoder_counts, drum_diameter_m,
                         progress)


def _simulate(tyre, states, speed_kmh, seconds, fs, sensor, seed, n, encoder_counts, drum, progress):
    from scipy.interpolate import CubicSpline

    rng = np.random.default_rng(seed)
    state_at = states if callable(states) else (lambda t, s=states: s)
    s0 = state_at(0.0)
    # Ω from V at the state of t = 0: r_road needs a solve at some Ω; the steady shape hardly depends on Ω
    # (only through EA/R² − ρAΩ²), so a first solve at a nominal Ω gives r_road, and the ring is rebuilt at Ω
    rout = tyre.radius + tyre.at(s0.pressure, s0.depth)["tau"]
    v_ms = speed_kmh * KMH
    ring = RingFD(tyre, s0.pressure, s0.depth, v_ms / rout, n=n, drum_diameter=drum)
    omega = v_ms / ring.solve(s0.load, s0.fx).r_road
    ring = RingFD(tyre, s0.pressure, s0.depth, omega, n=n, drum_diameter=drum)

    samples = int(round(seconds * fs))
    t = np.arange(samples) / fs
    phi0 = rng.uniform(-np.pi, np.pi)
    phi_u = phi0 + omega * t                       # unwrapped sensor angle
    rev_of = np.floor((phi_u + np.pi) / (2 * np.pi)).astype(int)
    rev_of -= rev_of[0]
    tau_hp = 1.0 / (2 * np.pi * sensor.corner_hz)
    lead = int(round(min(6.0 * tau_hp, 4.0) * fs))
    t_lead = -np.arange(lead, 0, -1) / fs
    phi_lead = phi0 + omega * t_lead
    grid = np.append(ring.phi, np.pi)
    sig = np.zeros((2, samples))
    sig_lead = np.zeros((2, lead))
    revs = []
    sol = last = None
    n_rev = int(rev_of[-1]) + 1
    for i in range(n_rev):
        sel = np.flatnonzero(rev_of == i)
        t_mid = 0.5 * (t[sel[0]] + t[sel[-1]])
        st = state_at(t_mid)
        if st.pressure != s0.pressure or st.depth != s0.depth:
            raise ValueError("pressure and tread depth must stay constant within a recording")
        if sol is None or st != last:  # a constant state is solved once
            sol = ring.solve(st.load, st.fx, start=sol)
            last = st
            rad, tan = ring.reading(sol, sensor)
            spl = CubicSpline(grid, np.vstack([np.append(rad, rad[0]), np.append(tan, tan[0])]).T,
                              bc_type="periodic")
        wrapped = (phi_u[sel] + np.pi) % (2 * np.pi) - np.pi
        sig[:, sel] = spl(wrapped).T
        if i == 0:
            sig_lead[:] = spl((phi_lead + np.pi) % (2 * np.pi) - np.pi).T
            level = np.array([np.mean(rad), np.mean(tan)])
        revs.append(dict(
            revolution=i, complete=int(0 < i < n_rev - 1), t_start_s=float(t[sel[0]]), t_end_s=float(t[sel[-1]]),
            load_n=st.load,
            pressure_bar=st.pressure / BAR, speed_kmh=omega * sol.r_road / KMH, rotation_hz=omega / (2 * np.pi),
            rolling_radius_m=sol.r_road, free_radius_m=sol.r_free, fx_n=sol.fx, slip=sol.slip,
            torque_nm=sol.fx * sol.axle_height, axle_height_m=sol.axle_height, tread_depth_mm=1e3 * st.depth,
            contact_length_m=sol.contact_length, fx_radial_n=sol.fx_radial))
        if progress:
            progress(i + 1, n_rev)
    full = np.concatenate([sig_lead, sig], axis=1)
    for c in range(2):
        full[c] *= sensor.gain[c]
        if sensor.noise[c] > 0:
            full[c] += coloured_time_noise(rng, full.shape[1], fs, sensor.noise[c], sensor.colour)
    out = iepe_highpass(full, sensor.corner_hz, fs, zi_level=level * np.asarray(sensor.gain))[:, lead:]
    offset = float(rng.uniform(-180.0, 180.0))
    enc = np.degrees(phi_u) - offset
    step = 360.0 / encoder_counts
    enc = np.round(enc / step) * step
    return Recording(acc=out, encoder_deg=enc, encoder_offset_deg=offset, fs=float(fs), omega=float(omega),
                     revolutions=revs)


# ============================================================================ the example folder
#: Calibration recordings: (name, speed [km/h], load [× rated], pressure [× p_ref], Fx [× Fz], depth [mm],
#: drum diameter [m] or None for the flat road).
CALIBRATION = (
    ("cal_p100_l050", 60.0, 0.5, 1.0, 0.0, 8.0, None),
    ("cal_p100_l100", 60.0, 1.0, 1.0, 0.0, 8.0, None),
    ("cal_p100_drive", 60.0, 0.8, 1.0, 0.2, 8.0, None),
    ("cal_p100_brake", 80.0, 0.8, 1.0, -0.2, 8.0, None),
    ("cal_p080_l080", 60.0, 0.8, 0.8, 0.0, 8.0, None),
    ("cal_p120_l080", 100.0, 0.8, 1.2, 0.0, 8.0, None),
    ("cal_p100_worn", 60.0, 0.8, 1.0, 0.0, 5.0, None),
    ("cal_drum_l080", 60.0, 0.8, 1.0, 0.0, 8.0, 1.2192),
)
#: Sample rates the recordings draw from [Hz].
SAMPLE_RATES = (10240.0, 12800.0, 20480.0, 25600.0)
NOISE_COLOURS = ("white", "pink", "red", "band")
#: The truth CSV's columns, in order (docs/formats.md §15.1).
TRUTH_COLUMNS = ("revolution", "complete", "t_start_s", "t_end_s", "load_n", "pressure_bar", "speed_kmh", "rotation_hz",
                 "rolling_radius_m", "free_radius_m", "fx_n", "slip", "torque_nm", "axle_height_m",
                 "tread_depth_mm", "contact_length_m", "fx_radial_n")


def nominal_tyre() -> TrueTyre:
    """The example's nominal tyre (Table 9 and the contract's example laws): what ``tyre.toml`` says."""
    return TrueTyre()


def jittered_tyre(rng, nominal: TrueTyre | None = None) -> TrueTyre:
    """The true tyre: every ring value and law of ``nominal`` moved at random (log-normal, σ 5 % on the
    stiffnesses and mass, 10 % on ζ, k_x; shares ± 0.1; μ ± 5 %)."""
    t = nominal or nominal_tyre()
    ln = lambda x, s: float(x * math.exp(rng.normal(0.0, s)))  # noqa: E731
    return replace(t, rho_a=ln(t.rho_a, 0.03), ei=ln(t.ei, 0.1), kw=ln(t.kw, 0.05), kv=ln(t.kv, 0.05),
                   damping_ratio=ln(t.damping_ratio, 0.1), k_tread=ln(t.k_tread, 0.05), kx=ln(t.kx, 0.1),
                   mu=ln(t.mu, 0.05), kw_share=float(np.clip(t.kw_share + rng.uniform(-0.1, 0.1), 0, 1)),
                   kv_share=float(np.clip(t.kv_share + rng.uniform(-0.1, 0.1), 0, 1)),
                   k_tread_share=float(np.clip(t.k_tread_share + rng.uniform(0.0, 0.1), 0, 1)))


def _sensor(rng, speed_kmh, rout) -> Sensor:
    scale = (speed_kmh * KMH) ** 2 / rout  # the centripetal acceleration
    sig = rng.uniform(0.003, 0.01) * scale
    return Sensor(offset=float(rng.uniform(0.0005, 0.002)), tilt=float(rng.uniform(0.3, 1.0)),
                  gain=(float(1 + rng.normal(0, 0.02)), float(1 + rng.normal(0, 0.02))),
                  corner_hz=float(rng.uniform(0.2, 1.0)), noise=(float(sig), float(sig * rng.uniform(0.5, 1.0))),
                  colour=str(rng.choice(NOISE_COLOURS)))


def _write_recording(path: Path, rec: Recording, condition: dict, overwrite: bool = False) -> None:
    from ringfit.io.continuous import ContinuousWriter

    with ContinuousWriter(path, axes=("radial", "tangential"), fs_hz=rec.fs, samples=rec.acc.shape[1],
                          encoder="angle", hall=False, encoder_offset_deg=rec.encoder_offset_deg,
                          condition=condition, acc_dtype=np.float32, overwrite=overwrite) as w:
        w.write(rec.acc, encoder=rec.encoder_deg)


def _write_free_modes(path: Path, tyre: TrueTyre, pressure: float, depth: float, rng, overwrite=False) -> None:
    """The free tyre's modes n = 1 … 8 at this pressure (docs/formats.md §2): frequencies with 0.2 % noise,
    damping 100·ζ with 5 %."""
    from ringfit.io.modes import ModeTable, write_mode_table

    k = np.arange(1, 9)
    f = free_frequencies(tyre, pressure, depth, k) * (1 + 0.002 * rng.normal(size=k.size))
    zeta = 100 * tyre.damping_ratio * np.exp(0.05 * rng.normal(size=k.size))
    write_mode_table(ModeTable(freq_hz=f, n=k, damping_pct=zeta, freq_std_hz=0.002 * f,
                               condition={"state": "free", "pressure_bar": pressure / BAR, "speed_kmh": 0.0,
                                          "rotation_hz": 0.0, "tread_depth_mm": 1e3 * depth}), path,
                     overwrite=overwrite)


def _write_truth_csv(path: Path, revs: list) -> None:
    lines = [",".join(TRUTH_COLUMNS)]
    lines += [",".join(str(r[c]) if c in ("revolution", "complete") else repr(float(r[c])) for c in TRUTH_COLUMNS)
              for r in revs]
    path.write_text("\n".join(lines) + "\n")


def write_state_example(folder, *, seed: int = 0, blind: int = 6, seconds: float = 4.0, n: int = 2048,
                        progress: bool = False, overwrite: bool = False, speed_stated: bool = False) -> dict:
    """Write ``ringfit example state`` into the existing, empty-enough ``folder``: ``tyre.toml`` (nominal),
    ``calibration/*.records.npz`` (known states) and ``calibration/free_pNNN.modes.csv`` (the free tyre's modes
    at NNN % of the reference pressure), ``blind/*.records.npz`` (hidden states), ``truth/``
    (``README.md``, ``tyre.truth.toml``, one ``NAME.truth.csv`` per recording, ``truth.json``).

    **Returns** the truth: ``{"tyre": {...}, "recordings": {name: {"state": ..., "sensor": ..., "revolutions":
    [...]}}}`` (SI in ``tyre``, file units in the rows). A ``folder`` that holds anything is refused before
    any work (:class:`ringfit.errors.InputError`) unless ``overwrite``. ``speed_stated``: the blind recordings
    also state their mean ``speed_kmh`` (as a vehicle's own speed signal would; by default the speed is
    hidden too and V = Ω·r_road is left to the estimate)."""
    from ringfit.errors import InputError
    from ringfit.io.tyre import write_tyre

    folder = Path(folder)
    if not overwrite and folder.is_dir() and any(folder.iterdir()):
        raise InputError("is not empty; the state example is written into an empty folder (or overwrite)",
                         source=folder)
    rng = np.random.default_rng(seed)
    nominal = nominal_tyre()
    truth_tyre = jittered_tyre(rng, nominal)
    for sub in ("calibration", "blind", "truth"):
        (folder / sub).mkdir(parents=True, exist_ok=True)
    write_tyre(nominal.tyre_file("example tyre (nominal)"), folder / "tyre.toml", overwrite=overwrite)
    write_tyre(truth_tyre.tyre_file("example tyre (TRUE)"), folder / "truth" / "tyre.truth.toml", overwrite=overwrite)
    jobs = []
    for name, speed, lf, pf, fxf, depth, drum in CALIBRATION:
        load = lf * RATED_LOAD
        st = State(load=load, pressure=pf * nominal.pressure_ref, fx=fxf * load, depth=depth * 1e-3)
        jobs.append(("calibration", name, speed, st, None, drum))
    for i in range(blind):
        speed = float(rng.uniform(20.0, 120.0))
        load = float(rng.uniform(0.3, 1.2) * RATED_LOAD)
        pressure = float(nominal.pressure_ref * rng.uniform(0.8, 1.2))
        depth = float(rng.uniform(2.0, 1e3 * nominal.depth_new) * 1e-3)
        fx0 = float(rng.uniform(-0.3, 0.3) * load)
        fx1 = float(np.clip(fx0 + rng.uniform(-0.1, 0.1) * load, -0.3 * load, 0.3 * load))
        amp, freq, ph = float(rng.uniform(0.0, 0.04)), float(rng.uniform(0.6, 1.5)), float(rng.uniform(0, 2 * np.pi))
        drift = dict(load_amplitude=amp, load_hz=freq, load_phase_rad=ph, fx_start_n=fx0, fx_end_n=fx1)

        def states(t, load=load, pressure=pressure, depth=depth, fx0=fx0, fx1=fx1, amp=amp, freq=freq, ph=ph):
            lt = load * (1 + amp * math.sin(2 * math.pi * freq * t + ph))
            return State(load=lt, pressure=pressure, fx=fx0 + (fx1 - fx0) * min(t / seconds, 1.0), depth=depth)

        jobs.append(("blind", f"blind_{i + 1:02d}", speed, states, drift, None))
    out = {"tyre": asdict(truth_tyre), "nominal": asdict(nominal), "recordings": {}}
    for kind, name, speed, states, drift, drum in jobs:
        st0 = states if isinstance(states, State) else states(0.0)
        rout = truth_tyre.radius + truth_tyre.at(st0.pressure, st0.depth)["tau"]
        sensor = _sensor(rng, speed, rout)
        fs = float(rng.choice(SAMPLE_RATES))
        rec = simulate_state_recording(truth_tyre, states, speed_kmh=speed, seconds=seconds, fs=fs, sensor=sensor,
                                       seed=int(rng.integers(2**31)), n=n, drum_diameter_m=drum)
        r0 = rec.revolutions[0]
        if kind == "calibration":
            condition = dict(speed_kmh=r0["speed_kmh"], rotation_hz=r0["rotation_hz"], load_n=r0["load_n"],
                             pressure_bar=r0["pressure_bar"], torque_nm=r0["torque_nm"],
                             tread_depth_mm=r0["tread_depth_mm"])
            if drum is None:
                condition["road"] = "flat"
            else:
                condition["drum_diameter_m"] = drum
        else:
            condition = dict(road="flat", note="state hidden: see truth/README.md")
            if speed_stated:
                condition["speed_kmh"] = _mean(rec.revolutions, "speed_kmh")
        _write_recording(folder / kind / f"{name}.records.npz", rec, condition, overwrite)
        _write_truth_csv(folder / "truth" / f"{name}.truth.csv", rec.revolutions)
        out["recordings"][name] = dict(kind=kind, fs_hz=fs, seconds=seconds, speed_kmh_nominal=speed,
                                       drum_diameter_m=drum,
                                       sensor=asdict(sensor), drift=drift, condition=condition,
                                       revolutions=rec.revolutions)
        if progress:
            print(f"  {kind}/{name}: {len(rec.revolutions)} revolutions", flush=True)
    for pf in sorted({c[3] for c in CALIBRATION}):
        _write_free_modes(folder / "calibration" / f"free_p{round(100 * pf):03d}.modes.csv", truth_tyre,
                          pf * nominal.pressure_ref, nominal.depth_ref, rng, overwrite)
    (folder / "truth" / "truth.json").write_text(json.dumps(out, indent=1))
    (folder / "truth" / "README.md").write_text(_truth_readme(out))
    (folder / "README.md").write_text(_readme(out, seed, blind, seconds))
    return out


def _mean(revs, key):
    return round(float(np.mean([r[key] for r in revs])), 6) + 0.0  # no "-0.0" for a force of −1e-12 N


def _truth_readme(out) -> str:
    t = out["tyre"]
    rows = ["| recording | kind | load_n | pressure_bar | speed_kmh | rolling_radius_m | fx_n | slip | "
            "torque_nm | tread_depth_mm | fs_hz | noise | tilt γ | f_c Hz |",
            "|---|---|---|---|---|---|---|---|---|---|---|---|---|---|"]
    for name, r in out["recordings"].items():
        rv = r["revolutions"]
        lo, hi = min(x["load_n"] for x in rv), max(x["load_n"] for x in rv)
        f_lo, f_hi = (round(f(x["fx_n"] for x in rv)) + 0.0 for f in (min, max))
        s = r["sensor"]
        rows.append(
            f"| {name} | {r['kind']} | {_mean(rv, 'load_n'):.1f} ({lo:.0f}…{hi:.0f}) "
            f"| {_mean(rv, 'pressure_bar'):.4f} "
            f"| {_mean(rv, 'speed_kmh'):.3f} | {_mean(rv, 'rolling_radius_m'):.5f} | {_mean(rv, 'fx_n'):.1f} "
            f"({f_lo:.0f}…{f_hi:.0f}) | {_mean(rv, 'slip'):.5f} | {_mean(rv, 'torque_nm'):.1f} "
            f"| {_mean(rv, 'tread_depth_mm'):.3f} | {r['fs_hz']:.0f} | {s['colour']} {s['noise'][0]:.2f} m/s² "
            f"| {s['tilt']:.3f} | {s['corner_hz']:.3f} |")
    laws = (f"k_w share {t['kw_share']:.3f}, k_v share {t['kv_share']:.3f}, k_trd share {t['k_tread_share']:.3f}, "
            f"k_x {t['kx']:.4g} N/m², μ {t['mu']:.4f}")
    return f"""# The truth of `ringfit example state` (keep out of sight of the estimate)

The true tyre is `tyre.truth.toml` (the nominal `../tyre.toml` jittered); its laws: {laws}.
True ring at the reference pressure {t['pressure_ref'] / BAR:.2f} bar and tread depth {1e3 * t['depth_ref']:.1f} mm:
ρA {t['rho_a']:.5g} kg/m, EI {t['ei']:.5g} N m², k_w {t['kw']:.5g} N/m², k_v {t['kv']:.5g} N/m²,
ζ {t['damping_ratio']:.4g}, k_trd {t['k_tread']:.5g} N/m², τ {t['tread_ref']:.4f} m.

Means over each recording's revolutions (the range for the quantities that drift). Per revolution:
`NAME.truth.csv` (docs/formats.md §15.1: load_n, pressure_bar, speed_kmh, rolling_radius_m, fx_n, slip,
tread_depth_mm, …), every number of the simulation in `truth.json`. Fx is the tread tips' net force along
the direction of travel (+ driving), torque = Fx·H (H the axle height); slip = r_free/r_road − 1.

{chr(10).join(rows)}
"""


def _readme(out, seed, blind, seconds) -> str:
    return f"""# `ringfit example state` (seed {seed}, {blind} blind recordings, {seconds:g} s each)

Continuous recordings (docs/formats.md §9) of a co-rotating radial + tangential accelerometer with a rim
encoder, from the independent simulator `ringfit.synth.state` (docs/physics.md §13.7: its own finite
differences of the ring, tread springs on a flat road, a memory brush with the lever, the IEPE high-pass in
time, coloured noise).

- `tyre.toml` — the NOMINAL tyre (not the truth), with the state keys (tread depth, k_x, friction, the
  pressure shares);
- `calibration/` — recordings at known states, stated in their conditions (load_n, pressure_bar,
  speed_kmh, rotation_hz, torque_nm, tread_depth_mm): two loads, three pressures, drive and brake, a
  worn tread (5 mm), one on a 1.2192 m drum (drum_diameter_m); and `free_pNNN.modes.csv` (+ `.json`),
  the free tyre's modes n = 1…8 at NNN % of the reference pressure;
- `blind/` — recordings whose state is hidden (speed 20–120 km/h, load 0.3–1.2 × {RATED_LOAD:.0f} N,
  pressure ± 20 %, Fx within ± 0.3 Fz, tread depth 2–8 mm; the load oscillates by up to 4 % at ~1 Hz and
  Fx ramps within a recording);
- `truth/` — the answers: `README.md`, `tyre.truth.toml`, `NAME.truth.csv` per recording, `truth.json`.

Try:

```
ringfit estimate calibration/cal_p100_l100.records.npz --tyre tyre.toml --out cal.estimate.json --per-revolution cal.csv
```

Identify the tyre from `calibration/` first (docs/formats.md §6): a case folder with `tyre.toml`, the free table at
its pressure as `free.modes.csv` (+ `.json`), the other free tables, and each flat-road recording at the tyre
file's tread depth averaged into a profile (`ringfit profile calibration/cal_p100_l100.records.npz --out
case/cal_p100_l100.profile.csv`; `ringfit.synth.examples.calibration_case` writes the whole folder), then

```
ringfit identify case --out identified.tyre.toml
ringfit estimate blind/blind_01.records.npz --tyre identified.tyre.toml --state --out blind_01.estimate.json
```
"""
