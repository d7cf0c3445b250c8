"""The statics view of a scene (beltjax.drive.statics_scene): what statics and the modal analysis
read, one structure per drive, so that a scene's statics, its modes and its transients' start
share one compiled program.  No compilation here: structures and values only."""

import jax
import numpy as np

from beltjax import drive
from beltjax.scene import loads_scene

from _scenes import scene_text, substitute

# two alternator pulses, 1-3 s and 5-7 s; the hybrid model (span loads need its nodes)
TEXT = substitute(scene_text("sim_tensioner_fluctuation_load.toml"),
                  ('fidelity = "rotational"', 'fidelity = "ancf"\nelements_per_span = 2'))


def _variant():
    """The same drive with other transient tables: a lasting load, a load on at t = 0, a span load,
    an [initial] table."""
    return loads_scene(TEXT + '\n[[torque]]\npulley = "alternator"\nmean_Nm = 4.0\n'
                       '\n[[torque]]\npulley = "alternator"\nmean_Nm = 2.5\namplitude_Nm = 1.0\nfrequency_hz = 5.0\nt_end_s = 0.5\n'
                       '\n[[span_load]]\nspan = "tensioner-alternator"\nnode = 1\namplitude_N = 1.0\nfrequency_hz = 10.0\n'
                       '\n[initial]\nrotation_deg = { alternator = 1.0 }\n')


def test_one_structure_per_drive():
    """The scene, a variant with other transient tables, and the view at a transient's start
    have one tree structure (hence one compilation); the view of a view is the view."""
    sc, other = loads_scene(TEXT), _variant()
    views = [drive.statics_scene(sc), drive.statics_scene(other), drive.statics_scene(other, at_t=0.0),
             drive.statics_scene(drive.statics_scene(other))]
    structures = {jax.tree_util.tree_structure(v) for v in views}
    assert len(structures) == 1, structures
    assert jax.tree_util.tree_structure(sc) != structures.pop()  # the scene itself differs (its tables)
    for a, b in zip(jax.tree_util.tree_leaves(views[1]), jax.tree_util.tree_leaves(views[3])):
        np.testing.assert_array_equal(a, b)
    assert views[1].span_loads == () and views[1].initial.rotation_deg == ()


def test_merged_loads_are_the_steady_means():
    """Per loaded pulley one moment: the lasting loads' means (the operating point: 4 N m; the
    pulses and the load that ends are no part of it), or the loads acting at t (s): at 0, the
    lasting 4 and the 2.5 that ends at 0.5 s; at 2 s, the lasting 4 and the first 30 N m pulse."""
    other = _variant()
    mean = lambda v: [float(t.mean_Nm) for t in v.torques]  # noqa: E731
    assert mean(drive.statics_scene(other)) == [4.0]
    assert mean(drive.statics_scene(other, at_t=0.0)) == [6.5]
    assert mean(drive.statics_scene(other, at_t=2.0)) == [34.0]
    assert mean(drive.statics_scene(other, at_t=4.0)) == [4.0]
    t = drive.statics_scene(other, at_t=2.0).torques[0]
    assert t.pulley == "alternator" and t.t_end_s is None and float(t.amplitude_Nm) == 0.0
    assert drive.lasting_loads(drive.statics_scene(loads_scene(TEXT)))  # a zero steady moment still listed
    assert not drive.has_mean_loads(drive.statics_scene(loads_scene(TEXT)))
