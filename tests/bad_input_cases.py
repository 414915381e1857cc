"""Every bad input of issue 14, replayed against the command line in-process.

:func:`build_fixtures` writes a small, valid set of inputs (tyre, mode table
with sidecar, impact records, rolling profile with sidecar, a continuous cleat
recording, a case folder) into a folder; :data:`CASES` lists the malformed
inputs and odd options of the issue, each as a command line over that folder
plus the files it breaks. :func:`replay` runs one case through
``ringfit.cli.main`` and says whether it got the promised answer: exit status
2, ONE line on stderr naming the file, row, field or option, no file written
or changed in the folder (or, for the few cases marked ``documented``, the
behaviour the docs promise).

Used by ``tests/test_bad_input_replay.py`` (pytest) and
``benchmarks/bench_bad_input.py`` (prints how many cases get the promised answer).
"""

from __future__ import annotations

import contextlib
import errno
import hashlib
import io
import json
import os
import re
import shutil
import signal
import traceback
from collections.abc import Callable
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

#: Sample rate of the fixture records [Hz]: Nyquist 1280 Hz, so a --band top of 5000 Hz is above it.
FS = 2560.0


# ----------------------------------------------------------------------------- fixtures


def _impact_records(fs=FS, seconds=0.5, n_angles=8):
    """Small impact records (NumPy only): two ring modes excited at t0, radial + tangential."""
    t = np.arange(int(fs * seconds)) / fs
    angles = np.arange(n_angles) * 360.0 / n_angles
    t0 = 0.02
    force = np.where((t >= t0) & (t < t0 + 0.002), 300.0 * np.sin(np.pi * (t - t0) / 0.002), 0.0)
    acc = np.zeros((n_angles, 2, t.size))
    tau = np.clip(t - t0, 0, None)
    for n, f, z in ((2, 110.0, 0.03), (3, 130.0, 0.03), (4, 150.0, 0.03)):
        decay = np.exp(-z * 2 * np.pi * f * tau) * np.sin(2 * np.pi * f * tau) * (t >= t0)
        for i, a in enumerate(np.deg2rad(angles)):
            acc[i, 0] += 50 * np.cos(n * a) * decay
            acc[i, 1] += 50 / n * np.sin(n * a) * decay
    acc += 0.01 * np.random.default_rng(0).standard_normal(acc.shape)
    return dict(acc=acc, axes=np.array(["radial", "tangential"]), sensor_angle_deg=angles, fs_hz=np.float64(fs),
                force=np.tile(force, (n_angles, 1)))


def _profile_csv(points=64, noise=0.0, seed=0):
    angle = -180.0 + 360.0 * np.arange(points) / points
    phi = np.deg2rad(angle)
    rad = 300.0 * (1 - np.exp(-0.5 * (phi / 0.2) ** 2)) - 150.0
    tan = 40.0 * np.sin(phi) * np.exp(-0.5 * (phi / 0.3) ** 2)
    if noise:
        rng = np.random.default_rng(seed)
        rad, tan = noise * rng.standard_normal(points), noise * rng.standard_normal(points)
    lines = ["angle_deg,acc_radial_ms2,acc_tangential_ms2"]
    lines += [f"{float(a)!r},{float(r)!r},{float(s)!r}" for a, r, s in zip(angle, rad, tan)]
    return "\n".join(lines) + "\n"


def _drum_record(fs=2000.0, seconds=3.0, rotation_hz=10.0, drum_period_s=np.pi * 1.2192 / (40.0 / 3.6)):
    """A small continuous drum recording (NumPy only): encoder, hall pulses, a steady pattern and ringing after each hit.

    The hits come once per revolution of the 1.2192 m drum at the stated 40 km/h (0.3447 s apart)."""
    from ringfit.io.continuous import ContinuousRecord

    t = np.arange(int(fs * seconds)) / fs
    phi = 360.0 * rotation_hz * t - 90.0
    p = np.deg2rad(phi)
    hits = np.arange(0.05, seconds, drum_period_s)
    tau = t[None, :] - hits[:, None]
    ring = np.where(tau >= 0, np.exp(-30 * np.clip(tau, 0, None)) * np.sin(2 * np.pi * 120 * np.clip(tau, 0, None)),
                    0.0).sum(axis=0)
    rng = np.random.default_rng(1)
    acc = np.stack([400 * np.exp(-0.5 * (np.angle(np.exp(1j * p)) / 0.2) ** 2) + 50 * ring,
                    40 * np.sin(p) + 20 * ring]) + rng.standard_normal((2, t.size))
    hall = ((tau >= -0.002) & (tau < 0.003)).any(axis=0).astype(float)
    return ContinuousRecord(acc=acc, axes=("radial", "tangential"), fs_hz=fs, encoder_angle_deg=phi % 360.0,
                            hall=hall, hall_delay_s=0.002,
                            condition={"speed_kmh": 40.0, "load_n": 4000.0, "pressure_bar": 2.2,
                                       "drum_diameter_m": 1.2192, "rotation_hz": rotation_hz})


PROFILE_SIDECAR = {"speed_kmh": 30.0, "load_n": 4000.0, "pressure_bar": 2.2, "revolutions": 26,
                   "sample_rate_hz": 25600.0, "rotation_hz": 4.29}


def build_fixtures(folder: str | os.PathLike) -> Path:
    """Write the valid inputs every case starts from into ``folder``; returns it."""
    from ringfit.data import path as data_path
    from ringfit.io.continuous import ContinuousRecord, write_continuous

    d = Path(folder)
    d.mkdir(parents=True, exist_ok=True)
    shutil.copy(data_path("table9.tyre.toml"), d / "tyre.toml")
    shutil.copy(data_path("free-ssi.modes.csv"), d / "free.modes.csv")
    shutil.copy(data_path("free-ssi.modes.json"), d / "free.modes.json")
    np.savez(d / "rec.records.npz", **_impact_records())
    (d / "run1.profile.csv").write_text(_profile_csv())
    (d / "run1.profile.json").write_text(json.dumps(PROFILE_SIDECAR))
    (d / "noise.profile.csv").write_text(_profile_csv(noise=50.0))
    (d / "noise.profile.json").write_text(json.dumps(PROFILE_SIDECAR))
    rec = _drum_record()
    write_continuous(rec, d / "cont.records.npz")
    frozen = ContinuousRecord(acc=rec.acc, axes=rec.axes, fs_hz=rec.fs_hz,
                              encoder_angle_deg=np.full(rec.samples, 12.5), hall=rec.hall,
                              hall_delay_s=rec.hall_delay_s, condition=rec.condition)
    write_continuous(frozen, d / "frozen.records.npz")
    case = d / "case"
    case.mkdir()
    for name in ("tyre.toml", "free.modes.csv", "free.modes.json"):
        shutil.copy(d / name, case / name)
    (d / "post.h5").write_bytes(b"\x89HDF\r\n\x1a\n" + b"\x00" * 64)  # an HDF5 signature, nothing readable
    return d


# ----------------------------------------------------------------------------- breaking files


def _write(name, text):
    def setup(d: Path):
        (d / name).write_text(text)
    return setup


def _tyre(extra="", ring="", tyre_body=None):
    body = tyre_body if tyre_body is not None else 'name = "t"\nradius_m = 0.296\nwidth_m = 0.152\npressure_bar = 2.2\n'
    ring_body = ring if ring else ("rho_a_kg_per_m = 2.715\nei_n_m2 = 0.9426\nkw_n_per_m2 = 1.294e6\n"
                                   "kv_n_per_m2 = 1.161e6\n")
    return _write("tyre.toml", f"{extra}[tyre]\n{body}\n[ring]\n{ring_body}")


def _top_tyre(line):
    return _write("tyre.toml", f"{line}\n[tyre]\nradius_m = 0.296\nwidth_m = 0.152\npressure_bar = 2.2\n")


def _modes(rows, header="n,a,tag,kind,freq_hz,freq_std_hz,damping_pct"):
    return _write("free.modes.csv", header + "\n" + "\n".join(rows) + "\n")


FREE_ROWS = ["1,0,,structural,107.0,,", "2,0,,structural,116.3,,", "3,0,,structural,130.5,,",
             "4,0,,structural,148.6,,", "5,0,,structural,170.1,,", "6,0,,structural,194.9,,"]


def _bytes(name, data):
    def setup(d: Path):
        (d / name).write_bytes(data)
    return setup


def _npz(name, **arrays):
    def setup(d: Path):
        base = _impact_records()
        base.update(arrays)
        with open(d / name, "wb") as fh:
            np.savez(fh, **{k: v for k, v in base.items() if v is not None})
    return setup


def _scaled_records(factor):
    def setup(d: Path):
        base = _impact_records()
        base["acc"] = base["acc"] * factor
        base["force"] = base["force"] * factor
        with open(d / "rec.records.npz", "wb") as fh:
            np.savez(fh, **base)
    return setup


def _truncate(name, keep=0.5):
    def setup(d: Path):
        data = (d / name).read_bytes()
        (d / name).write_bytes(data[: int(len(data) * keep)])
    return setup


def _bitflip(name, where=0.5, count=64):
    def setup(d: Path):
        data = bytearray((d / name).read_bytes())
        i = int(len(data) * where)
        for k in range(i, min(i + count, len(data))):
            data[k] ^= 0xFF
        (d / name).write_bytes(bytes(data))
    return setup


def _object_npz(d: Path):
    base = _impact_records()
    base["axes"] = np.array(["radial", "tangential"], dtype=object)
    base["acc"] = base["acc"].astype(object)
    with open(d / "rec.records.npz", "wb") as fh:
        np.savez(fh, **base)


def _json(name, doc_text):
    return _write(name, doc_text)


def _symlink(name, target):
    def setup(d: Path):
        os.symlink(target, d / name)
    return setup


def _mkdir(name):
    def setup(d: Path):
        (d / name).mkdir()
    return setup


def _both(*setups):
    def setup(d: Path):
        for s in setups:
            s(d)
    return setup


DEEP_JSON = "[" * 100_000 + "]" * 100_000
DEEP_TOML_ARRAY = "x = " + "[" * 100_000 + "]" * 100_000
HUGE_INT = "1" + "0" * 400
LONG_FIELD = "x" * 140_000


# ----------------------------------------------------------------------------- cases


@dataclass
class Case:
    """One replayed command line.

    - ``argv``: the command line; ``{d}`` is replaced by the fixture folder.
    - ``setup``: breaks or adds files in the folder before the run.
    - ``names``: the error line must contain one of these (file, field or option).
    - ``documented``: instead of a refusal, ``check(status, err, folder)`` must hold.
    - ``slow``: runs a real fit (kept out of the quick pytest selection).
    - ``issue``/``item``: where the case was reported (issue 14 unless said).
    - ``during``: ``during(folder)`` is a context manager the command runs inside (a simulated full disk,
      read-only folder or Ctrl-C; see the issue 23 section).
    - ``unchanged``: a ``check`` case must also leave the folder as it was.
    """

    id: str
    argv: list[str]
    setup: Callable | None = None
    names: tuple[str, ...] = ()
    check: Callable | None = None
    slow: bool = False
    item: int = 2
    issue: int = 14
    during: Callable | None = None
    unchanged: bool = False

    def args(self, d: Path) -> list[str]:
        return [a.replace("{d}", str(d)) for a in self.argv]


FIT = ["fit", "{d}/free.modes.csv", "--tyre", "{d}/tyre.toml", "--out", "{d}/out.toml"]
SAMPLE = ["sample", "{d}/free.modes.csv", "--tyre", "{d}/tyre.toml", "--out", "{d}/post_out.h5"]
SSI = ["ssi", "{d}/rec.records.npz", "--out", "{d}/out.modes.csv"]
FRF = ["frf", "{d}/rec.records.npz", "--out", "{d}/out.modes.csv"]
ROLL = ["roll", "--tyre", "{d}/tyre.toml", "--speed", "30", "--out", "{d}/sim.profile.csv"]
FITROLL = ["fit-rolling", "{d}/run1.profile.csv", "--tyre", "{d}/tyre.toml", "--out", "{d}/out.toml"]
PROFILE = ["profile", "{d}/cont.records.npz", "--out", "{d}/out.profile.csv"]
CLEAT = ["cleat", "{d}/cont.records.npz", "--out", "{d}/field.npz", "--sectors", "32"]
DIAG = ["diagnose", "{d}/case", "--out", "{d}/out.diagnosis.json"]
REPORT = ["report", "{d}/post.h5", "--out", "{d}/out.html"]


def _replace_out(argv, new):
    out = list(argv)
    out[out.index("--out") + 1] = new
    return out


CASES: list[Case] = []


def add(id, argv, setup=None, names=(), item=2, **kw):
    CASES.append(Case(id, list(argv), setup, tuple(names), item=item, **kw))


# --- 1. inputs never touched --------------------------------------------------------------------------------
add("fit-out-is-input-sidecar", _replace_out(FIT, "{d}/free.modes.json") + ["--force"], names=("free.modes.json",), item=1)
add("sample-out-is-input-sidecar", _replace_out(SAMPLE, "{d}/free.modes.json") + ["--force"], names=("free.modes.json",), item=1)
add("fit-rolling-out-is-profile-sidecar", _replace_out(FITROLL, "{d}/run1.profile.json") + ["--force"],
    names=("run1.profile.json",), item=1)
add("fit-rolling-plot-is-profile-sidecar", FITROLL + ["--plot", "{d}/run1.profile.json", "--force"],
    names=("run1.profile.json",), item=1)
add("fit-out-is-input", _replace_out(FIT, "{d}/free.modes.csv") + ["--force"], names=("free.modes.csv",), item=1)
add("fit-out-is-tyre", _replace_out(FIT, "{d}/tyre.toml") + ["--force"], names=("tyre.toml",), item=1)
add("ssi-plot-is-input", SSI + ["--plot", "{d}/rec.records.npz", "--force"], names=("rec.records.npz",), item=1)
add("frf-out-is-input", _replace_out(FRF, "{d}/rec.records.npz") + ["--force"], names=("rec.records.npz",), item=1)
add("cleat-snapshots-is-baseline-sidecar",
    CLEAT + ["--baseline", "{d}/run1.profile.csv", "--snapshots", "{d}/run1.profile.json", "--force"],
    names=("run1.profile.json",), item=1)
add("cleat-ssi-sidecar-is-baseline-sidecar",
    CLEAT + ["--baseline", "{d}/run1.profile.csv", "--ssi", "{d}/run1.profile.modes", "--force"],
    names=("run1.profile.json", "run1.profile.modes"), item=1)
add("profile-out-is-input", _replace_out(PROFILE, "{d}/cont.records.npz") + ["--force"], names=("cont.records.npz",), item=1)
add("diagnose-out-is-case-sidecar", _replace_out(DIAG, "{d}/case/free.modes.json") + ["--force"],
    names=("free.modes.json",), item=1)
add("report-out-is-input", _replace_out(REPORT, "{d}/post.h5") + ["--force"], names=("post.h5",), item=1)
add("roll-out-is-tyre", _replace_out(ROLL, "{d}/tyre.toml") + ["--force"], names=("tyre.toml",), item=1)

for cmd, argv, out in (("fit", FIT, "out.toml"), ("sample", SAMPLE, "post_out.h5"), ("ssi", SSI, "out.modes.csv"),
                       ("frf", FRF, "out.modes.csv"), ("roll", ROLL, "sim.profile.csv"),
                       ("fit-rolling", FITROLL, "out.toml"), ("profile", PROFILE, "out.profile.csv"),
                       ("cleat", CLEAT, "field.npz"), ("diagnose", DIAG, "out.diagnosis.json"),
                       ("report", REPORT, "out.html")):
    add(f"{cmd}-out-is-directory", argv, setup=_mkdir(out), names=(out,), item=1)
    add(f"{cmd}-out-is-directory-force", argv + ["--force"], setup=_mkdir(out), names=(out,), item=1)
    add(f"{cmd}-out-is-dangling-symlink", argv, setup=_symlink(out, "nowhere/target"), names=(out,), item=1)
add("demo-out-is-existing-file", ["demo", "--out", "{d}/tyre.toml"], names=("tyre.toml",), item=2)
add("demo-out-is-existing-file-force", ["demo", "--out", "{d}/tyre.toml", "--force"], names=("tyre.toml",), item=2)

# --- 2. no tracebacks ---------------------------------------------------------------------------------------
for line, tag in (("ring = 5", "int"), ('ring = "abc"', "str"), ("ring = [1, 2]", "list"), ("tyre = 5", "tyre-int")):
    add(f"tyre-toml-{tag}", FIT, setup=_write("tyre.toml", line + ("\n[tyre]\nradius_m = 0.296\nwidth_m = 0.152\n"
                                                                  "pressure_bar = 2.2\n" if "tyre" not in tag else "\n")),
        names=("tyre.toml",))
add("tyre-toml-radius-list", FIT, setup=_tyre(tyre_body="radius_m = [1]\nwidth_m = 0.152\npressure_bar = 2.2\n"),
    names=("radius_m",))
add("tyre-toml-huge-int", FIT, setup=_tyre(tyre_body=f"radius_m = {HUGE_INT}\nwidth_m = 0.152\npressure_bar = 2.2\n"),
    names=("radius_m",))
add("tyre-toml-huge-int-ring", FIT, setup=_tyre(ring=f"ei_n_m2 = {HUGE_INT}\n"), names=("ei_n_m2",))
add("tyre-toml-deep-array", FIT, setup=_write("tyre.toml", DEEP_TOML_ARRAY + "\n"), names=("tyre.toml",))
add("tyre-toml-binary", FIT, setup=_bytes("tyre.toml", b"\xff\xfe\x00garbage"), names=("tyre.toml",))
for cmd, argv in (("ssi", SSI), ("frf", FRF)):
    add(f"{cmd}-npz-empty", argv, setup=_bytes("rec.records.npz", b""), names=("rec.records.npz",))
    add(f"{cmd}-npz-truncated", argv, setup=_truncate("rec.records.npz"), names=("rec.records.npz",))
    add(f"{cmd}-npz-bitflip", argv, setup=_bitflip("rec.records.npz", 0.5), names=("rec.records.npz",))
    add(f"{cmd}-npz-bitflip-header", argv, setup=_bitflip("rec.records.npz", 0.0, 40), names=("rec.records.npz",))
    add(f"{cmd}-npz-object-arrays", argv, setup=_object_npz, names=("rec.records.npz",))
    add(f"{cmd}-records-all-zero", argv, setup=_npz("rec.records.npz", acc=np.zeros((8, 2, 1280))),
        names=("rec.records.npz", "acc"))
    add(f"{cmd}-records-1e300", argv, setup=_scaled_records(1e300), names=("rec.records.npz", "acc"))
    add(f"{cmd}-fs-1e300", argv, setup=_npz("rec.records.npz", fs_hz=np.float64(1e300)), names=("fs_hz",))
    add(f"{cmd}-two-samples", argv, setup=_npz("rec.records.npz", acc=np.ones((8, 2, 2)), force=np.ones((8, 2))),
        names=("rec.records.npz", "samples"))
    add(f"{cmd}-delay-nan", argv + ["--delay", "nan"], names=("--delay",))
    add(f"{cmd}-delay-inf", argv + ["--delay", "inf"], names=("--delay",))
    add(f"{cmd}-threshold-nan", argv + ["--threshold", "nan"], names=("--threshold", "threshold"))
    add(f"{cmd}-uff-garbage", [argv[0], "{d}/rec.uff", "--out", "{d}/out.modes.csv"],
        setup=_write("rec.uff", "    -1\n    58\nthis is not a dataset\n"), names=("rec.uff",))
add("ssi-skip-nan", SSI + ["--skip", "nan"], names=("--skip",))
add("ssi-block-rows-0", SSI + ["--block-rows", "0"], names=("--block-rows",))
add("ssi-radius-neg-no-force", SSI + ["--radius", "-1"], setup=_npz("rec.records.npz", force=None), names=("--radius",))
for cmd, argv in (("profile", PROFILE), ("cleat", CLEAT)):
    add(f"{cmd}-npz-empty", argv, setup=_bytes("cont.records.npz", b""), names=("cont.records.npz",))
    add(f"{cmd}-npz-truncated", argv, setup=_truncate("cont.records.npz"), names=("cont.records.npz",))
    add(f"{cmd}-npz-bitflip", argv, setup=_bitflip("cont.records.npz", 0.3), names=("cont.records.npz",))
    add(f"{cmd}-npz-bitflip-end", argv, setup=_bitflip("cont.records.npz", 0.995, 32), names=("cont.records.npz",))
    add(f"{cmd}-not-continuous", [argv[0], "{d}/rec.records.npz", *argv[2:]], names=("rec.records.npz",))
for w in ("0", "3", "-4"):
    add(f"sample-walkers-{w}", SAMPLE + ["--walkers", w], names=("--walkers",))
add("sample-min-steps-0", SAMPLE + ["--min-steps", "0"], names=("--min-steps",))
add("sample-max-steps-below-min", SAMPLE + ["--min-steps", "100", "--max-steps", "10"], names=("--max-steps",))
add("sample-seed-negative", SAMPLE + ["--seed", "-1"], names=("--seed",))
add("report-not-a-posterior", REPORT, names=("post.h5",))
add("report-empty-file", REPORT, setup=_bytes("post.h5", b""), names=("post.h5",))
# the readers
add("modes-n-1e30", FIT, setup=_modes(["1e30,0,,structural,107.0,,"] + FREE_ROWS[1:]), names=("'n'", "row 2"))
add("modes-huge-int-n", FIT, setup=_modes([f"{HUGE_INT},0,,structural,107.0,,"] + FREE_ROWS[1:]), names=("'n'",))
add("modes-long-field", FIT, setup=_modes([f"1,0,{LONG_FIELD},structural,107.0,,"] + FREE_ROWS[1:]),
    names=("free.modes.csv",))
add("modes-sidecar-huge-int", FIT, setup=_json("free.modes.json", f'{{"state": "free", "load_n": {HUGE_INT}}}'),
    names=("load_n",))
add("modes-sidecar-deep", FIT, setup=_json("free.modes.json", DEEP_JSON), names=("free.modes.json",))
add("modes-sidecar-deep-object", FIT, setup=_json("free.modes.json", '{"x": ' + DEEP_JSON + "}"),
    names=("free.modes.json",))
add("modes-sidecar-nan", FIT, setup=_json("free.modes.json", '{"state": "free", "speed_kmh": NaN}'), names=("speed_kmh",))
add("profile-sidecar-huge-int", FITROLL, setup=_json("run1.profile.json",
                                                     json.dumps(PROFILE_SIDECAR)[:-1] + f', "load_n": {HUGE_INT}}}'),
    names=("load_n",))
add("profile-sidecar-deep", FITROLL, setup=_json("run1.profile.json", DEEP_JSON), names=("run1.profile.json",))
add("profile-long-field", FITROLL, setup=_write("run1.profile.csv", "angle_deg,acc_radial_ms2,acc_tangential_ms2\n"
                                               f"{LONG_FIELD},1,2\n"), names=("run1.profile.csv",))
add("profile-csv-1e300-angle", FITROLL, setup=_write("run1.profile.csv", _profile_csv().replace("-180.0,", "-1e300,", 1)),
    names=("angle_deg",))
add("diagnose-case-sidecar-deep", DIAG, setup=_json("case/free.modes.json", DEEP_JSON), names=("free.modes.json",))
add("diagnose-case-tyre-ring-int", DIAG, setup=lambda d: (d / "case/tyre.toml").write_text(
    "ring = 5\n[tyre]\nradius_m = 0.296\nwidth_m = 0.152\npressure_bar = 2.2\n"), names=("tyre.toml",))
add("diagnose-not-a-folder", ["diagnose", "{d}/nope", "--out", "{d}/out.diagnosis.json"], names=("nope",))

# UFF files from other software (tests/data/uff, MIT): truncated, a microphone, FRFs given to SSI, no angle
UFF_DATA = Path(__file__).parent / "data" / "uff"


def _copy_uff(name, as_name=None, cut=None):
    def setup(d: Path):
        data = (UFF_DATA / name).read_bytes()
        (d / (as_name or name)).write_bytes(data if cut is None else data[: int(len(data) * cut)])
    return setup


for cmd in ("ssi", "frf"):
    add(f"{cmd}-uff-truncated-microphone", [cmd, "{d}/mic.uff", "--out", "{d}/out.modes.csv"],
        setup=_copy_uff("dataset_milestone_in_header.uff", "mic.uff"), names=("mic.uff",), item=5)
    add(f"{cmd}-uff-cut-in-half", [cmd, "{d}/half.uff", "--out", "{d}/out.modes.csv"],
        setup=_copy_uff("binary8byte.uff", "half.uff", cut=0.5), names=("half.uff",), item=5)
    add(f"{cmd}-uff-direction-0", [cmd, "{d}/b.uff", "--out", "{d}/out.modes.csv"],
        setup=_copy_uff("binary8byte.uff", "b.uff"), names=("b.uff",), item=5)
    add(f"{cmd}-uff-no-angle", [cmd, "{d}/b.uff", "--out", "{d}/out.modes.csv", "--axes", "0=radial"],
        setup=_copy_uff("binary8byte.uff", "b.uff"), names=("b.uff",), item=5)
    add(f"{cmd}-uff-band-above-nyquist", [cmd, "{d}/b.uff", "--out", "{d}/out.modes.csv", "--axes", "0=radial",
                                          "--angles", "1=0"], setup=_copy_uff("binary8byte.uff", "b.uff"),
        names=("--band",), item=5)
add("ssi-uff-frfs", ["ssi", "{d}/h.uff", "--out", "{d}/out.modes.csv", "--axes", "0=radial", "--angles", "0=0"],
    setup=_copy_uff("non_ascii_header.uff", "h.uff"), names=("h.uff",), item=5)
add("frf-uff-frfs-band-beyond-lines", ["frf", "{d}/h.uff", "--out", "{d}/out.modes.csv", "--axes", "0=radial",
                                       "--angles", "0=0"], setup=_copy_uff("non_ascii_header.uff", "h.uff"),
    names=("--band",), item=5)
add("ssi-angles-for-npz", SSI + ["--angles", "1=0"], names=("--angles",))
add("ssi-angles-garbage", SSI + ["--angles", "one=zero"], names=("--angles",))
add("ssi-axes-garbage", SSI + ["--axes", "0=vertical"], names=("--axes",))

# --- 3. no silent acceptance --------------------------------------------------------------------------------
add("tyre-unknown-ring-key", FIT, setup=_tyre(ring="rho_a_kg_per_m = 2.715\nei_nm2 = 0.9\n"), names=("ei_n_m2",), item=3)
add("tyre-unknown-tyre-key", FIT, setup=_tyre(tyre_body="radius_m = 0.296\nwidht_m = 0.152\nwidth_m = 0.15\n"
                                                        "pressure_bar = 2.2\n"), names=("width_m",), item=3)
add("tyre-unknown-table", FIT, setup=_write("tyre.toml", "[tyre]\nradius_m = 0.296\nwidth_m = 0.152\npressure_bar = 2.2\n"
                                                         "[rign]\nei_n_m2 = 0.9\n"), names=("[ring]", "'ring'"), item=3)
add("tyre-ei-1e300", FIT, setup=_tyre(ring="ei_n_m2 = 1e300\n"), names=("ei_n_m2",), item=3)
add("tyre-kw-1e-300", FIT, setup=_tyre(ring="kw_n_per_m2 = 1e-300\n"), names=("kw_n_per_m2",), item=3)
add("tyre-damping-2", FIT, setup=_tyre(ring="damping_ratio = 2.0\n"), names=("damping_ratio",), item=3)
add("tyre-width-1e300", FIT, setup=_tyre(tyre_body="radius_m = 0.296\nwidth_m = 1e300\npressure_bar = 2.2\n"),
    names=("width_m",), item=3)
add("modes-freq-1e300", FIT, setup=_modes(["1,0,,structural,1e300,,"] + FREE_ROWS[1:]), names=("freq_hz",), item=3)
add("modes-damping-1e300", FIT, setup=_modes(["1,0,,structural,107,,1e300"] + FREE_ROWS[1:]), names=("damping_pct",),
    item=3)
add("modes-std-1e300", FIT, setup=_modes(["1,0,,structural,107,1e300,"] + FREE_ROWS[1:]), names=("freq_std_hz",), item=3)
add("modes-sidecar-speed-1e300", FIT, setup=_json("free.modes.json", '{"state": "free", "speed_kmh": 1e300}'),
    names=("speed_kmh",), item=3)
add("profile-sidecar-speed-1e300", FITROLL, setup=_json("run1.profile.json", json.dumps({**PROFILE_SIDECAR,
                                                                                       "speed_kmh": 1e300})),
    names=("speed_kmh",), item=3)
add("profile-sidecar-load-1e300", FITROLL, setup=_json("run1.profile.json", json.dumps({**PROFILE_SIDECAR,
                                                                                      "load_n": 1e300})),
    names=("load_n",), item=3)
add("profile-acc-1e300", FITROLL, setup=_write("run1.profile.csv", "angle_deg,acc_radial_ms2,acc_tangential_ms2\n" + "\n".join(
    f"{-180 + 360 * i / 64!r},{1e300!r},0.0" for i in range(64)) + "\n"), names=("acc_radial_ms2",), item=3)
for cmd, argv in (("ssi", SSI), ("frf", FRF)):
    add(f"{cmd}-band-above-nyquist", argv + ["--band", "20:5000"], names=("--band",), item=3)
add("ssi-skip-negative", SSI + ["--skip", "-1"], names=("--skip",), item=3)
add("ssi-skip-too-long", SSI + ["--skip", "100"], names=("--skip",), item=3)
for v in ("2", "nan", "-0.5"):
    add(f"frf-min-coherence-{v}", FRF + ["--min-coherence", v], names=("--min-coherence",), item=3)
for v in ("-1", "nan", "0"):
    add(f"diagnose-noise-freq-{v}", DIAG + ["--noise-freq-hz", v], names=("--noise-freq-hz",), item=3)
    add(f"diagnose-noise-profile-{v}", DIAG + ["--noise-profile", v], names=("--noise-profile",), item=3)
add("fit-max-steps-0", FIT + ["--max-steps", "0"], names=("--max-steps",), item=3)
add("fit-max-steps-negative", FIT + ["--max-steps", "-5"], names=("--max-steps",), item=3)
add("fit-max-iterations-0", FIT + ["--max-iterations", "0"], names=("--max-iterations",), item=3)
add("sample-max-steps-0", SAMPLE + ["--max-steps", "0"], names=("--max-steps",), item=3)
add("fit-4-params-2-modes", FIT, setup=_modes(FREE_ROWS[:2]), names=("free.modes.csv", "--free", "modes"), item=3)
add("fit-4-params-1-mode", FIT, setup=_modes(FREE_ROWS[:1]), names=("free.modes.csv", "--free", "modes"), item=3)
add("fit-4-params-2-modes-no-prior", FIT + ["--prior", "none"], setup=_modes(FREE_ROWS[:2]),
    names=("free.modes.csv", "--free", "modes"), item=3)
add("fit-4-params-modes-used-1", FIT + ["--modes-used", "1"], names=("--modes-used", "--free", "modes"), item=3)
add("sample-4-params-2-modes", SAMPLE, setup=_modes(FREE_ROWS[:2]), names=("free.modes.csv", "--free", "modes"), item=3)
add("cleat-frozen-encoder", ["cleat", "{d}/frozen.records.npz", "--out", "{d}/field.npz", "--sectors", "32",
                             "--no-baseline"], names=("frozen.records.npz",), item=3)
add("profile-frozen-encoder", ["profile", "{d}/frozen.records.npz", "--out", "{d}/out.profile.csv"],
    names=("frozen.records.npz",), item=3)
# other options of every command
add("roll-speed-nan", ROLL[:4] + ["nan"] + ROLL[5:], names=("--speed",), item=3)
add("roll-load-1e300", ROLL + ["--load", "1e300"], names=("--load",), item=3)
add("roll-rotation-neg", ROLL + ["--rotation-hz", "-3"], names=("--rotation-hz",), item=3)
add("roll-rotation-nan", ROLL + ["--rotation-hz", "nan"], names=("--rotation-hz",), item=3)
add("roll-drum-inf", ROLL + ["--drum", "inf"], names=("--drum",), item=3)
add("roll-speed-1e300", ROLL[:4] + ["1e300"] + ROLL[5:], names=("--speed",), item=3)
add("roll-points-1e9", ROLL + ["--points", "1000000000"], names=("--points",), item=3)
add("fit-rolling-grid-odd", FITROLL + ["--grid", "63"], names=("--grid",), item=3)
add("fit-rolling-free-unknown", FITROLL + ["--free", "k_treed"], names=("k_treed", "--free"), item=3)
# the one angle offset of every profile is gone: the profile block fits each run's offset and gain (issue 31)
add("fit-rolling-free-angle-offset", FITROLL + ["--free", "k_tread,angle_offset"],
    names=("angle_offset", "each run's angle offset and gain"), item=3)
add("fit-default-std-nan", FIT + ["--default-std", "nan"], names=("--default-std",), item=3)
add("fit-modes-used-garbage", FIT + ["--modes-used", "1-x"], names=("--modes-used",), item=3)
add("fit-free-unknown", FIT + ["--free", "ei,stiffness"], names=("stiffness",), item=3)
add("profile-points-0", PROFILE + ["--points", "0"], names=("--points", "points"), item=3)
add("profile-quiet-after-neg", PROFILE + ["--quiet-after", "-1"], names=("--quiet-after",), item=3)
add("cleat-sectors-0", CLEAT[:-1] + ["0"], names=("--sectors", "sectors"), item=3)
add("cleat-time-step-neg", CLEAT + ["--time-step", "-1"], names=("--time-step", "time step"), item=3)
add("cleat-duration-nan", CLEAT + ["--duration", "nan"], names=("--duration",), item=3)
add("cleat-f-max-nan", CLEAT + ["--ssi", "{d}/c.modes.csv", "--f-max", "nan"], names=("--f-max",), item=3)
add("cleat-skip-neg", CLEAT + ["--ssi", "{d}/c.modes.csv", "--skip", "-1"], names=("--skip",), item=3)
add("cleat-channels-0", CLEAT + ["--ssi", "{d}/c.modes.csv", "--channels", "0"], names=("--channels",), item=3)
add("diagnose-effects-unknown", DIAG + ["--effects", "gravty"], names=("gravty", "--effects"), item=3)
add("ssi-orders-garbage", SSI + ["--orders", "10:2"], names=("--orders",), item=3)
add("ssi-workers-0", SSI + ["--workers", "0"], names=("--workers",), item=3)


# --- issue 23 item 3: the crashes, hangs and silent answers found by a new user -------------------------------


def _accelerance_uff(name="acc.uff", inc=0.5, top=100.0, modes=((2, 3.1, 0.02), (3, 5.3, 0.02), (4, 7.7, 0.02))):
    """An accelerance UFF58 (function type 4, 8 radial nodes 45° apart) written by pyuff, with its lines every
    ``inc`` Hz: a band at a few Hz leaves no line within 1 % of a peak (the 26-FRF ``dam0.unv`` case)."""
    def setup(d: Path):
        import pyuff

        nodes = np.arange(1, 9)
        f = np.arange(0, int(top / inc) + 1) * inc
        w = 2 * np.pi * f
        sets = []
        for node in nodes:
            a = np.deg2rad((node - 1) * 45.0)
            h = np.zeros(f.size, complex)
            for n, fn, z in modes:
                wn = 2 * np.pi * fn
                h += np.cos(n * a) * (-(w**2)) / (2.0 * (wn**2 - w**2 + 2j * z * wn * w))
            sets.append(pyuff.prepare_58(
                binary=0, id1="accelerance", id2="", id3="", id4="", id5="", func_type=4, ver_num=0, load_case_id=0,
                rsp_ent_name="tyre", rsp_node=int(node), rsp_dir=3, ref_ent_name="hammer", ref_node=100, ref_dir=3,
                abscissa_spacing=1, abscissa_min=0.0, abscissa_inc=inc, z_axis_value=0.0, abscissa_spec_data_type=18,
                abscissa_len_unit_exp=0, abscissa_force_unit_exp=0, abscissa_temp_unit_exp=0,
                abscissa_axis_units_lab="Hz", ordinate_spec_data_type=12, ordinate_len_unit_exp=0,
                ordinate_force_unit_exp=0, ordinate_temp_unit_exp=0, ordinate_axis_units_lab="m/s^2/N",
                orddenom_spec_data_type=13, orddenom_len_unit_exp=0, orddenom_force_unit_exp=0,
                orddenom_temp_unit_exp=0, orddenom_axis_units_lab="N", z_axis_spec_data_type=0,
                z_axis_len_unit_exp=0, z_axis_force_unit_exp=0, z_axis_temp_unit_exp=0, z_axis_axis_units_lab="",
                data=h, x=f))
        pyuff.UFF(str(d / name)).write_sets(sets, mode="add")
    return setup


ACC_ANGLES = ",".join(f"{k}={(k - 1) * 45}" for k in range(1, 9))


@contextlib.contextmanager
def _patched(obj, name, value):
    old = getattr(obj, name)
    setattr(obj, name, value)
    try:
        yield
    finally:
        setattr(obj, name, old)


def _writes_fail(folder_name: str, err: int):
    """A folder of the fixtures where every new file fails with ``err`` (errno.EROFS: a read-only mount, which
    root does not bypass; errno.ENOSPC: a full disk, where the file is created and its writing fails).

    Simulated (portable, no mount needed): files opened for writing under the folder raise ``OSError(err)``;
    ``os.open`` with O_CREAT (``tempfile.mkstemp``) raises for EROFS only. tests/test_output_failures.py
    does the same on a real read-only bind mount and a real full tmpfs where the machine allows mounts.
    """
    import builtins
    import errno as errno_mod

    def during(d: Path):
        root = (d / folder_name).resolve()
        real_os_open, real_open = os.open, builtins.open

        def inside(path) -> bool:
            try:
                return Path(os.fsdecode(path)).resolve().is_relative_to(root)
            except (TypeError, ValueError):
                return False

        def os_open(path, flags, *a, **k):
            if err == errno_mod.EROFS and flags & os.O_CREAT and inside(path):
                raise OSError(err, os.strerror(err), os.fsdecode(path))
            return real_os_open(path, flags, *a, **k)

        def open_(file, mode="r", *a, **k):
            if isinstance(file, (str, bytes, os.PathLike)) and any(c in mode for c in "wax+") and inside(file):
                raise OSError(err, os.strerror(err), os.fsdecode(file))
            return real_open(file, mode, *a, **k)

        stack = contextlib.ExitStack()
        stack.enter_context(_patched(os, "open", os_open))
        stack.enter_context(_patched(builtins, "open", open_))
        stack.enter_context(_patched(io, "open", open_))
        return stack

    return during


def _ctrl_c_while_sampling(after_calls=20):
    """SIGINT delivered from inside the log-probability, as a Ctrl-C lands while emcee evaluates it."""
    def during(d: Path):
        import ringfit.fit.posterior as posterior

        real = posterior.log_probability_function

        def wrapped(*a, **k):
            log_prob, lo, hi = real(*a, **k)
            calls = [0]

            def lp(u):
                calls[0] += 1
                if calls[0] == after_calls:
                    signal.raise_signal(signal.SIGINT)
                return log_prob(u)

            return lp, lo, hi

        return _patched(posterior, "log_probability_function", wrapped)
    return during


def _ctrl_c_while_compiled_sampling(after_calls=1):
    """SIGINT delivered while the compiled sampler runs a block (it is read when the block returns)."""
    def during(d: Path):
        import ringfit.fit.ensemble as ensemble

        real = ensemble._block
        calls = [0]

        def block(*a, **k):
            calls[0] += 1
            if calls[0] == after_calls:
                signal.raise_signal(signal.SIGINT)
            return real(*a, **k)

        return _patched(ensemble, "_block", block)
    return during


def _refused_after_work(names):
    """Exit 2, the last stderr line the error naming one of ``names``, the other lines ``WARNING:`` lines
    (a command that ran before its output failed may have warned), no traceback, no file written or changed."""
    def check(status, err, out, d):
        lines = error_lines(err)
        return (status == 2 and bool(lines) and any(n in lines[-1] for n in names) and "Traceback" not in err
                and all(line.startswith("WARNING:") for line in lines[:-1]))
    return check


def _interrupted(status, err, out, d):
    lines = error_lines(err)
    return status == 130 and lines == ["ringfit sample: interrupted"] and "Traceback" not in err + out \
        and not (d / "post_out.h5").exists()


def _rolling_case(edit):
    """The fixture case folder with a rolling test table (n = 2…4 rows) whose sidecar ``edit`` breaks."""
    def setup(d: Path):
        cond = {"state": "rolling", "load_n": 4000.0, "speed_kmh": 40.0, "pressure_bar": 2.2, "frame": "fixed"}
        edit(cond)
        text = "n,a,tag,kind,freq_hz,freq_std_hz,damping_pct\n2,,,structural,101.0,,\n3,,,structural,118.0,,\n"
        for folder in (d, d / "case"):
            (folder / "roll40.modes.csv").write_text(text)
            (folder / "roll40.modes.json").write_text(json.dumps(cond))
    return setup


def _drop(key):
    return lambda c: c.pop(key)


def _set(key, value):
    return lambda c: c.__setitem__(key, value)


CAMPBELL = ["campbell", "--tyre", "{d}/tyre.toml", "--speeds", "0:40:20", "--out", "{d}/out.campbell.csv"]
CAMPAIGN = ["campaign", "{d}/camp", "--out", "{d}/camp_out", "--workers", "1"]
BATCH_FIT = ["batch", "fit", "{d}/free.modes.csv", "--out", "{d}/batch_out"]


def _campaign_folder(d: Path):
    (d / "camp").mkdir()
    shutil.copytree(d / "case", d / "camp" / "t1")


def issue23(id, argv, setup=None, names=(), **kw):
    add(id, argv, setup, names, item=3, issue=23, **kw)


# frf on FRFs whose lines are coarser than the band's peaks (dam0.unv --band 0.5:12): argmax of an empty window
issue23("frf-uff-accelerance-lines-coarser-than-peaks",
        ["frf", "{d}/acc.uff", "--out", "{d}/out.modes.csv", "--band", "0.5:12", "--angles", ACC_ANGLES],
        setup=_accelerance_uff(), names=("--band",))
# ssi on pyuff's binary8byte.uff (one scalar channel at 100 Hz, no force): ZeroDivisionError in group_velocity
issue23("ssi-uff-binary8byte-group-velocity",
        ["ssi", "{d}/b.uff", "--out", "{d}/out.modes.csv", "--angles", "1=0", "--axes", "0=radial", "--band", "1:40",
         "--radius", "0.3"], setup=_copy_uff("binary8byte.uff", "b.uff"), names=("b.uff", "--orders", "--band"))
# campbell: a drum of 1e300 m ("matrix contains invalid numeric entries"), speeds that would fill the memory
for v in ("1e300", "0.001", "inf"):
    issue23(f"campbell-drum-{v}", CAMPBELL + ["--drum", v], names=("--drum",))
issue23("roll-drum-0.001", ROLL + ["--drum", "0.001"], names=("--drum",))
for v, tag in (("0:1e9:1", "range-1e9"), ("0:100:1e-9", "step-1e-9"), ("1e300", "value-1e300"),
               ("0:inf:1", "range-inf"), (",".join(["10"] * 401), "list-401"), ("-5,10", "negative")):
    issue23(f"campbell-speeds-{tag}", CAMPBELL[:3] + ["--speeds", v] + CAMPBELL[5:], names=("--speeds",))
issue23("campbell-load-1e300", CAMPBELL + ["--load", "1e300"], names=("--load",))
# example --out under a regular file or an unwritable place
issue23("example-out-under-a-file", ["example", "records", "--out", "{d}/tyre.toml/sub"], names=("--out", "tyre.toml"))
issue23("example-out-read-only", ["example", "records", "--out", "{d}/ro/ex"], setup=_mkdir("ro"),
        during=_writes_fail("ro", errno.EROFS), names=("--out", "ro/ex"))
# batch --scheduler "not a url"; inputs `/` and -x...
for v, tag in (("not a url", "not-a-url"), ("http://h:80", "http"), ("tcp://h:99999", "port"), ("tcp://:8786", "no-host")):
    issue23(f"batch-scheduler-{tag}", BATCH_FIT + ["--scheduler", v], names=("--scheduler",))
issue23("batch-input-root", ["batch", "fit", "/", "--out", "{d}/batch_out"], names=("/:",))
issue23("batch-input-like-an-option", ["batch", "fit", "-x.modes.csv", "--out", "{d}/batch_out"],
        setup=_both(_write("-x.modes.csv", "n,freq_hz\n2,100\n")), names=("-x.modes.csv",))
# any output into a read-only folder: one line, before any work
for cmd, argv, out in (("fit", FIT, "out.toml"), ("campbell", CAMPBELL, "out.campbell.csv"),
                       ("ssi", SSI, "out.modes.csv"), ("sample", SAMPLE, "post_out.h5"),
                       ("diagnose", DIAG, "out.diagnosis.json")):
    issue23(f"{cmd}-out-read-only-folder", _replace_out(argv, "{d}/ro/" + out), setup=_mkdir("ro"),
            during=_writes_fail("ro", errno.EROFS), names=("ro/" + out,))
issue23("campbell-plot-read-only-folder", CAMPBELL + ["--plot", "{d}/ro/c.png"], setup=_mkdir("ro"),
        during=_writes_fail("ro", errno.EROFS), names=("ro/c.png",))
# disk full: sample --force (was h5py tracebacks and a segfault); ssi --plot leaves no mode table behind
issue23("sample-disk-full", _replace_out(SAMPLE, "{d}/full/post_out.h5") + ["--min-steps", "100", "--max-steps", "100",
                                                                          "--force", "--quiet"],
        setup=_mkdir("full"), during=_writes_fail("full", errno.ENOSPC),
        check=_refused_after_work(("post_out.h5",)), unchanged=True, slow=True)
issue23("ssi-plot-disk-full", SSI + ["--plot", "{d}/full/stab.png", "--quiet"], setup=_mkdir("full"),
        during=_writes_fail("full", errno.ENOSPC), check=_refused_after_work(("stab.png",)), unchanged=True, slow=True)
# Ctrl-C in sample: the one-line message only (no emcee traceback), exit 130, nothing written
issue23("sample-ctrl-c", SAMPLE + ["--quiet", "--sampler", "emcee"], during=_ctrl_c_while_sampling(),
        check=_interrupted, unchanged=True, slow=True)
issue23("sample-ctrl-c-compiled", SAMPLE + ["--quiet"], during=_ctrl_c_while_compiled_sampling(), check=_interrupted,
        unchanged=True, slow=True)
# silent: a rolling table whose sidecar has no state, says free with a load, or has load_n 0
for tag, edit, key in (("no-state", _drop("state"), "'state'"), ("free-with-load", _set("state", "free"), "'state'"),
                       ("load-0", _set("load_n", 0), "'load_n'")):
    issue23(f"campbell-modes-sidecar-{tag}", CAMPBELL + ["--modes", "{d}/roll40.modes.csv"], setup=_rolling_case(edit),
            names=(key,))
    issue23(f"diagnose-rolling-sidecar-{tag}", DIAG, setup=_rolling_case(edit), names=(key,))
issue23("diagnose-rolling-sidecar-drum-1e300", DIAG, setup=_rolling_case(_set("drum_diameter_m", 1e300)),
        names=("'drum_diameter_m'",))
issue23("campbell-modes-sidecar-drum-0.001", CAMPBELL + ["--modes", "{d}/roll40.modes.csv"],
        setup=_rolling_case(_set("drum_diameter_m", 0.001)), names=("'drum_diameter_m'",))
# campaign arguments checked before any work
issue23("campaign-min-steps-50", CAMPAIGN + ["--min-steps", "50"], setup=_campaign_folder, names=("--min-steps",))
issue23("campaign-effects-bogus", CAMPAIGN + ["--effects", "bogus"], setup=_campaign_folder, names=("--effects",))
issue23("campaign-walkers-odd", CAMPAIGN + ["--walkers", "9"], setup=_campaign_folder, names=("--walkers",))
issue23("campaign-max-below-min", CAMPAIGN + ["--min-steps", "3000", "--max-steps", "2000"], setup=_campaign_folder,
        names=("--max-steps",))


# issue 23 (second round): degraded records that are answered with a warning and a repair, not a refusal


def _stated_rate(name, fs_hz):
    """``name``: the drum recording's samples with a wrong stated sampling rate."""
    def setup(d: Path):
        from ringfit.io.continuous import write_continuous

        rec = _drum_record()
        rec.fs_hz = float(fs_hz)
        write_continuous(rec, d / name)
    return setup


def _warned(*parts, outputs=(), agree_hz=None):
    """Exit 0, one ``WARNING:`` line holding every one of ``parts``, every output written; with ``agree_hz``,
    the line's "they agree at F Hz" within 1 % of it."""
    def check(status, err, out, d):
        said = [line for line in error_lines(err) if line.startswith("WARNING:") and all(p in line for p in parts)]
        if agree_hz is not None and len(said) == 1:
            m = re.search(r"they agree at ([0-9.eE+]+) Hz", said[0])
            if m is None or abs(float(m.group(1)) / agree_hz - 1) > 0.01:
                return False
        return status == 0 and len(said) == 1 and all((d / o).is_file() for o in outputs)
    return check


def _negated_channel(record, axis):
    """``rec1.records.npz``: single-repeat impact records of a ring (n = 1…6, 16 angles, 3.2 kHz) with one
    channel's sign inverted."""
    def setup(d: Path):
        from dataclasses import replace

        from ringfit.io.records import write_records
        from ringfit.params import table9
        from ringfit.synth.records import impact_records, ring_modes

        geometry, ring = table9()
        rec = impact_records(ring_modes(ring, geometry, n_values=range(1, 7), seed=1), np.arange(16) * 22.5,
                             fs_hz=3200.0, duration_s=0.4, seed=4)
        acc = rec.acc.copy()
        acc[record, axis] *= -1
        write_records(replace(rec, acc=acc), d / "rec1.records.npz")
    return setup


def _warned_and_recorded(*parts):
    """:func:`_warned` for a mode table, and the same finding in its sidecar's ``preprocessing`` list."""
    def check(status, err, out, d):
        if not _warned(*parts, outputs=("out.modes.csv", "out.modes.json"))(status, err, out, d):
            return False
        notes = json.loads((d / "out.modes.json").read_text()).get("preprocessing", [])
        return any(all(p in n for p in parts) for n in notes)
    return check


# a sampling rate that contradicts the cleat trigger's spacing: said with both numbers, the file named
issue23("cleat-sampling-rate-contradicts-the-trigger",
        ["cleat", "{d}/fast.records.npz", "--out", "{d}/field.npz", "--sectors", "32"],
        setup=_stated_rate("fast.records.npz", 2400.0),
        check=_warned("fast.records.npz", "stated sampling rate 2400 Hz", "contradicts the trigger spacing",
                      outputs=("field.npz",), agree_hz=2000.0))
issue23("profile-sampling-rate-contradicts-the-encoder",
        ["profile", "{d}/fast.records.npz", "--out", "{d}/out.profile.csv", "--points", "64"],
        setup=_stated_rate("fast.records.npz", 2400.0),
        check=_warned("fast.records.npz", "stated sampling rate 2400 Hz", "contradicts the encoder",
                      outputs=("out.profile.csv",), agree_hz=2000.0))
# a sign-flipped channel with a single repeat: told by the ring's mode shapes, turned round, said and recorded
for cmd in ("frf", "ssi"):
    issue23(f"{cmd}-single-repeat-sign-flip", [cmd, "{d}/rec1.records.npz", "--out", "{d}/out.modes.csv", "--band",
                                               "20:300"] + (["--orders", "2:40", "--quiet"] if cmd == "ssi" else []),
            setup=_negated_channel(3, 0),
            check=_warned_and_recorded("sign-flipped against the ring's mode shapes", "record 3 (67.5° radial)",
                                       "turned round"))


# issue 34 (readers and modal targets): contradictions the data reveal, timing faults, hostile rig files


def issue34(id, argv, setup=None, names=(), **kw):
    add(id, argv, setup, names, item=4, issue=34, **kw)


def _ring_records(how=None, angles=None, seed=3):
    """``r34.records.npz``: impact records of a ring (n = 1…6, 16 angles, two impacts each, 3.2 kHz, 0.4 s), with
    one :func:`ringfit.synth.records.degrade` fault, or every record at the angles ``angles``."""
    def setup(d: Path):
        from dataclasses import replace

        from ringfit.io.records import write_records
        from ringfit.params import table9
        from ringfit.synth.records import degrade, impact_records, ring_modes

        geometry, ring = table9()
        rec = impact_records(ring_modes(ring, geometry, n_values=range(1, 7), seed=1), np.arange(16) * 22.5,
                             impacts_per_angle=2, fs_hz=3200.0, duration_s=0.4, seed=4)
        if how is not None:
            rec = degrade(rec, how, seed=seed)
        if angles is not None:
            rec = replace(rec, sensor_angle_deg=np.resize(np.asarray(angles, dtype=np.float64), rec.n_records))
        write_records(rec, d / "r34.records.npz")
    return setup


def _truth_n():
    from ringfit.params import table9
    from ringfit.synth.records import ring_modes

    geometry, ring = table9()
    t = ring_modes(ring, geometry, n_values=range(1, 7), seed=1)
    return [(int(n), float(f)) for n, k, f in zip(t.n, t.kind, t.freq_hz) if k == "structural"]


def _mended(*parts, credible=True):
    """Exit 0, the fault said in one WARNING line and in the sidecar's preprocessing, the table's credibility as
    given, and (credible) every true ring mode n = 1…6 one structural row within 0.3 %."""
    def check(status, err, out, d):
        if not _warned_and_recorded(*parts)(status, err, out, d):
            return False
        from ringfit.io.modes import read_mode_table

        table = read_mode_table(d / "out.modes.csv")
        if table.condition.get("credible") is not credible:
            return False
        if not credible:
            return True
        for n, f in _truth_n():
            rows = np.flatnonzero((table.n == n) & (table.kind == "structural"))
            if rows.size != 1 or abs(table.freq_hz[rows[0]] / f - 1) > 0.003:
                return False
        return True
    return check


def _no_empty_reason_nor_twice(status, err, out, d):
    """Exit 0; every row that is not structural has a reason; no two rows within 0.5 % of each other."""
    from ringfit.io.modes import read_mode_table

    if status != 0:
        return False
    table = read_mode_table(d / "out.modes.csv")
    reason = table.extra.get("reason", np.full(len(table), "", dtype=object))
    if any(k != "structural" and not str(r).strip() for k, r in zip(table.kind, reason)):
        return False
    f = np.sort(table.freq_hz)
    return not np.any(np.diff(f) / f[1:] < 0.005)


def _refused_naming(*parts):
    """Exit 2 and one stderr line holding every one of ``parts`` (the case is also marked unchanged)."""
    def check(status, err, out, d):
        lines = error_lines(err)
        return status == 2 and len(lines) == 1 and all(p in lines[0] for p in parts)
    return check


def _ring_records_loud_hum(level=2.0, seed=9):
    """``r34.records.npz`` (the :func:`_ring_records` fixture, 0.4 s at 3.2 kHz) with 60 Hz hum and its 2nd and 3rd
    harmonics ``level`` × the records' rms, amplitude (0.5…1.5×) and phase drawn per channel (issue 34 item 7:
    the hum of such short records was never found; at this level the n = 6 mode, 1.5 % from the cavity, read
    n = 1 and was called acoustic)."""
    def setup(d: Path):
        from dataclasses import replace

        from ringfit.io.records import read_records, write_records

        _ring_records()(d)
        rec = read_records(d / "r34.records.npz")
        rng = np.random.default_rng(seed)
        r, a, s = rec.acc.shape
        t = np.arange(s) / rec.fs_hz
        rms = float(np.sqrt(np.mean(rec.acc**2)))
        acc = rec.acc.copy()
        for h, amp in ((1, 1.0), (2, rng.uniform(0.2, 0.6)), (3, rng.uniform(0.1, 0.4))):
            phase = rng.uniform(0, 2 * np.pi, (r, a))
            size = level * amp * rms * np.sqrt(2) * rng.uniform(0.5, 1.5, (r, a))
            acc += size[..., None] * np.cos(2 * np.pi * h * 60.0 * t + phase[..., None])
        write_records(replace(rec, acc=acc), d / "r34.records.npz", overwrite=True)
    return setup


def _loud_hum_mended(status, err, out, d):
    """The hum said; every true ring mode one structural row within 0.3 % except n = 2, which sits 0.13 % from
    the notched 120 Hz line (a row there is unclassified, naming the line), and n = 6, which may be one row
    unclassified as damped like the ring (its shape read n = 1 through what the notch left); one acoustic row,
    the cavity."""
    from ringfit.io.modes import read_mode_table

    if not _warned_and_recorded("mains hum (lines at 60, 120, 180 Hz")(status, err, out, d):
        return False
    table = read_mode_table(d / "out.modes.csv")
    if table.condition.get("credible") is not True or not _no_empty_reason_nor_twice(status, err, out, d):
        return False
    for n, f in _truth_n():
        rows = np.flatnonzero((table.n == n) & (table.kind == "structural"))
        if n == 2:
            near = np.flatnonzero(np.abs(table.freq_hz / f - 1) < 0.003)
            if rows.size or near.size != 1 or "mains line at 120" not in str(table.extra["reason"][near[0]]):
                return False
        elif n == 6 and not rows.size:
            near = np.flatnonzero(np.abs(table.freq_hz / f - 1) < 0.003)
            if near.size != 1 or "damped like the ring" not in str(table.extra["reason"][near[0]]):
                return False
        elif rows.size != 1 or abs(table.freq_hz[rows[0]] / f - 1) > 0.003:
            return False
    cavity = table.freq_hz[table.kind == "acoustic"]
    return cavity.size == 1 and abs(cavity[0] / 218.75 - 1) < 0.003


R34 = ["{d}/r34.records.npz", "--out", "{d}/out.modes.csv", "--band", "20:300"]
for cmd in ("ssi", "frf"):
    extra = ["--orders", "2:40", "--quiet"] if cmd == "ssi" else []
    # a stream that stalls (10 % of the samples repeated, inserted: every later sample late) or holds its value
    issue34(f"{cmd}-stalled-stream", [cmd, *R34, *extra], setup=_ring_records("stalled"),
            check=_mended("stalled stream", "repeats deleted"), slow=cmd == "ssi")
    issue34(f"{cmd}-held-stream", [cmd, *R34, *extra], setup=_ring_records("held"),
            check=_mended("stalled stream", "bridged"), slow=cmd == "ssi")
    # DC drift (a ramp on every channel): removed, not taken for noise
    issue34(f"{cmd}-dc-drift", [cmd, *R34, *extra], setup=_ring_records("drift"), check=_mended("drift in"),
            slow=cmd == "ssi")
    # 60 Hz mains hum: no row without a reason unless structural, no mode twice
    issue34(f"{cmd}-hum60-no-mode-twice", [cmd, *R34, *extra], setup=_ring_records("hum60"),
            check=_no_empty_reason_nor_twice, slow=cmd == "ssi")
    # 60 Hz hum 2× the signal in short records (0.4 s): found and notched; n = 6 (read n = 1 by what the hum
    # left) never called acoustic, the cavity the one acoustic row
    if cmd == "ssi":
        issue34("ssi-loud-hum60-short-records-n6-not-acoustic", [cmd, *R34, *extra], setup=_ring_records_loud_hum(),
                check=_loud_hum_mended, slow=True)
    # every record at one sensor angle: n cannot be told; the angle named, not the model orders
    issue34(f"{cmd}-one-sensor-angle", [cmd, *R34], setup=_ring_records(angles=[30.0]),
            check=_refused_naming("r34.records.npz", "one sensor angle 30°", "cannot be told"), unchanged=True)
    issue34(f"{cmd}-one-sensor-angle-mod-360", [cmd, *R34], setup=_ring_records(angles=[30.0, 390.0, -330.0]),
            check=_refused_naming("one sensor angle", "cannot be told"), unchanged=True)
    issue34(f"{cmd}-two-sensor-angles", [cmd, *R34], setup=_ring_records(angles=[0.0, 90.0]),
            check=_refused_naming("two sensor angles, 0° and 90°", "cannot be told"), unchanged=True)


def _rig_copy(fmt, *, angle=None, edit=None):
    """``rec34.<fmt>``: the fixture records as a rig file (``tdms``, ``mat`` or ``csv`` with ``rec34.toml``), every
    record at ``angle`` when given; ``edit(bytes) -> bytes`` changes the file (or, for csv, the map's text)."""
    def setup(d: Path):
        from dataclasses import replace

        from ringfit.io.channel_map import write_channel_map
        from ringfit.io.csv_records import write_csv_records
        from ringfit.io.records import read_records, write_records

        rec = read_records(d / "rec.records.npz")
        if angle is not None:
            rec = replace(rec, sensor_angle_deg=np.full(rec.n_records, float(angle)))
        if fmt == "csv":
            _, cmap = write_csv_records(rec, d / "rec34.csv")
            write_channel_map(cmap, d / "rec34.toml")
            if edit is not None:
                (d / "rec34.toml").write_text(edit((d / "rec34.toml").read_text()))
            return
        write_records(rec, d / f"rec34.{fmt}")
        if edit is not None:
            (d / f"rec34.{fmt}").write_bytes(edit((d / f"rec34.{fmt}").read_bytes()))
    return setup


def _append_mat_scalar(name, value):
    """A MATLAB v5 file with one more variable appended as a second save would (a concatenated file)."""
    def edit(data: bytes) -> bytes:
        import scipy.io

        buf = io.BytesIO()
        scipy.io.savemat(buf, {name: np.float64(value)}, format="5")
        return data + buf.getvalue()[128:]  # without the second file's 128-byte header
    return edit


RIG34 = ["--out", "{d}/out.modes.csv"]
# a v5 file holding fs_hz twice (6400 then 6000 in the issue; the fixture's 2560 then 2400 here)
for cmd in ("ssi", "frf"):
    issue34(f"{cmd}-mat-fs-stored-twice", [cmd, "{d}/rec34.mat", *RIG34],
            setup=_rig_copy("mat", edit=_append_mat_scalar("fs_hz", 2400.0)),
            check=_refused_naming("rec34.mat", "'fs_hz'", "2560", "2400"), unchanged=True)
    # every TDMS group at one angle; a channel map giving every channel the same angle
    issue34(f"{cmd}-tdms-one-sensor-angle", [cmd, "{d}/rec34.tdms", *RIG34], setup=_rig_copy("tdms", angle=45.0),
            check=_refused_naming("rec34.tdms", "one sensor angle 45°"), unchanged=True)
    issue34(f"{cmd}-channel-map-one-angle", [cmd, "{d}/rec34.csv", "--channels", "{d}/rec34.toml", *RIG34],
            setup=_rig_copy("csv", angle=90.0), check=_refused_naming("rec34.csv", "one sensor angle 90°"),
            unchanged=True)
# a channel map angle of 1e300 (was LinAlgError in targets/shapes.py), a sensitivity of 1e-300
issue34("ssi-channel-map-angle-1e300", ["ssi", "{d}/rec34.csv", "--channels", "{d}/rec34.toml", *RIG34],
        setup=_rig_copy("csv", edit=lambda t: t.replace("angle_deg = 0.0", "angle_deg = 1e300", 1)),
        check=_refused_naming("rec34.toml", "r000_radial", "angle_deg"), unchanged=True)
issue34("frf-channel-map-sensitivity-1e-300", ["frf", "{d}/rec34.csv", "--channels", "{d}/rec34.toml", *RIG34],
        setup=_rig_copy("csv", edit=lambda t: t.replace('unit = "m/s^2"', 'unit = "m/s^2"\nsensitivity = 1e-300', 1)),
        check=_refused_naming("rec34.toml", "sensitivity"), unchanged=True)
issue34("ssi-npz-angle-1e300", SSI, setup=_npz("rec.records.npz", sensor_angle_deg=np.array([1e300] + [45.0] * 7)),
        check=_refused_naming("rec.records.npz", "sensor_angle_deg"), unchanged=True)
# a TDMS file cut to 100 bytes: truncated, not "no numeric channels"; a CSV with a header and no rows
issue34("ssi-tdms-cut-to-100-bytes", ["ssi", "{d}/rec34.tdms", *RIG34], setup=_rig_copy("tdms", edit=lambda b: b[:100]),
        check=_refused_naming("rec34.tdms", "truncated"), unchanged=True)
issue34("ssi-csv-header-no-rows", ["ssi", "{d}/h.csv", *RIG34], setup=_write("h.csv", "time [s],radial [g]\n"),
        check=_refused_naming("h.csv", "no data rows"), unchanged=True)


def _drop_rows(every):
    """``rec34.csv`` with every ``every``-th data row left out (a logger that drops samples; the time column says)."""
    def setup(d: Path):
        _rig_copy("csv")(d)
        lines = (d / "rec34.csv").read_text().splitlines()
        (d / "rec34.csv").write_text("\n".join(x for i, x in enumerate(lines) if i < 2 or i % every) + "\n")
    return setup


# dropped samples (the time column jumps): filled on the time grid, said and recorded
issue34("frf-csv-dropped-rows", ["frf", "{d}/rec34.csv", "--channels", "{d}/rec34.toml", *RIG34], setup=_drop_rows(97),
        check=_warned_and_recorded("dropped samples", "filled by straight lines"))


def _mat73_leaving(how):
    """``ext.mat``: a MATLAB v7.3 file of the fixture records whose ``acc`` leaves the file (``how``: an external
    link, a soft link to an external link, a dangling soft link, external raw storage, a virtual dataset) pointing
    at ``secret.h5`` / ``secret.bin`` beside it."""
    def setup(d: Path):
        import h5py

        base = _impact_records()
        acc = np.asarray(base["acc"], dtype=np.float64).T.copy()  # MATLAB's column-major order on disk
        with h5py.File(d / "secret.h5", "w") as s:
            s["data"] = acc
        acc.tofile(d / "secret.bin")
        with h5py.File(d / "ext.mat", "w", userblock_size=512) as f:
            for key in ("sensor_angle_deg", "fs_hz", "force"):
                a = np.asarray(base[key], dtype=np.float64)
                a = a.reshape(1, -1) if a.ndim == 1 else (a.reshape(1, 1) if a.ndim == 0 else a)
                f.create_dataset(key, data=a.T).attrs["MATLAB_class"] = np.bytes_("double")
            codes = np.array([[ord(c) for c in s.ljust(10)] for s in ("radial", "tangential")], dtype=np.uint16)
            f.create_dataset("axes", data=codes.T).attrs["MATLAB_class"] = np.bytes_("char")
            if how == "external-link":
                f["acc"] = h5py.ExternalLink("secret.h5", "/data")
            elif how == "soft-link-to-external":
                f["acc"] = h5py.SoftLink("/zz")
                f["zz"] = h5py.ExternalLink("secret.h5", "/data")
            elif how == "dangling-soft-link":
                f["acc"] = h5py.SoftLink("/nowhere")
            elif how == "external-storage":
                ds = f.create_dataset("acc", shape=acc.shape, dtype="<f8", external=[("secret.bin", 0, acc.nbytes)])
                ds.attrs["MATLAB_class"] = np.bytes_("double")
            elif how == "virtual":
                layout = h5py.VirtualLayout(shape=acc.shape, dtype="<f8")
                layout[...] = h5py.VirtualSource("secret.h5", "data", shape=acc.shape)
                f.create_virtual_dataset("acc", layout).attrs["MATLAB_class"] = np.bytes_("double")
        with open(d / "ext.mat", "r+b") as fh:
            fh.write(b"MATLAB 7.3 MAT-file, HDF5 schema 1.00 .".ljust(116) + b"\x00" * 8 + b"\x00\x02IM")
    return setup


for how in ("external-link", "soft-link-to-external", "dangling-soft-link", "external-storage", "virtual"):
    issue34(f"ssi-mat73-{how}", ["ssi", "{d}/ext.mat", *RIG34], setup=_mat73_leaving(how),
            check=_refused_naming("ext.mat", "acc", "refusing"), unchanged=True)


# ----------------------------------------------------------------------------- issue 34: stated conditions


def issue34_stated(id, argv, setup=None, names=(), **kw):
    add(id, argv, setup, names, item=kw.pop("item", 1), issue=34, **kw)


def _case_profile(name="run1", source="run1", **edits):
    """The fixture case folder with a copy of the fixture profile ``source`` as ``name``, its sidecar edited."""
    def setup(d: Path):
        cond = dict(PROFILE_SIDECAR, **edits)
        shutil.copy(d / f"{source}.profile.csv", d / "case" / f"{name}.profile.csv")
        (d / "case" / f"{name}.profile.json").write_text(json.dumps(cond))
    return setup


def _no_ring(d: Path):
    (d / "noring.toml").write_text("[tyre]\nradius_m = 0.296\nwidth_m = 0.152\npressure_bar = 2.2\n")


def _json_strict(path):
    def ok(d):
        try:
            json.loads((d / path).read_text(), parse_constant=lambda c: (_ for _ in ()).throw(ValueError(c)))
        except (OSError, ValueError):
            return False
        return True
    return ok


def _identified(*parts, report="id.identify.json"):
    """Exit 0, a strict-JSON report, and every one of ``parts`` on stdout or stderr."""
    def check(status, err, out, d):
        return status == 0 and _json_strict(report)(d) and all(p in out + err for p in parts)
    return check


def _warned_status0(*parts):
    def check(status, err, out, d):
        return status == 0 and any(line.startswith("WARNING:") and all(p in line for p in parts)
                                   for line in error_lines(err))
    return check


IDENTIFY = ["identify", "{d}/case", "--out", "{d}/id.tyre.toml", "--quiet"]
# a profile whose rotation_hz contradicts its speed_kmh and whose readings (noise: no contact patch) cannot tell
NO_PATCH = dict(source="noise", speed_kmh=80.0, rotation_hz=30.0)
issue34_stated("identify-rotation-contradicts-speed-no-patch", IDENTIFY, setup=_case_profile("noise", **NO_PATCH),
        names=("rotation_hz = 30",))
issue34_stated("diagnose-rotation-contradicts-speed-no-patch", DIAG, setup=_case_profile("noise", **NO_PATCH),
        names=("rotation_hz = 30",))
# a rolling table whose rotation_hz contradicts its speed_kmh (no data can tell which): refused where it is read
issue34_stated("diagnose-rolling-table-rotation-contradicts-speed", DIAG, setup=_rolling_case(_set("rotation_hz", 12.0)),
        names=("rotation_hz = 12",))
issue34_stated("campbell-table-rotation-contradicts-speed", CAMPBELL + ["--modes", "{d}/roll40.modes.csv"],
        setup=_rolling_case(_set("rotation_hz", 12.0)), names=("rotation_hz = 12",))
issue34_stated("roll-rotation-contradicts-speed", ROLL + ["--rotation-hz", "12"], names=("--rotation-hz",))
# a profile at another pressure than the tyre file's
issue34_stated("identify-profile-at-another-pressure", IDENTIFY, setup=_case_profile(pressure_bar=3.5),
        names=("pressure_bar = 3.5",), item=2)
issue34_stated("fit-rolling-profile-at-another-pressure", FITROLL, setup=_write("run1.profile.json", json.dumps(
    dict(PROFILE_SIDECAR, pressure_bar=3.5))), names=("pressure_bar = 3.5",), item=2)
# the same readings under two stated conditions (a copy whose sidecar says another load)
issue34_stated("identify-same-profile-two-loads", IDENTIFY,
        setup=_both(_case_profile(), _case_profile("copy", load_n=5000.0)), names=("copy.profile.csv",), item=2)
issue34_stated("diagnose-same-profile-two-loads", DIAG,
        setup=_both(_case_profile(), _case_profile("copy", load_n=5000.0)), names=("copy.profile.csv",), item=2)
# a tyre file without [ring]: roll, fit-rolling and campbell refuse it as estimate does
for cmd, argv in (("roll", ROLL), ("fit-rolling", FITROLL), ("campbell", CAMPBELL)):
    issue34_stated(f"{cmd}-tyre-without-ring", [("{d}/noring.toml" if a == "{d}/tyre.toml" else a) for a in argv],
            setup=_no_ring, names=("[ring]",), item=8)
# estimate given a mode table: says it expects a profile or a recording
issue34_stated("estimate-given-a-mode-table", ["estimate", "{d}/free.modes.csv", "--tyre", "{d}/tyre.toml", "--out",
                                        "{d}/out.estimate.json"], names=("is a mode table",), item=11)
# --dashboard that is not an address: one line, before any cluster starts
issue34_stated("batch-dashboard-not-an-address", BATCH_FIT + ["--dashboard", "not an address", "--", "--tyre",
                                                       "{d}/tyre.toml"], names=("--dashboard",), item=10)
# documented: a free table alone (the bundled free-ssi table), and a 1-row table, identify with flags, strict JSON
issue34_stated("identify-free-table-only", IDENTIFY, check=_identified("EI is barely pinned"), item=9)
issue34_stated("identify-one-row-free-table", IDENTIFY,
        setup=_write("case/free.modes.csv", "n,a,tag,kind,freq_hz,freq_std_hz,damping_pct\n1,0,,structural,107.0,,12.46\n"),
        check=_identified("barely identified", "to the plausible bound"), item=9)
# documented: a profile whose rotation_hz contradicts its speed_kmh, told by its own contact patch: warned, and read
# at the speed's rotation
issue34_stated("fit-rolling-rotation-contradicts-speed-patch-tells", FITROLL + ["--grid", "128", "--free", "k_tread"],
        setup=_write("run1.profile.json", json.dumps(dict(PROFILE_SIDECAR, rotation_hz=12.0))),
        check=lambda status, err, out, d: status in (0, 1) and _warned_status0("rotation_hz = 12", "as speed_kmh says")(
            0, err, out, d), slow=True)
# documented: --dashboard on every interface is said; frf takes --quiet; cleat's old --channels N still works
issue34_stated("batch-dashboard-every-interface", BATCH_FIT + ["--dashboard", "0.0.0.0:8799", "--dry-run", "--", "--tyre",
                                                        "{d}/tyre.toml"],
        check=_warned_status0("every network interface"), item=10)
issue34_stated("frf-quiet", FRF + ["--quiet"], check=lambda status, err, out, d: status == 0, item=11)
issue34_stated("cleat-old-channels-count", CLEAT + ["--ssi", "{d}/c.modes.csv", "--channels", "8"],
        check=_warned_status0("--ssi-channels 8"), item=11, slow=True)


# ----------------------------------------------------------------------------- documented behaviour


def _fit_rolling_noise_check(status, err, out, d):
    """Pure noise: not "converged" with an absurd angle offset; exit 1 (no fit) or bounded offsets (each run's)."""
    if status == 1:
        return not (d / "out.toml").exists()
    if status != 0:
        return False
    m = re.search(r"angle offset ([-+0-9.eE]+)", out)
    return m is None or abs(float(m.group(1))) <= 180.0


add("fit-rolling-pure-noise", ["fit-rolling", "{d}/noise.profile.csv", "--tyre", "{d}/tyre.toml",
                               "--out", "{d}/out.toml", "--free", "k_tread", "--grid", "128"],
    check=_fit_rolling_noise_check, slow=True, item=3)



# ----------------------------------------------------------------------------- running one case


def snapshot(folder: Path) -> dict:
    """Path -> (kind, content hash) of everything under ``folder``, symlinks not followed."""
    out = {}
    for root, dirs, files in os.walk(folder, followlinks=False):
        for name in dirs + files:
            p = Path(root) / name
            rel = str(p.relative_to(folder))
            if p.is_symlink():
                out[rel] = ("link", os.readlink(p))
            elif p.is_dir():
                out[rel] = ("dir", None)
            else:
                out[rel] = ("file", hashlib.sha256(p.read_bytes()).hexdigest())
    return out


_PROGRESS = re.compile(r"\d+%\||\|\s*\d+(\.\d+)?[kM]?/\d+|it/s|s/it")


def error_lines(err: str) -> list[str]:
    """The stderr lines a user reads: progress-bar redraws (after '\\r', tqdm bars) left out."""
    lines = []
    for raw in err.split("\n"):
        line = raw.split("\r")[-1].strip()
        if line and not _PROGRESS.search(line):
            lines.append(line)
    return lines


@dataclass
class Outcome:
    ok: bool
    status: object
    why: str = ""
    err: str = ""
    extra: dict = field(default_factory=dict)


class CaseTimeout(Exception):
    """A case ran longer than its time limit (a hang, for a bad input)."""


def _alarm(signum, frame):
    raise CaseTimeout()


def replay(case: Case, folder: Path, *, timeout_s: float | None = None) -> Outcome:
    """Run ``case`` in ``folder`` (already holding the fixtures) and judge the answer.

    ``timeout_s`` (POSIX main thread only): a case still running after this
    long counts as a failure (a bad input that hangs the command).
    """
    from ringfit.cli import main

    if case.setup is not None:
        case.setup(folder)
    before = snapshot(folder)
    out_buf, err_buf = io.StringIO(), io.StringIO()
    status = None
    old = signal.signal(signal.SIGALRM, _alarm) if timeout_s else None
    during = case.during(folder) if case.during is not None else contextlib.nullcontext()
    with contextlib.redirect_stdout(out_buf), contextlib.redirect_stderr(err_buf):
        try:
            if timeout_s:
                signal.setitimer(signal.ITIMER_REAL, timeout_s)
            with during:
                status = main(case.args(folder))
        except SystemExit as exc:  # argparse
            status = exc.code
        except CaseTimeout:
            return Outcome(False, "timeout", f"still running after {timeout_s:g} s", err_buf.getvalue()[-2000:])
        except BaseException as exc:  # noqa: BLE001 - a traceback is exactly what we look for
            tb = traceback.format_exception(exc)
            return Outcome(False, "traceback", f"{exc.__class__.__name__}: {str(exc)[:200]}", "".join(tb)[-2000:])
        finally:
            if timeout_s:
                signal.setitimer(signal.ITIMER_REAL, 0)
                signal.signal(signal.SIGALRM, old)
    err = err_buf.getvalue()
    after = snapshot(folder)
    if case.check is not None:
        ok = bool(case.check(status, err, out_buf.getvalue(), folder))
        if ok and case.unchanged and after != before:
            changed = sorted(k for k in set(before) | set(after) if before.get(k) != after.get(k))
            return Outcome(False, status, f"files written or changed: {changed}", err)
        return Outcome(ok, status, "" if ok else "documented behaviour not met", err)
    lines = error_lines(err)
    if status != 2:
        return Outcome(False, status, f"exit {status}, expected 2", err)
    if len(lines) != 1:
        return Outcome(False, status, f"{len(lines)} stderr lines, expected 1", err)
    if case.names and not any(n in lines[0] for n in case.names):
        return Outcome(False, status, f"error line names none of {case.names}", err)
    if after != before:
        changed = sorted(k for k in set(before) | set(after) if before.get(k) != after.get(k))
        return Outcome(False, status, f"files written or changed: {changed}", err)
    return Outcome(True, status, "", err)


def run_all(cases=None, *, workdir: Path, fixtures: Path | None = None, verbose=False,
            timeout_s: float | None = None) -> list[tuple[Case, Outcome]]:
    """Replay ``cases`` (default all), each in a fresh copy of the fixtures under ``workdir``."""
    fixtures = fixtures or build_fixtures(workdir / "_fixtures")
    results = []
    for i, case in enumerate(cases or CASES):
        d = workdir / f"c{i:03d}"
        shutil.copytree(fixtures, d, symlinks=True)
        cwd = os.getcwd()
        os.chdir(d)
        try:
            outcome = replay(case, d, timeout_s=timeout_s)
        finally:
            os.chdir(cwd)
        results.append((case, outcome))
        if verbose:
            print(f"{'ok ' if outcome.ok else 'BAD'} {case.id:<45} {outcome.status!s:<9} {outcome.why}", flush=True)
        shutil.rmtree(d, ignore_errors=True)
    return results


# --- issue 33: a dead channel of a continuous recording ------------------------------------------------------------
def _dead_channel(axis: int, noise: float = 0.0):
    """cont.records.npz with channel ``axis`` (0 radial, 1 tangential) dead: zero, or ADC noise of ``noise`` m/s²."""
    def setup(d: Path):
        with np.load(d / "cont.records.npz", allow_pickle=False) as z:
            arrays = {k: z[k] for k in z.files}
        acc = arrays["acc"].copy()
        acc[..., axis, :] = noise * np.random.default_rng(5).standard_normal(acc.shape[-1])
        arrays["acc"] = acc
        with open(d / "cont.records.npz", "wb") as fh:
            np.savez(fh, **arrays)
    return setup


ESTIMATE = ["estimate", "{d}/cont.records.npz", "--tyre", "{d}/tyre.toml", "--out", "{d}/out.estimate.json"]
for noise in (0.0, 0.05):
    add(f"estimate-dead-radial-{noise:g}", ESTIMATE, setup=_dead_channel(0, noise),
        names=("radial channel is dead",), issue=33)
    add(f"estimate-state-dead-tangential-{noise:g}", ESTIMATE + ["--state"], setup=_dead_channel(1, noise),
        names=("tangential channel is dead",), issue=33)


def _dead_tangential_profile(noise: float):
    """run1.profile.csv with its tangential column dead: zeros, or noise of ``noise`` m/s² (the sidecar as it was)."""
    def setup(d: Path):
        rows = (d / "run1.profile.csv").read_text().splitlines()
        rng = np.random.default_rng(6)
        out = [rows[0]] + [f"{line.rsplit(',', 1)[0]},{float(noise * rng.standard_normal())!r}" for line in rows[1:]]
        (d / "run1.profile.csv").write_text("\n".join(out) + "\n")
    return setup


# the averaged profile's tangential channel, read by the state: the recording's rule (one line, exit 2)
for noise in (0.0, 0.05):
    add(f"estimate-state-profile-dead-tangential-{noise:g}",
        ["estimate", "{d}/run1.profile.csv", "--tyre", "{d}/tyre.toml", "--out", "{d}/out.estimate.json", "--state"],
        setup=_dead_tangential_profile(noise), names=("tangential channel is dead",), issue=33)
