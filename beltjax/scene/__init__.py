"""Scene files: reading and validating TOML drive descriptions into pytrees.

The format is the contract of ``DESIGN.md`` ("Scene files"); this module adds
only optional keys.  Units SI, angles in degrees where a key ends in ``_deg``,
speeds in rpm where it ends in ``_rpm``.  Tables and keys:

``[belt]``      EA (N), EI (N m^2), rhoA (kg/m); exactly one of static_tension (N)
                and length (unstretched, m).  Optional: CA (N s, viscous axial
                damping parameter of the thesis, span damping c = CA / L), default 0.
``[[pulley]]``  name, center [x, y] (m), radius (m), mass (kg), inertia (kg m^2);
                optional driven (bool, default false), speed_rpm (driven pulleys
                only, default 0).  Optional additions: acceleration_rpm_per_s and
                fluctuation_amplitude_deg / fluctuation_frequency_hz (driven
                pulleys only: theta(t) = theta0 + w t + a t^2 / 2 + A sin(2 pi f t),
                thesis eq. 4.62), cm_offset [x, y] (m, centre-of-mass offset in the
                pulley frame, the "unbalance" effect, thesis eq. 4.5),
                bearing_damping (N m s/rad), target_speed_rpm (driven only: the
                run-up holds this speed once reached).  All default to 0 / none.
                Signs: the belt runs in the route's direction; speed_rpm is its
                drive pulley's speed along that direction (its sign is ignored),
                acceleration > 0 speeds it up.
``[tensioner]`` optional; pivot [x, y] (m), arm_length (m), pulley_radius (m),
                arm_mass (kg), arm_inertia (kg m^2, about the arm's centre of mass),
                pulley_mass (kg), pulley_inertia (kg m^2), spring_stiffness
                (N m/rad), spring_preload_deg (the arm angle at zero spring moment).
                Optional additions: arm_angle_deg (initial guess / installed arm
                angle, CCW from +x, pivot -> idler), arm_cm_distance (m, pivot to
                the arm's centre of mass along the arm, default 0), damping
                (N m s/rad at the pivot, default 0).  Its idler is "tensioner" in
                the route.
``[route]``     order (names in the belt's direction of travel), back_side
                (default []), direction ("cw" default, or "ccw").
``[model]``     fidelity ("ancf" default, or "rotational"), elements_per_span
                (int, 1 to 400, default 16), effects (subset of :data:`EFFECTS`,
                default []), optional bending ("linear" default, or "exact").
``[[torque]]``  optional loads: pulley (a free route entry, or "tensioner_arm"), mean_Nm, amplitude_Nm,
                frequency_hz, phase_deg, t_start_s, t_end_s: a moment (N m, CCW
                positive) mean + amplitude sin(2 pi f t + phase) in [t_start, t_end).
``[[span_load]]`` optional (hybrid model only): span ("<from>-<to>"), node
                (interior, 1..N-1), amplitude_N, frequency_hz, phase_deg, t_start_s,
                t_end_s: a harmonic force normal to the installed span.
``[initial]``   optional transient start: rotation_deg = {pulley = deg} added to the
                static equilibrium, arm_angle_deg (absolute).
``[simulation]`` optional transient settings: solver (:data:`SOLVERS`; default by
                fidelity, see beltjax.transient.default_solver), dt_s,
                rho_inf, rtol, atol, output_dt_s, nodes (["<span>:<node>"]), max_steps.
Top level:      optional ``description`` (string).

An effect's parameter given while the effect is not in ``model.effects`` (belt.CA
without "belt_damping", cm_offset without "unbalance", ...) is an error, never
silently ignored.  Loads act when their tables are present; statics and modal
analysis ignore damping and loads (they are of the undamped, unloaded drive).

Every problem raises :class:`SceneError` (a ``ValueError``) with a one-line
message that starts with the key path, e.g. ``pulley[1].radius: must be > 0,
got -0.01`` (``pulley[i]`` counts the ``[[pulley]]`` tables from 0 in file
order); file-level problems start with the file name.

Every number must lie in its accepted range (below, from :mod:`beltjax.schema`: wide
enough for every real belt drive, inside what float64 carries), e.g. ``belt.EI: must lie
in [0, 100000] N m^2 (...), got 1e+20``; the whole drive then passes the layout checks and
the derived float64 limits of :mod:`beltjax.validate` (the same checks as a parameter set
with :mod:`beltjax.parameters`, a sweep case and the Python API).

The parsed :class:`Scene` is an equinox Module: every number is a float64 jax
array leaf (so ``jax.grad`` / ``eqx.filter_grad`` reach centres, radii,
stiffnesses...), names and switches are static fields.

"""

from beltjax.scene.spec import ARM, Belt, DIRECTIONS, EFFECTS, FIDELITIES, Initial, MAX_ELEMENTS_PER_SPAN, Model, Pulley, Route, SOLVERS, Scene, SceneError, Simulation, SpanLoad, TENSIONER, Tensioner, Torque, require_scene  # noqa: F401
from beltjax.scene.sections import _BELT_KEYS, _DRIVEN_ONLY, _INITIAL_KEYS, _MODEL_KEYS, _PULLEY_KEYS, _ROUTE_KEYS, _SIMULATION_KEYS, _SPAN_LOAD_KEYS, _TENSIONER_KEYS, _TOP_KEYS, _TORQUE_KEYS, _arr, _check_effects, _fail, _num, _parse_belt, _parse_initial, _parse_model, _parse_pulley, _parse_route, _parse_simulation, _parse_span_loads, _parse_tensioner, _parse_torques, _table, _vec, _window  # noqa: F401
from beltjax.scene.read import _check_geometry, _key_for, load_scene, loads_scene, parse_scene  # noqa: F401
from beltjax.scene.write import dumps_scene, scene_document, write_scene  # noqa: F401

from beltjax import schema as _schema  # noqa: E402

if __doc__:  # (None under python -OO)
    __doc__ += _schema.scene_doc()  # the accepted ranges: one source, beltjax.schema
