"""Who may (de)register a robot: its holder, or anyone once its site let it go."""

from __future__ import annotations

import pytest

from fleetlink.uplink.commands.ownership import Owner, claim_problem

A_HOLDS = Owner("a", registered=True, since_ms=1000)
A_LET_GO = Owner("a", registered=False, since_ms=1000)


@pytest.mark.parametrize(
    ("owner", "site", "registered", "now_ms", "problem"),
    [
        (None, "b", True, 0, None),  # a new robot: the first site to register it holds it
        (None, "b", False, 0, "deregisters a robot no site holds"),
        (A_HOLDS, "a", True, 2000, None),  # its own site, again
        (A_HOLDS, "a", False, 2000, None),
        (A_HOLDS, "b", True, 2000, "registered at site 'a'"),
        (A_HOLDS, "b", False, 2000, "is site 'a''s, not site 'b''s"),
        (A_LET_GO, "b", True, 1500, "stays its own for 5 s"),  # within release_after
        (A_LET_GO, "b", True, 6000, None),  # liveliness lost + grace + release_after: it moves
        (A_LET_GO, "b", False, 6000, "is site 'a''s"),
    ],
)
def test_claims(owner: Owner | None, site: str, registered: bool, now_ms: int, problem: str | None) -> None:
    found = claim_problem(owner, site=site, registered=registered, now_ms=now_ms, release_after_ms=5000)
    if problem is None:
        assert found is None
    else:
        assert found is not None
        assert problem in found
