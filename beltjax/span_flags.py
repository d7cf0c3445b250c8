"""Spans a transient flags in its outputs, and the one-line warnings of a run.

Both fidelities assume taut spans wrapped on their pulleys and pulling on them.  At every
output sample a span whose elastic tension is <= 0 has gone slack (:func:`slack_spans`), and
one whose force on the pulleys (tension less rhoA c^2 lam, :mod:`beltjax.critical`) is <= 0
has passed the critical belt speed (:func:`supercritical_spans`): the model's answer there
is not physical.  One mechanism finds both (:func:`span_episodes`); :func:`run_warnings`
words them, with the excitation warnings of :mod:`beltjax.excitation`, one line each, as
``beltjax simulate`` prints them.
"""

from __future__ import annotations

import numpy as np

from beltjax import excitation


def span_episodes(t, values, names, value_key: str, at_first: dict | None = None, what: str = "span") -> list[dict]:
    """Spans whose ``values`` (nt, n) fell to zero or below at an output sample of t (s).

    One record per such span (or pulley: ``what`` names the record's key): span, ``value_key``
    (the lowest value), t_first_s, t_last_s
    (the first and last such samples), samples (how many) and, for each name -> (nt,) array
    of ``at_first``, its value at the first such sample; [] when none did.  Dips shorter than
    the output interval can pass between samples.  The one mechanism of :func:`slack_spans`
    and :func:`supercritical_spans`.
    """
    out = []
    for j, name in enumerate(names):
        bad = np.flatnonzero(values[:, j] <= 0.0)
        if bad.size:
            rec = {what: name}
            rec.update(t_first_s=float(t[bad[0]]), t_last_s=float(t[bad[-1]]), samples=int(bad.size))
            rec[value_key] = float(np.min(values[:, j]))
            rec.update({k: float(v[bad[0]]) for k, v in (at_first or {}).items()})
            out.append(rec)
    return out


def slack_spans(t, tensions, names) -> list[dict]:
    """Spans whose elastic tension (N) fell to zero or below at an output sample of t (s).

    Both fidelities assume taut spans wrapped on the pulleys: a belt cannot push, so where a
    span's tension goes negative the real belt hangs slack and the model's answer there is
    not physical.  Returns one record per such span: span, min_tension_N, t_first_s,
    t_last_s (the first and last slack samples) and samples (how many); [] when all stayed
    taut.  Dips shorter than the output interval can pass between samples.
    """
    return span_episodes(t, tensions, names, "min_tension_N")


def supercritical_spans(t, forces, names, belt_speed, tensions=None) -> list[dict]:
    """Spans whose force on the pulleys (tension less rhoA c^2 lam, N: :mod:`beltjax.critical`)
    fell to zero or below at an output sample of t (s) while their tension (N, (nt, n), when
    given) stayed positive: past the critical belt speed (a slack span is :func:`slack_spans`'s).

    Both fidelities then describe a belt that would lift off its pulleys (and the hybrid
    model's span has lost its transverse stiffness): not physical.  Records as
    :func:`slack_spans` with min_force_N and belt_speed_m_s (m/s) at the first such sample.
    """
    if tensions is not None:
        forces = np.where(np.asarray(tensions) > 0.0, forces, np.inf)
    return span_episodes(t, forces, names, "min_force_N", {"belt_speed_m_s": belt_speed})


def slack_warning(record: dict) -> str:
    """One line saying that (and when) a span went slack, from a :func:`slack_spans` record,
    or passed the critical speed, from a :func:`supercritical_spans` record."""
    when = f"{record['samples']} output samples between t = {record['t_first_s']:.4g} and {record['t_last_s']:.4g} s"
    if "min_force_N" in record:
        return (f"warning: span {record['span']!r} passed the critical speed ({when}, from belt speed "
                f"{record['belt_speed_m_s']:.4g} m/s; its force on the pulleys, tension less rhoA c^2 lam, down to "
                f"{record['min_force_N']:.4g} N): the belt would lift off the pulleys, so the results there are not "
                "physical")
    return (f"warning: span {record['span']!r} went slack ({when}, tension down to {record['min_tension_N']:.4g} N): "
            "the model assumes taut spans, so its results there are not physical")


def slipping_pulleys(t, margins, names) -> list[dict]:
    """Pulleys whose slip margin (-, :mod:`beltjax.friction`) fell to zero or below at an output
    sample of t (s): the capstan limit of their arc was reached.  Records as
    :func:`slack_spans` with pulley and min_slip_margin."""
    return span_episodes(t, margins, names, "min_slip_margin", what="pulley")


def slip_warning(record: dict) -> str:
    """One line saying that (and when) a pulley's arc reached its capstan limit; the record's
    ``slides`` says whether the run's belt slides there (effect ``belt_slip``) or grips."""
    when = (f"({record['samples']} output samples between t = {record['t_first_s']:.4g} and "
            f"{record['t_last_s']:.4g} s, slip margin down to {record['min_slip_margin']:.3g})")
    if record.get("slides"):
        return (f"warning: the belt slid on {record['pulley']!r} {when}: the capstan limit was exceeded and the arc "
                "slid (belt_slip; see slip_speeds_m_s and friction_power_W)")
    return (f"warning: the belt would slip on {record['pulley']!r} {when}: the capstan limit is exceeded, and this "
            "model's belt does not slip (list belt_slip for its sliding)")


#: a span whose strain (tension / EA) passes this during a run is flagged: belts run at well below
#: 1 %, and the model's linear-elastic section has no footing far beyond
MAX_RUN_STRAIN = 0.05


def overstretched_spans(t, tensions, EA: float, names) -> list[dict]:
    """Spans whose strain T / EA (tensions (nt, n) N, EA N) passed :data:`MAX_RUN_STRAIN` at an
    output sample of t (s).  Records as :func:`slack_spans` with max_strain (-)."""
    return _beyond(t, np.asarray(tensions) / EA, MAX_RUN_STRAIN, names, "max_strain")


def _beyond(t, values, limit: float, names, key: str) -> list[dict]:
    """:func:`span_episodes` of spans whose ``values`` (nt, n) passed ``limit``, each record with its
    largest value under ``key``."""
    out = span_episodes(t, limit - values, names, "_margin")
    for r in out:
        del r["_margin"]
        r[key] = float(np.max(values[:, list(names).index(r["span"])]))
    return out


def overstretch_warning(record: dict) -> str:
    """One line saying that (and when) a span stretched beyond :data:`MAX_RUN_STRAIN`."""
    return (f"warning: span {record['span']!r} stretched by up to {100 * record['max_strain']:.3g} % "
            f"({record['samples']} output samples between t = {record['t_first_s']:.4g} and {record['t_last_s']:.4g} "
            f"s), beyond the {100 * MAX_RUN_STRAIN:g} % the model's linear-elastic belt is meant for: its results "
            "there are not physical")


#: the hybrid model's end nodes sit off their tangent points by the belt's axial perturbation
#: displacement there; beyond this fraction of a span's length the run flags the span
END_SLIDE_FRACTION = 0.05


def displaced_span_ends(t, slides, lengths, names) -> list[dict]:
    """Spans of a hybrid run whose end nodes sat more than :data:`END_SLIDE_FRACTION` of the
    span's length from their tangent points at an output sample of t (s).

    slides (nt, n, 2) m: each span's start and end node offsets along the span
    (:func:`beltjax.drive.end_slides`); lengths (n,) m.  The model carries the belt's axial
    perturbation displacement at a span's ends by sliding its end nodes along the span line: a
    slide along a straight span leaves tensions and pulley motion unchanged
    (tests/test_transient.py), but the span's transverse boundary, hence its free length, is off
    by as much.  Records as :func:`slack_spans` with max_end_slide_mm and fraction_of_span.
    """
    size = np.max(np.abs(np.asarray(slides)), axis=2)  # (nt, n) m: the farther end of each span
    frac = size / np.asarray(lengths)[None, :]
    out = _beyond(t, frac, END_SLIDE_FRACTION, names, "fraction_of_span")
    for r in out:
        r["max_end_slide_mm"] = 1e3 * float(np.max(size[:, list(names).index(r["span"])]))
    return out


def end_slide_warning(record: dict) -> str:
    """One line saying that (and when) a hybrid span's end nodes sat far from its tangent points."""
    return (f"warning: span {record['span']!r}: its end nodes sat up to {record['max_end_slide_mm']:.3g} mm "
            f"({100 * record['fraction_of_span']:.3g} % of the span) from the tangent points ({record['samples']} output "
            f"samples between t = {record['t_first_s']:.4g} and {record['t_last_s']:.4g} s): the hybrid model carries "
            "the belt's axial displacement there by sliding them along the span, so the span's free length and its "
            "transverse motion are approximate by that much (tensions and pulley motion are not affected)")


def run_warnings(meta: dict) -> list[str]:
    """The one-line warnings of a run, from its meta: slack spans, spans past the critical
    speed (:func:`slack_warning`), spans stretched too far (:func:`overstretch_warning`), arcs past their capstan limit (:func:`slip_warning`), hybrid
    spans whose ends slid far (:func:`end_slide_warning`) and forcing the step resolves poorly
    (:func:`beltjax.excitation.warning`)."""
    lines = [slack_warning(r) for k in ("slack_spans", "supercritical_spans") for r in meta.get(k, [])]
    lines += [overstretch_warning(r) for r in meta.get("overstretched_spans", [])]
    lines += [slip_warning(r) for r in meta.get("slipping_pulleys", [])]
    lines += [end_slide_warning(r) for r in meta.get("displaced_span_ends", [])]
    return lines + [excitation.warning(r) for r in meta.get("excitation_warnings", [])]


def check_initial_strain(qi, scene, inst):
    """``qi`` (m, rad), the transient's start from ``[initial]``, when no span is stretched beyond
    the installation's limit (:data:`beltjax.statics.MAX_INSTALL_STRAIN`, of its unstretched
    length) there; else a one-line :class:`beltjax.errors.BeltjaxError` naming the ``[initial]``
    key: a pulley turned by turns pulls metres of belt through its spans, which no belt stretches
    to and no solver step survives.  A start that slackens a span (an arm released) passes: the
    run reports it."""
    from beltjax import drive, statics
    from beltjax.errors import BeltjaxError

    unstretched = np.asarray(inst.span_length) / float(inst.stretch)  # (m) as drive.element_length
    strain = np.asarray(drive.span_lengths(qi, scene, inst)) / unstretched - 1
    j = int(np.argmax(strain))
    if strain[j] > statics.MAX_INSTALL_STRAIN:
        keys = [f"initial.rotation_deg.{n}" for n, _ in scene.initial.rotation_deg]
        keys += ["initial.arm_angle_deg"] if scene.initial.arm_angle_deg is not None else []
        raise BeltjaxError(f"the start stretches span {drive.span_names(scene)[j]} by {100 * strain[j]:.3g} % of "
                           f"its unstretched length, beyond the {100 * statics.MAX_INSTALL_STRAIN:g} % a belt is "
                           "installed at: turn the pulleys by less", keys[0] if len(keys) == 1 else "initial")
    return qi
