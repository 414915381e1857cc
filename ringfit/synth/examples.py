"""Example inputs with a known truth, for ``ringfit example {records,case,cleat,profiles,rolling} --out DIR``.

Each kind writes files in the formats of docs/formats.md from the generators
of :mod:`ringfit.synth`, and a ``README.md`` that states the truth behind
them (the modes, parameters or effect that were put in) and the one-line
commands that read them, so that every command of the README can be tried
at once and its answer checked against the truth:

- ``records`` — roving-sensor hammer records (``impact.records.npz`` and the
  same as UFF58 ``impact.uff``) of a ring with known modes, and a starting
  ``tyre.toml``: ``ssi``, ``frf``, ``fit``, ``sample``, ``report``;
- ``profiles`` — rolling profiles at two drum speeds from a ring with a known
  tread stiffness, and the tyre file fitted to its free modes: ``fit-rolling``, ``roll``;
- ``cleat`` — a continuous drum recording with a cleat (encoder, hall
  pulses), with the modes of the rolling, loaded tyre it excites (docs/physics.md §3.7) and the true
  ``true.tyre.toml`` to label them with: ``profile``, ``cleat`` (``--ssi --tyre``);
- ``case`` — a case folder (docs/formats.md §6) with one injected effect: ``diagnose``;
- ``rolling`` — a case folder with rolling mode tables (20/40/60 km/h, 4 kN, co-rotating sensor):
  ``diagnose`` (rotation + ground_contact), ``campbell``;
- ``state`` — continuous recordings of the independent simulator (:mod:`ringfit.synth.state`) at known
  states (``calibration/``) and hidden ones (``blind/``), a nominal ``tyre.toml`` and the truth per
  revolution (``truth/``): ``estimate``.

Files are generated in a temporary folder inside ``DIR`` and moved into
place only when all are ready; an existing file is replaced only with
``overwrite`` (``--force``), and never left half-written.
"""

from __future__ import annotations

import math
import os
import shutil
import tempfile
from pathlib import Path

import numpy as np

from ringfit.errors import InputError

KINDS = ("records", "case", "cleat", "profiles", "rolling", "identify", "state")
#: Rig formats ``records`` can also be written in (docs/formats.md §17).
RIG_FORMATS = ("tdms", "mat", "csv")


def write_example(kind: str, folder: str | os.PathLike, *, overwrite: bool = False, progress: bool = False,
                  fmt: str | None = None, effect: str | None = None, seed: int = 0, blind: int = 6,
                  seconds: float = 4.0) -> list[Path]:
    """Write the example ``kind`` into ``folder`` (created if missing); returns the paths written.

    ``fmt`` (``records`` only): also write the records as ``"tdms"``, ``"mat"``
    or ``"csv"`` (+ channel map), docs/formats.md §17.
    ``effect`` (``case`` only): the effect hidden in the case folder (one of
    :data:`ringfit.synth.cases.MODAL_INJECTIONS` or ``EXTRA_INJECTIONS``: mode tables; or a profile-only
    effect of ``PROFILE_INJECTIONS`` such as ``tread_shear``: rolling profiles; default ``ground_contact``).
    ``seed``, ``blind``, ``seconds`` (``state`` only): :func:`ringfit.synth.state.write_state_example`.

    **Raises** :class:`InputError` for an unknown kind, format or effect, a format or effect for
    another kind, a ``folder`` that is a file, or files that exist there already (unless ``overwrite``).
    """
    from ringfit.io.files import check_output_path
    from ringfit.synth.cases import EXTRA_INJECTIONS, MODAL_INJECTIONS, PROFILE_INJECTIONS

    if kind not in KINDS:
        raise InputError(f"unknown example {kind!r}; expected one of {', '.join(KINDS)}")
    if fmt is not None and (kind != "records" or fmt not in RIG_FORMATS):
        raise InputError(f"format {fmt!r} for example {kind!r}; expected one of {', '.join(RIG_FORMATS)} "
                         "with the records example")
    if effect is not None and kind != "case":
        raise InputError(f"--effect is for the 'case' example only, not {kind!r}", source="--effect")
    known = MODAL_INJECTIONS + EXTRA_INJECTIONS + tuple(e for e in PROFILE_INJECTIONS if e not in MODAL_INJECTIONS)
    if effect is not None and effect not in known:
        raise InputError(f"unknown effect {effect!r}; expected one of {', '.join(known)}", source="--effect")
    if kind == "state":
        if not (isinstance(blind, int) and 0 <= blind <= 200):
            raise InputError(f"--blind {blind}: expected a whole number of recordings in 0 … 200", source="--blind")
        if not (math.isfinite(seconds) and 0.5 <= seconds <= 120.0):
            raise InputError(f"--seconds {seconds}: expected a recording length in 0.5 … 120 s", source="--seconds")
        if not 0 <= seed < 2**32:
            raise InputError(f"--seed {seed}: expected 0 … 2³² − 1", source="--seed")
    folder = Path(folder)
    if folder.exists() and not folder.is_dir():
        raise InputError("exists and is not a folder; --out names the folder the example is written into",
                         source=folder)
    created = _make_folder(folder)
    try:
        tmp = Path(tempfile.mkdtemp(prefix=".ringfit-example-", dir=folder))
    except OSError as exc:
        _remove_created(created)
        raise InputError(f"--out: cannot write into this folder ({exc.strerror or exc.__class__.__name__})",
                         source=folder) from None
    done = False
    try:
        if kind == "records":
            _records(tmp, progress, fmt)
        elif kind == "case":
            _case(tmp, progress, effect or "ground_contact")
        elif kind == "state":
            from ringfit.synth.state import write_state_example

            write_state_example(tmp, seed=seed, blind=blind, seconds=seconds, progress=progress)
        else:
            {"cleat": _cleat, "profiles": _profiles, "rolling": _rolling, "identify": _identify}[kind](tmp, progress)
        made = sorted(p.relative_to(tmp) for p in tmp.rglob("*") if p.is_file())
        for rel in made:  # every destination checked before anything is moved
            dst = folder / rel
            parent = dst.parent
            while parent != folder and not parent.exists():
                parent = parent.parent
            if not parent.is_dir():
                raise InputError("is a file where the example needs a folder", source=parent)
            if dst.parent.is_dir():
                check_output_path(dst, overwrite=overwrite)
        for rel in made:
            (folder / rel).parent.mkdir(parents=True, exist_ok=True)
            os.replace(tmp / rel, folder / rel)
        done = True
    except OSError as exc:  # a disk that fills up while the example is generated
        raise InputError(f"--out: the example could not be written ({exc.strerror or exc.__class__.__name__}); "
                         "nothing was written", source=folder) from None
    finally:
        shutil.rmtree(tmp, ignore_errors=True)
        if not done:
            _remove_created(created)
    return [folder / rel for rel in made]


def _make_folder(folder: Path) -> list[Path]:
    """``mkdir -p folder``; returns the folders it created (outermost first). :class:`InputError` naming
    ``--out`` when a file stands in the way or the place takes no folder."""
    missing = []
    p = folder
    while not p.exists():
        if os.path.lexists(p):
            raise InputError("--out: is a dangling symbolic link; expected a folder", source=p)
        missing.append(p)
        p = p.parent
    if not p.is_dir():
        raise InputError(f"--out: {p} is a file, not a folder; the example needs a folder there", source=folder)
    created = []
    for q in reversed(missing):
        try:
            q.mkdir()
        except OSError as exc:
            _remove_created(created)
            raise InputError(f"--out: cannot create the folder ({exc.strerror or exc.__class__.__name__})",
                             source=folder) from None
        created.append(q)
    return created


def _remove_created(created: list[Path]) -> None:
    for q in reversed(created):
        try:
            q.rmdir()
        except OSError:
            pass


# ----------------------------------------------------------------------------- the kinds


def _true_ring():
    """Table 9 with every stiffness moved: the truth the fits should find (not the file's starting values)."""
    from ringfit.params import table9

    geometry, ring = table9()
    return geometry, ring.replace(rho_a=2.60, ei=0.60, kw=1.40e6, kv=1.08e6, k_tread=15.0e6)


def _starting_tyre(folder: Path, name="tyre.toml", ring=None):
    from ringfit.io.tyre import Tyre, write_tyre
    from ringfit.params import table9

    geometry, t9 = table9()
    ring = t9 if ring is None else ring
    values = {k: float(getattr(ring, k)) for k in ("rho_a", "ei", "kw", "kv", "damping_ratio", "k_tread")}
    write_tyre(Tyre(geometry, values), folder / name)


def _ring_table(ring) -> str:
    rows = [("ρA", "rho_a_kg_per_m", ring.rho_a, "kg/m"), ("EI", "ei_n_m2", ring.ei, "N m²"),
            ("k_w", "kw_n_per_m2", ring.kw, "N/m²"), ("k_v", "kv_n_per_m2", ring.kv, "N/m²"),
            ("ζ", "damping_ratio", ring.damping_ratio, "-"), ("k_tread", "k_tread_n_per_m2", ring.k_tread, "N/m²")]
    return "| parameter | TOML key | true value | unit |\n|---|---|---|---|\n" + "\n".join(
        f"| {a} | `{b}` | {float(c):.6g} | {d} |" for a, b, c, d in rows)


def _records(folder: Path, progress: bool, fmt: str | None = None) -> None:
    from ringfit.io.records import write_records
    from ringfit.synth.records import impact_records, ring_modes

    geometry, ring = _true_ring()
    modes = ring_modes(ring, geometry, n_values=range(1, 10), seed=11)
    angles = np.arange(24) * 15.0
    rec = impact_records(modes, angles, ring=ring, geometry=geometry, fs_hz=6400.0, duration_s=0.5,
                         impacts_per_angle=2, sensor_delay_s=0.4e-3, noise=0.01, seed=12)
    write_records(rec, folder / "impact.records.npz")
    write_records(rec, folder / "impact.uff")
    rig_line, rig_try = "", ""
    if fmt in ("tdms", "mat"):
        write_records(rec, folder / f"impact.{fmt}")
        what = "NI TDMS (a group per record)" if fmt == "tdms" else "MATLAB v5 (ringfit's keys as variables)"
        rig_line = f" and in {what} form in `impact.{fmt}`"
        rig_try = f"ringfit ssi impact.{fmt} --delay 0.0004 --out {fmt}.modes.csv\n"
    elif fmt == "csv":
        from ringfit.io.channel_map import write_channel_map
        from ringfit.io.csv_records import write_csv_records

        _, cmap = write_csv_records(rec, folder / "impact.csv")
        write_channel_map(cmap, folder / "impact.channels.toml")
        rig_line = " and as CSV in `impact.csv` (its channel map, angles and axes, in `impact.channels.toml`)"
        rig_try = "ringfit ssi impact.csv --channels impact.channels.toml --delay 0.0004 --out csv.modes.csv\n"
    _starting_tyre(folder)
    lines = "\n".join(f"| {'cavity' if k == 'acoustic' else int(n)} | {k} | {f:.2f} | {100 * z:.2f} |"
                      for n, k, f, z in zip(modes.n, modes.kind, modes.freq_hz, modes.damping))
    (folder / "README.md").write_text(f"""# Example: roving-sensor hammer records with known modes

Written by `ringfit example records`. A free tyre (Table 9 geometry, radius
{float(geometry.radius)} m) struck radially at 0° and read by one sensor moved round the tread in
15° steps, two impacts per angle (records × axes × samples = {rec.acc.shape}, {rec.fs_hz:g} Hz,
radial and tangential, hammer force included, the acceleration 0.4 ms behind the force,
noise 1 % of the signal's rms). The same records are in UFF58 form in `impact.uff`{rig_line}.

## The truth

Modes in the records (each ring mode a double pole split by 0.2 %):

| n | kind | frequency [Hz] | damping [%] |
|---|---|---|---|
{lines}

The ring they come from (eq. 18 of docs/physics.md §2.1):

{_ring_table(ring)}

`tyre.toml` holds the geometry and the Table 9 values as *starting* values, not the truth.

## Try

```bash
ringfit ssi impact.records.npz --delay 0.0004 --out ssi.modes.csv --plot ssi.png
ringfit frf impact.records.npz --delay 0.0004 --out frf.modes.csv --plot frf.png
ringfit ssi impact.uff --delay 0.0004 --out uff.modes.csv
{rig_try}ringfit fit ssi.modes.csv --tyre tyre.toml --out fitted.toml
ringfit sample ssi.modes.csv --tyre fitted.toml --out posterior.h5
ringfit report posterior.h5 --out report.html
```

`ssi` should list n = 1…9 within 0.3 % of the frequencies above and flag the cavity
as acoustic; the fit recovers k_w and k_v (EI is weakly identified by free-tyre modes:
see the identifiability report).
""")


def _profiles(folder: Path, progress: bool) -> None:
    from ringfit.io.profiles import write_profile
    from ringfit.synth.profiles import synthetic_profile

    geometry, ring = _true_ring()
    speeds = (30.0, 60.0)
    for i, v in enumerate(speeds):
        prof = synthetic_profile(ring, geometry, v, 4000.0, drum_diameter_m=1.2192, noise_ms2=2.0, seed=20 + i)
        write_profile(prof, folder / f"run{int(v)}.profile.csv")
    _starting_tyre(folder, ring=ring.replace(k_tread=19.0e6))
    (folder / "README.md").write_text(f"""# Example: rolling profiles with a known tread stiffness

Written by `ringfit example profiles`. What the co-rotating sensor reads over one
revolution on a 1.2192 m drum at {' and '.join(f'{v:g}' for v in speeds)} km/h, load 4000 N
(docs/formats.md §3; 1024 angles, white noise σ = 2 m/s² per channel, rotation_hz in the sidecar).

## The truth

{_ring_table(ring)}

`tyre.toml` holds the true ρA, EI, k_w, k_v and ζ (as a free-tyre fit would give them) but
k_tread = 19e6 N/m² (Table 9) as the starting value: the rolling fit should find
**k_tread = {float(ring.k_tread):.4g} N/m²**.

## Try

```bash
ringfit fit-rolling run30.profile.csv run60.profile.csv --tyre tyre.toml --out fitted.toml --plot fit.png
ringfit roll --tyre fitted.toml --speed 45 --drum 1.2192 --out sim45.profile.csv --plot roll.png
```
""")


def cleat_bench():
    """The bench of ``ringfit example cleat``: the true ring on the 1.2192 m drum at 40 km/h, 4 kN, its modes the
    rolling, loaded tyre's (``modes="loaded"``: the model ``ringfit campbell`` and ``cleat --ssi --tyre`` use,
    docs/physics.md §3.7)."""
    from ringfit.synth.cleat import CleatBench

    geometry, ring = _true_ring()
    return CleatBench(geometry=geometry, ring=ring, steady="ring", modes="loaded", fs_hz=12800.0, noise_ms2=5.0,
                      seed=31)


def _cleat(folder: Path, progress: bool) -> None:
    bench = cleat_bench()
    ring = bench.ring
    seconds = 20.0
    bench.write(folder / "cleat.records.npz", seconds, progress=progress)
    _starting_tyre(folder, "true.tyre.toml", ring=ring)  # the truth, for labelling (not a fit's start)
    m = bench.generating_modes()
    order = np.argsort(m["fixed_hz"])
    lines = "\n".join(
        f"| {m['n'][j]} | {m['branch'][j]}{' ' + m['tag'][j] if m['tag'][j] else ''} | {m['fixed_hz'][j]:.2f} | "
        f"{100 * m['damping_fixed'][j]:.2f} | "
        + ", ".join(f"{k:+d}: {100 * w:.0f} %" for k, w in zip(m["harmonics"][j], m["shares"][j])) + " |"
        for j in order)
    arrivals = bench.arrival_times(seconds)
    lead, trail = (math.degrees(float(x)) for x in (bench.contact_arc.leading, bench.contact_arc.trailing))
    (folder / "README.md").write_text(f"""# Example: a drum recording with a cleat

Written by `ringfit example cleat`. {seconds:g} s of one co-rotating tri-axial sensor
(radial, tangential) at {bench.fs_hz:g} Hz on a 1.2192 m drum at {bench.speed_kmh:g} km/h, {bench.load_n:g} N,
with an absolute encoder and the hall sensor that marks each cleat pass
(docs/records-continuous.md). White noise {bench.noise_ms2:g} m/s², an IEPE high-pass at
{bench.highpass_hz:g} Hz, gravity included.

## The truth

- wheel rotation: {bench.rotation_hz:.4f} Hz; {arrivals.size} cleat arrivals, one every
  {bench.drum_period_s:.4f} s; the tyre turns {bench.circumference_ratio:.4f} revolutions per pass;
- the ring: as in the table below (Table 9 geometry);
- the modes each cleat hit excites: those of the rolling tyre **in contact with the drum**, the tread
  springs on the patch of the steady rolling solution ({lead:.2f}° to {trail:+.2f}°) — the model of
  docs/physics.md §3.7 that `ringfit campbell` and `ringfit cleat --ssi --tyre` use, so a tyre file with
  the values below labels them as generated. The fixed observer of the angle–time field sees each mode at
  its fixed-frame frequency. Under contact the free ring's pairs of travelling waves (eq. 25/26) do not
  survive as such: the patch couples the forward wave of order n with the backward waves of n and n + 2
  (which lie near it in the fixed frame), so every mode is a hybrid of several harmonics; its order n and
  direction are those of its strongest harmonic in the radial acceleration (the last column: signed
  harmonic k, k > 0 backward, k < 0 forward, and its share). At {bench.load_n:g} N no mode between 100 and
  300 Hz is forward-dominated; standing modes carry the loaded tyre's tag (docs/physics.md §3.7):

| n | branch | fixed frame [Hz] | damping seen [%] | strongest harmonics (radial acceleration) |
|---|---|---|---|---|
{lines}

{_ring_table(ring)}

## Try

```bash
ringfit profile cleat.records.npz --quiet-after 0.25 --out drum.profile.csv
ringfit cleat cleat.records.npz --sectors 128 --out field.npz --snapshots snapshots.png --coverage-plot coverage.png
ringfit cleat cleat.records.npz --sectors 128 --out field2.npz --ssi rolling.modes.csv --animate field.gif
```

`true.tyre.toml` holds the values above (the truth, for labelling): with
`--tyre true.tyre.toml` added to the last line each identified mode is labelled with the model's branch
(`model_n`, `model_direction`, `label_flag`), and the Campbell diagram matches them to its branches:

```bash
ringfit cleat cleat.records.npz --sectors 128 --out field2.npz --ssi rolling.modes.csv --tyre true.tyre.toml --force
ringfit campbell --tyre true.tyre.toml --load 4000 --drum 1.2192 --speeds 0:40:10 --modes rolling.modes.csv --out cleat.campbell.csv
```
""")


def _profile_case(folder: Path, effect: str) -> None:
    """A case of rolling profiles hiding a profile-only effect (``tread_shear``: the independent lever truth)."""
    from ringfit.synth.cases import make_profile_case

    label = make_profile_case(folder / "case", effect=effect, seed=5)
    mag = ", ".join(f"{k} = {v:.4g}" for k, v in label.magnitude.items()) or "-"
    ring = label.ring
    (folder / "README.md").write_text(f"""# Example: a case folder of rolling profiles with one hidden effect

Written by `ringfit example case --effect {effect}`. `case/` is a case folder (docs/formats.md §6):
`tyre.toml` (Table 9 values as a start, not the truth), `free.modes.csv` (the free tyre) and one
rolling acceleration profile per speed (`run*.profile.csv` + sidecar) at {ring['load_n']:.0f} N, with
{label.noise['colour']} noise of {label.noise['grid_rms_ms2']:.3g} m/s² RMS.

{_truth_and_try(label, mag)}""")



def _truth_and_try(label, mag: str, *, k_tread_carried: bool = True) -> str:
    """The README's hidden truth and the command to try, shared by the modal and the profile case.

    A README states only what its data determine: ``k_tread_carried`` False (the modal case, whose loaded
    tables take a patch half-angle drawn apart from k_tread and load_n) leaves k_tread out, and says why."""
    ring = label.ring
    if k_tread_carried:
        tread = f", k_tread = {ring['k_tread']:.4g} N/m²."
    else:
        half = label.magnitude.get("half_angle_deg")
        tread = (".\n- k_tread is not stated: these data do not determine it. The loaded tables were computed "
                 + (f"with a contact patch of half-angle {half:.4g}° drawn at random, not solved from their load_n "
                    "with the tread stiffness, so identifying k_tread from load_n would not recover a true value."
                    if half is not None else "without ground contact (the injected effect is not the contact).")
                 )
    return f"""## The truth (kept out of the case folder)

- injected effect: **{label.effect}** ({mag}); the diagnosis should answer `{label.expected_verdict}`;
- the ring: ρA = {ring['rho_a']:.4g} kg/m, EI = {ring['ei']:.4g} N m², k_w = {ring['kw']:.4g} N/m²,
  k_v = {ring['kv']:.4g} N/m²{tread}

## Try

```bash
ringfit diagnose case --out case.diagnosis.json --report case.html
```
"""

def _case(folder: Path, progress: bool, effect: str = "ground_contact") -> None:
    from ringfit.synth.cases import EXTRA_INJECTIONS, MODAL_INJECTIONS, make_case

    if effect not in MODAL_INJECTIONS + EXTRA_INJECTIONS:
        return _profile_case(folder, effect)
    label = make_case(folder / "case", effect=effect, seed=5)
    def fmt(v):
        return "[" + ", ".join(f"{x:.4g}" for x in v) + "]" if isinstance(v, (list, tuple)) else f"{v:.4g}"

    mag = ", ".join(f"{k} = {fmt(v)}" for k, v in label.magnitude.items()) or "-"
    (folder / "README.md").write_text(f"""# Example: a case folder with one hidden effect

Written by `ringfit example case`. `case/` is a case folder (docs/formats.md §6): `tyre.toml`
(Table 9 values as a start, not the truth), `free.modes.csv` (the free tyre the ring is fitted
to) and test tables of the loaded and the spinning tyre{" and of the free tyre on the bench's suspension (suspended.modes.csv, its sidecar stating the fixture)" if effect == "wheel_suspension" else ""}, with relative frequency noise
{100 * label.noise['relative']:.2g} % ({label.noise['colour']}).

{_truth_and_try(label, mag, k_tread_carried=False)}""")


def _identify(folder: Path, progress: bool) -> None:
    import numpy as np

    from ringfit.io.profiles import write_profile
    from ringfit.synth.identify import make_identify_case
    from ringfit.synth.profiles import synthetic_profile

    truth = make_identify_case(folder / "case", seed=11, truth_file=False)
    ring = truth["ring"]
    load, speed = 4500.0, 60.0
    prof = synthetic_profile(truth["ring_object"], truth["geometry"], speed, load, n_points=1024,
                             noise_ms2=0.01 * 100.0, seed=12)
    prof.condition.pop("load_n", None)
    prof.source = ""
    write_profile(prof, folder / "unknown-load.profile.csv")
    runs = "\n".join(f"  - `run{i + 1}.profile.csv`: {p['load_n']:.0f} N, {p['speed_kmh']:.0f} km/h, gain "
                     f"{p['gain']:.4f}, angle offset {p['angle_offset_deg']:+.3f}°, {p['noise_colour']} noise "
                     f"{p['noise_ms2']:.3g} m/s²" for i, p in enumerate(truth["profiles"]))
    loads = ", ".join(f"{x:.0f} N" for x in truth["half_angles"])
    (folder / "README.md").write_text(f"""# Example: every state of one tyre, to identify it once

Written by `ringfit example identify`. `case/` is a case folder (docs/formats.md §6): `tyre.toml`
(Table 9 values as a start, not the truth), `free.modes.csv` (eq. 18 with damping), standing
loaded tables at {loads} (`loaded*.modes.csv`, tagged `extr`/`vert` and `0`/`hort`) and three rolling
profiles at known load and speed. Frequency noise {100 * truth['sigma_rel']:.2g} % (relative). The
truth was computed on a finer contact grid ({truth['truth_grid']} points) and with more loaded-mode
harmonics (48) than ringfit uses. `unknown-load.profile.csv` is a fourth profile whose sidecar has no
`load_n`: {load:.0f} N at {speed:.0f} km/h (1 m/s² white noise).

## The truth (kept out of the case folder)

- ρA = {ring['rho_a']:.5g} kg/m, EI = {ring['ei']:.5g} N m², k_w = {ring['kw']:.5g} N/m²,
  k_v = {ring['kv']:.5g} N/m², k_tread = {ring['k_tread']:.5g} N/m², ζ = {ring['damping_ratio']:.4g};
- profiles:
{runs}
- the load of `unknown-load.profile.csv`: **{load:.0f} N**.

## Try

```bash
ringfit identify case --out identified.tyre.toml          # also writes identified.identify.json
ringfit estimate unknown-load.profile.csv --tyre identified.tyre.toml --out unknown.estimate.json
```
""")


def _rolling(folder: Path, progress: bool) -> None:
    from ringfit.synth.cases import make_rolling_case

    label = make_rolling_case(folder / "rolling", contact=True, seed=0)
    ring = label.ring
    (folder / "README.md").write_text(f"""# Example: a case folder with rolling mode tables

Written by `ringfit example rolling`. `rolling/` is a case folder (docs/formats.md §6): `tyre.toml`
(Table 9 values as a start, not the truth), `free.modes.csv` (the free tyre the ring is fitted to) and
`roll20/40/60.modes.csv`: the modes of the tyre rolling at 20, 40 and 60 km/h under 4 kN as the
co-rotating sensor sees them (docs/physics.md §3.7), with modes missing, `extr`/`0` tags instead of
branches, one row per table without n, no `freq_std_hz`, relative frequency noise
{100 * label.noise['relative_rolling']:.2g} %.

## The truth (kept out of the case folder)

- the lines are those of the rolling, loaded tyre's model (contact patch of the steady rolling solution,
  rotation at Ω = V/R_e): the diagnosis should answer `rotation` and `ground_contact` (either order);
- the ring: ρA = {ring['rho_a']:.4g} kg/m, EI = {ring['ei']:.4g} N m², k_w = {ring['kw']:.4g} N/m²,
  k_v = {ring['kv']:.4g} N/m², k_tread = {ring['k_tread']:.4g} N/m².

## Try

```bash
ringfit diagnose rolling --effects ground_contact,rotation --out rolling.diagnosis.json
ringfit fit rolling/free.modes.csv --tyre rolling/tyre.toml --out fitted.toml
ringfit campbell --tyre fitted.toml --load 4000 --speeds 0:60:5 --modes rolling/roll20.modes.csv \
    rolling/roll40.modes.csv rolling/roll60.modes.csv --out rolling.campbell.csv --plot campbell.png
```
""")


__all__ = ["KINDS", "write_example", "calibration_case"]


def calibration_case(example, case) -> list[str]:
    """The ``ringfit identify`` case folder (docs/formats.md §6) a user assembles from a state example's
    ``calibration/``, written into the new folder ``case``: the example's ``tyre.toml``; the free table at its
    pressure as ``free.modes.csv`` and those at other pressures beside it; and every calibration recording on the
    flat road at the tyre file's tread depth averaged into a profile (``ringfit profile``: its stated load,
    pressure, torque and tread depth in the sidecar) — identify reads every measurement on one road and at the
    tyre file's depth, so the drum and the worn-tread recordings stay out. **Returns** the recordings left out.
    (Here, not in :mod:`ringfit.synth.state`: the independent simulator imports nothing of ringfit's targets.)"""
    import json
    import shutil

    from ringfit.io.continuous import read_continuous
    from ringfit.io.profiles import write_profile
    from ringfit.io.tyre import read_tyre
    from ringfit.targets.rolling_profile import rolling_profile

    example, case = Path(example), Path(case)
    case.mkdir(parents=True)
    nominal = read_tyre(example / "tyre.toml")
    shutil.copy(example / "tyre.toml", case / "tyre.toml")
    bar0 = float(nominal.geometry.pressure) / 1e5
    for table in sorted((example / "calibration").glob("free_p*.modes.csv")):
        side = table.with_name(table.name.removesuffix(".csv") + ".json")
        bar = float(json.loads(side.read_text()).get("pressure_bar", bar0))
        name = "free.modes" if abs(bar - bar0) < 1e-9 else table.name.removesuffix(".csv")
        shutil.copy(table, case / f"{name}.csv")
        shutil.copy(side, case / f"{name}.json")
    depth = nominal.state_values.get("tread_depth_mm")
    left = []
    for path in sorted((example / "calibration").glob("*.records.npz")):
        with read_continuous(path) as rec:
            cond = dict(rec.condition)
            if cond.get("drum_diameter_m") or (depth is not None and cond.get("tread_depth_mm") not in (None, depth)):
                left.append(path.name)
                continue
            prof = rolling_profile(rec)
        write_profile(prof.to_profile(), case / (path.name.removesuffix(".records.npz") + ".profile.csv"),
                      inputs=[path])
    return left
