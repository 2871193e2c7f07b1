"""The learning rate over a run (``train.lr_decay``): exponential decay from each parameter
group's own rate to ``lr_decay`` times it at the run's end, as VolSDF trains.

A run ends at ``train.iterations`` or, with ``train.max_minutes``, when its time budget is
spent, whichever comes first; the schedule's progress p ∈ [0, 1] is the larger of the two
shares, so a time-budgeted run reaches its final rate when its time runs out however fast
its steps are. A resumed run continues from the progress its checkpoint stored and decays
over the rest of this invocation's steps or budget.
"""

from __future__ import annotations

import torch


class LearningRateSchedule:
    """Sets ``optim``'s rates to ``base · decay^p`` before each step.

    ``end`` is the step the run stops at; ``budget_s`` its time budget in seconds (None:
    steps only). ``start_progress`` is the progress a resumed run had reached."""

    def __init__(self, optim: torch.optim.Optimizer, decay: float) -> None:
        self.optim, self.decay = optim, float(decay)
        self.base = [float(g["lr"]) for g in optim.param_groups]
        self.progress = 0.0
        self._start = 0.0
        self._steps0 = self._end = 0
        self._budget: float | None = None

    def begin(self, step: int, end: int, budget_s: float | None) -> None:
        """Start (or resume) at ``step`` of a run ending at ``end`` steps or ``budget_s``
        seconds from now; the progress so far (:meth:`load`) is kept and the rest of it
        spread over what remains."""
        self._start = self.progress
        self._steps0, self._end, self._budget = step, end, budget_s

    def _by_steps(self, step: int) -> float:
        span = max(1, self._end - self._steps0)
        return self._start + (1.0 - self._start) * (step - self._steps0) / span

    def update(self, step: int, elapsed_s: float) -> float:
        """The progress at ``step`` after ``elapsed_s`` seconds of this invocation; sets
        the optimiser's rates for the coming step and returns the first group's."""
        p = self._by_steps(step)
        if self._budget is not None and self._budget > 0:
            p = max(p, self._start + (1.0 - self._start) * elapsed_s / self._budget)
        self.progress = min(1.0, max(self.progress, p))
        factor = self.decay**self.progress
        for g, base in zip(self.optim.param_groups, self.base, strict=True):
            g["lr"] = base * factor
        return self.base[0] * factor

    def state(self, step: int) -> dict:
        """What a checkpoint after ``step`` steps stores: the progress the next step starts
        at (by steps; the clock is this invocation's own)."""
        return {"progress": min(1.0, max(self.progress, self._by_steps(step)))}

    def load(self, state: dict | None) -> None:
        """Restore a checkpoint's progress (absent: written before the schedule, 0)."""
        self.progress = 0.0 if state is None else float(state.get("progress", 0.0))
