"""Where everything lives under the one data root (default `./data`, env `JITROUTE_DATA`).

With an object root (`JITROUTE_OBJECT_ROOT`, e.g. `s3://bucket/jitroute`) the weather cube and the run exports live
there instead (`<object root>/cubes/weather.zarr`, `<object root>/exports/runs/<run id>/`); the warehouse, the raw
downloads and the locks stay under the local data root of the process that runs the jobs.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from pathlib import Path


@dataclass(frozen=True)
class DataLayout:
    root: Path
    object_root: str | None = None  # URL (s3://…) of the cube and the exports; None: both under `root`
    storage_options: dict = field(default_factory=dict, repr=False)  # fsspec options for object_root; may hold keys

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
        """Read-only copy for analysts, replaced atomically after each write once it passes the check (the newest
        recovery copy; `storage.warehouse.snapshot_generations` lists the older ones)."""
        return self.root / "warehouse.snapshot.duckdb"

    @property
    def exports(self) -> Path:
        return self.root / "exports"

    @property
    def weather_cube_url(self) -> str:
        """The cube as a URL or local path: under the object root when there is one."""
        return f"{self.object_root.rstrip('/')}/cubes/weather.zarr" if self.object_root else str(self.weather_cube)

    @property
    def cube_store(self):
        """The cube as `storage.cube` opens it: its path or URL with the storage options."""
        from storage.cube_location import locate

        return locate(self.weather_cube_url, self.storage_options)

    @property
    def cube_lock_dir(self) -> Path | None:
        """Where the cube's writer lock lives: beside a local cube (None), in `locks/` for a cube at a URL."""
        return self.locks if self.object_root else None

    @property
    def run_exports_url(self) -> str:
        """Where runs publish their export files (`runs/<run id>/`): under the object root when there is one."""
        return f"{self.object_root.rstrip('/')}/exports" if self.object_root else str(self.exports)

    @property
    def inbox(self) -> Path:
        """Input files (contracts, availability, ports, noon reports, fleet folders) for flow runs started through the
        Prefect API: a served flow reads files only from here (flows.settings.served_input_file)."""
        return self.root / "inbox"

    @property
    def locks(self) -> Path:
        return self.root / "locks"

    def is_data_root(self) -> bool:
        """The root exists and holds something a job made (warehouse, cubes/, raw/, exports/ or locks/): a read-only
        command (a check) given a mistyped root must fail, not report "nothing to check"."""
        return self.root.is_dir() and any(p.exists() for p in (self.warehouse, self.cubes, self.raw, self.exports,
                                                                self.locks))

    def ensure(self) -> "DataLayout":
        """Create the folders and check the warehouse: a job calls this before it writes anything, so a damaged
        warehouse stops it first (WarehouseCorruptError, naming the newest good snapshot)."""
        from storage import warehouse

        warehouse.check_before_writing(self.warehouse)
        for p in (self.root, self.raw, self.quarantine, self.cubes, self.exports, self.locks):
            p.mkdir(parents=True, exist_ok=True)
        return self
