"""The public API (``beltjax/__init__.py``): every name resolves, the README's API block runs as
written, and a scene changed through the API into what the file's parser refuses gets the
parser's one-line error."""

from __future__ import annotations

import contextlib
import io
import re
from pathlib import Path

import equinox as eqx
import jax.numpy as jnp
import numpy as np
import pytest

import beltjax
from beltjax.errors import BeltjaxError

ROOT = Path(__file__).resolve().parent.parent


def test_every_public_name_resolves():
    for name in beltjax.__all__:
        assert callable(getattr(beltjax, name)) or isinstance(getattr(beltjax, name), type), name
    with pytest.raises(AttributeError):
        beltjax.no_such_name  # noqa: B018


def _block(marker: str) -> str:
    text = (ROOT / "README.md").read_text()
    i = text.index(f"<!-- api: {marker} -->")
    m = re.compile(r"```python\n(.*?)```", re.S).search(text, i)
    return m.group(1)


def test_readme_api_block_runs(monkeypatch):
    monkeypatch.chdir(ROOT)
    out = io.StringIO()
    with contextlib.redirect_stdout(out):
        exec(compile(_block("drive"), "README.md (api: drive)", "exec"), {})
    lines = out.getvalue().splitlines()
    assert lines[0].startswith("crank torque") and "nan" not in lines[0]
    assert len(lines) == 5
    # the printed numbers are the analyses': the first mode and the arm differ between the
    # stiffness cases (a stiffer spring holds the arm closer to its free angle)
    arms = [float(x) for x in re.findall(r"[-\d.]+", lines[4].split("first mode")[0].split(":", 1)[1])]
    assert len(arms) == 3 and len(set(arms)) == 3


def _scene():
    return beltjax.load_scene(ROOT / "scenes" / "two_pulley_T200.toml")


@pytest.mark.parametrize("where, value, key", [
    (lambda s: s.belt.EA, jnp.array([1.0, 2.0]), "belt.EA"),
    (lambda s: s.pulleys[1].center, jnp.zeros(3), "pulley[1].center"),
    (lambda s: s.pulleys[0].radius, 1j, "pulley[0].radius"),
    (lambda s: s.belt.EA, -5.0, "belt.EA"),
    (lambda s: s.belt.rhoA, float("nan"), "belt.rhoA"),
])
def test_api_scene_refused_with_the_key(where, value, key):
    bad = eqx.tree_at(where, _scene(), value)
    with pytest.raises(BeltjaxError) as e:
        beltjax.analyse_statics(bad)
    msg = str(e.value)
    assert msg.startswith(f"{key}:") and "\n" not in msg, msg


def test_simulate_checks_the_scene_before_the_excitation():
    sc = beltjax.load_scene(ROOT / "scenes" / "fead_8pulley.toml")
    bad = eqx.tree_at(lambda s: s.pulleys[0].speed_rpm, sc, 1e9)
    with pytest.raises(BeltjaxError, match=r"^pulley\[0\]\.speed_rpm: must lie in"):
        beltjax.simulate(bad, 0.05)
    assert np.isfinite(float(sc.pulleys[0].speed_rpm))


def _fit_dataset(path):
    from identification.fit import fit_dataset

    return fit_dataset(path)


def _orders_settings(**kw):
    from beltjax.orders import Settings

    return Settings(**kw)



@pytest.mark.parametrize("call, key", [
    (lambda s: beltjax.simulate(s, 0.1, output_dt=float("nan")), "output_dt"),
    (lambda s: beltjax.simulate(s, 0.1, chunk_s=0.0), "chunk_s"),
    (lambda s: beltjax.simulate(s, 0.1, chunk_s="x"), "chunk_s"),
    (lambda s: beltjax.evaluate_cases(s, {"belt.EA": [1e5]}, modes=0), "modes"),
    (lambda s: beltjax.evaluate_cases(s, {"belt.EA": [1e5]}, chunk=0), "chunk"),
    (lambda s: beltjax.evaluate_cases(s, {"belt.EA": [1e5]}, chunk=2.5), "chunk"),
    (lambda s: beltjax.response_over_speed(s, [800.0], chunk=-1), "chunk"),
    (lambda s: beltjax.analyse_campbell(s, [0.0, 100.0], n_modes=True), "n_modes"),
    (lambda s: beltjax.simulate(s, 0.1, dt="x"), "dt"),
    (lambda s: beltjax.analyse_statics(s, loaded="no"), "loaded"),
    (lambda s: beltjax.analyse_statics(s, with_unloaded=1), "with_unloaded"),
    (lambda s: beltjax.response_over_speed(s, [800.0], settings=_orders_settings(rtol=float("nan"))), "rtol"),
    (lambda s: beltjax.response_over_speed(s, [800.0], settings=_orders_settings(atol=0.0)), "atol"),
    (lambda s: beltjax.response_over_speed(s, [800.0], settings=_orders_settings(max_steps=0)), "max_steps"),
    (lambda s: beltjax.response_over_speed(s, [800.0], settle_tol=float("nan")), "settle_tol"),
    (lambda s: beltjax.response_over_speed(s, [800.0], settle_tol="x"), "settle_tol"),
    (lambda s: beltjax.response_over_speed(s, [800.0], settings=_orders_settings(atol=float("inf"))), "atol"),
    (lambda s: beltjax.response_over_speed(s, [800.0], values={"belt.EA": [1e5, 2e5]}), "values"),
    (lambda s: beltjax.evaluate_cases(s, {"belt.EI": ["a"]}), "values"),
    (lambda s: beltjax.evaluate_cases(s, {"belt.EI": [0.03]}, reference="bogus"), "reference"),
    (lambda s: beltjax.evaluate_cases(s, {"belt.EI": [0.03]}, outputs=("campbell",), rpm=[float("nan")]), "rpm[0]"),
    (lambda s: beltjax.evaluate_cases(s, {"belt.EI": [0.03]}, outputs=("response",), settle_s=float("nan")),
     "settle_s"),
    (lambda s: beltjax.write_scene(s, "/nonexistent-folder/x.toml"), "path"),
    (lambda s: beltjax.response_over_speed(s, None), "rpm"),
    (lambda s: beltjax.response_over_speed(s, "fast"), "rpm"),
    (lambda s: beltjax.evaluate_cases(s, None), "values"),
    (lambda s: beltjax.sweep_cases(s, None), "spec"),
    (lambda s: beltjax.optimise(s, None), "problem"),
    (lambda s: beltjax.sweep_cases(None, beltjax.load_sweep(ROOT / "scenes" / "sweeps" / "two_pulley_tolerance.toml")),
     "scene"),
    (lambda s: beltjax.load_problem(ROOT / "scenes" / "optimize" / "tensioner_pivot.toml", None), "scene"),
    (lambda s: beltjax.evaluate_cases(None, {"belt.EI": [0.03]}), "scene"),
    (lambda s: beltjax.dumps_scene(None), "scene"),
    (lambda s: beltjax.load_scene(None), "path"),
    (lambda s: beltjax.load_scene(b"scenes/fead_8pulley.toml"), "path"),
    (lambda s: beltjax.load_sweep(None), "path"),
    (lambda s: beltjax.load_problem(None, s), "path"),
    (lambda s: _fit_dataset(None), "path"),
])
def test_api_arguments_refused_with_their_name(call, key):
    """Arguments the Python API takes beside the scene: one line naming the argument, before any work."""
    sc = beltjax.load_scene(ROOT / "scenes" / "fead_8pulley.toml")
    with pytest.raises(BeltjaxError) as e:
        call(sc)
    msg = str(e.value)
    assert msg.startswith(f"{key}:") and "\n" not in msg, msg
