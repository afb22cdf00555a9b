"""Measured road profiles: CSV text to a road (errors name the line), content hashes, and the
``profile:ID`` names of profiles stored by the service.

The command line reads a file with :func:`road_from_csv`; the service parses an upload the same
way, stores it (table ``road_profiles``) and resolves ``profile:ID`` in a job's roads from it.
"""

from __future__ import annotations

import csv
import hashlib
import json
from collections.abc import Iterable, Iterator, Mapping

from finaldrive.engine import ProfileResolver, Road, RoadError


class ProfileError(ValueError):
    """A profile that is not a road; ``line`` is the 1-based line of the CSV text at fault, if one is."""

    def __init__(self, msg: str, line: int | None = None) -> None:
        super().__init__(msg if line is None else f"line {line}: {msg}")
        self.msg = msg
        self.line = line


def parse_csv(text: str) -> tuple[list[float], list[float], list[int]]:
    """(x, y, line numbers) of the rows of a CSV of x, y [m]: an optional header line, # comments
    and blank lines skipped. Raises ProfileError naming the line of a row that is not two numbers."""
    xs: list[float] = []
    ys: list[float] = []
    lines: list[int] = []
    header = False
    for number, row in _rows(text):
        if not row or not "".join(row).strip() or row[0].lstrip().startswith("#"):
            continue
        if not xs and not header and not _is_number(row[0]):
            header = True
            continue
        if len(row) != 2:
            raise ProfileError(f"expected two columns x, y, got {len(row)}", number)
        try:
            x, y = float(row[0]), float(row[1])
        except ValueError:
            raise ProfileError(f"x and y must be numbers, got {row[0].strip()[:24]!r}, {row[1].strip()[:24]!r}",
                               number) from None
        xs.append(x)
        ys.append(y)
        lines.append(number)
    return xs, ys, lines


def _rows(text: str) -> Iterator[tuple[int, list[str]]]:
    """(1-based line number, fields) of each row of CSV text; a row the csv module refuses (a field longer
    than ``csv.field_size_limit()``, 128 KiB) is a ProfileError naming its line."""
    reader = csv.reader(text.splitlines())
    while True:
        try:
            row = next(reader)
        except StopIteration:
            return
        except csv.Error as exc:
            raise ProfileError(f"not a CSV row: {exc}", reader.line_num) from None
        yield reader.line_num, row


def road_from_csv(text: str, name: str) -> Road:
    """The road through the CSV's points (see :func:`parse_csv`); ProfileError names the line at fault."""
    xs, ys, lines = parse_csv(text)
    try:
        return Road.from_points(xs, ys, name=name)
    except RoadError as exc:
        raise ProfileError(exc.msg, None if exc.row is None else lines[exc.row]) from None


def content_hash(road: Road) -> str:
    """sha256 of a profile road's points (not its name): its identity in the store and the result cache."""
    return hashlib.sha256(json.dumps([road.xs, road.ys], separators=(",", ":")).encode()).hexdigest()


def profile_ids(roads: Iterable[str]) -> set[int]:
    """The ids of stored profiles a job's road texts name (``profile:ID`` items)."""
    out = set()
    for text in roads:
        for item in text.split(","):
            name = item.strip()[len("profile:"):] if item.strip().lower().startswith("profile:") else ""
            if _is_id(name):
                out.add(int(name))
    return out


def resolver(stored: Mapping[int, Road]) -> ProfileResolver:
    """Resolves ``profile:ID`` from ``stored`` (id -> road); anything else is a ValueError saying what to give."""

    def resolve(name: str) -> Road:
        if not _is_id(name):
            raise ValueError(f"profile:{name[:40]}: expected profile:ID, the id of a profile uploaded with "
                             "POST /v1/roads (finaldrive submit uploads profile:FILE.csv itself)")
        road = stored.get(int(name))
        if road is None:
            raise ValueError(f"profile:{name}: no such road profile (upload it with POST /v1/roads)")
        return road

    return resolve


#: Largest id a profile can have (a BIGINT).
_MAX_ID = 2**63 - 1


def _is_id(text: str) -> bool:
    return text.isascii() and text.isdigit() and len(text) < 20 and 1 <= int(text) <= _MAX_ID


def _is_number(text: str) -> bool:
    try:
        float(text)
        return True
    except ValueError:
        return False
