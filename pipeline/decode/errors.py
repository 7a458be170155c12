"""Errors raised by decoders; every message names the file."""

from __future__ import annotations

from pathlib import Path


class DecodeError(Exception):
    """A file that cannot be decoded: corrupt, truncated, wrong grid or a field missing."""

    def __init__(self, path: Path | str, problem: str):
        self.path = Path(path)
        self.problem = problem
        super().__init__(f"{self.path.name}: {problem}")
