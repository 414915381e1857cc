"""Rolling acceleration profiles — ``*.profile.csv`` with a ``*.profile.json`` sidecar (docs/formats.md §3).

A :class:`Profile` is what the co-rotating accelerometer read over one
revolution (averaged over many): angle from the patch centre along the sensor
path, radial reading (toward the wheel centre +) and tangential reading (along
travel +), plus the condition from the sidecar.

Reading validates everything and names file, row and column on error:
missing/duplicate columns, non-numeric or non-finite cells, angles outside
[−180, 180), unsorted angles, gaps (a spacing, including the wrap-around,
larger than 1.5× the median), fewer than :data:`MIN_POINTS` rows, a missing
sidecar or sidecar field. Writing is atomic, never overwrites an input and
round-trips exactly (floats written with ``repr``).

:func:`resample_profile` puts a profile on the model grid φ_j = −π + 2πj/M
(band-limited Fourier interpolation, harmonics above the grid's Nyquist
dropped) with an optional angle offset (the nuisance parameter of §5 layer 6).
"""

from __future__ import annotations

import csv
import io
import json
import math
import os
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from ringfit.errors import InputError
from ringfit.io.checks import check_condition_field, csv_columns, number_in_range, read_json_object, short_repr
from ringfit.io.files import atomic_write, check_output_path, read_text_file
from ringfit.units import KMH

#: Columns of docs/formats.md §3, in the order ringfit writes them.
COLUMNS = ("angle_deg", "acc_radial_ms2", "acc_tangential_ms2")
#: Sidecar fields every profile must have, and the optional ones (docs/formats.md §3).
REQUIRED_FIELDS = ("speed_kmh",)
#: load_n is needed by every command but ``ringfit estimate`` (which estimates it): :attr:`Profile.load_n`
#: raises then. revolutions and sample_rate_hz describe the averaging; ringfit uses them only when present.
#: pressure_bar, torque_nm (axle torque, + driving) and tread_depth_mm state the tyre's state where it is known
#: (docs/physics.md §13); a profile whose state is hidden states none of them (nor load_n), and a command that
#: needs the pressure takes the tyre file's.
OPTIONAL_FIELDS = ("load_n", "pressure_bar", "rotation_hz", "drum_diameter_m", "revolutions", "sample_rate_hz",
                   "torque_nm", "tread_depth_mm")
#: Fewest angle samples accepted per revolution.
MIN_POINTS = 16
#: A spacing larger than this multiple of the median spacing is a gap.
MAX_GAP_RATIO = 1.5
#: Largest plausible reading [m/s²] in a profile (10⁷ g: beyond any accelerometer).
MAX_ACC_MS2 = 1.0e8


@dataclass
class Profile:
    """One rolling acceleration profile (docs/formats.md §3).

    **Fields** (arrays of shape ``(N,)``): ``angle_deg`` (increasing, in
    [−180, 180)), ``acc_radial_ms2``, ``acc_tangential_ms2`` [m/s²];
    ``condition``: the sidecar (``speed_kmh``, ``load_n``, ``pressure_bar``,
    ``revolutions``, ``sample_rate_hz``, optional ``rotation_hz``,
    ``drum_diameter_m``, and any other keys, kept); ``extra``: other CSV
    columns, name -> array of str; ``source``: file name for messages.
    """

    angle_deg: np.ndarray
    acc_radial_ms2: np.ndarray
    acc_tangential_ms2: np.ndarray
    condition: dict = field(default_factory=dict)
    extra: dict[str, np.ndarray] = field(default_factory=dict)
    source: str = ""

    def __post_init__(self):
        self.angle_deg = np.asarray(self.angle_deg, dtype=np.float64)
        self.acc_radial_ms2 = np.asarray(self.acc_radial_ms2, dtype=np.float64)
        self.acc_tangential_ms2 = np.asarray(self.acc_tangential_ms2, dtype=np.float64)

    def __len__(self) -> int:
        return self.angle_deg.shape[0]

    @property
    def speed_kmh(self) -> float:
        return float(self.condition["speed_kmh"])

    @property
    def load_n(self) -> float:
        """Vertical load [N] from the sidecar; :class:`InputError` naming the file when it has none."""
        value = self.condition.get("load_n")
        if value is None:
            raise InputError("missing field 'load_n' in the sidecar (this command needs the load; only "
                             "`ringfit estimate` reads profiles without it)", source=self.source or None)
        return float(value)

    @property
    def rotation_hz(self) -> float | None:
        """Rim-encoder rotation rate [Hz], or None."""
        value = self.condition.get("rotation_hz")
        return None if value is None else float(value)

    @property
    def drum_diameter_m(self) -> float | None:
        """Drum diameter [m], or None for a flat road."""
        value = self.condition.get("drum_diameter_m")
        return None if value is None else float(value)

    def omega(self, rolling_radius: float | None = None) -> tuple[float, str]:
        """Wheel speed Ω [rad/s] and where it came from (docs/formats.md §3).

        ``2π·rotation_hz`` when the sidecar has it; else ``V / R_e`` with the
        given effective rolling radius R_e [m] (required then).
        """
        if self.rotation_hz is not None:
            return 2.0 * math.pi * self.rotation_hz, "rotation_hz (rim encoder)"
        if rolling_radius is None:
            raise InputError("no rotation_hz in the sidecar and no rolling radius given to turn speed_kmh into Ω",
                             source=self.source or None)
        return self.speed_kmh * KMH / rolling_radius, f"speed_kmh / R_e with R_e = {rolling_radius:.5g} m"

    @property
    def channels(self) -> np.ndarray:
        """``(2, N)``: radial, tangential [m/s²]."""
        return np.stack([self.acc_radial_ms2, self.acc_tangential_ms2])


def sidecar_path(path: str | os.PathLike) -> Path:
    """``x.profile.csv`` -> ``x.profile.json``."""
    return Path(path).with_suffix(".json")


def read_profile(path: str | os.PathLike) -> Profile:
    """Read and validate a profile CSV and its (required) JSON sidecar (docs/formats.md §3).

    **Raises** :class:`~ringfit.errors.InputError` with one line naming the
    file, row and column or sidecar field.
    """
    path = Path(path)
    text = read_text_file(path)
    side = sidecar_path(path)
    if not side.exists():
        raise InputError(f"missing sidecar {side.name} (needs {', '.join(REQUIRED_FIELDS)})", source=path)
    condition = read_condition(side)
    profile = parse_profile(text, source=str(path))
    profile.condition = condition
    return profile


def parse_profile(text: str, *, source: str = "<text>") -> Profile:
    """Parse and validate the CSV text of a profile (see :func:`read_profile`); no sidecar."""
    header, cols, lines = csv_columns(text, COLUMNS, source=source, empty=", ".join(COLUMNS))
    if len(lines) < MIN_POINTS:
        raise InputError(f"{len(lines)} data rows; a profile needs at least {MIN_POINTS} angles over one revolution",
                         source=source)
    values = {}
    for c in COLUMNS:
        out = np.empty(len(lines))
        for i, s in enumerate(cols[c]):
            try:
                out[i] = float(s)
            except ValueError:
                raise InputError(f"row {lines[i]}, column '{c}': {short_repr(s)} is not a number",
                                 source=source) from None
            if not math.isfinite(out[i]):
                raise InputError(f"row {lines[i]}, column '{c}': {short_repr(s)}; expected a finite number",
                                 source=source)
            if c != "angle_deg" and abs(out[i]) > MAX_ACC_MS2:
                raise InputError(f"row {lines[i]}, column '{c}': {out[i]:g}; outside the plausible range "
                                 f"±{MAX_ACC_MS2:g} m/s² (docs/formats.md §3)", source=source)
        values[c] = out
    check_angles(values["angle_deg"], lines, source)
    extra = {h: np.array(cols[h], dtype=object) for h in header if h not in COLUMNS}
    return Profile(values["angle_deg"], values["acc_radial_ms2"], values["acc_tangential_ms2"],
                   extra=extra, source=source)


def check_angles(angle_deg: np.ndarray, lines=None, source: str = "<profile>") -> None:
    """Angles must lie in [−180, 180), increase strictly and cover one revolution without gaps."""
    lines = list(range(2, angle_deg.size + 2)) if lines is None else lines
    bad = np.flatnonzero((angle_deg < -180.0) | (angle_deg >= 180.0))
    if bad.size:
        i = bad[0]
        raise InputError(f"row {lines[i]}, column 'angle_deg': {angle_deg[i]:g} outside [-180, 180)", source=source)
    step = np.diff(angle_deg)
    bad = np.flatnonzero(step <= 0.0)
    if bad.size:
        i = bad[0] + 1
        raise InputError(f"row {lines[i]}, column 'angle_deg': {angle_deg[i]:g} after {angle_deg[i - 1]:g}; "
                         "angles must increase strictly (sorted, no repeats)", source=source)
    spacing = np.append(step, angle_deg[0] + 360.0 - angle_deg[-1])
    typical = float(np.median(spacing))
    bad = np.flatnonzero(spacing > MAX_GAP_RATIO * typical)
    if bad.size:
        i = bad[0]
        if i == spacing.size - 1:
            raise InputError(f"column 'angle_deg': the angles span {angle_deg[0]:g} … {angle_deg[-1]:g} deg, "
                             f"a gap of {spacing[i]:.4g} deg at the wrap-around (typical spacing {typical:.4g}); "
                             "a profile must cover one whole revolution", source=source)
        raise InputError(f"row {lines[i + 1]}, column 'angle_deg': gap of {spacing[i]:.4g} deg after "
                         f"{angle_deg[i]:g} (typical spacing {typical:.4g} deg); angles must be evenly spaced",
                         source=source)


def read_condition(path: str | os.PathLike) -> dict:
    """Read and validate a profile sidecar (docs/formats.md §3)."""
    path = Path(path)
    return validate_condition(read_json_object(path), source=str(path))


def validate_condition(doc, *, source: str = "<sidecar>") -> dict:
    """Check a sidecar dict: required fields present, numeric, in range; returns a copy."""
    if not isinstance(doc, dict):
        raise InputError("expected a JSON object with " + ", ".join(REQUIRED_FIELDS), source=source)
    doc = dict(doc)
    for key in REQUIRED_FIELDS:
        if key not in doc or doc[key] is None:
            raise InputError(f"missing field {key!r} (a profile sidecar needs {', '.join(REQUIRED_FIELDS)})",
                             source=source)
    for key in OPTIONAL_FIELDS:
        if key in doc and doc[key] is None:
            del doc[key]
    for key in REQUIRED_FIELDS + OPTIONAL_FIELDS:
        if key not in doc:
            continue
        check_condition_field(doc, key, source=source)
        if key not in ("speed_kmh", "revolutions", "torque_nm"):  # the others must be > 0 (the torque is signed)
            number_in_range(doc[key], key, 0.0, None, lo_open=True, source=source)
    return doc


def write_profile(profile: Profile, path: str | os.PathLike, *, overwrite: bool = False, inputs=()) -> Path:
    """Write ``profile`` to ``path`` (CSV) and its sidecar (JSON) atomically (docs/formats.md §3).

    Validates the profile first (same rules as reading), refuses to overwrite an
    existing file unless ``overwrite`` and never overwrites one of ``inputs``.
    """
    path = check_output_path(path, overwrite=overwrite, inputs=inputs)
    side = check_output_path(sidecar_path(path), overwrite=overwrite, inputs=inputs)
    condition = validate_condition(profile.condition, source=f"{path}: condition")
    n = len(profile)
    for name in COLUMNS:
        arr = getattr(profile, name)
        if arr.shape != (n,) or not np.all(np.isfinite(arr)):
            raise InputError(f"column {name!r} must hold {n} finite numbers", source=path)
    if n < MIN_POINTS:
        raise InputError(f"{n} rows; a profile needs at least {MIN_POINTS}", source=path)
    check_angles(profile.angle_deg, source=str(path))
    buf = io.StringIO()
    writer = csv.writer(buf, lineterminator="\n")
    extra_names = list(profile.extra)
    writer.writerow(list(COLUMNS) + extra_names)
    for i in range(n):
        writer.writerow([repr(float(profile.angle_deg[i])), repr(float(profile.acc_radial_ms2[i])),
                         repr(float(profile.acc_tangential_ms2[i]))] + [profile.extra[k][i] for k in extra_names])
    text = buf.getvalue()
    atomic_write(path, lambda tmp: tmp.write_text(text))
    atomic_write(side, lambda tmp: tmp.write_text(json.dumps(condition, indent=2) + "\n"))
    return path


def grid_angles_deg(n_grid: int) -> np.ndarray:
    """Model grid φ_j = −180 + 360 j/M [deg], shape ``(M,)`` (same grid as :class:`~ringfit.physics.contact.ContactSolver`)."""
    return -180.0 + 360.0 * np.arange(n_grid) / n_grid


def band_limited_resample(signal: np.ndarray, n_points: int) -> np.ndarray:
    """Periodic grid signal on φ_j = −π + 2πj/M → the same revolution on N points (zero-padded/truncated spectrum).

    ``signal`` shape ``(..., M)``; returns ``(..., N)``. Nyquist harmonics are dropped.
    """
    M = signal.shape[-1]
    spec = np.fft.rfft(signal, axis=-1)
    keep = (min(M, n_points) - 1) // 2 + 1
    out = np.zeros(signal.shape[:-1] + (n_points // 2 + 1,), dtype=complex)
    out[..., :keep] = spec[..., :keep]
    return np.fft.irfft(out, n_points, axis=-1) * (n_points / M)


def resample_profile(profile: Profile, n_grid: int, offset_deg: float = 0.0) -> np.ndarray:
    """Band-limited resampling onto the model grid (docs/formats.md §3 → docs/physics.md §4.4 grid).

    Fourier coefficients of each channel by the trapezoidal rule over the
    recorded angles α_i (periodic), truncated below the grid's Nyquist
    harmonic, evaluated at α = φ_j − ``offset_deg`` (so that φ = α + offset,
    the §5 layer-6 nuisance).

    **Returns:** ``(2, M)`` array — radial, tangential [m/s²] on φ_j.
    """
    alpha = np.radians(profile.angle_deg)
    spacing = np.diff(np.append(alpha, alpha[0] + 2.0 * np.pi))
    weight = 0.5 * (spacing + np.roll(spacing, 1)) / (2.0 * np.pi)  # trapezoid on a periodic grid
    kmax = (min(len(profile), n_grid) - 1) // 2
    k = np.arange(kmax + 1)
    basis = np.exp(-1j * np.outer(k, alpha)) * weight  # (K, N)
    coeff = profile.channels @ basis.T  # (2, K): x(α) ≈ Re Σ c_k (2 − δ_k0) e^{ikα}
    phi = np.radians(grid_angles_deg(n_grid)) - math.radians(offset_deg)
    scale = np.where(k == 0, 1.0, 2.0)
    return np.real((coeff * scale) @ np.exp(1j * np.outer(k, phi)))


__all__ = ["Profile", "read_profile", "parse_profile", "write_profile", "read_condition", "validate_condition",
           "check_angles", "resample_profile", "band_limited_resample", "grid_angles_deg", "sidecar_path", "COLUMNS", "REQUIRED_FIELDS"]
