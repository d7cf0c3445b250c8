"""How many generalized-alpha steps a forcing period needs: the numbers behind beltjax.excitation.

Run: ``python benchmarks/bench_forcing_resolution.py`` (about 1 min; 2 min 18 s under load 5).  Writes
``benchmarks/results/forcing_resolution.json``.

A forced, damped oscillator ``x'' + 2 zeta w_max x' + w0^2 x = sin(w t)`` (w = 2 pi rad/s,
zeta = 0.1, w_max = max(w0, w), from rest) is integrated with beltjax's generalized-alpha
solver (as ``simulate`` uses it: ``diffrax.ConstantStepSize``) at n steps per forcing period,
for 150 periods; the steady response over the last 20 periods is fitted with
``a sin(w t) + b cos(w t) + c`` (the constant absorbs the free mass's drift) and compared with
the exact steady response.  Cases: w0 = 0 (mass-controlled), w0 = w / 2 (forcing above a
mode), w0 = 0.9 w (near a resonance), w0 = 2 w (below a mode; here the error is mostly that of
resolving the mode, w0 dt = 2 w dt).  rho_inf = 1 (midpoint rule) and 0.9 (the default).

The last rows force at n = 1.002 steps per period (just above the step's sampling rate): the
step sees the forcing at the alias frequency |f - 1/dt| = f / 500, and the "response" is that
of a forcing 500 times slower; the table gives its amplitude over the true steady amplitude.
This is what ``simulate`` now refuses (a 4990 Hz torque at dt = 2e-4 s is a 10 Hz torque).
"""

from __future__ import annotations

import sys

import diffrax
import jax
import jax.numpy as jnp
import numpy as np

from _common import machine_info, machine_line, save_json, table

sys.path.insert(0, str(__import__("pathlib").Path(__file__).resolve().parent))

from beltjax.integrators import GeneralizedAlpha  # noqa: E402

jax.config.update("jax_enable_x64", True)

ZETA = 0.1
PERIODS = 150
STEPS = (4, 6, 10, 20, 40)
RATIOS = (0.0, 0.5, 0.9, 2.0)


def run(n: float, ratio: float, rho: float, periods: int = PERIODS):
    """(x (nt,), t (nt,)) of the forced oscillator at n steps per forcing period (period 1 s)."""
    w = 2 * np.pi
    w0 = ratio * w
    c = 2 * ZETA * max(w0, w)

    def f(t, y, args):
        return jnp.array([y[1], -c * y[1] - w0**2 * y[0] + jnp.sin(w * t)])

    dt = 1.0 / n
    steps = int(np.ceil(periods * n))
    ts = jnp.arange(steps + 1) * dt
    sol = diffrax.diffeqsolve(diffrax.ODETerm(f), GeneralizedAlpha(rho_inf=rho), 0.0, float(ts[-1]), dt, jnp.zeros(2),
                              saveat=diffrax.SaveAt(ts=ts), stepsize_controller=diffrax.ConstantStepSize(),
                              max_steps=steps + 10)
    return np.asarray(sol.ys[:, 0]), np.asarray(ts), c, w0


def steady_error(n: float, ratio: float, rho: float) -> tuple[float, float, float]:
    """(complex relative error, amplitude error, phase error deg) of the steady response."""
    x, t, c, w0 = run(n, ratio, rho)
    w = 2 * np.pi
    k = t >= t[-1] - 20
    A = np.stack([np.sin(w * t[k]), np.cos(w * t[k]), np.ones(k.sum())], 1)
    a, b, _ = np.linalg.lstsq(A, x[k], rcond=None)[0]
    num = b - 1j * a  # x = Re(X e^{i w t})
    exact = -1j / (w0**2 - w**2 + 1j * w * c)
    return abs(num / exact - 1), abs(num) / abs(exact) - 1, float(np.degrees(np.angle(num / exact)))


def alias_ratio(ratio: float, rho: float, n: float = 1.002) -> float:
    """Amplitude of the response at the alias frequency over the true steady amplitude."""
    x, t, c, w0 = run(n, ratio, rho, periods=int(3 * 500))  # three alias periods (the alias is f / 500)
    w = 2 * np.pi
    exact = abs(1.0 / (w0**2 - w**2 + 1j * w * c))
    k = t >= t[-1] - 500
    return float(0.5 * np.ptp(x[k]) / exact)


def main():
    info = machine_info()
    print(machine_line(info))
    results, tables = [], []
    for rho in (1.0, 0.9):
        rows = []
        for ratio in RATIOS:
            errs = [steady_error(n, ratio, rho) for n in STEPS]
            for n, (e, ea, ph) in zip(STEPS, errs):
                results.append(dict(rho_inf=rho, w0_over_w=ratio, steps_per_period=n, complex_error=e,
                                    amplitude_error=ea, phase_error_deg=ph))
            rows.append([f"{ratio:g}"] + [f"{100 * ea:+.2f} % / {ph:+.2f} deg" for _, ea, ph in errs])
        txt = table(["w0 / w"] + [f"{n} steps" for n in STEPS], rows,
                    f"generalized-alpha, rho_inf = {rho:g}: steady amplitude / phase error of x'' + 2 zeta w_max x' + "
                    f"w0^2 x = sin(w t) (zeta = {ZETA}) at n steps per forcing period")
        print(txt)
        tables.append(txt)
    rows = []
    for ratio in (0.0, 0.5):
        r = alias_ratio(ratio, 0.9)
        results.append(dict(rho_inf=0.9, w0_over_w=ratio, steps_per_period=1.002, alias_amplitude_ratio=r))
        rows.append([f"{ratio:g}", f"{r:.3g}"])
    txt = table(["w0 / w", "alias amplitude / true amplitude"], rows,
                "forcing at 1.002 steps per period (rho_inf 0.9): response at the alias frequency f / 500")
    print(txt)
    tables.append(txt)
    path = save_json("forcing_resolution", dict(results=results, tables=tables))
    print(f"wrote {path}")


if __name__ == "__main__":
    main()
