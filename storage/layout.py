"""Where everything lives under the one data root (default `./data`, env `JITROUTE_DATA`)."""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path


@dataclass(frozen=True)
class DataLayout:
    root: Path

    @property
    def raw(self) -> Path:
        """Downloaded source files, as fetched (checksummed in the ingest log)."""
        return self.root / "raw"

    @property
    def quarantine(self) -> Path:
        """Corrupt or truncated downloads, kept for inspection, never decoded again."""
        return self.root / "quarantine"

    @property
    def cubes(self) -> Path:
        return self.root / "cubes"

    @property
    def weather_cube(self) -> Path:
        return self.cubes / "weather.zarr"

    @property
    def warehouse(self) -> Path:
        return self.root / "warehouse.duckdb"

    @property
    def warehouse_snapshot(self) -> Path:
        """Read-only copy for analysts, replaced atomically after each write."""
        return self.root / "warehouse.snapshot.duckdb"

    @property
    def exports(self) -> Path:
        return self.root / "exports"

    @property
    def locks(self) -> Path:
        return self.root / "locks"

    def ensure(self) -> "DataLayout":
        for p in (self.root, self.raw, self.quarantine, self.cubes, self.exports, self.locks):
            p.mkdir(parents=True, exist_ok=True)
        return self
