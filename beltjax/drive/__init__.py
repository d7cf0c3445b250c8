"""The hybrid drive model (thesis ch. 4): one kinematic map, reduced mass and forces.

Bodies and spans
----------------
Every route entry is a rigid pulley (the tensioner's idler included) with full
coordinates ``(x, y, angle)`` of its centre; a tensioner adds its arm as one more
rigid body ``(x_cm, y_cm, theta)``.  Each span between consecutive route entries
is a chain of ``N`` ANCF elements (``N + 1`` nodes of ``(x, y, x', y')``, global
frame).  The full coordinate vector ``q`` stacks the spans, then the bodies.

Independent coordinates ``q_i``
-------------------------------
* the rotation perturbation ``phi`` (rad, CCW) of every pulley that is not
  driven (a driven pulley's motion is prescribed: zero in statics and modal);
* the tensioner arm's angle change ``dtheta`` (rad) from the installation angle;
* per span, the two end slopes and all coordinates of its interior nodes (4 N).

The kinematic map ``q = Phi(q_i)`` (:func:`full_coordinates`) holds every
constraint of the drive (eqs. 4.37-4.46, 4.99-4.113 of the thesis): pulley centres
fixed or carried by the arm, and span end nodes pinned at their tangent points.
A span end node sits at its installation tangent point, is carried rigidly with
its pulley's centre (the arm for the idler) and slides along the span by
``s R phi`` when its pulley turns by ``phi`` (``s`` the wrap sense).  ``phi`` is
only the perturbation: the belt's steady motion is the transport speed ``c`` of
the Eulerian (ALE) span elements, so a steadily turning pulley does not drag
the span nodes away from the tangent points.

Reduced equations: ``M_ii = J^T M J`` and ``F_ii = J^T (F - M gamma)`` with the
Jacobian ``J = dPhi/dq_i`` (autodiff; it is the junction structure of the
power-port picture) and ``gamma = dJ/dt q_i_dot``.  ``F`` holds only the effects
the scene lists (``[model] effects``): elastic forces always, ``transport``
(gyroscopic + centrifugal terms of the moving belt) and ``gravity`` when asked
for; an effect not listed is not traced into the compiled function.
The rotational model's spans are massless bars, so the same equations need only the bodies'
rows of ``J`` and the span lengths ``l(q_i)`` (:func:`span_lengths`, closed form):
:func:`reduced_accelerations` takes that road for it (tests/test_fast_paths.py checks it
against the dense ``J^T M J`` solve with every effect).

Units: SI throughout (m, rad, N, N m, kg, kg m^2, s).
"""

from beltjax.drive.topology import GRAVITY, Installation, belt_speed, body_names, canonical, drive_pulley, element_length, flexible, is_free, n_full, n_independent, n_rigid, n_span_coordinates, section, span_elements, span_names, static_dofs, statics_scene, travel_coordinate, travel_follows_drive  # noqa: F401
from beltjax.drive.kinematics import _body_coordinates, _centers, _moved_tangents, _rim_slides, _span_ends, _split, angles_and_arm, arm_row, belt_travel, full_coordinates, installed_coordinates, end_slides, free_lengths, n_reaction_points, rotor_angles, span_lengths, span_lengths_and_jacobian, split_full, wraps  # noqa: F401
from beltjax.drive.effects import MODULES as EFFECT_MODULES, Effect, Effects, belt_weight_slide_moments, effects_of, span_dissipation  # noqa: F401
from beltjax.drive.forces import bar_axial_force, has_mean_loads, lasting_loads, mean_body_loads, span_potential, _window, body_forces, body_masses, full_forces, full_mass_matrix, span_forces, span_load_force, spring_moment, torque  # noqa: F401
from beltjax.drive.rotational import BodiesJacobian, _bar_accelerations, bar_accelerations, bodies_jacobian  # noqa: F401
from beltjax.drive.equations import ReducedMass, TravelInertia, UNROLLED_SOLVE_MAX, schur_accelerations, _full_motion, _rim_transport_speed, _small_matmul_tn, _small_spd_solve, _travel_gain, _travel_rates, full_motion, reduced_accelerations, reduced_mass, reduced_system, span_coordinate_index, span_transport_matrices, static_residual, steady_forces, drive_torque, transient_transport_speed, transport_speed, travel_inertia, with_travel_inertia  # noqa: F401
from beltjax.drive.spans import AncfSpans, BarSpans, SpanModel, bar_energy, spans_of  # noqa: F401
from beltjax.drive.layouts import FixedCentres, Layout, TensionerArm, layout_of  # noqa: F401
from beltjax.drive.assembly import Drive, drive_of  # noqa: F401
from beltjax.drive.outputs import full_span_lengths, hub_forces, span_tension_profile, span_tensions  # noqa: F401
