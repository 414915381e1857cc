"""The reports an engineer reads first (issue 34): the diagnosis report's order (verdict sentence, residual
before/after, the binding null, tables, folded method), the contact patch in degrees and mm, fitted and
computed lines labelled, numbers at the precision their σ warrants, plots that do not overlap or clip
silently, and progress relayed from long batch tasks.

The diagnosis here is hand-made (a :class:`ringfit.gap.Diagnosis` of known content and fits), so every
expected string is written from the inputs, not from the code under test."""

import io
import math
import re
import time
from types import SimpleNamespace

import numpy as np
import pytest

from ringfit.gap.diagnosis import Diagnosis, PartResult
from ringfit.report import numbers

NOISE_METHOD = ("free.modes.csv: relative σ 0.002; test rows: sqrt(measurement σ^2 + the reference fit's "
                "prediction σ^2); Huber weighting of test rows beyond |z| = 2")


# --------------------------------------------------------------------------- the hand-made diagnosis
def _fit(pred, heldout, chain=()):
    return SimpleNamespace(extra={"pred": np.asarray(pred, float), "heldout_pred": np.asarray(heldout, float),
                                  "chain": list(chain)})


def _null(observed, p, q95, draws):
    d = np.asarray(draws, float)
    return {"kind": "x", "draws": d.size, "statistic": "s", "median_pct": round(100 * float(np.median(d)), 2),
            "q95_pct": q95, "mean_pct": round(100 * float(d.mean()), 2), "sd_pct": round(100 * float(d.std()), 2),
            "observed_pct": observed, "p_value": p, "p_mc_error": 0.005}


def _candidate(variant, shrink, observed, accepted=True, half_angle=11.657, sd=0.234, length=127.7, scale=1.0):
    rng = np.random.default_rng(1)
    param = rng.normal(0.0, 0.06, 200)  # the informative null: the current model plus its noise
    rline = np.zeros(200)  # the random-line null of the rolling example: every draw exactly 0
    return {
        "effect": "ground_contact", "element": "ground_contact" + ("@computed" if variant == "computed" else ""),
        "variant": variant, "rms": 0.2, "heldout_rms": 0.25, "shrink_pct": shrink, "heldout_shrink_pct": shrink,
        "heldout_shrink_interval_pct": [shrink - 3, shrink + 1], "evidence": {"delta_bic": -1500.0},
        "params": {"patch_scale": {"value": scale, "lo": scale - 0.04, "hi": scale + 0.04, "null": 0.0, "unit": "-",
                                   "excludes_null": True,
                                   **({"fixed_by": "the measured condition"} if variant == "computed" else {}),
                                   "physical": {"loaded (loaded 4000 N)": {"half_angle_deg": half_angle,
                                                                          "half_angle_sd_deg": sd,
                                                                          "length_mm": length}}}},
        "accepted": accepted, "p_value": 0.00498,
        # a tie at the p floor: the parametric null (higher 95 % quantile) binds, the all-zero one does not
        "null": {"parametric": _null(observed, 0.00498, 11.0, param),
                 "random_line": _null(observed, 0.00498, 0.0, rline)},
        "null_draws": {"parametric": param.tolist(), "random_line": rline.tolist()},
    }


ROWS = [  # measured, baseline, with effects, σ [Hz]
    ("free n=2", "free 2", 146.0312, 146.05, 146.04, 0.043),
    ("free n=3", "free 3", 171.2, 171.0, 171.1, 12.3),
    ("loaded (loaded 4000 N) n=2 extr", "loaded 2 extr", 160.0, 146.0, 159.9, 0.2),
    ("loaded (loaded 4000 N) n=3 extr", "loaded 3 extr", 185.0, 171.0, 185.1, 0.2),
]


def _diagnosis():
    y = np.array([r[2] for r in ROWS])
    base = np.array([r[3] for r in ROWS])
    after = np.array([r[4] for r in ROWS])
    sigma = np.array([r[5] for r in ROWS])
    fitted, computed = _candidate("fitted", 98.5, 98.0, half_angle=9.981, sd=0.1, length=109.5, scale=0.8518), \
        _candidate("computed", 89.2, 89.0)
    baseline = {"model": "eq18-free", "rms": 9.455, "unit": "Hz", "heldout_rms": 9.4192, "noise_rms": 0.3432,
                "reduced_chi2": 81.975, "noise_dof": 36.0, "ideal_shrink_pct": 98.78, "noise_method": NOISE_METHOD,
                "heldout_method": "leave-modes-out (free rows)"}
    rows = [{"row": r[0], "short": r[1], "model_mode": "", "measured": r[2], "baseline": r[3], "with_effects": r[4],
             "sigma": r[5], "z_baseline": 0.0, "z_with_effects": 0.0, "outlier": False} for r in ROWS]
    damping_rows = [{"row": "free n=2 damping", "short": "free 2", "measured": math.log(0.015),
                     "baseline": math.log(0.0153), "with_effects": math.log(0.0153), "sigma": 0.12,
                     "z_baseline": 0.0, "z_with_effects": 0.0, "outlier": False}]
    summary = {"family": "frequency", "baseline": baseline, "candidates": [fitted, computed], "chain": [],
               "rows": rows}
    content = {
        "data": ["free.modes.csv", "loaded.modes.csv"], "family": "frequency", "baseline": baseline,
        "where": [{"region": "loaded (loaded 4000 N) n=3 extr", "share": 0.6}],
        "candidates": [fitted, computed], "rows": rows,
        "verdict": {"effect": "ground_contact", "effects": ["ground_contact"], "variants": ["fitted"],
                    "heldout_shrink_pct": 98.49, "alpha": 0.01, "explains": ["loaded (loaded 4000 N) n=2 extr"],
                    "leaves": [], "outliers": [], "rule": {"noise": NOISE_METHOD, "shrink": "100 (1 - SS_after/...)"}},
        "parts": [summary, {"family": "damping", "baseline": {**baseline, "unit": "ln(damping ratio)"},
                            "candidates": [], "rows": damping_rows}],
    }
    problem = SimpleNamespace(domain="modes", unit="Hz", m=len(ROWS), y=y, sigma=sigma, sigma_heldout=sigma,
                              labels={"short": [r[1] for r in ROWS]})
    chain = _fit(after, after, ["ground_contact"])
    part = PartResult(problem=problem, baseline=_fit(base, base), reference=None,
                      fits={("ground_contact",): chain, ("ground_contact@computed",): _fit(after + 0.1, after + 0.1)},
                      summary=summary, chain_fit=chain)
    return Diagnosis(content=content, parts=[part])


@pytest.fixture(scope="module")
def page():
    from ringfit.report.gap_report import build_gap_report

    return build_gap_report(_diagnosis())


# --------------------------------------------------------------------------- the diagnosis report
def test_diagnosis_report_reads_in_the_engineers_order(page):
    verdict = page.index("Adding ground contact (fitted) to the model explains the gap: it removes 98 %")
    alts = re.findall(r'<img src="[^"]*" alt="([^"]*)"', page)
    assert alts[0] == "mode frequencies: held-out residual per mode, before and after"  # the first picture
    assert alts[1].startswith("mode frequencies: held-out shrink against chance")  # then the null
    assert verdict < page.index("<img") and page.index("<table") > page.index(f'alt="{alts[1]}"')  # then tables
    # the method's jargon is folded away: only inside <details>
    details = page[page.index("<details>"): page.index("</details>")]
    assert "sqrt(measurement σ^2" in details and "Huber weighting" in details
    assert page.count("sqrt(measurement σ^2") == page.count("sqrt(measurement σ^2", page.index("<details>"))


def test_diagnosis_report_shows_the_binding_null_and_labels_the_variants(page):
    chance = page[page.index("Against chance"): page.index("Candidates — ")]
    assert "<b>ground_contact (fitted)</b>" in chance and "<b>ground_contact (computed)</b>" in chance
    assert chance.count("binding null: parametric") == 2
    # the all-zero random-line null is named as the one that does not bind, never as the chance line
    assert "random tables of this line density get 0 % ± 0 %" not in page
    assert "Not binding: random-line null p = 0.00498" in chance


def test_contact_patch_in_degrees_and_mm(page):
    assert "patch half-angle 9.98° ± 0.10°, length 109.5 mm (loaded)" in page
    assert "patch half-angle 11.66° ± 0.23°, length 127.7 mm (loaded)" in page
    assert "patch_scale 0.8518" not in page  # the raw scale is printed at its interval's precision, in brackets
    assert "(patch_scale 0.852 [0.812, 0.892])" in page


def test_rows_at_the_precision_of_their_sigma_and_damping_as_zeta(page):
    # 146.0312 Hz with σ 0.043 Hz: to the thousandth; 171.2 Hz with σ 12.3 Hz: to the hertz
    assert "<td>146.031</td><td>146.050</td><td>146.040</td><td>0.043</td>" in page.replace('class=""', "") \
        .replace("<td >", "<td>")
    cells = re.findall(r"<td[^>]*>([^<]*)</td>", page)
    assert "171" in cells and "12" in cells and "146" not in cells
    # damping rows (stored as ln ζ) as ζ in %: ln(0.015) → 1.50 %, σ 0.12 of ln ζ → 12 % of ζ
    assert "measured ζ [%]" in page and "1.50" in cells and "1.53" in cells


def test_stacked_null_histograms_do_not_overlap():
    from ringfit.report.gap_report import _null_figure

    cands = [_candidate("fitted", 98.5, 98.0), _candidate("computed", 89.2, 89.0), _candidate("fitted", 40.0, 40.0)]
    fig = _null_figure([(1, c) for c in cands], "nulls")
    fig.canvas.draw()
    r = fig.canvas.get_renderer()
    boxes = [ax.get_tightbbox(r) for ax in fig.axes]  # titles, tick labels and axis labels included
    assert len(boxes) == 3
    overlaps = [(i, j) for i in range(3) for j in range(i + 1, 3) if boxes[i].overlaps(boxes[j])]
    assert overlaps == []
    # each panel draws the binding (parametric) null's draws, not the all-zero random-line one
    for ax in fig.axes:
        assert "binding null parametric" in ax.get_title()
        heights = sum(p.get_height() for p in ax.patches)
        assert heights == 200 and ax.get_xlim()[0] < -5


def test_binding_null_is_the_larger_p_then_the_higher_quantile():
    from ringfit.report.gap_report import binding_null

    c = {"null": {"parametric": {"p_value": 0.005, "q95_pct": 11.0}, "random_line": {"p_value": 0.005, "q95_pct": 0.0}}}
    assert binding_null(c) == "parametric"
    c["null"]["random_line"]["p_value"] = 0.02
    assert binding_null(c) == "random_line"
    assert binding_null({"null": {}}) is None


# --------------------------------------------------------------------------- numbers
@pytest.mark.parametrize("value, sigma, text", [
    (146.0312, 0.043, "146.031"), (146.0312, 0.04, "146.031"), (146.0312, 0.4, "146.03"), (146.03, 12.3, "146"),
    (146.03, 123.0, "150"), (2.5435, 0.063, "2.543"), (1.111e6, 6.5e4, "1.111e+06"), (-0.31, 1.1, "-0.3"),
    (146.03, None, "146.0"), (146.03, float("nan"), "146.0"), (None, 1.0, "—"),
])
def test_value_at_the_precision_of_its_sigma(value, sigma, text):
    assert numbers.fmt_value(value, sigma) == text


def test_plus_minus_interval_and_damping():
    assert numbers.fmt_pm(146.0312, 0.043, "Hz") == "146.031 ± 0.043 Hz"
    assert numbers.fmt_interval(2.543, 2.457, 2.678) == ("2.543", "2.457", "2.678")
    assert numbers.fmt_interval(0.251, 0.038, 0.902) == ("0.251", "0.038", "0.902")  # the low end keeps 2 digits
    assert numbers.fmt_interval(0.000137, 0.0, 136.3) == ("0", "0", "136")  # at its bound: the other side
    assert numbers.fmt_interval(1.2e-4, 0.0, 9.8e-4) == ("1.2e-04", "0", "9.8e-04")  # one notation for the three
    assert numbers.fmt_damping(math.log(0.0123)) == "1.23 %"
    assert numbers.damping_pct(math.log(0.05)) == pytest.approx(5.0, rel=1e-12)


# --------------------------------------------------------------------------- free-report figures
def test_corner_titles_carry_the_digits_of_their_interval():
    from ringfit.report.free_plots import corner_figure

    rng = np.random.default_rng(0)
    draws = np.column_stack([rng.normal(2.5432, 0.04, 4000), rng.normal(1.3e6, 2e4, 4000)])
    fig = corner_figure(draws, ("rho_a", "kw"))
    titles = [fig.axes[0].get_title(), fig.axes[3].get_title()]
    lo, med, hi = np.quantile(draws[:, 0], [0.025, 0.5, 0.975])
    # half-width ~0.08 → three decimals (two significant digits of it), where corner's .3g gave "2.54"
    assert titles[0].startswith(f"ρA = {med:.3f}\n({lo:.3f} – {hi:.3f})")
    lo, med, hi = np.quantile(draws[:, 1] / 1e6, [0.025, 0.5, 0.975])
    assert titles[1].startswith(f"k_w = {med:.3f}")


def test_clipped_fisher_bar_is_marked_with_its_value():
    from ringfit.report.free_plots import FISHER_CLIP, identifiability_figure

    ident = SimpleNamespace(names=["ei", "kw"], log_std=np.array([4.2e5, 0.06]), eigenvectors=np.eye(2),
                            profiles={})
    fig = identifiability_figure(ident)
    ax = fig.axes[0]
    marks = [t for t in ax.texts if t.get_gid() == "clipped-bar"]
    assert len(marks) == 1 and "4.2e+05" in marks[0].get_text()
    assert marks[0].arrow_patch is not None and marks[0].xy == (0, FISHER_CLIP)
    assert ax.get_ylim()[1] > marks[0].xyann[1]  # the mark is inside the axes
    unclipped = identifiability_figure(SimpleNamespace(names=["ei", "kw"], log_std=np.array([0.2, 0.06]),
                                                       eigenvectors=np.eye(2), profiles={}))
    assert not [t for t in unclipped.axes[0].texts if t.get_gid() == "clipped-bar"]


def test_source_name_never_shows_the_senders_folders():
    from ringfit.report.html import source_name

    assert source_name("/home/alice/projects/tyre/free.modes.csv") == "free.modes.csv"
    assert source_name("C:\\Users\\bob\\free.modes.csv") == "free.modes.csv"
    assert source_name("free.modes.csv") == "free.modes.csv" and source_name(None) == ""


# --------------------------------------------------------------------------- the Campbell legend
class _Diagram:
    """A hand-made Campbell diagram: two backward branches and one standing, no forward one."""

    speed_kmh = np.array([0.0, 30.0, 60.0])
    branches = 3
    fixed_hz = np.array([[100.0, 120.0, 140.0], [99.0, 121.0, 140.0], [98.0, 122.0, 140.0]])
    order = np.array([[1, 2, 0]] * 3)
    drum_diameter_m = None
    load_n = 4000.0
    contact = True

    def branch_direction(self):
        return ["backward", "backward", "standing"]

    def frequencies(self, frame):
        return self.fixed_hz


def test_campbell_legend_names_only_drawn_directions_each_with_a_line():
    from ringfit.report.campbell_plots import plot_campbell

    fig = plot_campbell(_Diagram(), frame="fixed")
    ax = fig.axes[0]
    legend = ax.get_legend()
    labels = [t.get_text() for t in legend.get_texts()]
    assert "forward branch" not in labels and {"backward branch", "standing branch"} <= set(labels)
    for handle, label in zip(legend.legend_handles, labels):
        if label.endswith("branch"):  # a line sample, in the colour of curves drawn in the panel
            assert handle.get_linestyle() not in ("None", "none", "") and handle.get_linewidth() > 0
            colours = {tuple(np.round(__import__("matplotlib").colors.to_rgba(line.get_color()), 3))
                       for line in ax.get_lines() if len(line.get_xdata())}
            assert tuple(np.round(__import__("matplotlib").colors.to_rgba(handle.get_color()), 3)) in colours
    # the legend sits below the panel, over no curve
    fig.canvas.draw()
    r = fig.canvas.get_renderer()
    assert legend.get_window_extent(r).y1 <= ax.get_window_extent(r).y0


# --------------------------------------------------------------------------- progress of long work
def test_task_stream_logs_lines_and_relays_the_latest_bar_state():
    from ringfit.batch import TaskStream

    sent = []
    log = io.StringIO()
    s = TaskStream(log, sent.append, every_s=0.2)
    s.write("ringfit diagnose: case\n")
    s.write("\r  0%|          | 0/9 [00:00<?, ?candidate/s]")
    s.write("\rmodes: rotation:  44%|████▍     | 4/9 [00:02<00:02,  2.42candidate/s]")
    time.sleep(0.5)  # the newest line goes out when the interval is over
    s.close()
    assert log.getvalue() == "ringfit diagnose: case\n"  # bar redraws are not logged
    assert sent[0] == "ringfit diagnose: case"
    assert sent[-1] == "modes: rotation: 44% 4/9 [00:02<00:02, 2.42candidate/s]"
    assert len(sent) == 2  # the middle redraw came too soon and was superseded


def test_running_status_names_tasks_their_time_and_latest_line():
    from ringfit.batch import running_status

    started = {"t1/diagnose": 0.0, "t2/identify": 500.0, "t3/sample": 700.0}
    latest = {"t1/diagnose": "modes: rotation 4/9"}
    text = running_status(started, latest, failed=1, now=723.0)
    assert text == "t1/diagnose 12m03s [modes: rotation 4/9]; t2/identify 3m43s; +1 running; 1 failed"


def test_campaign_says_up_front_what_takes_long():
    from ringfit.batch import Task
    from ringfit.cli.batch import work_summary

    tasks = [Task(f"t{i}/{k}", print, kind=k) for i in range(3) for k in ("fit", "sample", "diagnose")]
    opts = SimpleNamespace(walkers=32, min_steps=2000, max_steps=20000)
    text = "\n".join(work_summary(tasks, opts))
    assert text.startswith("work: 9 tasks (3 fit, 3 sample, 3 diagnose)")
    assert "3 posteriors (sample), each 32 walkers × 2000–20000 steps" in text
    assert "3 diagnoses" in text and "200 draws of each null" in text


def test_diagnose_prints_each_chance_line_with_its_variant():
    from ringfit.cli.gap import chance_lines

    sentence = "data with no effect in it (the current model plus its noise) get -1 % ± 6 %; these get {} %: p = 0.005"
    v = {"calibration": [
        {"effect": "rotation", "variant": "fitted", "sentence": "rotation: " + sentence.format(50)},
        {"effect": "rotation", "variant": "computed", "sentence": "rotation: " + sentence.format(43)}]}
    assert chance_lines(v) == ["rotation (fitted): " + sentence.format(50),
                               "rotation (computed): " + sentence.format(43)]


def test_profile_residual_figure_before_and_after_without_overlap():
    from ringfit.report.gap_report import _profile_heldout_figure, _profile_residual_figure

    P, M = 2, 24
    angle = np.linspace(-90, 90, M)
    y = np.concatenate([np.sin(np.radians(angle)) * (p + 1) * (c + 1) for p in range(P) for c in range(2)])
    labels = {"profile": np.repeat(np.arange(P), 2 * M), "angle_deg": np.tile(angle, 2 * P),
              "speed_kmh": np.repeat([30.0, 50.0], 2 * M)}
    problem = SimpleNamespace(domain="profiles", unit="m/s^2", m=y.size, y=y, sigma=np.full(y.size, 0.1),
                              sigma_heldout=None, labels=labels)
    chain = _fit(y + 0.05, y + 0.07, ["sensor_tilt"])
    summary = {"candidates": [{"effect": "sensor_tilt", "element": "sensor_tilt", "variant": "fitted",
                               "accepted": True, "heldout_shrink_pct": 90.0}], "baseline": {}}
    part = PartResult(problem=problem, baseline=_fit(0 * y, 0 * y), reference=None,
                      fits={("sensor_tilt",): chain}, summary=summary, chain_fit=chain)
    fig = _profile_residual_figure(part)
    labels_drawn = [t.get_text() for t in fig.legends[0].get_texts()]  # one legend, below the panels
    assert labels_drawn == ["before: baseline", "after: + sensor_tilt"]
    fig.canvas.draw()
    r = fig.canvas.get_renderer()
    boxes = [ax.get_tightbbox(r) for ax in fig.axes]
    assert len(boxes) == 4 and not [1 for i in range(4) for j in range(i + 1, 4) if boxes[i].overlaps(boxes[j])]
    held = _profile_heldout_figure(part)
    assert "sensor_tilt, held out" in [t.get_text() for t in held.legends[0].get_texts()]
    held.canvas.draw()
    legend_top = held.legends[0].get_window_extent(held.canvas.get_renderer()).y1
    assert all(legend_top <= ax.get_tightbbox(held.canvas.get_renderer()).y0 + 1 for ax in held.axes)
