"""Session ids that no two sessions share: a ULID and the robot's id in plan.json."""

from __future__ import annotations

import datetime as dt
import json
import re
from pathlib import Path

from kasparctl.config import default_robot_id
from kasparctl.game.session import PLAN_FILE, Session, new_ulid

ULID = re.compile(r"[0-9A-HJKMNP-TV-Z]{26}")
NOW = dt.datetime(2026, 3, 2, 9, 41, 7, tzinfo=dt.UTC)


def test_sessions_started_together_in_many_state_dirs_get_distinct_uids(tmp_path: Path) -> None:
    created = [Session.create(tmp_path / str(i), {"group": "G1"}, now=NOW) for i in range(10)]
    plans = [json.loads((s.directory / PLAN_FILE).read_text()) for s in created]
    # The readable id is the same in every state directory; the uid never is.
    assert {plan["session"] for plan in plans} == {"20260302T094107-G1"}
    assert len({plan["uid"] for plan in plans}) == 10
    assert all(ULID.fullmatch(plan["uid"]) for plan in plans)
    for session in created:
        session.close()


def test_the_robot_is_given_or_derived(tmp_path: Path) -> None:
    given = Session.create(tmp_path / "a", {"group": "G1"}, robot="kaspar-3")
    derived = Session.create(tmp_path / "b", {"group": "G1"})
    for session, robot in ((given, "kaspar-3"), (derived, default_robot_id())):
        assert json.loads((session.directory / PLAN_FILE).read_text())["robot"] == {
            "id": robot,
            "name": "Kaspar",
        }
        session.close()


def test_a_ulid_sorts_by_its_millisecond() -> None:
    earlier, later = new_ulid(NOW), new_ulid(NOW + dt.timedelta(milliseconds=1))
    assert earlier < later and earlier[:10] != later[:10]
    # The first ten characters are the time: the same millisecond, the same prefix.
    assert new_ulid(NOW)[:10] == earlier[:10]
    assert new_ulid(dt.datetime(1970, 1, 1, tzinfo=dt.UTC)).startswith("0000000000")
