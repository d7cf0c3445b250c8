"""When one start of the optimiser has stalled: a stop rule that an early dip cannot end.

The loss of Adam's iterates is not monotone: after a kink (a mode passing an order line, a
penalty switching on) the momentum can carry the iterate uphill for tens of steps before it
comes down again, often far below the point where it turned.  A rule that counts patience
from the best loss met (the rule before issue 20) ends such a run when the climb back takes
longer than the patience, with the goal far from met.  Here:

* the loss is smoothed: s_t = SMOOTHING s_(t-1) + (1 - SMOOTHING) L_t over the accepted steps
  (a time constant of 5 steps), so one low or high step moves it little;
* an improvement is a smoothed value below the lowest of the previous WINDOW (10) smoothed
  values by more than ``tolerance`` (relative): a steady descent improves at every step, even
  while it is still above an earlier dip, and a dip is forgotten WINDOW steps later;
* a record is a smoothed value below the lowest of all earlier ones by more than ``tolerance``;
* the start has stalled when no improvement came in the last ``patience`` accepted steps, or
  no record in the last LONG x ``patience`` (a plateau whose noise is above the tolerance keeps
  making local lows, but ever fewer records), and never before ``min_steps`` accepted steps.

A stall only ends a start; whether the run then stops, or tries another start, depends on the
goal (see :mod:`beltjax.optimize.solver`).
"""

from __future__ import annotations

from dataclasses import dataclass, field

#: weight of the previous smoothed value (time constant 1 / (1 - SMOOTHING) = 5 steps)
SMOOTHING = 0.8
#: improvements are counted against the lowest of this many previous smoothed values
WINDOW = 10
#: a start also stalls after LONG x patience accepted steps without a record
LONG = 3


@dataclass
class StopRule:
    """Incremental stall detector (module docstring): feed each accepted loss to :meth:`update`.

    tolerance (relative, >= 0), patience (accepted steps >= 1), min_steps (accepted steps >= 0).
    """

    tolerance: float
    patience: int
    min_steps: int = 0
    smoothed: list[float] = field(default_factory=list)
    last_improvement: int = 0
    last_record: int = 0

    def update(self, loss: float) -> bool:
        """Record the loss of the next accepted point (the start first); True once stalled."""
        t = len(self.smoothed)
        s = loss if t == 0 else SMOOTHING * self.smoothed[-1] + (1.0 - SMOOTHING) * loss
        if t and s < self._below(self.smoothed[-WINDOW:]):
            self.last_improvement = t
        if t and s < self._below(self.smoothed):
            self.last_record = t
        self.smoothed.append(s)
        return self.stalled

    def _below(self, values) -> float:
        low = min(values)
        return low - self.tolerance * abs(low)

    @property
    def stalled(self) -> bool:
        """No improvement in the last ``patience`` accepted steps (or no record in LONG x
        patience), after ``min_steps`` of them."""
        t = len(self.smoothed) - 1
        return t >= self.min_steps and (t - self.last_improvement >= self.patience
                                        or t - self.last_record >= LONG * self.patience)

    @property
    def reason(self) -> str:
        """Why the start stalled (for the reports)."""
        t = len(self.smoothed) - 1
        if t - self.last_improvement >= self.patience:
            return (f"stalled: no new low of the smoothed loss (relative {self.tolerance:g}, against the previous "
                    f"{WINDOW}) in {self.patience} steps")
        return f"stalled: no new record of the smoothed loss (relative {self.tolerance:g}) in {LONG * self.patience} steps"


def stall_step(losses, tolerance: float, patience: int, min_steps: int = 0) -> int | None:
    """Index into ``losses`` (the loss at the start, then after each accepted step) at which
    :class:`StopRule` declares the stall, or None if it never does."""
    rule = StopRule(tolerance, patience, min_steps)
    for k, v in enumerate(losses):
        if rule.update(float(v)):
            return k
    return None
