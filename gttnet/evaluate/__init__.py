"""Evaluation of reconstructions against ground truth."""

from __future__ import annotations

from gttnet.evaluate.metrics import kendall_tau, mpjpe_mm, pa_mpjpe_mm

__all__ = ["kendall_tau", "mpjpe_mm", "pa_mpjpe_mm"]
