"""Post-processing of time histories: spectra, dominant frequencies, summaries, plots."""

import json

import numpy as np
import pytest

from beltjax import signals

FS = 1000.0
T = np.arange(2000) / FS  # 2 s at 1 kHz: 0.5 Hz bins


def three_tones(noise=0.05, seed=0):
    rng = np.random.default_rng(seed)
    x = (3.0 * np.sin(2 * np.pi * 10 * T + 0.3) + 1.5 * np.sin(2 * np.pi * 20 * T + 1.0)
         + 0.7 * np.sin(2 * np.pi * 40 * T + 2.0) + 4.0)
    return x + noise * rng.standard_normal(T.size)


def test_spectrum_amplitude_and_frequencies():
    f, a = signals.spectrum(T, 2.5 * np.sin(2 * np.pi * 50 * T) + 1.0)
    assert f.shape == a.shape == (1001,)
    assert f[1] == pytest.approx(0.5) and f[-1] == pytest.approx(500.0)
    k = int(np.argmax(a))
    assert f[k] == pytest.approx(50.0)
    assert a[k] == pytest.approx(2.5, rel=1e-6)  # coherent gain of the Hann window corrected
    # a rectangular window and no detrending: the mean lands in the DC bin
    f, a = signals.spectrum(T, 2.5 * np.sin(2 * np.pi * 50 * T) + 1.0, detrend=False, window="rect")
    assert a[0] == pytest.approx(1.0) and a[100] == pytest.approx(2.5)


def test_three_tones_with_noise():
    peaks = signals.dominant_frequencies(T, three_tones(), count=3, fmin=1.0)
    assert len(peaks) == 3
    for (f, a), (f0, a0) in zip(peaks, [(10.0, 3.0), (20.0, 1.5), (40.0, 0.7)]):
        assert abs(f - f0) < 0.1
        assert a == pytest.approx(a0, rel=0.03)
    # count and min_relative prune
    assert len(signals.dominant_frequencies(T, three_tones(), count=2)) == 2
    assert [round(f) for f, _ in signals.dominant_frequencies(T, three_tones(), min_relative=0.4)] == [10, 20]
    # fmin/fmax restrict the band
    assert [round(f) for f, _ in signals.dominant_frequencies(T, three_tones(), fmin=15, fmax=30)] == [20]


def test_off_bin_tone_interpolated():
    # 96.7 Hz lies 0.4 bin off the 0.5 Hz grid
    (f, a), = signals.dominant_frequencies(T, 1.2 * np.sin(2 * np.pi * 96.7 * T + 0.4), count=3)
    assert abs(f - 96.7) < 0.05
    assert a == pytest.approx(1.2, rel=0.05)


def test_summary_statistics():
    x = 2.0 + 0.5 * np.sin(2 * np.pi * 25 * T)
    s = signals.channel_summary(T, x)
    assert s["peak_to_peak"] == pytest.approx(1.0, rel=1e-6)
    assert s["min"] == pytest.approx(1.5, rel=1e-6) and s["max"] == pytest.approx(2.5, rel=1e-6)
    assert s["mean"] == pytest.approx(2.0, abs=1e-9)
    assert s["rms_alternating"] == pytest.approx(0.5 / np.sqrt(2), rel=1e-6)
    assert s["dominant_hz"] == [pytest.approx(25.0, abs=0.01)]
    assert s["dominant_amplitudes"] == [pytest.approx(0.5, rel=1e-3)]
    json.dumps(s)
    assert all(type(v) is float for k, v in s.items() if not k.startswith("dominant"))


def test_settle_fraction_drops_transient():
    # a decaying 5 Hz transient of amplitude 50 in the first 0.4 s, then a steady 30 Hz tone
    transient = np.where(T < 0.4, 50.0 * np.exp(-T / 0.05) * np.sin(2 * np.pi * 5 * T), 0.0)
    x = transient + np.sin(2 * np.pi * 30 * T)
    whole = signals.channel_summary(T, x)
    late = signals.channel_summary(T, x, settle_fraction=0.25)
    assert whole["peak_to_peak"] > 20
    assert late["peak_to_peak"] == pytest.approx(2.0, rel=1e-3)
    assert late["dominant_hz"][0] == pytest.approx(30.0, abs=0.05)
    assert late["dominant_amplitudes"][0] == pytest.approx(1.0, rel=0.03)


def test_constant_and_short_signals_have_no_peaks():
    for x in (np.full(T.size, 3.3), np.zeros(T.size)):
        s = signals.channel_summary(T, x)
        assert s["dominant_hz"] == [] and s["dominant_amplitudes"] == []
        assert s["peak_to_peak"] == 0.0 and s["rms_alternating"] == 0.0
        assert all(np.isfinite(v) for k, v in s.items() if not k.startswith("dominant"))
    short = signals.channel_summary(T[:5], np.arange(5.0))
    assert short["dominant_hz"] == [] and short["peak_to_peak"] == 4.0
    assert signals.dominant_frequencies(T, np.zeros(T.size)) == []


def test_bad_time_raises():
    t = T.copy()
    t[500] += 1e-4
    with pytest.raises(ValueError, match="uniformly"):
        signals.spectrum(t, np.sin(t))
    with pytest.raises(ValueError, match="uniformly"):
        signals.channel_summary(t, np.sin(2 * np.pi * 10 * t))
    with pytest.raises(ValueError, match="at least 8"):
        signals.spectrum(T[:7], np.ones(7))


def test_summarise_nested_labels():
    nt = T.size
    sines = np.stack([np.sin(2 * np.pi * f * T) for f in (10, 20)], axis=1)
    channels = {"arm_angle_deg": 30 + 0.1 * np.sin(2 * np.pi * 15 * T),
                "span_tensions_N": 400 + 10 * sines,
                "hub_forces_N": np.stack([sines, -2 * sines], axis=2)}
    columns = {"span_tensions_N": ["tight", "slack"], "hub_forces_N": ["crank", "alternator"]}
    out = signals.summarise(T, channels, columns, settle_fraction=0.1)
    assert list(out["arm_angle_deg"]) == ["arm_angle_deg"]
    assert list(out["span_tensions_N"]) == ["tight", "slack"]
    assert list(out["hub_forces_N"]) == ["crank x", "crank y", "alternator x", "alternator y"]
    assert out["hub_forces_N"]["alternator y"]["dominant_hz"][0] == pytest.approx(20.0, abs=0.05)
    assert out["hub_forces_N"]["alternator y"]["peak_to_peak"] == pytest.approx(4.0, rel=0.01)
    assert out["span_tensions_N"]["slack"]["mean"] == pytest.approx(400.0, abs=0.05)
    json.dumps(out)
    bad = dict(channels, span_forces_N=np.full((nt, 2), np.nan))
    with pytest.raises(ValueError, match="span_forces_N"):
        signals.summarise(T, bad, columns)


def test_plots_write_png(tmp_path):
    from beltjax import plotting

    t = np.arange(1500) / 1000.0
    w = 2 * np.pi * t[:, None]
    f3 = np.array([35.0, 70.0, 12.0])
    channels = {
        "span_tensions_N": 300 + 20 * np.sin(w * f3[:2]),
        "hub_forces_N": np.stack([100 * np.cos(w * f3), 50 * np.sin(w * f3)], axis=2),  # (nt, 3, 2)
        "arm_angle_deg": 20 + np.sin(2 * np.pi * 7 * t),
        "not_a_channel": np.zeros(t.size),  # ignored
    }
    columns = {"span_tensions_N": ["tight", "slack"], "hub_forces_N": ["crank", "alternator", "tensioner"]}
    units = {"span_tensions_N": "N", "hub_forces_N": "N", "arm_angle_deg": "deg"}
    p1, p2 = tmp_path / "sim.png", tmp_path / "spec.png"
    plotting.plot_simulation(t, channels, columns, units, p1, title="synthetic drive")
    plotting.plot_spectra(t, channels, columns, units, p2, title="synthetic drive", settle_fraction=0.2)
    for p in (p1, p2):
        assert p.stat().st_size > 1000
        assert p.read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"
    assert plotting._channel_unit("node_displacements_m", units, "m") == ("m", 1e3, "mm")  # drawn in mm
