"""Identifiers that become file names or keys: voyage IDs and IMO numbers.

A voyage ID names its export files (`<run folder>/<voyage_id>.rtz`), so it must be a plain name:
`VOYAGE_ID_PATTERN` — a letter or digit, then up to 63 letters, digits, `.`, `_` or `-` — and no `..`.
That excludes path separators, absolute paths, control characters, newlines and spaces.
IMO numbers are seven digits whose last is the check digit: the sum of the first six digits weighted
7, 6, 5, 4, 3, 2, modulo 10.
Names (vessels, ports, suppliers, …) may hold any printable text but no control character or line break
(`has_control_characters`; `name_problem` also refuses spreadsheet formulas): they end up in log lines, terminals, Markdown tables and XML (RTZ), where one such
character forges a line, recolours a terminal or makes the file invalid. `printable` and `markdown_cell` escape
text for those places when it comes from elsewhere.
"""

from __future__ import annotations

import re

# C0 and C1 controls (ESC, CR, LF, NUL, …), DEL, and the Unicode line and paragraph separators
_CONTROL = re.compile("[\x00-\x1f\x7f-\x9f\u2028\u2029]")

VOYAGE_ID_PATTERN = r"^[A-Za-z0-9][A-Za-z0-9._-]{0,63}$"
VOYAGE_ID_MAX_LEN = 64
_VOYAGE_ID = re.compile(VOYAGE_ID_PATTERN)


def voyage_id_problem(voyage_id) -> str | None:
    """Why `voyage_id` is not a usable voyage ID (None when it is). The reason never repeats the ID
    itself, which may hold control characters; callers keep the raw text separately."""
    if voyage_id is None or (isinstance(voyage_id, float) and voyage_id != voyage_id):
        return "missing voyage_id"
    vid = str(voyage_id)
    if vid.strip() == "":
        return "missing voyage_id"
    if len(vid) > VOYAGE_ID_MAX_LEN:
        return f"voyage_id longer than {VOYAGE_ID_MAX_LEN} characters ({len(vid)})"
    if any(ord(ch) < 32 or ord(ch) == 127 for ch in vid):
        return "voyage_id contains control characters or a line break"
    if "/" in vid or "\\" in vid:
        return "voyage_id contains a path separator"
    if ".." in vid:
        return "voyage_id contains '..'"
    if not _VOYAGE_ID.match(vid):
        return "voyage_id has characters other than letters, digits, '.', '_' and '-' (or does not start with a letter or digit)"
    return None


class InvalidIdentifier(ValueError):
    """An identifier that cannot be used as given; the message says why and names it safely."""


def check_voyage_id(voyage_id) -> str:
    """`voyage_id` as a string, or InvalidIdentifier naming it (repr, so control characters show)."""
    problem = voyage_id_problem(voyage_id)
    if problem:
        shown = repr(str(voyage_id)) if len(str(voyage_id)) <= 80 else repr(str(voyage_id)[:80]) + "…"
        raise InvalidIdentifier(f"voyage {shown}: {problem}; a voyage ID must match {VOYAGE_ID_PATTERN} without '..'")
    return str(voyage_id)


def imo_check_digit(first_six: int) -> int:
    digits = [int(c) for c in f"{int(first_six):06d}"]
    return sum(d * w for d, w in zip(digits, range(7, 1, -1))) % 10


def is_valid_imo(imo: int) -> bool:
    """Seven digits whose last is the IMO check digit of the first six."""
    return 1_000_000 <= int(imo) <= 9_999_999 and imo_check_digit(int(imo) // 10) == int(imo) % 10


def has_control_characters(value) -> bool:
    """A text value holding a control character or a line break (non-text values: False)."""
    return isinstance(value, str) and _CONTROL.search(value) is not None


_FORMULA_START = ("=", "+", "-", "@")  # what a spreadsheet opening an export or a refused-rows CSV would evaluate


def name_problem(value) -> str | None:
    """Why a name (port, cargo type) cannot be used (None when it can): a control character or line break, or text a
    spreadsheet would run as a formula (starting with =, +, - or @ — a CSV or report opened in one executes it)."""
    if not isinstance(value, str):
        return None
    if has_control_characters(value):
        return "control characters or a line break"
    if value.strip().startswith(_FORMULA_START):
        return "starts with =, +, - or @ (a spreadsheet would run it as a formula)"
    return None


def printable(text) -> str:
    """`text` with every control character and line break written as an escape (`\\n`, `\\x1b`): safe in one log
    line or a terminal."""
    return _CONTROL.sub(lambda m: repr(m.group())[1:-1], "" if text is None else str(text))


def markdown_cell(text) -> str:
    """`text` for one cell of a Markdown table: printable, `|` escaped."""
    return printable(text).replace("|", "\\|")
