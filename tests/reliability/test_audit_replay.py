"""The audit replay (``tests/reliability/audit_replay.py``): malformed inputs through the command lines.

Every case must end in a result or ONE error line: no traceback, no crash, no multi-line failure. The
default run replays every 3rd case (about 120, a few seconds); ``-m slow`` replays all of them (about 370).
"""

from __future__ import annotations

import pytest

from tests.reliability import audit_replay


@pytest.fixture(scope="module")
def fixtures(tmp_path_factory):
    return audit_replay.build_fixtures(tmp_path_factory.mktemp("audit") / "fixtures")


def _check(results) -> None:
    print("\n" + audit_replay.table(results))
    bad = [r for r in results if r.outcome in ("traceback", "segfault", "multi-line")]
    report = "\n".join(f"{r.outcome}: {r.case.program} {r.case.name}\n{r.output[-2000:]}" for r in bad[:5])
    assert not bad, f"{len(bad)} of {len(results)} cases failed the one-line contract:\n{report}"


def test_the_replay_covers_every_command(fixtures):
    cases = audit_replay.build_cases(fixtures)
    commands = {c.command for c in cases}
    assert len(cases) >= 300
    assert commands == {
        "gttnet reconstruct", "gttnet sync", "gttdata generate", "gttdata verify", "gttnet train", "gttnet evaluate"
    }  # fmt: skip


def test_audit_replay_fast_subset(fixtures, tmp_path):
    cases = audit_replay.build_cases(fixtures)[::3]
    _check(audit_replay.replay(cases, tmp_path))


@pytest.mark.slow
def test_audit_replay_every_case(fixtures, tmp_path):
    _check(audit_replay.replay(audit_replay.build_cases(fixtures), tmp_path))


@pytest.mark.slow
def test_audit_replay_in_real_processes(fixtures, tmp_path):
    """A tenth of the cases as real processes, where a segfault shows as a negative exit status."""
    cases = audit_replay.build_cases(fixtures)[::10]
    _check(audit_replay.replay(cases, tmp_path, subprocess_mode=True))
