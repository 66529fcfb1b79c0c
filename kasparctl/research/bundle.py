"""What leaves the robot: `kasparctl export --bundle DIR`, anonymised and checksummed.

The bundle holds the sessions' records as anonymised copies (records/sessions/
<session_name>/plan.json and records.jsonl), the CSVs made from those copies
(trials, events, sessions), the codebook, datapackage.json and MANIFEST.sha256
(`sha256sum -c MANIFEST.sha256` checks every file). Anonymised means:

- first names dropped: the plan's `children` emptied, every name elsewhere (lines
  Kaspar spoke, the child field, seats) replaced by "child N" as a whole word;
- ULIDs re-keyed: a session's `uid` is a new ULID (its shifted start time and a
  keyed hash of the old one), its `session_name` the shifted start and group code,
  the same in every file of the bundle;
- dates shifted (`--shift-dates`): every wall-clock time (records' `time`, the
  plan's `created`, clock records' `offset`) moved back by a whole number of weeks
  (1 to 104, so weekdays stay) drawn from the key.

The key is the secret file's bytes (`--secret FILE`: the same secret gives the same
ids and shift in every bundle, so bundles taken on different days join), else
random for this bundle only. The secret never goes into the bundle. Participant
and group codes stay: they are the study's pseudonyms.
"""

from __future__ import annotations

import datetime as dt
import hashlib
import hmac
import json
import os
from collections.abc import Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Any

from kasparctl.game.jsonl import record_to_plain
from kasparctl.game.session import PLAN_FILE, RECORDS_FILE
from kasparctl.research.anonymise import Pseudonyms
from kasparctl.research.catalogue import SessionData, derived_uid
from kasparctl.research.output import private_directory, write_bytes

MANIFEST = "MANIFEST.sha256"
_CROCKFORD = "0123456789ABCDEFGHJKMNPQRSTVWXYZ"


@dataclass(frozen=True)
class Keying:
    """The bundle's key, and the date shift it gives (timedelta(0) without a shift)."""

    key: bytes
    shift: dt.timedelta

    @classmethod
    def make(cls, secret: bytes | None, shift_dates: bool) -> Keying:
        """From a secret (random without one); a shift of 1-104 weeks back if asked."""
        key = secret if secret else os.urandom(32)
        weeks = 1 + _keyed_int(key, b"date shift") % 104
        return cls(key, dt.timedelta(weeks=-weeks) if shift_dates else dt.timedelta(0))

    def time(self, text: str) -> str:
        """An ISO 8601 time shifted; text that is no time is left as it is."""
        if not self.shift or not text:
            return text
        try:
            when = dt.datetime.fromisoformat(text)
        except ValueError:
            return text
        return (when + self.shift).isoformat(timespec="milliseconds")

    def uid(self, old: str, created: str) -> str:
        """The session's new ULID: its shifted start's milliseconds, a keyed hash's bits."""
        try:
            when = dt.datetime.fromisoformat(self.time(created))
            milliseconds = int(when.timestamp() * 1000) & ((1 << 48) - 1)
        except (ValueError, OverflowError, OSError):
            milliseconds = 0
        value = (milliseconds << 80) | (_keyed_int(self.key, old.encode()) & ((1 << 80) - 1))
        return "".join(_CROCKFORD[(value >> shift) & 31] for shift in range(125, -1, -5))


def _keyed_int(key: bytes, message: bytes) -> int:
    return int.from_bytes(hmac.new(key, message, hashlib.sha256).digest(), "big")


def _name(session: SessionData, keying: Keying) -> str:
    """The re-keyed readable id: the shifted start (UTC, to the second) and group code."""
    try:
        when = dt.datetime.fromisoformat(keying.time(session.created)).astimezone(dt.UTC)
        stamp = when.strftime("%Y%m%dT%H%M%S")
    except ValueError:
        stamp = "unknown"
    return f"{stamp}-{session.group}"


def anonymised_plan(
    plan: dict[str, Any], names: Pseudonyms, keying: Keying, uid: str, name: str
) -> dict[str, Any]:
    """plan.json with names dropped, ids re-keyed and its time shifted."""
    plain: dict[str, Any] = names.value(plan)
    plain.update(uid=uid, session=name, created=keying.time(str(plan.get("created", ""))))
    entry = plain.get("plan")
    if isinstance(entry, dict):
        entry["children"] = []
    return plain


def anonymised_record(
    record: dict[str, Any], names: Pseudonyms, keying: Keying, plan: dict[str, Any]
) -> dict[str, Any]:
    """A record with names replaced and its wall-clock times shifted."""
    plain: dict[str, Any] = names.value(record)
    plain["time"] = keying.time(str(plain.get("time", "")))
    if plain.get("kind") == "clock" and isinstance(plain.get("offset"), int | float):
        plain["offset"] = plain["offset"] + keying.shift.total_seconds()
    if plain.get("kind") == "session" and isinstance(plain.get("plan"), dict):
        plain["plan"] = plan  # the start record repeats plan.json
    return plain


def copy_session(session: SessionData, out: Path, keying: Keying) -> Path:
    """The session's anonymised copy under `out`/sessions; its directory."""
    names = Pseudonyms(session.first_names())
    try:
        plan_bytes = (session.directory / PLAN_FILE).read_bytes()
        raw = json.loads(plan_bytes)
    except (OSError, ValueError):
        raw = {}
        plan_bytes = b""
    old = session.uid or derived_uid(plan_bytes, session.created)
    uid, name = keying.uid(old, session.created), _name(session, keying)
    plan = anonymised_plan(raw if isinstance(raw, dict) else {}, names, keying, uid, name)
    directory = out / "sessions" / name
    suffix = 2
    while directory.exists():  # two groups' sessions in one second, shifted alike
        directory = out / "sessions" / f"{name}-{suffix}"
        suffix += 1
    private_directory(directory)
    write_bytes(directory / PLAN_FILE, _json(plan))
    lines = [
        _json(anonymised_record(record_to_plain(record), names, keying, plan))
        for record in session.records()
    ]
    write_bytes(directory / RECORDS_FILE, b"".join(lines))
    return directory


def _json(value: Any) -> bytes:
    return json.dumps(value, ensure_ascii=False, separators=(",", ":")).encode() + b"\n"


def write_manifest(out: Path) -> int:
    """MANIFEST.sha256 over every file of the bundle (sha256sum's format); files listed."""
    lines = []
    for path in sorted(p for p in out.rglob("*") if p.is_file() and p.name != MANIFEST):
        digest = hashlib.sha256(path.read_bytes()).hexdigest()
        lines.append(f"{digest}  {path.relative_to(out).as_posix()}\n")
    write_bytes(out / MANIFEST, "".join(lines).encode())
    return len(lines)


def copy_sessions(sessions: Sequence[SessionData], out: Path, keying: Keying) -> list[Path]:
    """Every session's anonymised copy, in order; their directories."""
    private_directory(out / "records")
    return [copy_session(session, out / "records", keying) for session in sessions]
