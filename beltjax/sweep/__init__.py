"""Batched parametric sweeps: parameter grids, random samples and tolerance studies.

One compiled function evaluates a whole batch of scenes: ``jax.vmap`` of
``case_outputs(set_values(scene, values))`` over the cases, run in chunks of a fixed
size (the last chunk padded, so there is no recompilation).  The batch carries every
scalar parameter of the scene (:func:`full_values`), so every sweep of a scene, and of
any scene with the same structure (pulleys, mesh, effects, belt given by tension or by
length), shares one compilation.  Scale-out:

* several local accelerators (GPUs): each chunk is sharded over them (``shard_map`` on
  the case axis; not measured here, the machine has none).  Host CPU "devices" are used
  only when passed explicitly (``devices=``; see :func:`_devices` for why);
* ``backend="dask"``: the chunks are tasks on a ``dask.distributed`` cluster, each
  worker running the same compiled function (compiled once per worker process): the
  scheduler at the sweep file's ``dask_scheduler``, else at ``$BELTJAX_DASK_SCHEDULER``,
  else a LocalCluster of one single-threaded worker process per core.  Needs the extra
  ``pip install 'beltjax[dask]'``.

Library: :func:`load_spec` / :func:`parse_spec` (+ :func:`check_spec`) read a sweep,
:func:`cases` makes its case table ``{path: (n,) values}``, :func:`evaluate` runs any
case table, :func:`case_outputs` is the pure single-case function (jit, vmap, grad),
:func:`columns`, :func:`statistics` and :func:`failures` summarise, :func:`run` is
``beltjax sweep``.

Sweep file (TOML)
-----------------
::

    description = "two-pulley bench: tension x EI"   # optional
    outputs = ["statics", "modal"]    # any of "statics", "modal", "campbell", "response" (default statics, modal)
    modes = 12                        # modes kept per case (default 12; rigid-body modes count)
    # rpm = [0, 2500, 50]             # campbell only: drive-pulley speeds A, B, STEP (rpm, B included)
    # settle_s = 1.0                  # response only: settling transient where the shooting gives up (s, default 1)
    # chunk = 1                       # cases per compiled batch (default 1 per CPU device; on GPUs from memory and size)
    # samples = 200                   # random samples (or in each [[random]] table; all must agree)
    # seed = 0                        # default seed of the [[random]] tables
    # dask_scheduler = "tcp://host:8786"   # backend "dask": an existing scheduler

    [[grid]]                          # a full-factorial axis
    parameter = "belt.static_tension" # a beltjax.parameters path (file units)
    values = [200, 400, 600]          # or: start, stop, num (and spacing = "linear" | "log")

    [[random]]                        # a random parameter (all drawn jointly: `samples` cases)
    parameter = "pulley.alternator.center.x"
    distribution = "normal"           # "normal" or "uniform" (required)
    nominal = true                    # centre: the scene's value (or mean = 0.2232)
    tolerance = 0.0005                # spread; see below
    samples = 200
    seed = 0

Spread of a ``[[random]]`` table, exactly one of:

* ``std`` (normal only): standard deviation (parameter units);
* ``low`` and ``high`` (uniform only, no centre): the interval;
* ``tolerance``: an absolute band ``centre +- tolerance``; uniform draws fill the
  band, normal draws take it as +-3 standard deviations (std = tolerance / 3);
* ``relative_tolerance``: the same band as a fraction of the centre
  (``0.003`` is +-0.3 %).

A spread is > 0, and its band (centre +- tolerance, +- 3 std) must lie in the parameter's
accepted range (:mod:`beltjax.schema`), as ``low`` and ``high`` must: a wider one is refused
naming its key (std = 1e300 made every case invalid); a normal draw beyond the band that
leaves the range is that case's ``invalid_value``.

The centre is ``mean``, or with ``nominal = true`` the scene's value.  The belt's
unstretched ``belt.length`` of a scene given by ``static_tension`` is the
installed length (:func:`beltjax.statics.install`), and vice versa; sweeping
``belt.length`` switches every case to length mode (the tension follows from the
installation), so a belt-length tolerance changes the tension as a real belt does.

Cases: the grid axes are full-factorial (the first axis varies slowest); the
random parameters are drawn jointly, each from its own stream seeded by
``(seed, table index)``.  A grid together with random tables is allowed: every
grid point gets the same ``samples`` draws (common random numbers, so grid
points differ by the grid values only); cases = grid points x samples, the
samples varying fastest.  A parameter may appear in only one axis, and
``belt.static_tension`` and ``belt.length`` not together.  At most
:data:`MAX_CASES` cases.

Outputs per case
----------------
statics
    span tensions per span (route order), hub force magnitudes per route entry,
    installation tension, unstretched belt length, the tensioner's arm angle and
    spring moment (tensioner drives), Newton convergence.  At the drive pulley's
    ``speed_rpm`` (steady motion), as ``beltjax statics``.
modal
    natural frequencies (Hz) of the nominal scene's lowest ``modes`` modes, followed
    into every case by their shapes, and a stability flag: column ``f<k>_hz`` is the
    nominal's k-th mode (its label in ``sweep.json``, ``nominal_modes``) in every row,
    wherever it sits in the case's own order, so a column keeps its mode where two
    modes cross (a transverse mode rising through a rotational one as the tension
    grows).  Each case's modes come from the compiled eigen-solve with their
    mass-weighted shapes (a few more modes than kept, so that a mode that moved up is
    still found) and are matched to the nominal's by MAC and an optimal assignment
    (:mod:`beltjax.mode_tracking`; a repeated pair as a subspace); ``mode_match`` is a
    case's lowest MAC (near 1: every column holds the nominal's mode; low: a mode has
    changed shape, e.g. two modes mixed near a veering; a column whose mode is not found
    is NaN and counts 0).  Tracking to the nominal rather than along a grid axis works for
    random (tolerance) studies too and needs no order of the cases.  Without modes of
    the nominal (its statics fail, or it is unstable) the columns are the lowest
    ``modes`` sorted per case, and ``sweep.json`` says so.
campbell
    the same modes' frequencies at each ``rpm`` speed per case: matched to the nominal's
    at the lowest speed, then followed along the case's speeds by their shapes (as
    ``beltjax campbell``); ``campbell_mode_match`` is a case's lowest MAC.
response
    the periodic steady state at the case's drive-pulley speed under the scene's crank orders
    and lasting loads (:func:`beltjax.orders.steady_case`; the scene must have one:
    :func:`beltjax.orders.check`): ``arm_p2p_deg``, ``tension_p2p_<span>_N``,
    ``tension_min_<span>_N``, ``hub_max_<bearing>_N``, ``dynamic_min_slip_margin``; statuses
    ``transient_failed``, ``span_slack`` (a span's force on the pulleys <= 0 in the cycle) and
    ``not_settled`` (still changing after ``settle_s``).  For Monte-Carlo tolerance studies of
    belt length, tensioner friction or accessory inertias.

A case without an admissible state is never silently wrong: its outputs are NaN
and its ``status`` names the cause (:data:`STATUS`): before any computation, the
scene file's checks (:func:`beltjax.validate.case_status`, vectorised over the
cases) give ``invalid_value`` (a value outside the parameter's range of
:mod:`beltjax.schema`), ``overlap`` (pulleys overlap, or no tangent between
neighbours), ``no_belt_path`` (a degenerate wrap, a span through a pulley, spans
crossing) and ``ill_conditioned`` (a derived float64 limit); then a belt that cannot
be fitted (slack, over-stretched, no tensioner balance), statics not converged
(retried with speed stepping), a span gone slack, loads that overpower the belt
(``arm_wound``: the tensioner arm turned over half a turn; ``span_overstretched``: a span past
2 %: :func:`beltjax.statics.operating_faults`), non-finite outputs, ``supercritical``
(the drive speed past the critical belt speed: a span's force on the pulleys <= 0,
:mod:`beltjax.critical`); ``unstable`` (modes that grow) keeps the statics and has NaN
frequencies.  The run summary counts them by cause.  A sweep accepts exactly what a scene
file accepts.

Command line: ``beltjax sweep SCENE SWEEP.toml [--backend local|dask] --out DIR``
writes ``sweep.csv`` (one row per case: case, parameters, outputs, status),
``sweep.json`` (spec, statistics of every output, failures, timing),
``sweep_campbell.csv`` (campbell output, one row per case and speed) and plots.
"""

from beltjax.sweep.spec import CAMPBELL_CHUNK_POINTS, DISTRIBUTIONS, GridAxis, MAX_CAMPBELL_POINTS, MAX_CASES, MAX_SPEEDS, OUTPUTS, REASONS, RandomAxis, SPACINGS, STATUS, Spec, SweepError, _CODE, _GRID_KEYS, _RANDOM_KEYS, _READ, _TOP_KEYS, _check_range, _draw, _parse_grid, _parse_random, _precheck, _raise, _rpm_range, cases, check_spec, load_spec, nominal_value, parse_spec  # noqa: F401
from beltjax.sweep.batch import _Options, _batch_fn, _case, _chunk_size, _devices, _finish, _matrix, _run_chunk, _run_local, _slices, case_outputs, default_chunk, evaluate, full_values  # noqa: F401
from beltjax.sweep.dask_backend import _EXECUTION_LOCK, _chunk_task, _dask_client, _dask_client_check, _run_dask  # noqa: F401
from beltjax.sweep.tables import _columns_meaning, _fmt, _jsonable, columns, failures, report, statistics, summary_table, write_campbell_csv, write_csv  # noqa: F401
from beltjax.sweep.figures import _axis_label, _column_label, _flexible_columns, plot_campbell_band, plot_grid, plot_histograms, plots  # noqa: F401
from beltjax.sweep.command import progress_bar, run  # noqa: F401
