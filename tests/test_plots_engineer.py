"""The plots an engineer expects (issue 14 item 8): titles, units on every axis, labels that do not overlap,
unstable poles and a spectrum behind the stabilization diagram, MAC and shapes from `ssi --plot`, FRF phase,
EI on a log axis in the corner plot, one scale for cleat snapshots and animation."""

import numpy as np
import pytest

from ringfit.params import table9
from ringfit.synth.records import impact_records, ring_modes


@pytest.fixture(scope="module")
def records():
    geometry, ring = table9()
    modes = ring_modes(ring, geometry, n_values=range(1, 7), seed=1)
    return impact_records(modes, np.arange(16) * 22.5, fs_hz=6400.0, duration_s=0.5, seed=2)


def _texts_overlap(fig, texts):
    fig.canvas.draw()
    r = fig.canvas.get_renderer()
    boxes = [t.get_window_extent(r) for t in texts if t.get_text()]
    return [(a, b) for i, a in enumerate(boxes) for b in boxes[i + 1:] if a.overlaps(b)]


def _has_unit(label: str) -> bool:
    return "[" in label and "]" in label


def test_ssi_summary(records):
    from ringfit.report.targets_plots import plot_ssi_summary
    from ringfit.targets.identify import ssi_modes

    res = ssi_modes(records, f_range=(20, 300), orders=range(2, 81, 2))
    fig = plot_ssi_summary(res, f_range=(20, 300))
    stab = fig.axes[0]
    assert "stabilization" in stab.get_title() and _has_unit(stab.get_xlabel()) and _has_unit(stab.get_ylabel())
    legend = [t.get_text() for t in stab.get_legend().get_texts()]
    assert "not stable" in legend  # the unstable poles are drawn
    spectrum = [a for a in fig.axes if "PSD singular" in a.get_ylabel()]
    assert spectrum and spectrum[0].get_yscale() == "log" and _has_unit(spectrum[0].get_ylabel())
    assert len(spectrum[0].get_lines()) >= 1
    labels = [t for t in stab.texts if t.get_text().startswith(("n=", "ac"))]
    assert len(labels) == len(res.table) and _texts_overlap(fig, labels) == []  # the cavity sits beside n = 6
    mac = [a for a in fig.axes if a.get_title().startswith("MAC")]
    assert mac and mac[0].images[0].get_array().shape == (len(res.table), len(res.table))
    polar = [a for a in fig.axes if a.name == "polar" and a.get_title()]
    assert len(polar) == len(res.table)


def test_frf_plot_says_which_curve_and_has_phase(records):
    from ringfit.report.targets_plots import plot_frf
    from ringfit.targets.frf import frf_modes

    res = frf_modes(records, f_range=(20, 300))
    fig = plot_frf(res, f_range=(20, 300))
    mag, phase = fig.axes[0], fig.axes[1]
    curves = [t.get_text() for t in mag.get_legend().get_texts()]
    assert any("rms |H| over 16 angles" in c for c in curves) and any("at 0°, radial" in c for c in curves)
    assert "phase [deg]" in phase.get_ylabel() and _has_unit(phase.get_xlabel()) and _has_unit(mag.get_ylabel())
    assert mag.get_title()
    assert _texts_overlap(fig, mag.texts) == []


def test_corner_plot_log_ei_and_no_offset_text():
    from ringfit.report.free_plots import corner_figure

    rng = np.random.default_rng(0)
    draws = np.column_stack([rng.normal(2.7, 0.03, 4000), np.exp(rng.normal(np.log(0.5), 0.8, 4000)),
                             rng.normal(1.3e6, 2e4, 4000), rng.normal(1.16e6, 1e4, 4000)])
    fig = corner_figure(draws, ("rho_a", "ei", "kw", "kv"))
    fig.canvas.draw()
    k = 4
    bottom = fig.axes[k * (k - 1): k * k]
    assert [a.get_xlabel() for a in bottom] == ["ρA [kg/m]", "EI [N m²]", "k_w [MN/m²]", "k_v [MN/m²]"]
    assert bottom[1].get_xscale() == "log" and fig.axes[k + 0].get_yscale() == "log"  # EI on log axes
    assert all(not a.xaxis.get_offset_text().get_text() and not a.yaxis.get_offset_text().get_text()
               for a in fig.axes)  # no "1e6" offsets
    titles = [a.title for a in fig.axes if a.get_title()]
    assert len(titles) == k and _texts_overlap(fig, titles) == []


def test_cleat_snapshots_and_animation_share_one_scale(tmp_path):
    from ringfit.report import cleat_plots
    from ringfit.synth.cleat import CleatBench
    from ringfit.targets.cleat import angle_time_field

    rec = CleatBench(steady="analytic", fs_hz=3200.0, noise_ms2=1.0).record(6.0)
    field = angle_time_field(rec, sectors=32, duration_s=0.05)
    scale = cleat_plots.field_scale(field)
    fig = cleat_plots.plot_polar_snapshots(field, [0.0, 0.01, 0.02])
    assert f"{scale:.3g} m/s²" in fig._suptitle.get_text()  # default = the animation's default scale
    for ax in fig.axes:
        dashed = [ln for ln in ax.get_lines() if ln.get_linestyle() == "--"]
        assert dashed and np.allclose(dashed[0].get_ydata(), 1.0)  # the reference circle (a = 0)
        assert any("contact patch" in t.get_text() for t in ax.texts)
    seen = {}
    real = cleat_plots._polar_curve

    def spy(field_, axis, index, scale_, r0):
        seen["scale"] = scale_
        return real(field_, axis, index, scale_, r0)

    cleat_plots._polar_curve = spy
    try:
        cleat_plots.animate_field(field, tmp_path / "a.gif", frames=3)
    finally:
        cleat_plots._polar_curve = real
    assert seen["scale"] == pytest.approx(scale)
