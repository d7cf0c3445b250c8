"""The text tables the commands print: span modes, statics, modal table, Campbell summary, transient
channels (units in the column heads)."""

from __future__ import annotations


def span_table(result, n_rows: int = 12) -> str:
    """A readable table of a SpanResult (first n_rows modes plus the first longitudinal ones)."""
    import numpy as np

    r = result
    head = (f"span {r.bc[0]}-{r.bc[1]}: L = {r.length:g} m, T = {r.tension:g} N, c = {r.speed:g} m/s, "
            f"EA = {float(r.section.EA):g} N, EI = {float(r.section.EI):g} N m^2, "
            f"rhoA = {float(r.section.rhoA):g} kg/m, {r.n_elements} elements ({r.bending} bending)")
    lines = [head, f"critical speed {r.critical_speed_m_s:.2f} m/s; " + ("stable" if r.stable else "UNSTABLE")]
    if not r.stable:
        lines.append("past the critical speed the span is unstable (it diverges, or is held only by gyroscopic "
                     "coupling, which any damping destroys); unstable eigenvalues [1/s]:")
        lines += [f"  {lam.real:+.4g} {lam.imag:+.4g}j" for lam in r.unstable_eigenvalues]
        return "\n".join(lines)
    show_formula = r.speed == 0.0 and r.bc == ("pinned", "pinned")
    lines.append(f"{'mode':>4}  {'frequency [Hz]':>14}  {'label':<20} {'transverse share':>16}"
                 + (f"  {'beam formula [Hz]':>17}" if show_formula else ""))
    rows = list(range(min(n_rows, len(r.frequencies_hz))))
    rows += [i for i, lab in enumerate(r.labels) if lab.endswith("longitudinal")][:3]
    for i in sorted(set(rows)):
        line = f"{i + 1:>4}  {r.frequencies_hz[i]:>14.2f}  {r.labels[i]:<20} {r.transverse_share[i]:>16.3f}"
        if show_formula and r.labels[i].endswith("transverse"):
            n = int(r.labels[i].split()[0][:-2])
            EI, rhoA, L = float(r.section.EI), float(r.section.rhoA), r.length
            f = n / (2 * L) * np.sqrt((r.tension + EI * (n * np.pi / L) ** 2) * r.stretch / rhoA)
            line += f"  {f:>17.2f}"
        lines.append(line)
    lines.append(f"({len(r.frequencies_hz)} modes in all; beam formula: n/(2L) sqrt((T + EI (n pi/L)^2)/rhoA'),"
                 " rhoA' per stretched length)" if show_formula else f"({len(r.frequencies_hz)} modes in all)")
    return "\n".join(lines)


def statics_table(res) -> str:
    """Span tensions, hub forces and the tensioner's state of a StaticResult, as text."""
    import numpy as np

    state = res.state
    if res.state == "operating point":
        loads = ", ".join(f"{k} {v:+.4g} N m" for k, v in res.loads_Nm.items())
        state = f"operating point (mean loads: {loads})"
    lines = [f"belt: unstretched length {res.belt_length_m:.6g} m, installation tension "
             f"{res.installation_tension_N:.4g} N, stretch {res.stretch:.6f}, belt speed {res.speed_m_s:g} m/s",
             f"state: {state}"]
    unloaded = res.unloaded["span_tensions_N"] if res.unloaded else None
    head = f"{'span':<26} {'length [m]':>11} {'tension [N]':>12}" + (f" {'unloaded [N]':>13}" if unloaded else "")
    lines += ["", head]
    free = res.span_lengths_m if res.span_free_lengths_m is None else res.span_free_lengths_m  # tangent to tangent
    for i, (name, L, T) in enumerate(zip(res.span_names, free, res.span_tensions_N)):
        lines.append(f"{name:<26} {float(L):>11.5f} {float(T):>12.2f}" + (f" {unloaded[i]:>13.2f}" if unloaded else ""))
    lines += ["", f"{'hub (force of the belt)':<26} {'Fx [N]':>10} {'Fy [N]':>10} {'|F| [N]':>10} {'wrap [deg]':>11}"]
    for name, F in res.hub_forces_N.items():
        F = np.asarray(F, float)
        lines.append(f"{name:<26} {F[0]:>10.2f} {F[1]:>10.2f} {np.hypot(*F):>10.2f} "
                     f"{res.wrap_angles_deg.get(name, float('nan')):>11.2f}")
    if res.tensioner_angle_deg is not None:
        px, py = res.tensioner_pivot_force_N
        lines += ["", f"tensioner: arm angle {res.tensioner_angle_deg:.3f} deg, spring moment "
                  f"{res.spring_moment_Nm:.4g} N m, pivot force ({px:.2f}, {py:.2f}) N"]
    for name, d in res.decouplers.items():
        lines += ["", f"decoupler on {name}: wound up {d['windup_deg']:.4g} deg, moment {d['moment_Nm']:.4g} N m"]
    if res.state == "operating point":
        lines += ["", f"drive torque (on the drive pulley, CCW +): {res.drive_torque_Nm:.4g} N m"]
    if any(v["friction_needed"] > 1e-9 for v in res.friction.values()):
        lines += ["", f"{'arc (capstan law)':<26} {'mu needed':>10} {'mu avail.':>10} {'slip margin':>12} "
                      f"{'sliding [deg]':>14} {'creep loss':>11}"]
        for name, v in res.friction.items():
            have = "-" if v["friction_available"] is None else f"{v['friction_available']:.3f}"
            margin = "-" if v["slip_margin"] is None else f"{v['slip_margin']:+.3f}"
            arc = "-" if v["sliding_arc_deg"] is None else f"{v['sliding_arc_deg']:.1f}"
            creep = "-" if v["creep_speed_loss"] is None else f"{100 * v['creep_speed_loss']:.3f} %"
            lines.append(f"{name:<26} {v['friction_needed']:>10.3f} {have:>10} {margin:>12} {arc:>14} {creep:>11}"
                         + ("  SLIPS" if v["slip_margin"] is not None and v["slip_margin"] < 0 else ""))
    lines.append(f"Newton iterations: {res.iterations}")
    return "\n".join(lines)


def modal_table(m, n_modes: int) -> str:
    """Mode number, frequency and label of the first n_modes modes of a ModalResult."""
    if not m.stable:
        lines = [f"UNSTABLE at belt speed {m.speed_m_s:g} m/s: {m.unstable_reason}"]
        if len(m.unstable_eigenvalues):
            lines.append("unstable eigenvalues [1/s]:")
            lines += [f"  {lam.real:+.4g} {lam.imag:+.4g}j" for lam in m.unstable_eigenvalues]
        return "\n".join(lines)
    k = min(n_modes, len(m.frequencies_hz))
    lines = [f"{'mode':>4}  {'frequency [Hz]':>14}  label"]
    lines += [f"{i + 1:>4}  {m.frequencies_hz[i]:>14.2f}  {m.labels[i]}" for i in range(k)]
    lines.append(f"({k} of {len(m.frequencies_hz)} modes shown; {m.n_independent} independent coordinates)")
    return "\n".join(lines)


def _panels_note(m, n_modes: int) -> str:
    """The line saying which modes modes.png draws (and that it draws at most MAX_MODE_PANELS)."""
    from beltjax.plotting import MAX_MODE_PANELS, mode_panels

    picks, available = mode_panels(m, n_modes, n_modes)
    if not picks:
        return "modes.png: no flexible mode to draw"
    shown = ", ".join(str(i + 1) for i in picks)
    more = (f"; {available - len(picks)} more flexible modes not drawn (at most {MAX_MODE_PANELS} panels)"
            if available > len(picks) else "")
    return f"modes.png: the flexible modes among the first {n_modes}: {shown}{more}"


def campbell_summary(c, n_rows: int = 12) -> str:
    """Frequencies at the lowest and highest speeds of each tracked mode, the crossings (each
    with the label of the mode that crosses, read from its shape there) and the label changes
    (veering) of a CampbellResult."""
    import numpy as np

    F = np.asarray(c.frequencies_hz, float)
    r0, r1 = c.rpm[0], c.rpm[-1]
    lines = [f"{len(c.rpm)} speeds of the {c.drive_pulley} pulley, {r0:g} to {r1:g} rpm; "
             f"orders {', '.join(f'{k:g}x' for k in c.orders)}"]
    if not c.transport:
        lines.append("note: the scene does not list the \"transport\" effect, so the frequencies do not depend on "
                     "speed (add \"transport\" to [model] effects)")
    unstable = ~np.asarray(c.stable, bool)
    failed = ~np.asarray(c.converged, bool)
    if np.any(failed):
        bad = np.asarray(c.rpm)[failed]
        lines.append(f"no frequencies at {int(failed.sum())} of {len(c.rpm)} speeds (from {bad.min():g} rpm): "
                     "no steady-motion equilibrium found there")
    if np.any(unstable & ~failed):
        bad = np.asarray(c.rpm)[unstable & ~failed]
        lines.append(f"UNSTABLE at {int((unstable & ~failed).sum())} of {len(c.rpm)} speeds (from {bad.min():g} rpm): "
                     "past a critical speed, no natural frequencies")
    k = min(n_rows, F.shape[1])
    tracked = getattr(c, "tracked", False)
    head = ("label (each mode followed across speeds by its shape)" if tracked
            else f"label (at {r0:g} rpm; modes sorted by frequency)")
    lines += ["", f"{'mode':>4}  {f'{r0:g} rpm [Hz]':>14}  {f'{r1:g} rpm [Hz]':>14}  {head}"]
    fmt = lambda x: f"{x:>14.2f}" if np.isfinite(x) else f"{'-':>14}"  # noqa: E731
    for i in range(k):
        lines.append(f"{i + 1:>4}  {fmt(F[0, i])}  {fmt(F[-1, i])}  {c.labels[i]}")
    if F.shape[1] > k:
        lines.append(f"({k} of {F.shape[1]} modes shown)")
    lines.append("")
    if c.crossings:
        lines.append(f"{len(c.crossings)} crossings (mode meets order line):")
        for x in c.crossings:
            lines.append(f"  {x['rpm']:>8.1f} rpm  {x['frequency_hz']:>8.2f} Hz  order {x['order']:g}x  "
                         f"mode {x['mode']} ({x['label']})")
    else:
        lines.append("no crossings in this speed range")
    changes = getattr(c, "label_changes", None) or []
    if changes:
        lines.append(f"{len(changes)} label changes along a mode (veering: two modes exchange their shapes):")
        for x in changes:
            lines.append(f"  mode {x['mode']} between {x['after_rpm']:g} and {x['rpm']:g} rpm: {x['from']} -> {x['to']}")
    uncertain = c.uncertain() if tracked else []
    if uncertain:
        from beltjax.mode_tracking import UNCERTAIN_MAC

        where = sorted({u["rpm"] for u in uncertain})
        lines.append(f"tracking uncertain at {len(where)} speeds (a mode's shape changes much within one step, "
                     f"MAC < {UNCERTAIN_MAC:g}; from {where[0]:g} rpm): a finer --rpm step resolves it")
    return "\n".join(lines)


_STEMS = {"slip_margins": "slip margin", "slip_speeds_m_s": "gross slip speed", "creep_speeds_m_s": "creep speed"}


def simulation_table(res, summary) -> str:
    """Mean, peak-to-peak and dominant frequencies of the main channels of a simulation."""
    m = res.meta
    units = summary["units"]
    rows = []
    for name in ("span_tensions_N", "span_forces_N", "hub_force_magnitudes_N", "pulley_speeds_rpm",
                 "rotor_speeds_rpm", "decoupler_moments_Nm", "isolator_moment_Nm", "arm_angle_deg",
                 "spring_moment_Nm", "pivot_friction_moment_Nm", "pivot_friction_power_W", "drive_torques_Nm",
                 "node_displacements_m", "slip_margins", "slip_speeds_m_s", "creep_speeds_m_s", "friction_power_W"):
        if name not in summary["channels"]:
            continue
        for col, st in summary["channels"][name].items():
            stem = _STEMS.get(name) or name.rsplit('_', 1)[0].replace('_', ' ')
            label = f"{stem}: {col}" if col != name else name
            dom = ", ".join(f"{f:.4g}" for f in st["dominant_hz"]) or "-"
            rows.append((" ".join(label.split()), st, dom, units[name]))
    width = max([len("channel")] + [len(r[0]) for r in rows])  # the longest channel name, never cut
    lines = [f"{m['fidelity']} model, {m['n_independent']} independent coordinates; solver {m['solver']}, "
             f"dt {m['dt_s']:.3g} s, {m['steps']} steps; t = 0 to {m['t_end_s']:g} s; "
             f"wall {m['wall_s']:.1f} s (first chunk with compilation {m['first_chunk_s']:.1f} s)",
             "", f"{'channel':<{width}} {'mean':>10} {'peak-peak':>10}  dominant [Hz]"]
    for label, st, dom, unit in rows:
        lines.append(f"{label:<{width}} {st['mean']:>10.4g} {st['peak_to_peak']:>10.4g}  {dom}  [{unit}]")
    return "\n".join(lines)
