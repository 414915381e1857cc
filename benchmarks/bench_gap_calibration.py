"""False-accept rate and power of the gap diagnosis's verdicts (issue 20; docs/physics.md §6.4).

A verdict is worth its false-accept rate. This script diagnoses folders with **no effect in them**
and counts how often any effect is accepted, per kind of folder, with the rate's 95 % interval
(Clopper–Pearson) against the target α + 1 %:

- ``rolling-random``: the source study's real free table beside three rolling tables (20/40/60 km/h,
  4 kN, rotating frame) whose rows hold uniformly random frequencies in 75–485 Hz, with the row counts
  of ``ringfit example rolling``, no n, tag or branch (the issue's reproduction);
- ``loaded-random``: the real free table beside two loaded tables (2 and 4 kN) of random frequencies
  in 75–485 Hz with ``extr``/``0`` tags and no n;
- ``modal-noise``: ``make_case(effect="none")`` — noise-only mode tables from the generator, whose
  noise level (0.05–0.2 %) and colour (white, coloured) are drawn per seed;
- ``profile-noise``: ``make_profile_case(effect="none")`` — noise-only rolling profiles (white, pink,
  red and band noise at 0.05–3 m/s²).

Issue 30 (every freedom the diagnosis uses, labels included):

- ``rolling-labelled``: the real free table beside three rolling tables shaped like the source study's
  (20/40/60 km/h, 4 kN, rotating frame, 12/13/12 rows) whose rows carry n and tag labels in the source
  study's order (``vert``/``hort`` n = 1, then ``extr``/``0`` for n = 2 …) but frequencies drawn uniformly over
  the span (75–485 Hz): the issue's reproduction (before: ``ground_contact + rotation`` at 91–98 %, p = 0.005);
- ``rolling-half-labelled``: the same with every other row's labels removed;
- ``rolling-tags-only``: the same with tags but no n;
- ``rolling-mixed-frames``: labelled random tables, the 40 km/h one in the fixed frame;
- ``rolling-permuted``: the *model's* rolling tables (``make_rolling_case``: frequencies of the rolling, loaded
  tyre, an effect is in them) with their labels shuffled among each table's rows. An effect may rightly be
  accepted here; what is counted is the label-permutation test calling these shuffled labels informative
  (p < α: a false "the labels carry information");
- ``profile-nuisance``: noise-only profiles (``make_profile_case(effect="none")``) with the rig's nuisances
  added: a per-revolution gain drifting 1–4 % over the session (runs in speed order, either sign), a per-run
  angle jitter (σ 0.2°), AR(2) noise (poles 0.9 and 0.5) and 1/f noise, heteroscedastic by run and channel.

A kind the diagnosis's noise model does not have:

- ``profile-patch-noise``: noise-only profiles with extra noise whose level varies with angle, largest at the
  contact patch (the patch's impacts excite each revolution differently, so an averaged profile keeps more
  noise there): white noise of std A·σ·exp(−½(φ/w)²) per channel, A 2–8 × the case's noise σ, w 10–25°. The
  far-side noise estimate cannot see it, and the phase-randomised null spreads it round the wheel: an
  accepted effect is a false accept; ``unexplained`` is the rule's honest answer.
- ``modal-heavy-tail``: ``make_case(effect="none")`` with every table's frequencies also scattered by Student-t
  errors of 2 degrees of freedom (scale 0.05–0.2 %: most rows at the stated noise, a few far out — a row taken
  from the wrong peak, a mode fitted through a neighbour);
- ``modal-replicate``: ``make_case(effect="none")`` beside a second identification of the free tyre
  (``replicate.modes.csv``, the free table's state and n): eq. 18 of the true ring with its own errors, 1–4 × the
  free table's noise and heavy-tailed (Student-t, ν = 3), as SSI and FRF of one tyre disagree. The diagnosis
  reads the two tables' difference as the identification spread; a table of the reference state may also carry
  an effect (``sensor_mass``), so this is where that freedom is tried;
- ``profile-spikes``: noise-only profiles with 1–3 single-sample spikes of 10–30 × the noise σ per channel
  (an electrical glitch, a stone's hit kept in the average).

With ``--power`` it also diagnoses effect cases (every injected effect of ``bench_gap.py`` and the rolling
cases of ``bench_gap_rolling.py``) twice in the same process, interleaved — with the calibration
(``--alpha``) and without it (``null_draws=0``, the rule alone) — and prints the share of the rule's
detections the calibration keeps (target ≥ 95 %).

Run: ``python benchmarks/bench_gap_calibration.py [--folders N] [--kinds a,b] [--power N] [--alpha A]
[--draws D] [--seed-offset S] [--show FOLDER]`` (``--folders`` = ``--per-kind``: null folders per kind; the full size
is 100; ``--show``: one folder's verdict with every null and the label counts, e.g. the real rolling folder). Figures are refused when any diagnosis failed.
"""

from __future__ import annotations

import json
import shutil
import sys
import tempfile
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parent))
import _common as bc  # noqa: E402

KINDS = ("rolling-random", "loaded-random", "modal-noise", "profile-noise", "rolling-labelled",
         "rolling-half-labelled", "rolling-tags-only", "rolling-mixed-frames", "rolling-permuted", "profile-nuisance",
         "profile-patch-noise", "modal-heavy-tail", "profile-spikes", "modal-replicate")
#: the source study's label order on a rolling table (n, tag)
LABELS = [(1, "vert"), (1, "hort"), (2, "extr"), (2, "0"), (3, "extr"), (3, "0"), (4, "extr"), (4, "0"),
          (5, "extr"), (5, "0"), (6, "extr"), (6, "0"), (7, "extr")]
LABELLED_COUNTS = (12, 13, 12)
HEADER = "n,a,tag,kind,freq_hz,freq_std_hz,damping_pct,branch"


def _args(argv):
    p = bc.parser(__doc__.split("\n")[0], quick_help="5 folders per kind, no power table (a smoke run)")
    p.add_argument("--per-kind", "--folders", dest="per_kind", type=bc.count("a number of null folders per kind"),
                   default=100)
    p.add_argument("--kinds", type=bc.choices_list(KINDS, "kinds"), default=list(KINDS))
    p.add_argument("--power", type=bc.count("a number of effect cases per effect (0: none)", 0), default=0)
    p.add_argument("--alpha", type=bc.number("a level in (0, 0.5)", 0.0, 0.5, lo_open=True), default=0.01)
    p.add_argument("--draws", type=bc.count("a number of null draws", 20, 20000), default=200)
    p.add_argument("--seed-offset", type=bc.count("a seed offset", 0, 10**6), default=0)
    p.add_argument("--show", metavar="FOLDER", default=None,
                   help="diagnose one case folder (e.g. the source study's real free + rolling tables) and print its "
                        "verdict with every null's distribution and the label-override counts, then stop")
    a = p.parse_args(argv)
    if a.quick:
        a.per_kind, a.power = 5, 0
    return a


def _copy_free(out: Path):
    from ringfit.data import path

    out.mkdir(parents=True)
    shutil.copy(path("free-ssi.modes.csv"), out / "free.modes.csv")
    shutil.copy(path("free-ssi.modes.json"), out / "free.modes.json")
    shutil.copy(path("table9.tyre.toml"), out / "tyre.toml")


def _table(out: Path, name: str, freqs, tags, sidecar: dict, rng):
    lines = [HEADER] + [f",0,{t},structural,{f:.4f},,{rng.uniform(2, 8):.2f}," for f, t in zip(freqs, tags)]
    (out / f"{name}.modes.csv").write_text("\n".join(lines) + "\n")
    (out / f"{name}.modes.json").write_text(json.dumps(sidecar))


def rolling_random(out: Path, seed: int, counts) -> None:
    _copy_free(out)
    rng = np.random.default_rng(seed)
    for v, m in zip((20, 40, 60), counts):
        _table(out, f"roll{v}", np.sort(rng.uniform(75, 485, m)), [""] * m,
               {"state": "rolling", "load_n": 4000.0, "speed_kmh": float(v), "pressure_bar": 2.2, "frame": "rotating"},
               rng)


def rolling_labelled(out: Path, seed: int, mode: str = "full") -> None:
    """Random frequencies with the source study's labels (``mode``: ``full``, ``half`` — every other row
    unlabelled —, ``tags`` — tags without n —, ``mixed`` — the 40 km/h table in the fixed frame)."""
    _copy_free(out)
    rng = np.random.default_rng(seed)
    for v, m in zip((20, 40, 60), LABELLED_COUNTS):
        f = np.sort(rng.uniform(75, 485, m))
        rows = []
        for i, (x, (n, t)) in enumerate(zip(f, LABELS)):
            if mode == "half" and i % 2:
                n, t = "", ""
            elif mode == "tags":
                n = ""
            rows.append(f"{n},0,{t},structural,{x:.4f},,{rng.uniform(2, 8):.2f},")
        (out / f"roll{v}.modes.csv").write_text("\n".join([HEADER] + rows) + "\n")
        frame = "fixed" if mode == "mixed" and v == 40 else "rotating"
        (out / f"roll{v}.modes.json").write_text(json.dumps(
            {"state": "rolling", "load_n": 4000.0, "speed_kmh": float(v), "pressure_bar": 2.2, "frame": frame}))


def rolling_permuted(out: Path, seed: int) -> None:
    """``make_rolling_case`` (contact) with the labels (n, tag, branch) shuffled among each rolling table's rows."""
    from ringfit.synth.cases import make_rolling_case, relabel_rolling_tables

    make_rolling_case(out, contact=True, seed=seed)
    rng = np.random.default_rng(10**6 + seed)
    relabel_rolling_tables(out, rng.permutation)


def _ar2(rng, n: int, a1: float = 1.4, a2: float = -0.45) -> np.ndarray:
    """Periodic-ish AR(2) noise (poles 0.9 and 0.5), unit σ."""
    e = rng.standard_normal(n + 200)
    x = np.zeros_like(e)
    for i in range(2, e.size):
        x[i] = a1 * x[i - 1] + a2 * x[i - 2] + e[i]
    x = x[200:]
    return x / np.std(x)


def profile_nuisance(out: Path, seed: int) -> None:
    """``make_profile_case(effect="none")`` with the rig's nuisances added (module docstring)."""
    from ringfit.io.profiles import Profile, read_profile, write_profile
    from ringfit.synth.cases import coloured_noise, make_profile_case

    make_profile_case(out, effect="none", seed=seed)
    rng = np.random.default_rng(2 * 10**6 + seed)
    runs = sorted(out.glob("*.profile.csv"))
    profiles = [read_profile(p) for p in runs]
    order = np.argsort(np.argsort([float(p.condition["speed_kmh"]) for p in profiles]))
    drift = rng.uniform(0.01, 0.04) * rng.choice([-1.0, 1.0])
    for path, prof, rank in zip(runs, profiles, order):
        gain = 1.0 + drift * rank / max(len(runs) - 1, 1)
        n = len(prof)
        jitter = rng.normal(0.0, 0.2)  # deg: the run's angle origin moves
        chans = []
        step = np.diff(prof.angle_deg)
        assert np.allclose(step, 360.0 / n), "the generator's profiles are on an even angle grid"
        k = np.arange(n // 2 + 1)
        for ch in (prof.acc_radial_ms2, prof.acc_tangential_ms2):
            # the run's angle origin moved: a pure shift of the periodic record (band-limited; a linear
            # interpolation would also low-pass the record, an effect of its own that sensor_mass can explain)
            x = np.fft.irfft(np.fft.rfft(ch) * np.exp(1j * k * np.radians(jitter)), n=n)
            level = float(np.std(ch)) * rng.uniform(2e-4, 2e-3)  # heteroscedastic: per run and channel
            chans.append(gain * x + level * (_ar2(rng, n) + coloured_noise(rng, n, 1.0, "pink")))
        write_profile(Profile(prof.angle_deg, chans[0], chans[1], condition=prof.condition), path, overwrite=True)


def profile_patch_noise(out: Path, seed: int) -> None:
    """``make_profile_case(effect="none")`` with noise concentrated at the contact patch (module docstring)."""
    from ringfit.synth.cases import add_patch_noise, make_profile_case

    label = make_profile_case(out, effect="none", seed=seed)
    rng = np.random.default_rng(3 * 10**6 + seed)
    amp, width = rng.uniform(2.0, 8.0), rng.uniform(10.0, 25.0)
    add_patch_noise(out, float(label.noise["grid_rms_ms2"]), amp, width, rng)


def modal_heavy_tail(out: Path, seed: int) -> None:
    """``make_case(effect="none")`` with Student-t (ν = 2) frequency errors on every table (module docstring)."""
    from ringfit.synth.cases import add_heavy_tailed_errors, make_case

    make_case(out, effect="none", seed=seed)
    rng = np.random.default_rng(4 * 10**6 + seed)
    add_heavy_tailed_errors(out, rng.uniform(0.0005, 0.002), rng)


def modal_replicate(out: Path, seed: int) -> None:
    """``make_case(effect="none")`` and a second identification of its free table (module docstring)."""
    import jax.numpy as jnp

    from ringfit.io.modes import ModeTable, read_mode_table, write_mode_table
    from ringfit.io.tyre import read_tyre
    from ringfit.params import RingParams
    from ringfit.physics.natural import natural_frequencies
    from ringfit.synth.cases import make_case

    label = make_case(out, effect="none", seed=seed)
    free = read_mode_table(out / "free.modes.csv")
    geometry = read_tyre(out / "tyre.toml").geometry
    n = free.n[(free.kind == "structural") & (free.n >= 1)].astype(float)
    truth = np.asarray(natural_frequencies(RingParams(**label.ring), geometry, jnp.asarray(n)))
    rng = np.random.default_rng(6 * 10**6 + seed)
    scale = float(label.noise["relative"]) * rng.uniform(1.0, 4.0)
    f = truth * (1.0 + scale * rng.standard_t(3.0, n.size) / np.sqrt(3.0))
    write_mode_table(ModeTable(freq_hz=f, n=n.astype(int), condition=dict(free.condition)), out / "replicate.modes.csv")


def profile_spikes(out: Path, seed: int) -> None:
    """Noise-only profiles with 1–3 single-sample spikes of 10–30 σ per channel (module docstring)."""
    from ringfit.io.profiles import Profile, read_profile, write_profile
    from ringfit.synth.cases import make_profile_case

    sigma = float(make_profile_case(out, effect="none", seed=seed).noise["grid_rms_ms2"])
    rng = np.random.default_rng(5 * 10**6 + seed)
    for path in sorted(out.glob("*.profile.csv")):
        prof = read_profile(path)
        chans = [np.array(prof.acc_radial_ms2, dtype=np.float64), np.array(prof.acc_tangential_ms2, dtype=np.float64)]
        for ch in chans:
            at = rng.choice(ch.size, size=int(rng.integers(1, 4)), replace=False)
            ch[at] += rng.choice([-1.0, 1.0], at.size) * rng.uniform(10.0, 30.0, at.size) * sigma
        write_profile(Profile(prof.angle_deg, chans[0], chans[1], condition=prof.condition), path, overwrite=True)


def loaded_random(out: Path, seed: int) -> None:
    _copy_free(out)
    rng = np.random.default_rng(seed)
    for load in (2000.0, 4000.0):
        m = int(rng.integers(8, 13))
        _table(out, f"loaded{int(load)}", np.sort(rng.uniform(75, 485, m)), [("extr", "0")[i % 2] for i in range(m)],
               {"state": "loaded", "load_n": load, "pressure_bar": 2.2}, rng)


def _example_counts(tmp: Path):
    from ringfit.synth.examples import write_example

    write_example("rolling", tmp / "ex")
    folder = next(p.parent for p in (tmp / "ex").rglob("roll20.modes.csv"))
    return [sum(1 for line in (folder / f"roll{v}.modes.csv").read_text().splitlines()[1:] if ",structural," in line)
            for v in (20, 40, 60)]


def clopper_pearson(k: int, n: int, level: float = 0.95):
    """The exact (Clopper–Pearson) interval of a rate k/n (scipy's ``binomtest``)."""
    from scipy.stats import binomtest

    ci = binomtest(k, n).proportion_ci(confidence_level=level, method="exact")
    return float(ci.low), float(ci.high)


def accepted_effects(content: dict) -> list[str]:
    v = content["verdict"]
    eff = [e for e in v["effects"] if e not in ("none", "unexplained")]
    eff += [e for e in (v.get("damping") or {}).get("effects", []) if e not in ("none", "unexplained")]
    return eff


def show(folder: str, alpha: float, draws: int) -> int:
    """One folder's verdict with every null's distribution and the labels kept/overridden (issue 30 item 5)."""
    from ringfit.gap import diagnose

    d, t = bc.timed(diagnose, folder, progress=False, alpha=alpha, null_draws=draws)
    c = d.content
    v = c["verdict"]
    print(f"{folder}: verdict {' + '.join(v['effects'])} (held-out shrink {v.get('heldout_shrink_pct')} %; "
          f"{t.wall:.1f} s wall, {t.cpu:.1f} s CPU)")
    if v.get("nearest"):
        print(f"  nearest candidate: {v['nearest']}")
    st = c["baseline"].get("rolling_structure")
    if st:
        print(f"  structure: {st['chosen']} (cost {st['cost']}, tolerance % {st['tolerance_pct']})")
    lab = v.get("labels")
    if lab:
        print(f"  labels: {lab['sentence']}")
        for name, n in lab["tables"].items():
            print(f"    {name}: {n}")
    for x in v.get("calibration", []):
        print(f"  accepted: {x['sentence']}")
    print("\n| candidate | held-out shrink % | accepted | null | median % | q95 % | mean ± sd % | observed % | p |")
    print("|---|---|---|---|---|---|---|---|---|")
    for x in c["candidates"]:
        for kind, n in (x.get("null") or {}).items():
            print(f"| {x['element']} | {x['heldout_shrink_pct']} | {x.get('accepted')} | {kind} | {n['median_pct']} | "
                  f"{n['q95_pct']} | {n['mean_pct']} ± {n['sd_pct']} | {n['observed_pct']} | {n['p_value']:.3g} |")
            if n.get("labels_overridden_in_draws"):
                print(f"|  |  |  | (labels overridden in the draws) | {n['labels_overridden_in_draws']} |  |  |  |  |")
    return 0


def main(argv=None) -> int:
    args = _args(sys.argv[1:] if argv is None else argv)
    import ringfit  # noqa: F401

    if args.show:
        return show(args.show, args.alpha, args.draws)
    from ringfit.gap import diagnose
    from ringfit.synth.cases import make_case, make_profile_case

    bc.start(f"bench_gap_calibration: {args.per_kind} null folders per kind ({', '.join(args.kinds)})"
             + (" [--quick]" if args.quick else ""))
    print(f"alpha {args.alpha}, {args.draws} null draws per null; target: false accepts <= alpha + 1 % per kind")
    results = {}
    failures = bc.Failures()
    with tempfile.TemporaryDirectory() as tmpd:
        tmp = Path(tmpd)
        counts = _example_counts(tmp) if "rolling-random" in args.kinds else None
        for kind in args.kinds:
            rows = []
            for i in range(args.per_kind):
                seed = args.seed_offset + 1000 * KINDS.index(kind) + i
                folder = tmp / f"{kind}-{seed}"
                if kind == "rolling-random":
                    rolling_random(folder, seed, counts)
                elif kind == "loaded-random":
                    loaded_random(folder, seed)
                elif kind == "modal-noise":
                    make_case(folder, effect="none", seed=seed)
                elif kind == "profile-noise":
                    make_profile_case(folder, effect="none", seed=seed)
                elif kind.startswith("rolling-") and kind != "rolling-permuted":
                    rolling_labelled(folder, seed, {"rolling-labelled": "full", "rolling-half-labelled": "half",
                                                    "rolling-tags-only": "tags",
                                                    "rolling-mixed-frames": "mixed"}[kind])
                elif kind == "rolling-permuted":
                    rolling_permuted(folder, seed)
                elif kind == "profile-patch-noise":
                    profile_patch_noise(folder, seed)
                elif kind == "modal-heavy-tail":
                    modal_heavy_tail(folder, seed)
                elif kind == "modal-replicate":
                    modal_replicate(folder, seed)
                elif kind == "profile-spikes":
                    profile_spikes(folder, seed)
                else:
                    profile_nuisance(folder, seed)
                try:
                    d, t = bc.timed(diagnose, folder, progress=False, alpha=args.alpha, null_draws=args.draws)
                except Exception as exc:  # noqa: BLE001 - counted and reported: no figures then
                    failures.add(f"{kind} seed {seed}", f"{type(exc).__name__}: {exc}")
                    continue
                eff = accepted_effects(d.content)
                if kind == "rolling-permuted":  # the false claim counted here: shuffled labels called informative
                    perm = (d.content["verdict"].get("labels") or {}).get("permutation") or {}
                    eff = ["labels informative"] if perm.get("p_value", 1.0) < args.alpha else []
                rows.append((eff, t.wall, t.cpu))
                print(f"  {kind:15s} seed {seed:5d}: {' + '.join(d.content['verdict']['effects']):40s} "
                      f"{'FALSE ACCEPT ' + '+'.join(eff) if eff else ''} ({rows[-1][1]:.1f} s wall, "
                      f"{rows[-1][2]:.1f} s CPU)", flush=True)
                shutil.rmtree(folder, ignore_errors=True)
            results[kind] = rows
    failures.refuse()
    target = args.alpha + 0.01
    print(f"\n| null folders | n | false accepts | rate | 95 % interval | target <= {100 * target:.0f} % | "
          "median wall / CPU per folder |")
    print("|---|---|---|---|---|---|---|")
    for kind, rows in results.items():
        n = len(rows)
        k = sum(1 for e, _, _ in rows if e)
        lo, hi = clopper_pearson(k, n)
        ok = "met" if k / n <= target else "NOT met"
        ok = ok if n >= 100 else ok + f" (n = {n} < 100: indicative)"
        print(f"| {kind} | {n} | {k} | {100 * k / n:.1f} % | {100 * lo:.1f} … {100 * hi:.1f} % | {ok} | "
              f"{np.median([w for _, w, _ in rows]):.1f} s / {np.median([c for _, _, c in rows]):.1f} s |")
    if args.power:
        _power(args)
    bc.finish()
    return 0


def _power(args) -> None:
    """Detections of effect cases with the calibration against the rule alone, interleaved per case."""
    from ringfit.gap import diagnose
    from ringfit.synth.cases import MODAL_INJECTIONS, PROFILE_INJECTIONS, make_case, make_profile_case, make_rolling_case

    cases = [("modal", e) for e in MODAL_INJECTIONS if e not in ("none", "tread_pitch")]
    cases += [("profile", e) for e in PROFILE_INJECTIONS if e not in ("none", "tread_pitch")]
    cases += [("rolling", "contact"), ("rolling", "control")]
    kept = found_rule = total = 0
    print("\nA detection is the expected set of effects exactly (an extra effect, e.g. a contact claimed on the "
          "no-contact control, is not one).")
    print("\n| case | effect | seed | rule alone | calibrated | p | calibrated: wall / CPU |")
    print("|---|---|---|---|---|---|---|")
    with tempfile.TemporaryDirectory() as tmpd:
        for kind, effect in cases:
            for i in range(args.power):
                seed = args.seed_offset + 5000 + i
                folder = Path(tmpd) / f"{kind}-{effect}-{seed}"
                if kind == "modal":
                    label = make_case(folder, effect=effect, seed=seed)
                elif kind == "profile":
                    label = make_profile_case(folder, effect=effect, seed=seed)
                else:
                    label = make_rolling_case(folder, contact=effect == "contact", seed=seed)
                want = set(label.expected_verdict.split("+"))
                rule = set(accepted_effects(diagnose(folder, progress=False, null_draws=0).content))
                d, t = bc.timed(diagnose, folder, progress=False, alpha=args.alpha, null_draws=args.draws)
                cal = set(accepted_effects(d.content))
                hit_rule = want == {x for e in rule for x in e.split("+")}
                hit_cal = want == {x for e in cal for x in e.split("+")}
                total += 1
                found_rule += hit_rule
                kept += hit_rule and hit_cal
                ps = [c["p_value"] for c in d.content["verdict"].get("calibration", [])]
                print(f"| {kind} | {effect} | {seed} | {'+'.join(sorted(rule)) or 'none'} | "
                      f"{'+'.join(sorted(cal)) or 'none'} | {', '.join(f'{p:.3g}' for p in ps)} | {t.wall:.1f} s / {t.cpu:.1f} s |", flush=True)
                shutil.rmtree(folder, ignore_errors=True)
    share = kept / found_rule if found_rule else float("nan")
    print(f"\npower: the calibration keeps {kept} of the rule's {found_rule} detections ({100 * share:.0f} %; "
          f"target >= 95 %); {total} cases")


if __name__ == "__main__":
    raise SystemExit(main())
