"""The criteria a run's outcome is judged by (summary.json ``outcome``, cosim.runtime.outcome; docs/field.md)."""
from __future__ import annotations

from .base import Model, NonNegFloat

__all__ = ["Outcome"]


class Outcome(Model):
    """When the job counts as done.

    * ``overfill_tolerance_m``: the highest grain may stand this much above ``controller.target_fill_m``; more is
      a failed job;
    * ``underfill_tolerance_m``: every section's peak must reach the target less this for the cart to count as
      filled;
    * ``spill_tolerance_kg``: spill above this fails the job (0: any spill does).
    """

    overfill_tolerance_m: NonNegFloat = 0.05
    """The highest grain may stand this much above controller.target_fill_m; more is a failed job, m."""
    underfill_tolerance_m: NonNegFloat = 0.05
    """Every section's peak must reach the target less this for the cart to count as filled, m."""
    spill_tolerance_kg: NonNegFloat = 0.0
    """Spill above this fails the job (0: any spill does), kg."""
