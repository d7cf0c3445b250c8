"""An effect that a scene does not list adds nothing to the compiled program (issue 21).

The transient's vector field (the program ``simulate`` compiles) is traced with every array
of the scene as an input; after dead-code elimination, the inputs that belong to an effect
(``belt.CA`` to belt_damping, ``bearing_damping`` to bearing_damping, ``cm_offset`` to
unbalance, the fluctuation's amplitude and frequency to speed_fluctuation, the pivot damping to
tensioner_damping) must be unused when the effect is not listed, and used when it is (so the
test can fail).  Both fidelities: the rotational model's fast path and the ANCF model (2
elements per span).  Tracing only, nothing is compiled.
"""

from __future__ import annotations

import dataclasses
import pathlib
import sys

import equinox as eqx
import jax
import jax.numpy as jnp
import pytest
from jax._src.interpreters import partial_eval as pe  # dce_jaxpr: which inputs the program uses

from beltjax import drive, statics, transient
from beltjax.scene import loads_scene

sys.path.insert(0, str(pathlib.Path(__file__).parent))
from _scenes import scene_text  # noqa: E402

#: effect -> the scene arrays it owns (attribute names on the pytree path)
OWNS = {
    "belt_damping": ("CA",),
    "bearing_damping": ("bearing_damping",),
    "unbalance": ("cm_offset",),
    "speed_fluctuation": ("fluctuation_amplitude_deg", "fluctuation_frequency_hz"),
    "tensioner_damping": ("damping",),
}
ALL = ("transport", "belt_damping", "bearing_damping", "tensioner_damping", "unbalance", "speed_fluctuation")


def _scene(fidelity: str, effects: tuple[str, ...]):
    sc = loads_scene(scene_text("sim_tensioner_fluctuation_load.toml"))
    model = dataclasses.replace(sc.model, fidelity=fidelity, elements_per_span=2, effects=effects)
    return eqx.tree_at(lambda s: s.model, sc, model)


def _used_leaves(scene) -> dict[str, bool]:
    """{pytree path: whether the traced vector field uses that array}."""
    inst = statics.install(drive.canonical(scene))
    leaves, treedef = jax.tree_util.tree_flatten_with_path(scene)
    names = [jax.tree_util.keystr(p) for p, _ in leaves]
    n = drive.n_independent(scene)
    y = jnp.full(2 * n, 1e-3)

    def field(*arrays):
        sc = jax.tree_util.tree_unflatten(treedef, arrays)
        return transient.vector_field(sc, inst)(jnp.asarray(0.37), y, None)

    closed = jax.make_jaxpr(field)(*[x for _, x in leaves])
    _, used = pe.dce_jaxpr(closed.jaxpr, [True] * len(closed.jaxpr.outvars))
    return dict(zip(names, used))


def _owned(used: dict[str, bool], effect: str) -> dict[str, bool]:
    return {k: v for k, v in used.items() if any(k.endswith(f".{a}") for a in OWNS[effect])
            and not (effect == "bearing_damping" and "tensioner" in k)
            and not (effect == "tensioner_damping" and "tensioner" not in k)}


@pytest.mark.parametrize("fidelity", ["rotational", "ancf"])
def test_unlisted_effects_leave_no_trace(fidelity):
    every = _used_leaves(_scene(fidelity, ALL))
    for effect in OWNS:
        owned = _owned(every, effect)
        assert owned and any(owned.values()), (effect, owned)  # listed: its parameters reach the program
        without = _used_leaves(_scene(fidelity, tuple(e for e in ALL if e != effect)))
        assert not any(_owned(without, effect).values()), (effect, _owned(without, effect))
        # and nothing else the program used is lost
        others = {k for k, v in every.items() if v} - set(_owned(every, effect))
        assert {k for k in others if not without[k]} == set(), effect


def test_effects_are_switched_in_the_assembly_only():
    """Every listable effect is one module of beltjax.drive.effects, and no other module of the
    package asks the scene's model whether an effect is listed (issue 21: effect switching lives
    in the assembly, effects_of)."""
    import re

    from beltjax.drive import effects
    from beltjax.scene import EFFECTS

    assert tuple(effects.MODULES) == EFFECTS
    root = pathlib.Path(drive.__file__).resolve().parents[1]
    offenders = [f"{p.relative_to(root)}:{i + 1}" for p in sorted(root.rglob("*.py"))
                 for i, line in enumerate(p.read_text().splitlines())
                 if re.search(r"model\.has\(|in\s+\w+\.model\.effects", line)
                 and p.name != "effects.py" and "def has" not in line]
    assert offenders == [], offenders
    # the assembly is built once per list of names and holds only the listed modules
    sc = loads_scene(scene_text("sim_tensioner_fluctuation_load.toml"))
    fx = effects.effects_of(sc)
    assert fx is effects.effects_of(sc)
    assert {type(m).name for m in fx.listed} == set(sc.model.effects)


def test_an_unlisted_effects_parameter_cannot_be_swept_or_fitted():
    """The schema names each parameter's owning effect: moving a parameter whose effect the scene
    does not list (a sweep axis, an optimisation variable, a fitted value) would change nothing,
    so parameters.check refuses it, naming the effect; a listed one passes."""
    import dataclasses

    from beltjax import parameters
    from beltjax.errors import BeltjaxError

    sc = loads_scene(scene_text("two_pulley_T200.toml"))
    assert "belt_damping" not in sc.model.effects
    with pytest.raises(BeltjaxError, match=r'^belt\.CA: belongs to the effect "belt_damping"'):
        parameters.check(sc, "belt.CA")
    listed = dataclasses.replace(sc, model=dataclasses.replace(sc.model, effects=(*sc.model.effects, "belt_damping")))
    assert parameters.check(listed, "belt.CA") == "belt.CA"
    assert parameters.check(sc, "belt.EI") == "belt.EI"  # no owning effect


def test_every_effect_owns_the_schema_fields_that_name_it():
    from beltjax import schema
    from beltjax.drive.effects import MODULES

    owned = {k for m in MODULES.values() for k in m().parameters()}
    assert owned == {k for k, f in schema.FIELDS.items() if f.effect}
    assert all(f.effect in MODULES for f in schema.FIELDS.values() if f.effect)
