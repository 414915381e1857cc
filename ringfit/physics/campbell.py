"""Campbell diagram of the rolling, loaded tyre: the model's modes against speed, tracked into branches
(docs/physics.md §3.7). A model view: no measurement enters here.

The modes are :mod:`ringfit.physics.rolling_modes`'s (fixed-frame modes of the ring rotating at Ω with
the tread springs of the steady contact patch). :func:`campbell_diagram` computes them at a series of
speeds (one jit, vmapped) and **tracks** them into branches by continuity of their harmonic content
(:func:`track_branches`: MAC between neighbouring speeds), each branch with its dominant order n,
travelling direction (backward / forward / standing), contact character (``extr``/``0``,
``vert``/``hort``) and the lines the co-rotating sensor sees, ``ω + kΩ`` with their weights
(docs/physics.md §3.7 *Observers*); the cavity's two acoustic lines ride along
(:func:`ringfit.physics.cavity.loaded_cavity_lines`). Labels are read from the **radial acceleration**
content, ``−(ω + kΩ)² W_k``, the content an accelerometer's data (a co-rotating sensor, a cleat field)
carry.

Measured mode tables are matched to a diagram by :mod:`ringfit.gap.campbell` (``ringfit campbell
--modes``, the gap diagnosis's rolling rows).
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Literal, get_args

import numpy as np

from ringfit.errors import InputError
# frames of docs/formats.md §2 (``rotating`` = the co-rotating sensor; the CLI calls it ``sensor``) and the
# standing/travelling threshold (a mode whose dominant order's backward/forward amplitude ratio is below it is
# standing): the mode files' and the cleat SSI's own, so that a diagram and a measured table classify alike
from ringfit.io.modes import FRAMES, Frame
from ringfit.physics.operating import road_from_drum_diameter
from ringfit.targets.rolling_modes import TRAVELLING_RATIO

#: Highest dominant order kept in a diagram (the issue's n ≤ 15).
DEFAULT_N_MAX = 15
#: Speeds of one diagram are padded to a multiple of this, so that tables at a few speeds share a compilation.
SPEED_BUCKET = 8


#: A frame as the commands and plots take it: a table's :data:`~ringfit.io.modes.Frame` or ``"sensor"`` (the CLI's
#: name for ``"rotating"``).
FrameChoice = Literal[Frame, "sensor"]


def frame_name(frame: FrameChoice) -> Frame:
    """``sensor``/``rotating`` → ``rotating``; ``fixed`` → ``fixed`` (docs/formats.md §2 names)."""
    if not isinstance(frame, str) or frame not in get_args(FrameChoice):
        raise InputError(f"frame {frame!r}; expected 'sensor' (= 'rotating') or 'fixed'")
    return "rotating" if frame == "sensor" else frame


@dataclass
class CampbellDiagram:
    """Tracked branches of the rolling, loaded tyre against speed (docs/physics.md §3.7).

    **Fields** (S speeds ascending, B branches, H = 2K + 1 harmonics k = −K…K):

    - ``speed_kmh``, ``omega`` (Ω [rad/s]): ``(S,)``; Ω = V/R_e, ``rolling_radius_m`` R_e = R_out − δ/3.
    - ``fixed_hz``: fixed-frame frequency of each branch ``(S, B)`` [Hz].
    - ``order``: dominant n ``(S, B)``; ``travel``: signed backward/forward amplitude ratio of
      that order; ``symmetry``: share of the radial content even about the patch centre
      ``(S, B)`` (1 = ``extr``, 0 = ``0``); all from the radial acceleration content.
    - ``damping_ratio``: ζ ``(S, B)`` (first order, hysteretic).
    - ``k``: harmonics ``(H,)``; ``line_hz``: signed sensor lines ``(ω + kΩ)/2π`` ``(S, B, H)``;
      ``line_weight``: their radial-acceleration weights, normalised per mode ``(S, B, H)``
      (tangential for a mode without radial content, the inextensible ring's n = 0).
    - ``mode_index``: index of each branch among the modes at each speed ``(S, B)``.
    - ``load_n``, ``drum_diameter_m`` (None: flat road), ``contact`` (False: free spinning ring).
    - ``leading_deg``, ``trailing_deg``: patch edges ``(S,)``; ``ok``: contact solve converged ``(S,)``.
    """

    speed_kmh: np.ndarray
    omega: np.ndarray
    fixed_hz: np.ndarray
    order: np.ndarray
    travel: np.ndarray
    symmetry: np.ndarray
    damping_ratio: np.ndarray
    k: np.ndarray
    line_hz: np.ndarray
    line_weight: np.ndarray
    mode_index: np.ndarray
    load_n: float
    drum_diameter_m: float | None
    contact: bool
    rolling_radius_m: float
    leading_deg: np.ndarray
    trailing_deg: np.ndarray
    ok: np.ndarray
    #: the cavity's first acoustic pair in the fixed frame ``(S, 2)`` [Hz]: fore-aft, vertical (docs/physics.md §6
    #: cavity_mode, :func:`ringfit.physics.cavity.loaded_cavity_lines`); None = not computed
    acoustic_hz: np.ndarray | None = None

    @property
    def rotation_hz(self) -> np.ndarray:
        """Wheel rotation rate Ω/2π [Hz], ``(S,)``."""
        return self.omega / (2.0 * math.pi)

    @property
    def branches(self) -> int:
        return self.fixed_hz.shape[1]

    def direction(self) -> np.ndarray:
        """``backward``/``forward``/``standing`` per speed and branch ``(S, B)`` (|travel| ≥ 3 is travelling)."""
        return np.where(self.travel >= TRAVELLING_RATIO, "backward",
                        np.where(self.travel <= -TRAVELLING_RATIO, "forward", "standing")).astype(object)

    def tag(self) -> np.ndarray:
        """Loaded-tyre tag of standing modes (``extr``/``0``, ``vert``/``hort`` for n = 1), ``""`` otherwise ``(S, B)``."""
        standing = self.direction() == "standing"
        cos_type = self.symmetry >= 0.5
        one = self.order == 1
        tag = np.where(one, np.where(cos_type, "vert", "hort"), np.where(cos_type, "extr", "0"))
        ok = standing & (self.order >= 1) & np.isfinite(self.symmetry) & self.contact
        return np.where(ok, tag, "").astype(object)

    def sensor_line(self):
        """The principal sensor line of each branch: ``(hz, k, weight)``, each ``(S, B)`` (hz = |ω + kΩ|/2π).

        One line ``ω + kΩ`` per branch, the same k at every speed: the k whose weight summed over the
        speeds is largest (the strongest line of a mode can change with speed where contact spreads its
        content; following the strongest line at each speed would jump between lines, a jagged curve
        that no single wave follows). ``weight`` is that line's weight at each speed.
        """
        w = np.where(np.isfinite(self.line_weight), self.line_weight, 0.0)
        j = np.argmax(w.sum(axis=0), axis=-1)  # (B,)
        jj = np.broadcast_to(j[None, :, None], (w.shape[0], w.shape[1], 1))
        hz = np.abs(np.take_along_axis(self.line_hz, jj, -1)[..., 0])
        weight = np.take_along_axis(self.line_weight, jj, -1)[..., 0]
        return hz, np.broadcast_to(self.k[j].astype(int), hz.shape).copy(), weight

    def branch_direction(self) -> np.ndarray:
        """The prevailing direction of each branch ``(B,)``: the most frequent of ``direction()`` over the
        speeds above 0 (all speeds for a diagram at standstill only); ties go to the fastest speed's."""
        d = self.direction()
        moving = self.speed_kmh > 0
        rows = d[moving] if moving.any() else d
        out = []
        for b in range(self.branches):
            vals = list(rows[:, b])
            best = max(("backward", "forward", "standing"), key=lambda x: (vals.count(x), x == vals[-1]))
            out.append(best)
        return np.array(out, dtype=object)

    def frequencies(self, frame: FrameChoice) -> np.ndarray:
        """Branch frequencies in ``frame`` (``fixed``, or ``rotating``/``sensor``: the principal line) ``(S, B)`` [Hz]."""
        return self.fixed_hz if frame_name(frame) == "fixed" else self.sensor_line()[0]

    def rows(self, frame: FrameChoice = "fixed") -> list[dict]:
        """One dict per (branch, speed): the columns of ``*.campbell.csv`` (docs/formats.md)."""
        frame = frame_name(frame)
        f = self.frequencies(frame)
        shz, sk, sw = self.sensor_line()
        direction, tag = self.direction(), self.tag()
        out = []
        for b in range(self.branches):
            for s in range(len(self.speed_kmh)):
                out.append({
                    "branch": b + 1, "speed_kmh": float(self.speed_kmh[s]), "rotation_hz": float(self.rotation_hz[s]),
                    "frame": frame, "freq_hz": float(f[s, b]), "fixed_hz": float(self.fixed_hz[s, b]),
                    "sensor_hz": float(shz[s, b]), "sensor_k": int(sk[s, b]), "sensor_weight": float(sw[s, b]),
                    "n": int(self.order[s, b]), "direction": direction[s, b], "tag": tag[s, b],
                    "travel": float(self.travel[s, b]), "symmetry": _float_or_nan(self.symmetry[s, b]),
                    "damping_pct": 100.0 * float(self.damping_ratio[s, b]), "load_n": float(self.load_n),
                    "contact": bool(self.contact), "ok": bool(self.ok[s]), "kind": "structural",
                })
        out += self._acoustic_rows(frame)
        return out

    def _acoustic_rows(self, frame: str) -> list[dict]:
        """The cavity's fore-aft and vertical lines as two more branches (``kind`` = ``acoustic``).

        Fixed frame: the lines of :func:`ringfit.physics.cavity.loaded_cavity_lines`; the co-rotating
        sensor sees each shifted by ∓Ω (the air turns with the tyre): ``f_a ± (√(Ω² + g²) − Ω)/2π``.
        """
        if self.acoustic_hz is None:
            return []
        out = []
        mid = self.acoustic_hz.mean(axis=1)
        for j, name in enumerate(("fore_aft", "vertical")):
            upper = self.acoustic_hz[:, j] >= mid
            sensor = np.where(upper, self.acoustic_hz[:, j] - self.rotation_hz, self.acoustic_hz[:, j] + self.rotation_hz)
            sensor = np.where(self.omega > 0, sensor, self.acoustic_hz[:, j])
            for s in range(len(self.speed_kmh)):
                fixed = float(self.acoustic_hz[s, j])
                out.append({
                    "branch": self.branches + j + 1, "speed_kmh": float(self.speed_kmh[s]),
                    "rotation_hz": float(self.rotation_hz[s]), "frame": frame,
                    "freq_hz": fixed if frame == "fixed" else float(sensor[s]), "fixed_hz": fixed,
                    "sensor_hz": float(sensor[s]), "sensor_k": 0 if self.omega[s] == 0 else (-1 if upper[s] else 1),
                    "sensor_weight": 1.0, "n": 1, "direction": name, "tag": "", "travel": math.nan,
                    "symmetry": 1.0 if name == "vertical" else 0.0, "damping_pct": math.nan,
                    "load_n": float(self.load_n), "contact": bool(self.contact), "ok": bool(self.ok[s]),
                    "kind": "acoustic",
                })
        return out


def _float_or_nan(x) -> float:
    x = float(x)
    return x if math.isfinite(x) else math.nan


CAMPBELL_COLUMNS = ("branch", "speed_kmh", "rotation_hz", "frame", "freq_hz", "fixed_hz", "sensor_hz", "sensor_k",
                    "sensor_weight", "n", "direction", "tag", "travel", "symmetry", "damping_pct", "load_n",
                    "contact", "ok", "kind")


def campbell_diagram(
    ring,
    geometry,
    load_n: float,
    speeds_kmh,
    *,
    drum_diameter_m: float | None = None,
    contact: bool = True,
    n_max: int = DEFAULT_N_MAX,
    harmonics: int | None = None,
    wheel=None,
) -> CampbellDiagram:
    """Branches of the tyre's modes against speed (docs/physics.md §3.7).

    **Arguments:**

    - ``ring``, ``geometry``: the tyre (``ring.k_tread`` is the tread spring).
    - ``load_n``: Fz [N]; ``speeds_kmh``: ``(S,)`` road speeds [km/h], ascending, ≥ 0.
    - ``drum_diameter_m``: drum under the tyre (None: flat road).
    - ``contact``: ``False`` for a free spinning ring (no patch; ``load_n`` unused, R_e = R_out).
    - ``n_max``: branches whose dominant order exceeds n_max at every speed are dropped.
    - ``harmonics``: Hill basis K (default :data:`ringfit.physics.rolling_modes.DEFAULT_HARMONICS`; ≥ 2 n_max).
    - ``wheel``: ``None`` (rim fixed) or a :class:`ringfit.physics.wheel.Wheel`: the rim on its suspension
      (docs/physics.md §6 ``wheel_suspension``), three more modes per speed that move the n ≤ 1 branches.

    **Returns:** :class:`CampbellDiagram` (check ``ok``). One compilation per
    bucket of :data:`SPEED_BUCKET` speeds and settings.
    """
    import jax

    from ringfit.physics.rolling_modes import DEFAULT_HARMONICS, campbell_modes_jit
    from ringfit._threads import small_matrix_threads

    K = DEFAULT_HARMONICS if harmonics is None else int(harmonics)
    if n_max < 1 or 2 * n_max > K:
        raise InputError(f"n_max = {n_max}: expected 1 ≤ n_max ≤ K/2 = {K // 2} (Hill basis K = {K})")
    speeds = np.asarray(speeds_kmh, dtype=np.float64).ravel()
    if speeds.size == 0 or not np.all(np.isfinite(speeds)) or np.any(speeds < 0) or np.any(np.diff(speeds) <= 0):
        raise InputError(f"speeds {speeds.tolist()}: expected finite speeds ≥ 0 km/h in increasing order")
    if contact and not (math.isfinite(load_n) and load_n > 0):
        raise InputError(f"load {load_n}: expected a positive load in N")
    S = speeds.size
    pad = np.concatenate([speeds, np.full(-S % SPEED_BUCKET, speeds[-1])])
    road = road_from_drum_diameter(drum_diameter_m)
    with small_matrix_threads():
        cm = campbell_modes_jit(ring, geometry, float(load_n) if contact else 0.0, pad, road, harmonics=K,
                                contact=contact, wheel=wheel)
        labels = acceleration_labels(cm.modes)
        cm, labels = jax.device_get((cm, labels))
    m = cm.modes
    sl = slice(0, S)
    freq = np.asarray(m.angular_frequency)[sl] / (2 * math.pi)
    content = np.concatenate([np.asarray(m.radial)[sl], np.asarray(m.tangential)[sl]], axis=-1)
    perm = track_branches(freq, content)
    order, travel, symmetry, line_hz, line_w = (np.asarray(x)[sl] for x in labels)
    take = lambda a: np.take_along_axis(a, perm if a.ndim == 2 else perm[..., None], axis=1)  # noqa: E731
    order, travel, symmetry = take(order), take(travel), take(symmetry)
    keep = np.flatnonzero(np.any(order <= n_max, axis=0))
    keep = keep[np.argsort(take(freq)[0, keep], kind="stable")]
    sel = lambda a: a[:, keep]  # noqa: E731
    ok = np.asarray(cm.ok)[sl] & np.all(np.isfinite(freq), axis=1)
    acoustic = _acoustic_lines(ring, geometry, float(load_n) if contact else 0.0, road, np.asarray(cm.omega)[sl])
    return CampbellDiagram(
        speed_kmh=speeds, omega=np.asarray(cm.omega)[sl], fixed_hz=sel(take(freq)), order=sel(order).astype(int),
        travel=sel(travel), symmetry=sel(symmetry), damping_ratio=sel(take(np.asarray(m.damping_ratio)[sl])),
        k=np.asarray(m.k)[0], line_hz=sel(take(line_hz)), line_weight=sel(take(line_w)), mode_index=sel(perm),
        load_n=float(load_n), drum_diameter_m=drum_diameter_m, contact=bool(contact),
        rolling_radius_m=float(cm.rolling_radius), leading_deg=np.degrees(np.asarray(cm.leading)[sl]),
        trailing_deg=np.degrees(np.asarray(cm.trailing)[sl]), ok=ok, acoustic_hz=acoustic,
    )


def _acoustic_lines(ring, geometry, load_n: float, road, omegas) -> np.ndarray:
    """``(S, 2)`` fore-aft and vertical cavity lines [Hz] in the fixed frame (docs/physics.md §6 cavity_mode):
    eq. 22's line split by the flat of the static contact solve at ``load_n`` (none at 0) and by rotation."""
    from ringfit.physics.cavity import loaded_cavity_lines, static_cavity_split
    from ringfit.physics.natural import cavity_frequency

    e = float(static_cavity_split(ring, geometry, load_n, road=road)) if load_n > 0 else 0.0
    wa = 2 * math.pi * float(cavity_frequency(1))
    fa, vt = loaded_cavity_lines(wa, e, np.asarray(omegas, dtype=np.float64))
    return np.stack([np.asarray(fa), np.asarray(vt)], axis=1) / (2 * math.pi)


def acceleration_labels(modes):
    """Labels of rolling modes read from their radial acceleration content (docs/physics.md §3.7), as a
    co-rotating sensor's or a cleat field's data carry them: the labels of :class:`CampbellDiagram`.

    **Arguments:** ``modes`` — :class:`ringfit.physics.rolling_modes.RollingModes` (any leading axes).

    **Returns:** ``(order, travel, symmetry, line_hz, line_weight)``: dominant order, signed travelling
    ratio and contact symmetry ``(..., N)`` of :func:`~ringfit.physics.rolling_modes.mode_labels` on
    ``−(ω + kΩ)² W_k``, and the sensor lines with their weights ``(..., N, H)``
    (:func:`~ringfit.physics.rolling_modes.sensor_lines`). A mode without radial content (the inextensible
    ring's n = 0) keeps its displacement order and travel, NaN symmetry and its tangential line weights.
    One compilation (jit).
    """
    return _acceleration_labels_jit(modes)


def _labels_impl(modes):
    import jax.numpy as jnp

    from ringfit.physics.rolling_modes import material_acceleration, mode_labels, sensor_lines

    A, _ = material_acceleration(modes)
    k = modes.k.reshape(-1, modes.k.shape[-1])[0]  # the harmonics (one speed, or the first of several)
    lab = mode_labels(A, jnp.zeros_like(A), k, modes.angular_frequency, modes.omega)
    f, wr, wt = sensor_lines(modes, "acceleration")
    # a mode without radial content (the inextensible ring's n = 0) keeps its displacement labels and
    # its tangential lines
    radial = jnp.sum(jnp.abs(modes.radial) ** 2, -1) > 1e-12
    pick = lambda a, b: jnp.where(radial, a, b)  # noqa: E731
    return (pick(lab["order"], modes.order), pick(lab["travel"], modes.travel), pick(lab["symmetry"], jnp.nan),
            f, jnp.where(radial[..., None], wr, wt))


def _lazy_jit(fn):
    cache = {}

    def call(*args):
        if "f" not in cache:
            import equinox as eqx

            cache["f"] = eqx.filter_jit(fn)
        return cache["f"](*args)

    return call


_acceleration_labels_jit = _lazy_jit(_labels_impl)


def track_branches(freq: np.ndarray, content: np.ndarray) -> np.ndarray:
    """Order the modes at each speed by continuity with the previous speed.

    **Arguments:** ``freq`` ``(S, N)`` [Hz]; ``content`` ``(S, N, D)`` complex harmonic content.

    **Returns:** ``perm`` ``(S, N)``: ``perm[s, b]`` is the mode at speed s on branch b
    (branch b = mode b at the first speed). Neighbouring speeds are assigned one-to-one
    (Hungarian) on ``(1 − MAC) + ½ min(1, |Δf|/(0.1 f))``: harmonic content first,
    frequency to break ties (e.g. between a standing pair that rotation starts to mix).
    Δf is taken from the frequency the branch's last two speeds extrapolate to, so a
    pair whose frequencies cross (their frequency order swaps) keeps its shapes: the
    branches are never sorted by frequency.
    """
    from scipy.optimize import linear_sum_assignment

    S, N = freq.shape
    perm = np.zeros((S, N), dtype=int)
    perm[0] = np.arange(N)
    unit = content / np.maximum(np.linalg.norm(content, axis=-1, keepdims=True), 1e-300)
    for s in range(1, S):
        prev = unit[s - 1, perm[s - 1]]
        mac = np.abs(np.conj(prev) @ unit[s].T) ** 2
        fp = freq[s - 1, perm[s - 1]][:, None]
        if s >= 2:  # linear extrapolation along the branch (crossings keep their slopes)
            fp = 2.0 * fp - freq[s - 2, perm[s - 2]][:, None]
        df = np.abs(freq[s][None, :] - fp) / np.maximum(0.1 * np.abs(fp), 1e-12)
        cost = (1.0 - mac) + 0.5 * np.minimum(1.0, np.nan_to_num(df, nan=1.0))
        r, c = linear_sum_assignment(cost)
        perm[s, r] = c
    return perm


__all__ = ["DEFAULT_N_MAX", "TRAVELLING_RATIO", "SPEED_BUCKET", "FRAMES", "FrameChoice", "frame_name",
           "CampbellDiagram", "CAMPBELL_COLUMNS", "campbell_diagram", "track_branches", "acceleration_labels"]
