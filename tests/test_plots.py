"""Figures: user text drawn literally, modes.png following --modes, units on the sweep's axes,
coinciding curves kept visible, the summary table's channel names whole, the fit's CA block.

Hostile names (mathtext, backslashes, format specifiers, braces, a very long name, non-ASCII,
a leading underscore) run through statics, modal and campbell of the two-pulley bench with 4
elements per span (one compilation each for the module); the other checks draw synthetic data.
"""

import json
import math
import pathlib
import shutil
import subprocess
import sys
import tomllib
from types import SimpleNamespace

import numpy as np
import pytest

from _scenes import scene_text, substitute
from beltjax import parameters, plotting
from beltjax.cli import main, simulation_table
from beltjax.scene import load_scene

REPO = pathlib.Path(__file__).resolve().parents[1]

HOSTILE = [r"$\foo$", "$x^$", r"\n", "%s", "{}", "{0} %d %%", "a\\$b$", "_hidden", "Lichtmaschine-ü-Ω-発電機",
           "line\nbreak", "bell\x07", "L" * 400]

#: the crank and the alternator renamed, and a description, all hostile
CRANK = r"$\foo$ %s {} {0} \n ü-Ω 発電機"
ALTERNATOR = "_$x^$ " + "long name " * 9  # 96 characters: scene names are at most 100
DESCRIPTION = r"$x^$ 50% {} \\ a real\nnewline"


@pytest.fixture(autouse=True)
def _cache(tmp_path_factory, monkeypatch):
    monkeypatch.setenv("BELTJAX_CACHE", str(tmp_path_factory.getbasetemp() / "jax_cache"))
    monkeypatch.delenv("BELTJAX_DEBUG", raising=False)


@pytest.fixture
def figures(monkeypatch):
    """Every figure saved through beltjax.plotting.save (still written to its file)."""
    saved = []
    real = plotting.save

    def keep(fig, path, dpi=110, **kwargs):
        saved.append(fig)
        real(fig, path, dpi, **kwargs)

    monkeypatch.setattr(plotting, "save", keep)
    return saved


def _texts(fig) -> list[str]:
    """Every text drawn in a figure, as matplotlib will render it (mathtext escapes resolved)."""
    out = []
    for t in fig.findobj(lambda a: hasattr(a, "get_text") and hasattr(a, "_preprocess_math")):
        s, math_mode = t._preprocess_math(t.get_text())
        assert math_mode is False, t.get_text()  # never read as mathtext
        out.append(s)
    return out


# --------------------------------------------------------------------------- the helper


@pytest.mark.parametrize("text", HOSTILE, ids=range(len(HOSTILE)))
def test_literal_text_is_drawn_as_written(text, tmp_path):
    fig, ax = plotting.subplots(figsize=(4, 3))
    shown = plotting.literal(text)
    ax.plot([0, 1], [0, 1], label=shown)
    ax.set_title(shown)
    ax.set_xlabel(plotting.literal(text, 40))
    ax.annotate(shown, (0.5, 0.5))
    ax.set_xticks([0.5], [shown])
    leg = ax.legend()
    assert len(leg.get_texts()) == 1  # a leading "_" would hide the entry
    plotting.save(fig, tmp_path / "t.png")  # mathtext would raise here
    assert (tmp_path / "t.png").stat().st_size > 1000
    drawn = _texts(fig)
    want = "".join(f"\\x{ord(c):02x}" if c == "\x07" else c for c in text)  # a control character, spelt out
    want = " " + want if want.startswith("_") else want
    assert drawn.count(want) >= 4  # title, annotation, tick label, legend entry
    short = plotting.literal(text, 40).replace("\\$", "$")
    assert len(short) <= 41 and (len(want) <= 40 or "..." in short)


# --------------------------------------------------------------------------- the commands


@pytest.fixture(scope="module")
def hostile_scene(tmp_path_factory):
    text = substitute(scene_text("two_pulley_T200.toml"), ("elements_per_span = 16", "elements_per_span = 4"))
    text = text.replace('"crank"', f"'{CRANK}'").replace('"alternator"', f"'{ALTERNATOR}'")
    text = text.replace(text.splitlines()[0], f'description = "{DESCRIPTION}"')
    p = tmp_path_factory.mktemp("hostile") / "hostile $x^$ {}.toml"
    p.write_text(text)
    scene = load_scene(p)
    assert [q.name for q in scene.pulleys] == [CRANK, ALTERNATOR] and "$x^$" in scene.description
    return p


@pytest.mark.parametrize("argv,files", [
    (["statics"], ["statics.json", "layout.png"]),
    (["modal", "--modes", "8"], ["modal.json", "modes.png"]),
    (["campbell", "--rpm", "0:1000:500", "--modes", "6"], ["campbell.json", "campbell.png"]),
], ids=["statics", "modal", "campbell"])
def test_hostile_names_run_through_the_commands(hostile_scene, argv, files, tmp_path, capsys, figures):
    out = tmp_path / "out"
    code = main([argv[0], str(hostile_scene), *argv[1:], "--out", str(out)])
    captured = capsys.readouterr()
    assert code == 0, captured.err
    for f in files:
        assert (out / f).stat().st_size > (10_000 if f.endswith(".png") else 100), f
    assert len(figures) == 1
    drawn = "\n".join(_texts(figures[0]))
    assert "$x^$" in drawn  # the description (or the scene path) literally
    if argv[0] != "campbell":  # pulley names on the layout (the long one shortened)
        assert CRANK in drawn and "_$x^$ long name" in drawn
    else:
        assert CRANK in drawn  # the drive pulley on the speed axis


# --------------------------------------------------------------------------- modes.png


@pytest.fixture(scope="module")
def modal_result(hostile_scene):
    from beltjax import drive_modal

    scene = load_scene(hostile_scene)
    return scene, drive_modal.analyse_modes(scene)


@pytest.mark.parametrize("modes,panels", [(1, 1), (2, 1), (7, 6), (30, 24)])
def test_modes_png_panels_follow_modes(modal_result, modes, panels, tmp_path):
    """--modes 7 draws modes 2-7 (mode 1 is the rigid-body rotation); more than 24 are cut to 24, with a note."""
    scene, m = modal_result
    assert m.labels[0] == "rigid body" and len(m.frequencies_hz) >= 30
    fig = plotting.plot_drive_modes(scene, m, tmp_path / "modes.png", n_modes=modes, pool=modes)
    visible = [ax for ax in fig.axes if ax.get_visible()]
    assert len(visible) == panels
    titles = [ax.get_title() for ax in visible]
    if modes == 1:
        assert "no flexible modes to show" in "".join(t.get_text() for t in visible[0].texts)
    else:
        assert [t.split(":")[0] for t in titles] == [f"mode {k}" for k in range(2, panels + 2)]
    names = [t.get_text() for ax in visible for t in ax.texts]
    assert names.count(plotting.literal(CRANK, 40)) == panels  # pulley names on every panel
    title = fig.get_suptitle()
    assert ("at most 24 panels" in title) == (modes == 30)


# --------------------------------------------------------------------------- sweep plots


def _sweep(tmp_path):
    from beltjax import sweep

    spec = sweep.parse_spec({"description": "$x^$ sweep", "grid": [
        {"parameter": "belt.static_tension", "values": [200, 300, 400]},
        {"parameter": "pulley.alternator.center.x", "values": [0.22, 0.23]}]})
    T = np.repeat([200.0, 300.0, 400.0], 2)  # the second axis changes nothing: its two lines coincide
    f = 30.0 * np.sqrt(T / 200.0)
    cols = {"tension_crank-alternator_N": T, "tension_alternator-crank_N": T, "hub_crank_N": 2 * T,
            "f1_hz": 0 * T, "f2_hz": f, "f3_hz": f, "belt_length_m": 1.79 + 0 * T}
    return sweep, spec, cols


def test_sweep_plots_have_units_and_show_coinciding_lines(tmp_path, figures):
    sweep, spec, cols = _sweep(tmp_path)
    sweep.plot_grid(spec, cols, tmp_path, labels=["rigid body", "1st transverse $a$", "1st transverse $b$"])
    freq, stat = figures
    for fig in (freq, stat):
        for ax in fig.axes:
            if ax.get_visible():
                assert ax.get_xlabel() == "belt.static_tension [N]"
                assert ax.get_ylabel().endswith("[Hz]" if fig is freq else "[N]")
        _texts(fig)
    legend = [t.get_text() for t in stat.axes[0].get_legend().get_texts()]
    assert legend[0] == "pulley.alternator.center.x = 0.22 m"
    assert legend[1].startswith("pulley.alternator.center.x = 0.23 m (on pulley.alternator.center.x = 0.22 m")
    assert stat.axes[0].lines[1].get_linestyle() != "-"  # dashed over the first
    h = sweep.plot_histograms(spec, cols, tmp_path)
    assert h.exists()
    hist = figures[-1]
    assert {ax.get_ylabel() for ax in hist.axes if ax.get_visible()} == {"cases"}
    assert "span tension [N]" in [ax.get_xlabel() for ax in hist.axes]


def test_sweep_campbell_band_keeps_coinciding_modes_visible(tmp_path, figures):
    from beltjax import sweep

    rpm = np.array([0.0, 500.0, 1000.0])
    F = np.zeros((3, 3, 3))
    F[:, :, 1] = F[:, :, 2] = 30.0 - 0.002 * rpm  # the two spans' transverse modes: equal
    result = {"campbell_rpm": rpm, "campbell_hz": F}
    sweep.plot_campbell_band(result, tmp_path, "$\\foo$")
    (fig,) = figures
    assert fig.axes[0].get_xlabel() == "$\\foo$ speed [rpm]".replace("$", "\\$")
    entries = [t.get_text() for t in fig.axes[0].get_legend().get_texts()]
    assert entries == ["mode 2", "mode 3 (on mode 2)"]


def test_every_parameter_has_a_unit():
    scene = load_scene(REPO / "scenes" / "tensioner_bench_stage2.toml")
    missing = [p for p in parameters.paths(scene) if not parameters.unit(p)]
    assert not missing, missing
    assert parameters.unit("pulley.crank.center.x") == "m" and parameters.unit("belt.EI") == "N m^2"


# --------------------------------------------------------------------------- time histories


def test_time_history_coinciding_curves_and_hostile_columns(tmp_path, figures):
    t = np.linspace(0.0, 1.0, 400)
    F = 400.0 + 20.0 * np.sin(2 * np.pi * 10 * t)
    channels = {"hub_force_magnitudes_N": np.stack([F, F], axis=1),  # a two-pulley drive: equal
                "span_tensions_N": np.stack([200 + 0 * t, 200 + 10 * np.sin(6 * t)], axis=1)}
    columns = {"hub_force_magnitudes_N": [CRANK, "_$x^$"], "span_tensions_N": ["a-b", "b-a"]}
    plotting.plot_simulation(t, channels, columns, {}, tmp_path / "sim.png", title=DESCRIPTION)
    (fig,) = figures
    hub = next(ax for ax in fig.axes if ax.get_ylabel().startswith("hub force"))
    entries = [t.get_text() for t in hub.get_legend().get_texts()]
    assert entries[1].endswith(f"(on {plotting.literal(CRANK, 50)})")
    assert hub.lines[0].get_linestyle() == "-" and hub.lines[1].get_linestyle() != "-"
    assert CRANK in "\n".join(_texts(fig))


def test_many_spans_are_drawn_as_small_multiples(tmp_path, figures):
    """Eight span tensions are not overlaid in one panel: one small panel each, titled by its span,
    four to a row; a channel of few lines keeps one panel with a legend."""
    t = np.linspace(0.0, 1.0, 200)
    spans = [f"s{i}-s{i + 1}" for i in range(8)]
    channels = {"span_tensions_N": np.stack([300 + i * 20 + 5 * np.sin(10 * t + i) for i in range(8)], axis=1),
                "arm_angle_deg": 60 + np.sin(5 * t)}
    plotting.plot_simulation(t, channels, {"span_tensions_N": spans}, {}, tmp_path / "sim.png", title="eight spans")
    (fig,) = figures
    titled = [ax for ax in fig.axes if ax.get_title() in spans]
    assert [ax.get_title() for ax in titled] == spans and all(len(ax.lines) == 1 for ax in titled)
    assert titled[0].get_ylabel() == "span tension (N)" and titled[4].get_ylabel() == "span tension (N)"
    arm = [ax for ax in fig.axes if ax.get_ylabel().startswith("tensioner arm angle")]
    assert len(arm) == 1 and len(fig.axes) == 9
    assert all(ax.get_xlabel() == "time (s)" for ax in [arm[0]])


# --------------------------------------------------------------------------- the summary table


def test_summary_table_keeps_long_channel_names():
    long = "alternator_of_the_front_end_accessory_drive_$x^$"
    meta = dict(fidelity="rotational", n_independent=3, solver="dopri8", dt_s=1e-4, steps=10, t_end_s=0.1,
                wall_s=1.0, first_chunk_s=0.5)
    st = {"mean": 200.0, "peak_to_peak": 5.0, "dominant_hz": [96.3]}
    summary = {"units": {"span_tensions_N": "N", "pulley_speeds_rpm": "rpm"},
               "channels": {"span_tensions_N": {f"crank-{long}": st, f"{long}-crank": st},
                            "pulley_speeds_rpm": {"crank": st, long: st}}}
    text = simulation_table(SimpleNamespace(meta=meta), summary)
    rows = text.splitlines()[3:]
    for name in (f"span tensions: crank-{long}", f"span tensions: {long}-crank", f"pulley speeds: {long}"):
        assert any(r.startswith(name + " ") for r in rows), name
    assert len({r.index("200") for r in rows}) == 1  # one column for the numbers


# --------------------------------------------------------------------------- the fit's CA block


def test_fit_block_gives_CA_at_the_chosen_frequency(tmp_path, capsys):
    data = tmp_path / "belt B"
    shutil.copytree(REPO / "identification" / "examples" / "tensile_belt_B", data)
    ds = data / "dataset.toml"
    ds.write_text(substitute(ds.read_text(), ("scene_frequency_hz = 10.0", "scene_frequency_hz = 100.0")))
    out = tmp_path / "out"
    assert main(["fit", str(ds), "--out", str(out)]) == 0
    printed = capsys.readouterr().out
    assert printed.rstrip().endswith(f"{out / 'fitted_parameters.toml'}")  # final paths, after the move
    block = (out / "fitted_parameters.toml").read_text()
    fit = json.loads((out / "fit.json").read_text())["tensile"]
    belt = tomllib.loads(block)["belt"]
    assert belt["CA"] == pytest.approx(fit["CA_Ns"]["100"], rel=1e-5)
    assert belt["EA"] == pytest.approx(fit["EA_N"]["100"], rel=1e-5)
    assert "for f = 100 Hz" in block and "N s at 100 Hz" in block
    rows = {float(line.split()[1]): float(line.split()[3]) for line in block.splitlines()
            if line.startswith("#   ") and line.split()[1][0].isdigit()}
    assert set(rows) >= {10.0, 100.0}
    assert rows[10.0] == pytest.approx(fit["CA_Ns"]["10"], rel=1e-3)
    assert rows[100.0] == pytest.approx(belt["CA"], rel=1e-3)
    assert rows[10.0] > 10 * rows[100.0]  # the 10 Hz value is no value for a 100 Hz drive


# --------------------------------------------------------------------------- nothing global


def test_plotting_leaves_matplotlib_as_the_user_set_it(tmp_path):
    code = (
        "import sys, matplotlib\n"
        "matplotlib.use('svg'); matplotlib.rcParams['lines.linewidth'] = 7.0\n"
        "from beltjax import plotting, sweep, optimize\n"
        "from identification import fit, tensile, damping, modal_fit, torque_angle\n"
        "fig, ax = plotting.subplots(figsize=(2, 2)); ax.plot([0, 1]); plotting.save(fig, sys.argv[1])\n"
        "assert matplotlib.get_backend() == 'svg', matplotlib.get_backend()\n"
        "assert matplotlib.rcParams['lines.linewidth'] == 7.0\n"
        "assert 'matplotlib.pyplot' not in sys.modules\n"
    )
    subprocess.run([sys.executable, "-c", code, str(tmp_path / "a.png")], check=True, cwd=REPO, timeout=300)
    assert (tmp_path / "a.png").stat().st_size > 100


def test_sweep_histograms_lead_with_the_response_and_leave_out_twin_columns():
    """A tolerance study's histograms: the arm motion and slip margins first, the dynamic tensions of
    the spans that swing most, then the static tensions without a span equal to an earlier one in
    every case (the two sides of an idler)."""
    from beltjax.sweep import figures as sweep_figures

    a = np.array([1.0, 2.0, 3.0])
    cols = {"tension_a-b_N": 100 * a, "tension_b-c_N": 100 * a, "tension_c-a_N": 100 * a + 50,
            "tension_p2p_a-b_N": 5 * a, "tension_p2p_b-c_N": 9 * a, "tension_min_a-b_N": a,
            "min_slip_margin": 0.3 * a, "arm_p2p_deg": 0.1 * a, "dynamic_min_slip_margin": 0.1 - 0.1 * a,
            "belt_length_m": 1.6 + 0.001 * a}
    names = sweep_figures._histogram_columns(cols)
    assert names == ["arm_p2p_deg", "dynamic_min_slip_margin", "min_slip_margin", "tension_p2p_b-c_N",
                     "tension_p2p_a-b_N", "tension_a-b_N", "tension_c-a_N", "belt_length_m"]
    assert sweep_figures._column_label("tension_p2p_b-c_N") == "dynamic span tension, peak to peak [N]"
