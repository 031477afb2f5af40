"""The record of a training run: JSONL log (and TensorBoard scalars), git revision, loss curve."""

from __future__ import annotations

import json
import logging
import subprocess
from pathlib import Path

__all__ = ["RunLog", "git_sha", "plot_loss_curve"]

log = logging.getLogger(__name__)


def git_sha() -> str:
    """The checked-out git revision, or ``"unknown"`` outside a repository."""
    try:
        out = subprocess.run(
            ["git", "rev-parse", "HEAD"], capture_output=True, text=True, timeout=5, check=False
        )
        return out.stdout.strip() or "unknown"
    except OSError:
        return "unknown"


class RunLog:
    """JSONL records in ``run_dir/log.jsonl`` (and TensorBoard scalars when installed); rank 0 only.

    Args:
        run_dir: The run directory.
        enabled: False on ranks other than 0 (every write is then a no-op).
    """

    def __init__(self, run_dir: Path, enabled: bool) -> None:
        self.enabled, self.path, self.tb = enabled, run_dir / "log.jsonl", None
        if enabled:
            try:
                from torch.utils.tensorboard import SummaryWriter

                self.tb = SummaryWriter(str(run_dir / "tensorboard"))
            except ImportError:
                log.debug("tensorboard not installed: JSONL log only")

    def drop_after(self, global_step: int) -> int:
        """Forget the records an interrupted run wrote after its last checkpoint (resume starts there).

        Keeps the meta records and every record with ``global_step <= global_step``; the file is replaced
        atomically. Without it a resumed run logs those steps twice.

        Args:
            global_step: The checkpoint's global step.

        Returns:
            How many records were dropped.
        """
        if not self.enabled or not self.path.is_file():
            return 0
        from gttdata.fileio import atomic_write

        lines = [ln for ln in self.path.read_text().splitlines() if ln.strip()]
        keep = []
        for ln in lines:
            rec = json.loads(ln)
            if rec.get("kind") == "meta" or int(rec.get("global_step", 0)) <= global_step:
                keep.append(ln)
        if len(keep) < len(lines):
            with atomic_write(self.path, "w") as fh:
                fh.write("".join(k + "\n" for k in keep))
        return len(lines) - len(keep)

    def write(self, record: dict) -> None:
        """Append one record (keys ``kind`` and ``global_step`` required); numbers go to TensorBoard."""
        if not self.enabled:
            return
        with self.path.open("a") as fh:
            fh.write(json.dumps(record) + "\n")
        if self.tb is not None:
            for k, v in record.items():
                if isinstance(v, int | float) and k not in ("step", "global_step", "stage_index"):
                    self.tb.add_scalar(f"{record['kind']}/{k}", v, record["global_step"])


def plot_loss_curve(run_dir: Path, history: list[dict]) -> None:
    """``run_dir/loss_curve.png``: the run's learning curves (:func:`gttnet.train.curves.plot_learning_curves`)."""
    from gttnet.train.curves import plot_learning_curves

    plot_learning_curves(history, run_dir / "loss_curve.png", title=run_dir.name)
