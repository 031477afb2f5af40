"""Every committed figure in docs/figures shows what its documented command draws today.

A remade figure is compared with the committed one by what it shows (``tests/_figures.py``): its lines,
markers and edges must sit within 2 px of the committed ones, so another font, OpenCV or GL stack passes and
a figure of other data, a blank or a cut render fails (the synthetic cases at the end keep that true).

The preview figures are remade by running the bash block of ``docs/figures/README.md`` as written (through
click's CliRunner, with ``/tmp/gtt-figures`` moved into a temporary folder): each ``cp SRC DST`` line is
checked as "SRC matches the committed DST" instead of copied. The sweep figures are re-plotted from the
committed table of the evaluation they come from (``docs/figures/sweep_errors.csv``); the full evaluation
that writes that table is the slow test at the end.
"""

from __future__ import annotations

import re
import shlex
from pathlib import Path

import cv2
import numpy as np
import pytest
from click.testing import CliRunner

from tests._figures import MAX_FRAC, assert_figures_agree, figure_difference

ROOT = Path(__file__).resolve().parents[1]
FIGURES = ROOT / "docs" / "figures"
README = FIGURES / "README.md"


def _commands() -> list[list[str]]:
    """The first bash block of the figures README, one argv per command (continuation lines joined)."""
    block = re.search(r"```bash\n(.*?)```", README.read_text(), re.S).group(1)
    return [shlex.split(line) for line in block.replace("\\\n", " ").splitlines() if line.strip()]


def _copies() -> list[tuple[str, str]]:
    return [(c[1], c[2]) for c in _commands() if c[0] == "cp"]


#: Where each preview figure writes labels, (y0, y1, x0, x1): the font depends on the OpenCV version, so the
#: boxes are only checked to hold a label (tests/_figures.py).
TEXT_BOXES: dict[str, tuple[tuple[int, int, int, int], ...]] = {
    "contact_sheet.png": ((0, 72, 0, 10_000), (72, 10_000, 0, 64)),  # title, legend, times; camera names
    "skeleton_3d.png": tuple((0, 26, x, x + 200) for x in (0, 322, 644, 966)),  # one label per panel
}


@pytest.fixture(scope="module")
def remade(tmp_path_factory) -> Path:
    """Run the figures README's gttdata commands into a temporary folder; returns that folder."""
    from gttdata.cli import main

    tmp = tmp_path_factory.mktemp("gtt-figures")
    runner = CliRunner()
    for argv in _commands():
        if argv[0] == "cp":
            continue
        assert argv[0] == "gttdata", f"docs/figures/README.md: unexpected command {argv[0]!r}"
        args = [a.replace("/tmp/gtt-figures", str(tmp)) for a in argv[1:]]
        res = runner.invoke(main, args, catch_exceptions=False)
        assert res.exit_code == 0, f"{shlex.join(argv)}\n{res.output}"
    return tmp


def test_figures_readme_documents_every_preview_figure():
    documented = {Path(dst).name for _, dst in _copies()}
    assert documented == {"contact_sheet.png", "timestamp_raster.png", "skeleton_3d.png"}


@pytest.mark.parametrize("src,dst", _copies(), ids=[Path(d).name for _, d in _copies()])
def test_preview_figure_matches_its_command(remade, src, dst):
    made = Path(src.replace("/tmp/gtt-figures", str(remade)))
    if dst.endswith("_3d.png") or "skeleton_3d" in dst:
        from gttdata.preview import _gl

        try:
            _gl.offscreen_renderer(8, 8)
        except (_gl.RendererUnavailableError, _gl.PreviewDependencyError) as exc:
            pytest.skip(f"no offscreen GL: {exc}")
    assert_figures_agree(made, ROOT / dst, text=TEXT_BOXES.get(Path(dst).name, ()))


#: The evaluation table behind the sweep figures: the rows of ``gttnet evaluate recipes/gttnet/eval_paper.yaml``'s
#: errors.csv for each committed sweep (see docs/figures/README.md).
SWEEP_TABLE = FIGURES / "sweep_errors.csv"


def _sweep_rows() -> list[dict]:
    from gttnet.evaluate.run import read_rows

    return read_rows(SWEEP_TABLE) if SWEEP_TABLE.exists() else []


def _sweeps_in_table() -> list[str]:
    import csv

    if not SWEEP_TABLE.exists():
        return []
    with SWEEP_TABLE.open() as f:
        return sorted({r["condition"] for r in csv.DictReader(f)})


@pytest.mark.parametrize("condition", _sweeps_in_table())
def test_sweep_figure_matches_its_table(condition, tmp_path):
    """The committed sweep figure is plot_sweeps of the committed table, with no bar below zero error."""
    pytest.importorskip("matplotlib")
    from gttnet.evaluate.plots import plot_sweeps
    from gttnet.evaluate.recipe import load_eval_recipe
    from gttnet.evaluate.summary import mean_interval

    rows = [r for r in _sweep_rows() if r["condition"] == condition]
    recipe = load_eval_recipe(ROOT / "recipes/gttnet/eval_paper.yaml", [])
    (made,) = plot_sweeps(rows, recipe, tmp_path)
    assert_figures_agree(made, FIGURES / f"sweep_{condition}.png")
    cells: dict[tuple, list[float]] = {}
    for r in rows:
        if r["status"] == "ok" and r["mpjpe_mm"]:
            cells.setdefault((r["value"], r["sequencing"], r["method"]), []).append(float(r["mpjpe_mm"]))
    assert cells and all(mean_interval(np.array(v), recipe.error_bars)[0] >= 0 for v in cells.values())


def test_training_curves_match_their_log(tmp_path):
    """The committed learning-curve figure is plot_learning_curves of the committed run log."""
    pytest.importorskip("matplotlib")
    from gttnet.train.curves import plot_learning_curves, read_history

    (tmp_path / "log.jsonl").write_bytes((FIGURES / "training_curves_cpu.jsonl").read_bytes())
    history = read_history(tmp_path)
    assert {r["stage"] for r in history} == {"bootstrap_affinity", "dloe"}
    made = plot_learning_curves(
        history, tmp_path / "curves.png", title="default recipe, 400 + 200 steps on the CPU"
    )
    assert made is not None
    assert_figures_agree(made, FIGURES / "training_curves_cpu.png")


def test_long_training_curves_match_their_log(tmp_path):
    """The committed curves of the long CPU continuation are plot_learning_curves of its committed log."""
    pytest.importorskip("matplotlib")
    from gttnet.train.curves import plot_learning_curves, read_history

    (tmp_path / "log.jsonl").write_bytes((FIGURES / "training_curves_long.jsonl").read_bytes())
    history = read_history(tmp_path)
    steps = [r["global_step"] for r in history if r["kind"] == "train"]
    assert steps == sorted(set(steps))  # one record per step: the crashed run's extra record is gone
    made = plot_learning_curves(
        history,
        tmp_path / "curves.png",
        title="bundled CMU-31 model continued on the CPU: stage 2, 30,000-step cosine schedule, all 30,000 steps",
    )
    assert made is not None
    assert_figures_agree(made, FIGURES / "training_curves_long.png")


def test_sync_clocks_figure_matches_its_command(tmp_path):
    """docs/figures/sync_clocks.png is what its documented command writes (clock recovery is deterministic)."""
    pytest.importorskip("matplotlib")
    import subprocess
    import sys

    from tests._subprocess import repo_env

    out = tmp_path / "sync_clocks.png"
    res = subprocess.run(
        [sys.executable, str(ROOT / "benchmarks/plot_sync_clocks.py"), "--out", str(out)],
        cwd=ROOT,
        capture_output=True,
        text=True,
        env=repo_env(),
    )
    assert res.returncode == 0, res.stderr
    assert_figures_agree(out, FIGURES / "sync_clocks.png")


def _committed(name: str) -> np.ndarray:
    return cv2.imread(str(FIGURES / name))


@pytest.mark.parametrize("name", ["contact_sheet.png", "skeleton_3d.png", "timestamp_raster.png"])
def test_comparison_passes_a_one_pixel_shift(name):
    img = _committed(name)
    moved = np.roll(img, (1, 1), axis=(0, 1))
    assert figure_difference(moved, img, text=TEXT_BOXES.get(name, ()))["unexplained"] <= MAX_FRAC


@pytest.mark.parametrize("name", ["contact_sheet.png", "skeleton_3d.png", "timestamp_raster.png"])
def test_comparison_fails_blank_cut_or_moved_figures(name):
    img = _committed(name)
    text = TEXT_BOXES.get(name, ())
    h, w = img.shape[:2]
    blank = np.full_like(img, img[-1, -1])
    cut = img.copy()
    cut[h // 2 :] = img[-1, -1]
    mirrored = img.copy()
    mirrored[:, w // 2 :] = img[:, : w - w // 2]  # the left half drawn twice: other data on the right
    moved = np.roll(img, 4, axis=1)
    for wrong in (blank, cut, mirrored, moved):
        assert figure_difference(wrong, img, text=text)["unexplained"] > MAX_FRAC


def test_sweep_comparison_fails_on_other_data(tmp_path):
    """The noise sweep re-plotted with DLOE's errors 15 % higher no longer passes for the committed figure."""
    pytest.importorskip("matplotlib")
    from gttnet.evaluate.plots import plot_sweeps
    from gttnet.evaluate.recipe import load_eval_recipe

    rows = [dict(r) for r in _sweep_rows() if r["condition"] == "noise"]
    if not rows:
        pytest.skip("no noise sweep in the committed table")
    for r in rows:
        if r["method"] == "dloe" and r["mpjpe_mm"]:
            r["mpjpe_mm"] = str(1.15 * float(r["mpjpe_mm"]))
    (made,) = plot_sweeps(rows, load_eval_recipe(ROOT / "recipes/gttnet/eval_paper.yaml", []), tmp_path)
    assert figure_difference(made, FIGURES / "sweep_noise.png")["unexplained"] > MAX_FRAC
